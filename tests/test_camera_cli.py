"""Command line: camera project, camera dlt estimate/convert, orient resection/intersection,
and the camera examples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.examples import get
from photogeom.io import read_points
from photogeom.report import Report

IO = pg.InteriorOrientation(152.14, 0.008, -0.12)
EOS = [
    pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
    pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8),
]
CAMERA = ["--f", "152.14", "--x0", "0.008", "--y0", "-0.12"]


@pytest.fixture
def scene(tmp_path: Path):
    rng = np.random.default_rng(0)
    g = np.column_stack(
        [rng.uniform(1050, 1550, 12), rng.uniform(750, 1100, 12), rng.uniform(100, 300, 12)]
    )
    files = []
    for k, eo in enumerate(EOS):
        xy = pg.project(g, IO, eo) + rng.normal(0, 0.003, (12, 2))
        ctl = tmp_path / f"control{k}.csv"
        rows = [
            f"P{i},{'check' if i >= 10 else 'control'},{float(g[i, 0])!r},{float(g[i, 1])!r},"
            f"{float(g[i, 2])!r},{float(xy[i, 0])!r},{float(xy[i, 1])!r}"
            for i in range(12)
        ]
        ctl.write_text("id,role,X,Y,Z,x,y\n" + "\n".join(rows) + "\n")
        img = tmp_path / f"image{k}.csv"
        img.write_text(
            "id,x,y\n"
            + "\n".join(f"P{i},{float(xy[i, 0])!r},{float(xy[i, 1])!r}" for i in range(12))
            + "\n"
        )
        files.append((ctl, img))
    return g, files


def test_project_spec_examples(cli, tmp_path):
    pts = tmp_path / "g.csv"
    pts.write_text("id,X,Y,Z\nA,1300,650,169\n")
    code, out, err = cli("camera", "project", pts, *CAMERA, "--eo", "1114,862,1600,2,3,10")
    assert code == 0, err
    assert "A,22.7354" in out and ",-32.7917" in out
    code, out, err = cli(
        "camera",
        "project",
        pts,
        "--f",
        "10000",
        "--unit",
        "px",
        "--principal-point",
        "3840,6912",
        "--eo",
        "1160,792,1500,1.5,2,4",
        "--pixel",
        "--json",
    )
    assert code == 0, err
    p = json.loads(out)["points"][0]
    assert round(p["col"], 1) == 5152.8 and round(p["row"], 1) == 8345.3


def test_project_behind_camera(cli, tmp_path):
    pts = tmp_path / "g.csv"
    pts.write_text("id,X,Y,Z\nA,1300,650,169\nB,1100,860,2000\n")
    args = ["camera", "project", pts, *CAMERA, "--eo", "1114,862,1600,2,3,10"]
    code, _, err = cli(*args)
    assert code == 2 and "behind the camera" in err
    code, out, _ = cli(*args, "--behind", "nan")
    assert code == 0 and "B,nan,nan" in out


def test_dlt_estimate_and_convert(scene, tmp_path, cli):
    _, files = scene
    params = tmp_path / "dlt.json"
    code, out, err = cli(
        "camera", "dlt", "estimate", files[0][0], "--output-params", params, "--json"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["redundancy"] == 20 - 11 and len(data["check_residuals"]) == 2
    assert abs(data["orientation"]["exterior"]["X0"] - 1000) < 5
    # the decomposed orientation comes with its standard deviations, as the library's
    orient = data["orientation"]
    assert orient["std_kind"] == "a posteriori"
    assert set(orient["std"]) >= {"cx", "x0", "X0", "omega", "kappa"}
    assert all(v is not None and v > 0 for v in orient["std"].values())
    code, out, err = cli("camera", "dlt", "estimate", files[0][0])
    assert code == 0, err
    assert "std. dev. (a posteriori): cx" in out
    assert "Z0 = " in out and out.count("[m]") >= 2  # the projection centre and its std
    code, out, err = cli("camera", "dlt", "convert", "--params", params)
    assert code == 0, err
    assert "interior: cx =" in out
    code, out, err = cli(
        "camera", "dlt", "convert", *CAMERA, "--eo", "1114,862,1600,2,3,10", "--json"
    )
    L = json.loads(out)
    assert round(L["L4"], 4) == -109.9007 and round(L["L11"], 8) == -0.00061413
    code, out, err = cli("camera", "dlt", "estimate", files[0][0], "--constrained")
    assert code == 0, err
    assert "constrained DLT" in out


def test_resection_report_and_intersection(scene, tmp_path, cli):
    g, files = scene
    cams = []
    for k, (ctl, _) in enumerate(files):
        cam = tmp_path / f"cam{k}.json"
        rep = tmp_path / f"res{k}.html"
        code, out, err = cli(
            "orient",
            "resection",
            ctl,
            *CAMERA,
            "--sigma",
            "0.003",
            "--output-params",
            cam,
            "--report",
            rep,
        )
        assert code == 0, err
        assert "10 control, 2 check point(s)" in out and "v = computed - observed [mm]" in out
        html = rep.read_text()
        assert "<img" in html and "Image residual vectors" in html
        cams.append(cam)
    out_csv = tmp_path / "points.csv"
    code, _, err = cli(
        "orient",
        "intersection",
        files[0][1],
        files[1][1],
        "--camera",
        cams[0],
        "--camera",
        cams[1],
        "--sigma",
        "0.003",
        "-o",
        out_csv,
        "--report",
        tmp_path / "i.html",
    )
    assert code == 0, err
    table = read_points(out_csv, ["X", "Y", "Z"])
    np.testing.assert_allclose(table.coords, g, atol=1.0)  # noise 3 um -> decimetres
    assert any("ground unit of the cameras" in c for c in table.comments)
    assert "ground unit of the cameras" in (tmp_path / "i.html").read_text()
    code, _, err = cli("orient", "intersection", files[0][1], files[1][1], "--camera", cams[0])
    assert code == 2 and "one camera per image" in err


def test_resection_errors(cli, scene):
    _, files = scene
    code, _, err = cli("orient", "resection", files[0][0])
    assert code == 2 and "no camera given" in err
    code, _, err = cli("orient", "resection", files[0][0], *CAMERA, "--initial", "1,2,3")
    assert code == 2 and "expected 6" in err


@pytest.mark.parametrize("name", ["collinearity", "digital-camera", "affine-camera", "dlt"])
def test_examples_reproduce_published_numbers(name):
    text = get(name).run(None)
    line = next(ln for ln in text.splitlines() if "published numbers reproduced" in ln)
    n_ok, n_all = (int(w) for w in line.split()[:3:2])
    assert n_ok == n_all


def test_resection_example_with_report():
    rep = Report("examples")
    text = get("resection").run(rep)
    assert "estimate - truth in standard deviations" in text
    assert len(rep) >= 2
