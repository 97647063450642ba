"""`orient absolute --output-params` writes the parameters that `transform apply`
and `cloud transform --params` read, as `transform estimate --output-params` does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets

LIDAR = str(datasets.path("lidar_wang2014"))


def _two_files(tmp_path: Path) -> tuple[Path, Path]:
    t = datasets.load("lidar_wang2014")
    src, dst = tmp_path / "scan.csv", tmp_path / "ref.csv"
    src.write_text("# crs: EPSG:25832\nid,x,y,z\n" + "".join(
        f"{i},{a},{b},{c}\n" for i, a, b, c in zip(t["id"], t["x"], t["y"], t["z"])))
    dst.write_text("# crs: EPSG:25832\nid,E,N,U\n" + "".join(
        f"{i},{a},{b},{c}\n" for i, a, b, c in zip(t["id"], t["X"], t["Y"], t["Z"])))
    return src, dst


def test_output_params_is_the_json_and_transform_apply_reads_it(cli, tmp_path: Path):
    params = tmp_path / "abs.json"
    code, out, err = cli("orient", "absolute", LIDAR, "--output-params", params)
    assert code == 0, err
    assert f"wrote {params}" in out
    code, js, err = cli("orient", "absolute", LIDAR, "--json")
    assert code == 0, err
    written, printed = json.loads(params.read_text()), json.loads(js)
    for d in (written, printed):
        d.pop("elapsed_s")
    assert written == printed
    assert written["input"]["source_columns"] == ["x", "y", "z"]
    assert written["input"]["target_columns"] == ["X", "Y", "Z"]
    code, out, err = cli("transform", "apply", params, LIDAR)
    assert code == 0, err
    lines = [ln for ln in out.splitlines() if not ln.startswith("#")]
    assert lines[0] == "id,X,Y,Z"
    got = np.array([[float(v) for v in ln.split(",")[1:]] for ln in lines[1:]])
    t = datasets.load("lidar_wang2014")
    obs = np.column_stack([t["X"], t["Y"], t["Z"]])
    res = np.asarray(written["residuals"])
    np.testing.assert_allclose(got - obs, res, atol=1e-9)  # computed - observed, as fitted


def test_output_params_with_two_files_records_crs_and_columns(cli, tmp_path: Path):
    src, dst = _two_files(tmp_path)
    params, rep = tmp_path / "p.json", tmp_path / "r.html"
    code, _, err = cli("orient", "absolute", src, dst, "--rigid", "--check-ids", "17,18",
                         "--output-params", params, "--report", rep)
    assert code == 0, err
    d = json.loads(params.read_text())
    assert d["crs"] == "EPSG:25832" and d["source_crs"] == "EPSG:25832"
    assert d["input"]["n_check"] == 2 and d["input"]["target_columns"] == ["E", "N", "U"]
    assert rep.read_text().startswith("<!DOCTYPE html>")
    out_csv = tmp_path / "o.csv"
    code, _, err = cli("transform", "apply", params, src, "-o", out_csv)
    assert code == 0, err
    text = out_csv.read_text()
    assert "# crs: EPSG:25832" in text and "\nid,E,N,U\n" in text


def test_output_params_of_ransac_is_the_inlier_fit(cli, tmp_path: Path):
    params = tmp_path / "p.json"
    code, _, err = cli("orient", "absolute", LIDAR, "--ransac", "--threshold", "0.1",
                       "--seed", "1", "--output-params", params)
    assert code == 0, err
    d = json.loads(params.read_text())
    assert "ransac" in d and len(d["inliers"]) == 18


def test_output_params_with_compare_is_refused_before_reading(cli, tmp_path: Path):
    params = tmp_path / "p.json"
    code, _, err = cli("orient", "absolute", tmp_path / "missing.csv", "--compare",
                       "--output-params", params)
    assert code == 2
    assert "--output-params" in err and "--compare" in err and "Traceback" not in err
    assert not params.exists()


def test_failed_estimate_leaves_the_old_parameter_file(cli, tmp_path: Path):
    params = tmp_path / "p.json"
    params.write_text("old")
    bad = tmp_path / "two.csv"
    bad.write_text("id,x,y,z,X,Y,Z\n1,0,0,0,1,1,1\n2,1,0,0,2,1,1\n")
    code, _, err = cli("orient", "absolute", bad, "--output-params", params)
    assert code == 2 and err.startswith("error:")
    assert params.read_text() == "old"


@pytest.mark.parametrize("option", ["--output-params"])
def test_help_names_the_option(cli, option):
    code, out, _ = cli("orient", "absolute", "--help")
    assert code == 0 and option in out and "transform apply" in " ".join(out.split())
