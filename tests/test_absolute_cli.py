"""`photogeom orient absolute` and the absolute orientation examples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.examples import get

LIDAR = str(datasets.path("lidar_wang2014"))
KRAUS = str(datasets.path("kraus_absolute_orientation"))


def test_kraus_gon_in_the_table(cli):
    code, out, err = cli("orient", "absolute", KRAUS, "--method", "gauss-markov",
                         "--angle-unit", "gon")
    assert code == 0, err
    assert "-0.185368 gon" in out and "-1.091984 gon" in out
    assert "transposed convention" in out


def test_json_output_and_direct_convention(cli):
    code, out, err = cli("orient", "absolute", LIDAR, "--json", "--convention", "direct",
                         "--angle-unit", "deg", "--method", "quaternion")
    assert code == 0, err
    d = json.loads(out)
    assert d["method"] == "quaternion"
    assert d["angles"]["convention"] == "direct" and d["angles"]["unit"] == "deg"
    assert d["parameters"]["scale"]["value"] == pytest.approx(1.0003854424, abs=1e-10)
    assert len(d["residuals"]) == 18
    assert d["orthogonality_defect"] < 1e-14


def test_two_files_joined_by_id_with_check_points(cli, tmp_path: Path):
    t = datasets.load("lidar_wang2014")
    src = tmp_path / "model.csv"
    dst = tmp_path / "ground.csv"
    src.write_text("id,x,y,z\n" + "".join(
        f"{i},{a},{b},{c}\n" for i, a, b, c in zip(t["id"], t["x"], t["y"], t["z"])))
    order = np.arange(18)[::-1]  # another order: joined by id
    dst.write_text("id,X,Y,Z\n" + "".join(
        f"{t['id'][k]},{t['X'][k]},{t['Y'][k]},{t['Z'][k]}\n" for k in order))
    code, out, err = cli("orient", "absolute", src, dst, "--check-ids", "17,18",
                         "--json")
    assert code == 0, err
    d = json.loads(out)
    assert len(d["residuals"]) == 16 and len(d["check_residuals"]) == 2
    assert d["check_ids"] == ["17", "18"]


def test_compare_prints_all_methods_and_writes_report(cli, tmp_path: Path):
    rep = tmp_path / "cmp.html"
    code, out, err = cli("orient", "absolute", LIDAR, "--compare", "--report", rep)
    assert code == 0, err
    for m in ("closed-form", "svd", "quaternion", "dual-quaternion", "gauss-markov",
              "gauss-helmert"):
        assert m in out
    assert "solve" in out and "[us]" in out
    html = rep.read_text()
    assert "gauss-helmert" in html and "data:image/png;base64" in html
    code, out, err = cli("orient", "absolute", LIDAR, "--compare", "--json")
    d = json.loads(out)
    assert {r["method"] for r in d["methods"]} >= {"svd", "closed-form"}
    gm = next(r for r in d["methods"] if r["method"] == "gauss-markov")
    assert gm["differences_to_reference"]["scale"] == 0.0


def test_ransac_option_and_report(cli, tmp_path: Path):
    rng = np.random.default_rng(0)
    x = rng.uniform(-20, 20, (40, 3))
    X = x + np.array([5.0, 6.0, 7.0])
    X[:8] = X[rng.permutation(8)[::-1]][:8] + rng.uniform(3, 9, (8, 3))
    f = tmp_path / "pairs.csv"
    f.write_text("id,x,y,z,X,Y,Z\n" + "".join(
        f"p{i},{a[0]},{a[1]},{a[2]},{b[0]},{b[1]},{b[2]}\n" for i, (a, b) in enumerate(zip(x, X))))
    rep = tmp_path / "fit.html"
    code, out, err = cli("orient", "absolute", f, "--ransac", "--threshold", "0.01",
                         "--seed", "1", "--report", rep)
    assert code == 0, err
    assert "RANSAC inliers: 32 of 40" in out
    assert rep.exists()
    code, _, err = cli("orient", "absolute", f, "--ransac")
    assert code == 2 and "--threshold" in err


def test_errors_are_reported(cli, tmp_path: Path):
    f = tmp_path / "line.csv"
    f.write_text("id,x,y,z,X,Y,Z\n" + "".join(
        f"{i},{i},{2 * i},{3 * i},{i},{2 * i},{3 * i}\n" for i in range(5)))
    code, _, err = cli("orient", "absolute", f)
    assert code == 2 and "collinear" in err
    g = tmp_path / "two.csv"
    g.write_text("id,x,y,z,X,Y,Z\n1,0,0,0,1,1,1\n2,1,0,0,2,1,1\n")
    code, _, err = cli("orient", "absolute", g)
    assert code == 2 and "at least 3" in err


@pytest.mark.parametrize("name", ["absolute-lidar", "absolute-afary", "absolute-kraus"])
def test_examples_run(name):
    from photogeom.report import Report

    rep = Report("test")
    text = get(name).run(rep)
    assert "gauss-markov" in text and "closed-form" in text
    assert len(rep) >= 2
    if name == "absolute-kraus":
        assert "ours: -0.1854, -1.0920, 298.6799 gon" in text


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--threshold", "0.5"], "--threshold applies only with --ransac"),
        (["--method", "closed-form", "--threshold", "0.5"], "--threshold applies only with"),
        (["--compare", "--threshold", "0.5"], "--threshold applies only with --ransac"),
        (["--seed", "3"], "--seed applies only with --ransac"),
        (["--ransac", "--threshold", "0.5", "--initial", "zeros"], "--initial is not used with"),
        (["--ransac", "--threshold", "0.5", "--sigma-source", "0.1"], "--sigma-source is not"),
        (["--compare", "--sigma-source", "0.1"], "--sigma-source is not used with --compare"),
        (["--compare", "--ransac", "--threshold", "0.5"], "cannot be combined"),
    ],
)
def test_options_the_mode_would_ignore_are_refused(cli, tmp_path: Path, args, words):
    out_file = tmp_path / "r.html"
    code, out, err = cli("orient", "absolute", KRAUS, *args, "--report", out_file)
    assert code == 2 and out == "" and not out_file.exists()
    assert err.startswith("error: ") and words in err


def test_threshold_and_seed_with_ransac_are_used(cli):
    code, out, err = cli("orient", "absolute", KRAUS, "--ransac", "--threshold", "0.5",
                         "--seed", "3", "--json")
    assert code == 0, err
    assert json.loads(out)["ransac"]["threshold"] == 0.5
