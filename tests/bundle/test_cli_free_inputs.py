"""`--free` reads the same in `bundle simulate` and `bundle adjust`: names or 'none'."""

from __future__ import annotations

import json

import pytest

import photogeom as pg

SMALL = ["-p", "FC6310", "--strips", "2", "--images-per-strip", "4",
         "--tie-points-per-image", "60"]


@pytest.mark.parametrize("given, expected", [("none", ()), ("NONE", ()), ("F,cx", ("f", "cx"))])
def test_simulate_marks_what_free_says(cli, tmp_path, given, expected):
    code, _, err = cli("bundle", "simulate", tmp_path / "b", *SMALL, "--free", given)
    assert code == 0, err
    block = pg.bundle.read_csv_block(tmp_path / "b")
    assert set(block.free.values()) == {expected}


def test_simulate_none_block_adjusts_with_none(cli, tmp_path):
    assert cli("bundle", "simulate", tmp_path / "b", *SMALL, "--free", "none")[0] == 0
    code, out, err = cli("bundle", "adjust", tmp_path / "b", "--free", "none", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["converged"]
    assert set(d["calibration_std"]["FC6310"].values()) == {None}  # nothing estimated


@pytest.mark.parametrize("command", ["simulate", "adjust"])
def test_unknown_names_are_refused_alike(cli, tmp_path, command):
    pg.bundle.write_csv_block(
        pg.simulate.uav_block("FC6310", seed=1, strips=2, images_per_strip=4,
                              tie_points_per_image=60).block,
        tmp_path / "src",
    )
    args = [tmp_path / "new", *SMALL] if command == "simulate" else [tmp_path / "src"]
    code, _, err = cli("bundle", command, *args, "--free", "f,zz")
    assert code == 2
    assert err.startswith("error: --free: unknown calibration parameter(s) zz;")
    assert not (tmp_path / "new").exists()
