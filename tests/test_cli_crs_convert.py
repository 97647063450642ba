"""`crs convert` of points that are not longitude, latitude (projected coordinates
given a geographic --from, a latitude of 95) stopped with PROJ's "Invalid latitude" naming
no point and no fix; a missing grid named the Python keyword allow_ballpark=True."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("pyproj")


def test_latitude_out_of_range_names_the_points_and_the_fix(cli, tmp_path: Path):
    pts = tmp_path / "p.csv"
    pts.write_text("id,lon,lat,h\nA,8,47,100\nB,8,95,100\nC,500000,5300000,100\n")
    out = tmp_path / "o.csv"
    code, _, err = cli("crs", "convert", pts, "--from", "EPSG:4979", "--to", "EPSG:4978",
                       "-o", out)
    assert code == 2 and not out.exists()
    assert "2 point(s) are not longitude, latitude in degrees" in err
    assert "B (lon 8, lat 95)" in err and "C (lon 500000, lat 5.3e+06)" in err
    assert "--from" in err and "--cols" in err and "PROJ" not in err


def test_valid_geographic_points_still_convert(cli, tmp_path: Path):
    pts = tmp_path / "p.csv"
    pts.write_text("id,lon,lat,h\nA,8,47,100\nB,-179.5,-89.9,0\n")
    code, out, err = cli("crs", "convert", pts, "--from", "EPSG:4979", "--to", "EPSG:4978")
    assert code == 0, err
    assert "\nid,x,y,z\n" in out


def test_ballpark_message_names_the_option_only():
    from photogeom.cli._common import in_cli_words

    msg = "no transformation ... (x); allow it explicitly (allow_ballpark=True / --allow-ballpark)"
    assert in_cli_words(msg).endswith("allow it explicitly (--allow-ballpark)")
