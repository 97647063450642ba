"""`photogeom rpc info|project|localize|fit|refine` and the RPC examples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.examples import get
from photogeom.examples.rpc import simulated_control
from photogeom.io import read_points, write_points
from photogeom.rpc import RPC

WV2 = str(pg.datasets.path("worldview2"))


@pytest.fixture(scope="module")
def control_csv(tmp_path_factory) -> Path:
    _, ground, true, observed = simulated_control()
    p = tmp_path_factory.mktemp("rpc") / "control.csv"
    coords = np.column_stack([ground, np.vstack([observed[:4], true[4:]])])
    roles = ["control"] * 4 + ["check"] * 20
    write_points(p, [f"P{i}" for i in range(24)], coords, ["lon", "lat", "h", "col", "row"],
                 extra={"role": roles})  # fmt: skip
    return p


def test_info_text_and_json(cli):
    code, out, err = cli("rpc", "info", WV2)
    assert code == 0, err
    assert "centre of the first pixel" in out and "28244 x 20289" in out and "top-left" in out
    code, out, _ = cli("rpc", "info", WV2, "--json")
    data = json.loads(out)
    assert data["metadata"]["LINE_OFF"] == 10108.0
    assert len(data["footprint_lon_lat_deg"]) == 4


def test_project_and_localize_round_trip(cli, tmp_path):
    rpc = RPC.from_file(WV2)
    g = tmp_path / "ground.csv"
    g.write_text("id,lon,lat,h\np1,-0.33,45.65,100\np2,-0.30,45.66,50\n")
    img = tmp_path / "img.csv"
    code, _, err = cli("rpc", "project", WV2, g, "-o", img)
    assert code == 0, err
    t = read_points(img, ["col", "row"])
    c, r = rpc.project([-0.33, -0.30], [45.65, 45.66], [100.0, 50.0])
    np.testing.assert_array_equal(t.coords, np.column_stack([c, r]))
    # localize at per-point heights from a column
    li = tmp_path / "loc.csv"
    c, r = c.tolist(), r.tolist()
    li.write_text(f"id,col,row,h\np1,{c[0]!r},{r[0]!r},100\np2,{c[1]!r},{r[1]!r},50\n")
    code, out, err = cli("rpc", "localize", WV2, li)
    assert code == 0, err
    lines = [x for x in out.splitlines() if x.startswith("p")]
    lon1, lat1 = (float(v) for v in lines[0].split(",")[1:3])
    assert abs(lon1 + 0.33) < 1e-9 and abs(lat1 - 45.65) < 1e-9
    assert lines[0].endswith(",converged")
    code, out, _ = cli("rpc", "localize", WV2, img, "--height", "100", "--json")
    data = json.loads(out)
    assert data["counts"]["converged"] == 2
    assert abs(data["points"][0]["lon"] + 0.33) < 1e-9


def test_localize_failures_are_reported_not_guessed(cli, tmp_path):
    li = tmp_path / "bad.csv"
    li.write_text("id,col,row,h\nok,1000,2000,100\nfar,50000000,3,0\n")
    code, out, err = cli("rpc", "localize", WV2, li)
    assert code == 0
    assert "far,nan,nan,0.0,diverged" in out
    assert "did not converge" in err
    code, _, err = cli("rpc", "localize", WV2, li, "--strict")
    assert code == 2 and "did not converge" in err
    nh = tmp_path / "noh.csv"
    nh.write_text("id,col,row\na,1,2\n")
    code, _, err = cli("rpc", "localize", WV2, nh)
    assert code == 2 and "height" in err


def test_refine_with_check_points_and_outputs(cli, control_csv, tmp_path):
    out_rpc = tmp_path / "refined_RPC.TXT"
    rep = tmp_path / "refine.html"
    code, out, err = cli("rpc", "refine", WV2, control_csv, "--model", "shift+drift",
                         "--sigma", "0.3", "-o", out_rpc, "--report", rep)  # fmt: skip
    assert code == 0, err
    assert "a0" in out and "b2" in out and "check" in out.lower()
    assert rep.read_text().startswith("<!DOCTYPE html>")
    refined = RPC.from_file(out_rpc)
    rpc, ground, true, _ = simulated_control()
    c, r = refined.project(*ground[4:].T)
    # the written (re-fitted) model reproduces the true check positions to the noise level
    assert np.sqrt(np.mean((np.column_stack([c, r]) - true[4:]) ** 2)) < 0.5
    code, out, _ = cli("rpc", "refine", WV2, control_csv, "--model", "shift", "--json")
    data = json.loads(out)
    assert set(data["parameters"]) == {"a0", "b0"}
    assert data["input"]["n_check"] == 20
    # the shift-only model folds exactly into the offsets
    out2 = tmp_path / "shift_RPC.TXT"
    code, _, _ = cli("rpc", "refine", WV2, control_csv, "--model", "shift", "-o", out2)
    assert RPC.from_file(out2).samp_off == pytest.approx(
        rpc.samp_off + data["parameters"]["a0"]["value"], abs=1e-12
    )


def test_fit_command(cli, tmp_path):
    rpc = RPC.from_file(WV2)
    rng = np.random.default_rng(1)
    c, r, h = rng.uniform(0, 28000, 30), rng.uniform(0, 20000, 30), rng.uniform(0, 500, 30)
    lon, lat = rpc.localize(c, r, h)
    p = tmp_path / "many.csv"
    roles = {"role": ["control"] * 25 + ["check"] * 5}
    cols = ["lon", "lat", "h", "col", "row"]
    write_points(p, [f"Q{i}" for i in range(30)], np.column_stack([lon, lat, h, c, r]), cols,
                 extra=roles)  # fmt: skip
    out_rpc = tmp_path / "fit_RPC.TXT"
    code, out, err = cli("rpc", "fit", p, "-o", out_rpc, "--order", "1")
    assert code == 0, err
    assert "SAMP_NUM_1" in out and "wrote" in out
    assert RPC.from_file(out_rpc).coefficients.shape == (4, 20)
    code, _, err = cli("rpc", "fit", p, "--order", "3")
    assert code == 2 and "at least 39" in err


def test_bad_files_give_one_line_errors(cli, tmp_path):
    bad = tmp_path / "x_RPC.TXT"
    bad.write_text("LINE_OFF: 1\n")
    code, _, err = cli("rpc", "info", bad)
    assert code == 2 and "missing key" in err


@pytest.mark.parametrize("name", ["rpc-files", "rpc-round-trip", "rpc-bias"])
def test_examples_run(name):
    from photogeom.report import Report

    # the bias example's report (residual plots) is exercised by the refine command's test
    rep = None if name == "rpc-bias" else Report("examples")
    text = get(name).run(rep)
    assert text and (rep is None or len(rep) > 0)
    if name == "rpc-bias":
        assert "shift+drift" in text
    if name == "rpc-files":
        for f in ("quickbird", "ikonos", "skysat", "pleiades", "worldview2"):
            assert f in text


def test_localize_into_a_crs_names_its_columns_for_the_next_command(cli, tmp_path):
    """rpc localize --crs writes lon,lat,h for a geographic CRS (what rpc project reads),
    x,y,z for a projected one; a geographic output goes back through rpc project."""
    li = tmp_path / "loc.csv"
    li.write_text("id,col,row\np1,14000.5,10000.25\np2,15000,11000\n")
    geo = tmp_path / "geo.csv"
    code, _, err = cli("rpc", "localize", WV2, li, "--height", "80", "--crs", "EPSG:4979",
                       "-o", geo)  # fmt: skip
    assert code == 0, err
    t = read_points(geo, ["lon", "lat", "h"])
    back = tmp_path / "back.csv"
    code, _, err = cli("rpc", "project", WV2, geo, "-o", back)
    assert code == 0, err
    np.testing.assert_allclose(read_points(back, ["col", "row"]).coords,
                               [[14000.5, 10000.25], [15000, 11000]], atol=1e-6)  # fmt: skip
    assert t.coords.shape == (2, 3)
    code, out, err = cli("rpc", "localize", WV2, li, "--height", "80", "--crs", "EPSG:32630",
                         "--json")  # fmt: skip
    assert code == 0, err
    assert set(json.loads(out)["points"][0]) >= {"x", "y", "z"}
