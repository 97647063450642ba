"""`transform apply --crs`: a CRS contradicting the one the parameter file records for the
side the points are transformed to (the target, or the source with --inverse) is refused.

It used to be written into the output's '# crs:' line: output labelled with a CRS its
coordinates are not in. The input file's own '# crs:' line is checked against the side the
parameters transform from.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

SRC = "enu:47.1,8.5,400"
TGT = "EPSG:32632"
T = pg.Similarity3D.from_angles(1.00002, 0.001, -0.002, 0.4, [480000.0, 5300000.0, 250.0])


@pytest.fixture
def params(tmp_path):
    """A parameter file recording source and target CRS, one recording none, and points."""
    rec = tmp_path / "params.json"
    rec.write_text(json.dumps({**T.to_dict(), "crs": TGT, "source_crs": SRC}))
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(T.to_dict()))
    pts = tmp_path / "pts.csv"
    pts.write_text("id,x,y,z\n1,10,20,3\n2,-5,7,1\n")
    back = tmp_path / "back.csv"
    back.write_text("id,X,Y,Z\n1,480010,5300020,253\n")
    return rec, bare, pts, back


def _coords(out: str) -> np.ndarray:
    rows = [ln.split(",") for ln in out.splitlines() if ln and not ln.startswith("#")][1:]
    return np.array([[float(v) for v in r[1:4]] for r in rows])


def _crs_line(out: str) -> str | None:
    lines = [ln for ln in out.splitlines() if ln.startswith("# crs:")]
    return lines[0][len("# crs:"):].strip() if lines else None


def test_contradicting_crs_is_refused(cli, params, tmp_path):
    rec, _, pts, back = params
    out_csv = tmp_path / "out.csv"
    code, out, err = cli("transform", "apply", rec, pts, "--crs", "EPSG:25832", "-o", out_csv)
    assert code == 2 and out == ""
    assert err.startswith("error: --crs EPSG:25832") and TGT in err and "target CRS" in err
    assert not out_csv.exists()
    # with --inverse the points are transformed to the source CRS
    code, out, err = cli("transform", "apply", rec, back, "--inverse", "--crs", TGT)
    assert code == 2 and out == "" and "--crs EPSG:32632" in err and SRC in err
    assert "--inverse" in err
    # refused before the points file is read
    code, out, err = cli("transform", "apply", rec, tmp_path / "none.csv", "--crs", "EPSG:25832")
    assert code == 2 and "--crs EPSG:25832" in err and "none.csv" not in err


def test_agreeing_crs_gives_the_same_output(cli, params):
    rec, bare, pts, back = params
    code, out, err = cli("transform", "apply", rec, pts)
    assert code == 0, err
    assert _crs_line(out) == TGT
    np.testing.assert_allclose(_coords(out), T.apply(np.array([[10, 20, 3], [-5, 7, 1.0]])))
    # the same CRS spelled otherwise is accepted
    code, out2, err = cli("transform", "apply", rec, pts, "--crs", "epsg:32632")
    assert code == 0, err
    np.testing.assert_array_equal(_coords(out2), _coords(out))
    code, out, err = cli("transform", "apply", rec, back, "--inverse", "--crs", SRC)
    assert code == 0, err
    assert _crs_line(out) == SRC
    # a parameter file without a record: --crs is what the output records
    code, out, err = cli("transform", "apply", bare, pts, "--crs", "EPSG:25832")
    assert code == 0, err
    assert _crs_line(out) == "EPSG:25832"
    code, out, err = cli("transform", "apply", bare, pts)
    assert code == 0 and _crs_line(out) is None


def test_input_crs_line_must_name_the_source_side(cli, params, tmp_path):
    rec, _, _, _ = params
    wrong = tmp_path / "wrong.csv"
    wrong.write_text(f"# crs: {TGT}\nid,x,y,z\n1,10,20,3\n")
    code, out, err = cli("transform", "apply", rec, wrong)
    assert code == 2 and out == "" and f"records the CRS {TGT}" in err and SRC in err
    code, out, err = cli("transform", "apply", rec, wrong, "--inverse")
    assert code == 0, err
    assert _crs_line(out) == SRC
    local = tmp_path / "local.csv"
    local.write_text(f"# crs: {SRC}\nid,X,Y,Z\n1,480010,5300020,253\n")
    code, out, err = cli("transform", "apply", rec, local, "--inverse")
    assert code == 2 and out == "" and f"records the CRS {SRC}" in err and "(--inverse)" in err
    code, out, err = cli("transform", "apply", rec, local)
    assert code == 0 and _crs_line(out) == TGT
