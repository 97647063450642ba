"""``photogeom crs convert`` names the unit of every column it writes.

Before, its first comment line said only "EPSG:4979 -> EPSG:2263": x and y are then in US
survey feet, while z, which a CRS without a height axis does not convert, stays the input's
ellipsoidal height in metres, and nothing in the file said so. The line now ends with the
unit of each column.
"""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.io import read_points

pyproj = pytest.importorskip("pyproj")


@pytest.fixture
def lonlath(tmp_path):
    p = tmp_path / "ll.csv"
    p.write_text("id,lon,lat,h\np1,-74.0,40.7,100.0\np2,-73.9,40.8,-20.5\n")
    return p


def test_a_2d_target_says_z_is_not_converted(cli, lonlath, tmp_path):
    out = tmp_path / "ny.csv"
    code, _, err = cli("crs", "convert", lonlath, "--from", "EPSG:4979", "--to", "EPSG:2263",
                       "--allow-ballpark", "-o", out)  # fmt: skip
    assert code == 0, err
    first = out.read_text().splitlines()[0]
    assert first.endswith(
        "; x in ftUS, y in ftUS, z in m (the input's h, not converted: EPSG:2263 has no "
        "height axis)"
    )
    # independently: PROJ's two axes of EPSG:2263 are US survey feet, and z is h as given
    assert [a.unit_name for a in pyproj.CRS("EPSG:2263").axis_info] == ["US survey foot"] * 2
    np.testing.assert_array_equal(read_points(out).coords[:, 2], [100.0, -20.5])


def test_a_3d_target_and_the_round_trip(cli, lonlath, tmp_path):
    out = tmp_path / "ecef.csv"
    code, _, err = cli("crs", "convert", lonlath, "--from", "EPSG:4979", "--to", "EPSG:4978",
                       "-o", out)  # fmt: skip
    assert code == 0, err
    assert out.read_text().splitlines()[0] == "# EPSG:4979 -> EPSG:4978; x in m, y in m, z in m"
    back = tmp_path / "back.csv"  # the '# crs:' line still gives the CRS
    code, _, err = cli("crs", "convert", out, "--to", "EPSG:4979", "-o", back)
    assert code == 0, err
    assert back.read_text().splitlines()[0].endswith("; lon in deg, lat in deg, h in m")
    got, given = (read_points(p, "lon,lat,h").coords for p in (back, lonlath))
    np.testing.assert_allclose(got, given, atol=1e-7)
