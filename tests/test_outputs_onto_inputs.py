"""An output option naming an input file is refused before the computation (the report or
the parameters would replace the data they are computed from)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from photogeom import datasets

FIDUCIALS = datasets.path("lecture_fiducials")


@pytest.mark.parametrize("option", ["--output-params", "--report"])
def test_transform_estimate_refuses_its_source_as_output(cli, tmp_path: Path, option):
    src = tmp_path / "fid.csv"
    shutil.copy(FIDUCIALS, src)
    before = src.read_bytes()
    code, _, err = cli("transform", "estimate", "similarity2d", src, option, src)
    assert code == 2
    assert f"{option} {src} is the input file SOURCE" in err
    assert "give " + option + " another file" in err
    assert src.read_bytes() == before


def test_a_link_to_the_input_is_the_input(cli, tmp_path: Path):
    src = tmp_path / "fid.csv"
    shutil.copy(FIDUCIALS, src)
    link = tmp_path / "link.json"
    link.symlink_to(src)
    code, _, err = cli("transform", "estimate", "similarity2d", src, "--output-params", link)
    assert code == 2 and "is the input file SOURCE" in err


def test_orient_absolute_refuses_its_target_as_report(cli, tmp_path: Path):
    t = datasets.load("lidar_wang2014")
    src = tmp_path / "model.csv"
    dst = tmp_path / "ground.csv"
    src.write_text("id,x,y,z\n" + "".join(
        f"{i},{a},{b},{c}\n" for i, a, b, c in zip(t["id"], t["x"], t["y"], t["z"])))
    dst.write_text("id,X,Y,Z\n" + "".join(
        f"{i},{a},{b},{c}\n" for i, a, b, c in zip(t["id"], t["X"], t["Y"], t["Z"])))
    before = dst.read_bytes()
    code, _, err = cli("orient", "absolute", src, dst, "--report", dst)
    assert code == 2 and f"--report {dst} is the input file TARGET" in err
    assert dst.read_bytes() == before


def test_other_outputs_are_still_written(cli, tmp_path: Path):
    src = tmp_path / "fid.csv"
    shutil.copy(FIDUCIALS, src)
    code, _, err = cli("transform", "estimate", "similarity2d", src,
                       "--output-params", tmp_path / "p.json")
    assert code == 0, err
    assert (tmp_path / "p.json").is_file()
