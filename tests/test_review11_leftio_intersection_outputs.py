"""``orient intersection --camera c1.json ... -o c1.json`` replaced the camera file with the
intersected points (review 11; exit 0): only the IMAGES were checked as inputs. The
``--camera`` files are now inputs too, refused as destinations before the computation."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from photogeom import datasets


@pytest.fixture
def block(cli, tmp_path: Path) -> dict[str, Path]:
    pts = tmp_path / "pts.csv"
    shutil.copyfile(datasets.path("lecture_two_images"), pts)
    c1, c2 = tmp_path / "c1.json", tmp_path / "c2.json"
    code, _, err = cli("orient", "relative", pts, "--f", "100", "--unit", "px", "--method",
                       "independent", "--output-cameras", c1, c2)
    assert code == 0, err
    rows = [ln.split(",") for ln in pts.read_text().splitlines() if not ln.startswith("#")]
    images = []
    for k, (x, y) in enumerate(((1, 2), (3, 4)), start=1):
        f = tmp_path / f"img{k}.csv"
        f.write_text("\n".join(["id,x,y"] + [f"{r[0]},{r[x]},{r[y]}" for r in rows[1:]]) + "\n")
        images.append(f)
    return {"i1": images[0], "i2": images[1], "c1": c1, "c2": c2}


@pytest.mark.parametrize("option,cam", [("-o", "c1"), ("--report", "c2")])
def test_an_output_onto_a_camera_file_is_refused(cli, block, option, cam):
    before = block[cam].read_bytes()
    code, _, err = cli("orient", "intersection", block["i1"], block["i2"], "--camera",
                       block["c1"], "--camera", block["c2"], option, block[cam])
    assert code == 2
    assert f"is the input file --camera {block[cam]}" in err
    assert block[cam].read_bytes() == before


def test_other_outputs_are_written(cli, block, tmp_path: Path):
    out = tmp_path / "xyz.csv"
    code, _, err = cli("orient", "intersection", block["i1"], block["i2"], "--camera",
                       block["c1"], "--camera", block["c2"], "-o", out)
    assert code == 0, err
    assert out.is_file()
