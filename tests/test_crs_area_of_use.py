"""crs convert warns when points land outside the area of use of the projected CRS they are
converted to (the wrong UTM zone), naming the count and the first point."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom import crs as pgcrs

pytest.importorskip("pyproj")


def test_area_of_use_of_projected_crs_only():
    a = pgcrs.projected_area_of_use("EPSG:32632")
    assert (a.west, a.south, a.east, a.north) == (6.0, 0.0, 12.0, 84.0)
    np.testing.assert_array_equal(
        a.outside([9.0, 13.0, -170.0, 9.0, 369.0], [45.0, 45.0, 45.0, -1.0, 45.0]),
        [False, True, True, True, False],
    )
    assert pgcrs.projected_area_of_use("EPSG:4979") is None
    assert pgcrs.projected_area_of_use("EPSG:4978") is None
    # an area across the antimeridian (west > east)
    pdc = pgcrs.projected_area_of_use("EPSG:3832")
    assert pdc.west > pdc.east
    assert not pdc.outside(179.0, 0.0).any() and not pdc.outside(-170.0, 0.0).any()
    assert pdc.outside(0.0, 0.0).all()


def test_crs_convert_warns_outside_the_zone(cli, tmp_path):
    geo = tmp_path / "geo.csv"
    geo.write_text("id,lon,lat,h\nA,9.1,47.2,500\nB,13.5,47.0,400\nC,-56.0,-34.9,10\n")
    utm = tmp_path / "utm.csv"
    code, _out, err = cli("crs", "convert", str(geo), "--from", "EPSG:4979", "--to",
                          "EPSG:32632", "-o", str(utm))
    assert code == 0, err
    assert "warning: 2 of 3 point(s) (first: B) lie outside the area of use of EPSG:32632" in err
    assert "check --to" in err
    # from projected coordinates: where they are is taken from the output
    code, _out, err = cli("crs", "convert", str(utm), "--to", "EPSG:32633", "-o",
                          str(tmp_path / "u33.csv"))
    assert code == 0, err
    assert "2 of 3 point(s) (first: A)" in err and "EPSG:32633" in err
    # inside: no warning; a geocentric target has no area to leave
    inside = tmp_path / "in.csv"
    inside.write_text("id,lon,lat,h\nA,9.1,47.2,500\nB,11.5,47.0,400\n")
    for to in ("EPSG:32632", "EPSG:4978"):
        code, _out, err = cli("crs", "convert", str(inside), "--from", "EPSG:4979", "--to",
                              to, "-o", str(tmp_path / "o.csv"))
        assert code == 0 and "warning" not in err, err
