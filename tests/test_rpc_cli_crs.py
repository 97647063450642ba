"""`rpc project`, `rpc fit`, `rpc refine`: the CRS a point file records is not overridden.

`rpc project --crs X` used to project a file whose '# crs:' line said another CRS as if
its coordinates were in X (exit 0, columns of garbage); `rpc fit` / `rpc refine` took
ground columns in any recorded CRS for lon, lat, h of WGS 84.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

pyproj = pytest.importorskip("pyproj")

IKONOS = pg.datasets.path("ikonos")
LONLATH = np.array([[-56.24, -34.948, 30.0], [-56.166, -34.9165, 12.0]])


def _csv(path, header, rows, crs=None):
    lines = ([f"# crs: {crs}"] if crs else []) + [header]
    lines += [f"p{i}," + ",".join(repr(float(v)) for v in r) for i, r in enumerate(rows)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _utm():
    t = pyproj.Transformer.from_crs(4979, 32721, always_xy=True)
    return np.column_stack(t.transform(*LONLATH.T))


@pytest.mark.parametrize(
    "file_crs, option, header, coords",
    [
        ("EPSG:4979", "EPSG:32721", "id,lon,lat,h", lambda: LONLATH),  # a geographic file into UTM
        ("EPSG:32721", "EPSG:4979", "id,x,y,z", _utm),
        ("EPSG:32721", "EPSG:32722", "id,x,y,z", _utm),
        ("enu:-34.9,-56.2,0", "EPSG:32721", "id,x,y,z", _utm),
    ],
)
def test_project_refuses_a_crs_option_contradicting_the_file(
    cli, tmp_path, file_crs, option, header, coords
):
    pts = _csv(tmp_path / "g.csv", header, coords(), crs=file_crs)
    out_csv = tmp_path / "out.csv"
    code, out, err = cli("rpc", "project", IKONOS, pts, "--crs", option, "-o", out_csv)
    assert code == 2 and out == ""
    assert err.startswith("error: ") and f"records the CRS {file_crs}" in err
    assert f"--crs says {option}" in err and "leave --crs out" in err
    assert not out_csv.exists()


def test_project_with_the_files_own_crs_or_none_gives_the_same_pixels(cli, tmp_path):
    code, out, err = cli("rpc", "project", IKONOS, _csv(tmp_path / "a.csv", "id,lon,lat,h",
                                                         LONLATH), "--json")  # fmt: skip
    assert code == 0, err
    want = np.array([[p["col"], p["row"]] for p in json.loads(out)["points"]])
    rpc = pg.RPC.from_file(IKONOS)
    np.testing.assert_allclose(want, np.column_stack(rpc.project(*LONLATH.T)), atol=1e-9)
    geo = _csv(tmp_path / "geo.csv", "id,lon,lat,h", LONLATH, crs="EPSG:4979")
    utm = _csv(tmp_path / "utm.csv", "id,x,y,z", _utm(), crs="EPSG:32721")
    for args in ((geo,), (geo, "--crs", "EPSG:4979"), (utm,), (utm, "--crs", "EPSG:32721"),
                 (utm, "--crs", "epsg:32721")):  # fmt: skip
        code, out, err = cli("rpc", "project", IKONOS, *args, "--json")
        assert code == 0, (args, err)
        got = np.array([[p["col"], p["row"]] for p in json.loads(out)["points"]])
        np.testing.assert_allclose(got, want, atol=1e-6)


def test_project_names_an_unreadable_crs_line(cli, tmp_path):
    pts = _csv(tmp_path / "g.csv", "id,x,y,z", _utm(), crs="EPSG:99999")
    code, _, err = cli("rpc", "project", IKONOS, pts, "--crs", "EPSG:32721")
    assert code == 2 and f"{pts} ('# crs:' line)" in err and "EPSG:99999" in err


def _control_rows():
    rpc = pg.RPC.from_file(IKONOS)
    rng = np.random.default_rng(3)
    lon = rng.uniform(-56.24, -56.11, 30)
    lat = rng.uniform(-34.96, -34.85, 30)
    h = rng.uniform(0, 80, 30)
    col, row = rpc.project(lon, lat, h)
    return np.column_stack([lon, lat, h, col, row])


@pytest.mark.parametrize("command", [["fit"], ["refine", str(IKONOS)]])
def test_fit_and_refine_refuse_ground_columns_in_another_crs(cli, tmp_path, command):
    rows = _control_rows()
    header = "id,lon,lat,h,col,row"
    ok = _csv(tmp_path / "ok.csv", header, rows, crs="EPSG:4979")
    code, _, err = cli("rpc", *command, ok, "--json")
    assert code == 0, err
    bad = _csv(tmp_path / "bad.csv", header, rows, crs="EPSG:32721")
    code, out, err = cli("rpc", *command, bad, "--json")
    assert code == 2 and out == ""
    assert "records the CRS EPSG:32721" in err and "EPSG:4979" in err and "crs convert" in err
