"""`photogeom bundle convert --angle-unit arcsec`: refused while `bundle adjust -o` writes
the same block in degrees; both now accept it and write deg, saying so."""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    from photogeom.cli.main import main

    path = tmp_path_factory.mktemp("arcsec") / "blk"
    try:
        main(["bundle", "simulate", str(path), "--strips", "2", "--images-per-strip", "3",
              "--tie-points-per-image", "30"])  # fmt: skip
    except SystemExit as exc:
        assert not exc.code
    return path


def test_convert_takes_arcsec_as_adjust_does(cli, block, tmp_path):
    out = tmp_path / "c"
    code, text, err = cli("bundle", "convert", block, out, "--to", "csv", "--angle-unit", "arcsec")
    assert code == 0, err
    assert "angles written in deg" in text
    header = (out / "images.csv").read_text().splitlines()[1]
    assert "omega_deg" in header
    # the same numbers as --angle-unit deg
    deg = tmp_path / "d"
    code, _, err = cli("bundle", "convert", block, deg, "--to", "csv", "--angle-unit", "deg")
    assert code == 0, err
    assert (deg / "images.csv").read_text() == (out / "images.csv").read_text()
    code, text, err = cli(
        "bundle", "convert", block, tmp_path / "j", "--to", "csv", "--angle-unit", "arcsec",
        "--json",
    )  # fmt: skip
    assert code == 0, err
    assert json.loads(text)["angle_unit"] == "deg"


def test_adjust_says_it_wrote_deg_for_arcsec(cli, block, tmp_path):
    code, text, err = cli(
        "bundle", "adjust", block, "-o", tmp_path / "a", "--angle-unit", "arcsec", "--no-snooping"
    )
    assert code == 0, err
    assert "angles written in deg" in text
