"""``rpc project --json`` and ``rpc localize --json`` name the unit of every coordinate.

Before, neither had a ``"units"`` mapping: ``rpc project`` gave col, row with the pixel
convention but no unit, and ``rpc localize --crs`` gave x, y, z in a CRS whose axes may be
feet or degrees, while z of a CRS without a height axis (a 2D projected CRS such as
EPSG:32721) is the ellipsoidal height of WGS 84 in metres that PROJ passes through, which
neither the JSON nor the CSV said.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

pyproj = pytest.importorskip("pyproj")

IKONOS = pg.datasets.path("ikonos")
LONLATH = np.array([[-56.24, -34.948, 30.0], [-56.166, -34.9165, 12.0]])


@pytest.fixture
def image_points(tmp_path):
    col, row = pg.RPC.from_file(IKONOS).project(*LONLATH.T)
    path = tmp_path / "img.csv"
    cells = np.column_stack([col, row, LONLATH[:, 2]]).tolist()
    rows = [f"p{i},{c!r},{r!r},{h!r}" for i, (c, r, h) in enumerate(cells)]
    path.write_text("id,col,row,h\n" + "\n".join(rows) + "\n")
    return path


def test_project_names_pixels(cli, tmp_path):
    pts = tmp_path / "g.csv"
    rows = [f"p{i},{a!r},{b!r},{c!r}" for i, (a, b, c) in enumerate(LONLATH.tolist())]
    pts.write_text("id,lon,lat,h\n" + "\n".join(rows) + "\n")
    code, out, err = cli("rpc", "project", IKONOS, pts, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["units"] == {"col": "px", "row": "px"}
    assert set(d["units"]) == set(d["points"][0]) - {"id"}


@pytest.mark.parametrize(
    ("crs", "units"),
    [
        (None, {"lon": "deg", "lat": "deg", "h": "m"}),
        ("EPSG:4979", {"lon": "deg", "lat": "deg", "h": "m"}),
        ("enu:-34.93,-56.2,0", {"E": "m", "N": "m", "U": "m"}),
        (
            "EPSG:32721",
            {
                "x": "m",
                "y": "m",
                "z": "m (ellipsoidal height of WGS 84, not converted: the CRS has no height)",
            },
        ),
    ],
)
def test_localize_names_the_unit_of_each_column(cli, image_points, tmp_path, crs, units):
    more = () if crs is None else ("--crs", crs)
    code, out, err = cli("rpc", "localize", IKONOS, image_points, *more, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["units"] == units
    assert set(d["units"]) == set(d["points"][0]) - {"id", "status", "iterations"}
    if crs == "EPSG:32721":
        # independently: PROJ's two axes of the CRS are metres, and the third column is the
        # height given, passed through
        assert [a.unit_name for a in pyproj.CRS(crs).axis_info] == ["metre", "metre"]
        np.testing.assert_allclose([p["z"] for p in d["points"]], LONLATH[:, 2], atol=1e-9)
        out_csv = tmp_path / "out.csv"
        code, _, err = cli("rpc", "localize", IKONOS, image_points, *more, "-o", out_csv)
        assert code == 0, err
        head = out_csv.read_text().splitlines()[0]
        assert "x in m, y in m, z in m (ellipsoidal height of WGS 84, not converted" in head
