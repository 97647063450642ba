"""``photogeom cloud info`` names the unit of the coordinates it prints.

Before, the text and ``--json`` gave scales, offsets, min and max with no unit, although the
file's CRS record says it (metres for EPSG:32633, US survey feet for EPSG:2263+6360); the
Z of a 2D CRS and the coordinates of a file without a CRS record have none, which it now
says instead of leaving the reader to guess.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.cli.cloud import NO_UNIT

laspy = pytest.importorskip("laspy")
pyproj = pytest.importorskip("pyproj")


@pytest.mark.parametrize(
    ("crs", "units"),
    [
        ("EPSG:32633", {"X": "m", "Y": "m", "Z": NO_UNIT}),
        ("EPSG:2263+6360", {"X": "ftUS", "Y": "ftUS", "Z": "ftUS"}),
        (None, {"X": NO_UNIT, "Y": NO_UNIT, "Z": NO_UNIT}),
    ],
)
def test_info_names_the_units(cli, tmp_path, crs, units):
    x = np.random.default_rng(1).uniform(0, 10, (20, 3)) + np.array([480000.0, 5300000.0, 250.0])
    path = tmp_path / "c.laz"
    pg.io.write_cloud(path, x, crs=crs)
    if crs is not None:  # independently, the axes PROJ gives the CRS
        axes = pyproj.CRS(crs).axis_info
        want = {"metre": "m", "US survey foot": "ftUS"}
        assert [want[a.unit_name] for a in axes] == [u for u in units.values() if u != NO_UNIT]
    code, out, err = cli("cloud", "info", path, "--json")
    assert code == 0, err
    assert json.loads(out)["units"] == units
    code, out, err = cli("cloud", "info", path)
    assert code == 0, err
    line = next(s for s in out.splitlines() if s.startswith("units "))
    if crs is None:
        assert line == "units   not recorded (no CRS) (of scales, offsets, min, max)"
    else:
        assert line == "units   " + ", ".join(f"{k} {u}" for k, u in units.items()) + (
            " (of scales, offsets, min, max)"
        )


def test_axis_units_as_labelled():
    from photogeom.crs import axis_units

    assert axis_units("EPSG:4979") == ["deg", "deg", "m"]
    assert axis_units("EPSG:2263") == ["ftUS", "ftUS"]
    assert axis_units("EPSG:32633") == ["m", "m"]
    assert axis_units("enu:47.1,8.5,500") == ["m", "m", "m"]
