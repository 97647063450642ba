"""The `photogeom` command line: transform estimate/apply, examples, errors and help."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.cli.main import main
from photogeom.io import read_points

FIDUCIALS = str(datasets.path("lecture_fiducials"))
TWO_IMAGES = str(datasets.path("lecture_two_images"))


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --- estimate ----------------------------------------------------------------------------------


def test_estimate_reproduces_lecture_example_4(cli):
    code, out, err = cli("transform", "estimate", "similarity2d", FIDUCIALS, "--unit", "mm")
    assert code == 0, err
    # a = 1.0000354, b = -0.0000022, c = 130.00875, d = 130.009 (lecture example 4)
    for s in ("1.0000354", "-0.0000022", "130.00875", "130.00900"):
        assert s in out
    assert "4 control, 4 check" in out
    assert "v = computed - observed [mm]" in out
    assert "Check point residuals (4, not in the estimate)" in out
    assert "-0.00850" in out and "0.00725" in out  # check points 7 and 5


def test_estimate_json_parses(cli):
    code, out, _ = cli("transform", "estimate", "similarity2d", FIDUCIALS, "--json")
    assert code == 0
    data = json.loads(out)
    p = data["parameters"]
    assert round(p["a"]["value"], 7) == 1.0000354
    assert round(p["b"]["value"], 7) == -0.0000022
    assert round(p["c"]["value"], 5) == 130.00875
    assert round(p["d"]["value"], 3) == 130.009
    assert data["redundancy"] == 4 and data["residual_convention"] == "computed minus observed"
    assert data["check_ids"] == ["5", "6", "7", "8"]
    assert data["input"]["n_check"] == 4
    np.testing.assert_allclose(data["check_residuals"][2], [-0.0085, 0.00575], atol=5e-7)


def test_check_ids_option_overrides_roles(cli):
    code, out, _ = cli("transform", "estimate", "affine2d", FIDUCIALS, "--check-ids", "8", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["check_ids"] == ["8"] and data["redundancy"] == 14 - 6
    code, _, err = cli("transform", "estimate", "affine2d", FIDUCIALS, "--check-ids", "99")
    assert code == 2 and "error:" in err and "99" in err


def test_two_images_three_models(cli):
    # lecture example 5: similarity (1.86, 0.48, -62.16, 89.33); affine a1 = 2.62 ... b3 = -127.03
    args = ["--source-cols", "x2,y2", "--target-cols", "x1,y1", "--json"]
    _, out, _ = cli("transform", "estimate", "similarity2d", TWO_IMAGES, *args)
    p = json.loads(out)["parameters"]
    assert [round(p[k]["value"], 2) for k in "abcd"] == [1.86, 0.48, -62.16, 89.33]
    _, out, _ = cli("transform", "estimate", "affine2d", TWO_IMAGES, *args)
    p = json.loads(out)["parameters"]
    got = [round(p[k]["value"], 2) for k in ("a1", "a2", "a3", "b1", "b2", "b3")]
    assert got == [2.62, 1.72, -298.19, 0.31, 2.88, -127.03]
    code, out, _ = cli("transform", "estimate", "projective2d", TWO_IMAGES, *args[:-1])
    assert code == 0 and "Gauss-Markov" in out and "converged" in out


def test_two_files_joined_by_id(tmp_path, cli):
    src = _write(tmp_path, "src.csv", "id,x,y\n1,0,0\n2,10,0\n3,0,10\n4,10,10\n5,5,5\n")
    dst = _write(tmp_path, "dst.csv", "id,X,Y\n5,110,60\n1,100,50\n2,120,50\n3,100,70\n4,120,70\n")
    code, out, err = cli("transform", "estimate", "affine2d", src, dst, "--json")
    assert code == 0, err
    p = json.loads(out)["parameters"]
    np.testing.assert_allclose(
        [p[k]["value"] for k in ("a1", "a2", "a3", "b1", "b2", "b3")],
        [2, 0, 100, 0, 2, 50],
        atol=1e-9,
    )


def test_ids_in_one_file_only_are_reported(tmp_path, cli):
    src = _write(tmp_path, "src.csv", "id,x,y\n1,0,0\n2,10,0\n3,0,10\n4,10,10\n7,1,1\n")
    dst = _write(tmp_path, "dst.csv", "id,X,Y\n1,100,50\n2,120,50\n3,100,70\n4,120,70\n9,0,0\n")
    code, _, err = cli("transform", "estimate", "affine2d", src, dst)
    assert code == 2
    assert "only in" in err and "7" in err and "9" in err
    assert len(err.strip().splitlines()) == 1  # one line, no traceback
    code, out, err = cli("transform", "estimate", "affine2d", src, dst, "--allow-unmatched")
    assert code == 0, err
    assert "left out" in out and "7" in out and "9" in out


@pytest.mark.parametrize(
    "content, args, pattern",
    [
        ("id,x,y,X,Y\n1,0,0,1,1\n", ["similarity2d"], r"1 point\(s\) given, at least 2"),
        (
            "id,x,y,X,Y\n1,0,0,1,1\n2,1,1,2,2\n3,2,2,3,3\n",
            ["affine2d"],
            "collinear",
        ),
        ("id,x,y,X,Y\n1,0,nan,1,1\n2,1,1,2,2\n", ["similarity2d"], "NaN"),
        ("id,x,y,X,Y\n1,0,0,1,1\n1,1,1,2,2\n", ["similarity2d"], r"duplicate point id\(s\) 1"),
        ("id,a,b\n1,0,0\n", ["similarity2d"], "the file has columns id, a, b"),
        ("id,x,y,X,Y\n1,0,0,1\n", ["similarity2d"], "field"),
        ("id,x,y,X,Y\n1,0,0,1,1\n2,1,0,2,1\n", ["polynomial2d"], "order"),
        (
            "id,x,y,z,X,Y\n1,0,0,0,1,1\n2,1,0,0,2,1\n3,0,1,0,1,2\n",
            ["affine2d", "--source-cols", "x,y,z"],
            r"works on 2D points.*x,y,z",
        ),
    ],
)
def test_bad_input_one_line_error(tmp_path, cli, content, args, pattern):
    import re

    f = _write(tmp_path, "p.csv", content)
    code, out, err = cli("transform", "estimate", args[0], f, *args[1:])
    assert code == 2, (out, err)
    assert err.startswith("error: ")
    assert re.search(pattern, err, re.IGNORECASE), err
    assert "Traceback" not in err


def test_unreadable_file(tmp_path, cli):
    code, _, err = cli("transform", "estimate", "affine2d", tmp_path / "nope.csv")
    assert code == 2 and "no such file" in err


def test_usage_errors_and_help(cli):
    code, out, err = cli("transform", "estimate", "bogus-model", FIDUCIALS)
    assert code == 2 and "bogus-model" in (out + err) and "similarity2d" in (out + err)
    code, out, _ = cli("--help")
    assert code == 0 and "transform" in out and "examples" in out
    code, out, _ = cli("transform", "estimate", "--help")
    assert code == 0 and "--check-ids" in out and "--report" in out
    code, out, err = cli()
    assert "Usage" in (out + err)  # no arguments: the help


def test_console_script_entry_point():
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "photogeom.cli.main",
            "transform",
            "estimate",
            "projective2d",
            FIDUCIALS,
            "--source-cols",
            "x,y",
            "--check-ids",
            "1,2,3,4,5,6,7,8",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: ") and "0 point(s) given, at least 4" in proc.stderr


# --- outputs: report, parameters, atomicity ---------------------------------------------------


def test_report_and_params_files(tmp_path, cli):
    rep, par = tmp_path / "r.html", tmp_path / "p.json"
    code, out, err = cli(
        "transform",
        "estimate",
        "similarity2d",
        FIDUCIALS,
        "--report",
        rep,
        "--output-params",
        par,
        "--angle-unit",
        "gon",
    )
    assert code == 0, err
    html = rep.read_text()
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")
    assert "<img" in html and "data:image/png;base64," in html
    assert "1.0000354" in html and ">gon<" in html
    assert json.loads(par.read_text())["model_parameters"]["model"] == "similarity2d"
    assert f"wrote {rep}" in out


def test_no_half_written_output(tmp_path, capsys, monkeypatch):
    rep = tmp_path / "r.html"
    rep.write_text("old report")

    def crash(src, dst):
        raise OSError("simulated crash during rename")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(SystemExit) as info:
        main(["transform", "estimate", "similarity2d", FIDUCIALS, "--report", str(rep)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot write") and "simulated crash" in err
    assert rep.read_text() == "old report"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html"]


def test_failed_estimate_writes_nothing(tmp_path, cli):
    rep = tmp_path / "r.html"
    bad = _write(tmp_path, "p.csv", "id,x,y,X,Y\n1,0,0,1,1\n")
    code, _, _ = cli("transform", "estimate", "affine2d", bad, "--report", rep)
    assert code == 2 and not rep.exists()


# --- apply -------------------------------------------------------------------------------------


def test_apply_round_trip_with_inverse(tmp_path, cli):
    par = tmp_path / "p.json"
    for model in ("similarity2d", "projective2d"):
        code, _, err = cli(
            "transform", "estimate", model, FIDUCIALS, "--output-params", par, "--json"
        )
        assert code == 0, err
        fwd, back = tmp_path / "fwd.csv", tmp_path / "back.csv"
        code, _, err = cli("transform", "apply", par, FIDUCIALS, "-o", fwd)
        assert code == 0, err
        t = read_points(fwd)
        assert t.columns == ("X", "Y") and list(t.roles)[-1] == "check"
        # forward: close to the measured machine coordinates (residuals of a few micrometres)
        machine = read_points(FIDUCIALS, "X,Y").coords
        assert np.abs(t.coords - machine).max() < 0.02
        code, _, err = cli("transform", "apply", par, fwd, "--inverse", "-o", back)
        assert code == 0, err
        b = read_points(back)
        assert b.columns == ("x", "y")
        np.testing.assert_allclose(b.coords, read_points(FIDUCIALS, "x,y").coords, atol=1e-9)


def test_apply_to_stdout_and_json_input(tmp_path, cli):
    par = tmp_path / "fit.json"
    _, out, _ = cli("transform", "estimate", "affine2d", FIDUCIALS, "--json")
    par.write_text(out)  # the --json output works as a parameter file too
    code, out, _ = cli("transform", "apply", par, FIDUCIALS, "--out-cols", "E,N")
    assert code == 0 and "id,E,N,role" in out


def test_apply_errors(tmp_path, cli):
    bad = _write(tmp_path, "bad.json", "{not json")
    code, _, err = cli("transform", "apply", bad, FIDUCIALS)
    assert code == 2 and "not valid JSON" in err
    other = _write(tmp_path, "o.json", '{"a": 1}')
    code, _, err = cli("transform", "apply", other, FIDUCIALS)
    assert code == 2 and "no transformation parameters" in err
    par = tmp_path / "p.json"
    cli("transform", "estimate", "affine2d", FIDUCIALS, "--output-params", par)
    pts3 = _write(tmp_path, "p3.csv", "id,x,y,z\n1,0,0,0\n")
    code, _, err = cli("transform", "apply", par, pts3)
    assert code == 2 and "2D points" in err


# --- examples ----------------------------------------------------------------------------------


def test_examples_list_and_run(tmp_path, cli):
    code, out, _ = cli("examples", "list")
    assert code == 0 and "fiducials" in out and "two-images" in out
    rep = tmp_path / "ex.html"
    code, out, err = cli("examples", "run", "fiducials", "--report", rep)
    assert code == 0, err
    assert "20 of 20 published numbers reproduced" in out
    html = rep.read_text()
    assert "<img" in html and "Comparison with the published numbers" in html
    code, _, err = cli("examples", "run")
    assert code == 2 and "--all" in err
    code, _, err = cli("examples", "run", "no-such-example")
    assert code == 2 and "no example" in err


def test_two_images_example_reports_every_published_number():
    from photogeom.examples.transforms import agreement, run_two_images

    text = run_two_images(None)
    assert "21 of 21 published numbers reproduced" in text
    assert "yes, rounded via -0.0145" in text  # lecture prints b1 = -0.015 for -0.01447
    assert agreement(-62.16496, "-62.16") == "yes" and agreement(1.5, "1.7") == "NO"


def test_3d_similarity_and_polynomial_with_report(tmp_path, cli):
    lidar = str(datasets.path("lidar_wang2014"))
    rep = tmp_path / "r3.html"
    code, out, err = cli(
        "transform", "estimate", "similarity3d", lidar, "--unit", "m", "--report", rep
    )
    assert code == 0, err
    assert ("v_z" in out or "v_Z" in out) and "scale" in out and " m" in out
    html = rep.read_text()
    assert "<img" in html and "first two components" in html
    code, out, err = cli(
        "transform",
        "estimate",
        "polynomial2d",
        FIDUCIALS,
        "--order",
        "2",
        "--check-ids",
        "8",
        "--json",
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["redundancy"] == 14 - 12 and len(data["parameters"]) == 12


def test_sigma_column_weights_the_points(tmp_path, cli):
    from photogeom.estimation import estimate_transform

    rng = np.random.default_rng(3)
    src = rng.uniform(0, 100, (8, 2))
    dst = src @ np.array([[0.9, 0.1], [-0.1, 0.9]]).T + [5.0, 7.0] + rng.normal(0, 0.1, (8, 2))
    sigma = np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 5.0])
    ids = [f"P{k}" for k in range(8)]
    s_lines = "".join(f"{i},{x:.17g},{y:.17g}\n" for i, (x, y) in zip(ids, src))
    d_lines = "".join(f"{i},{x:.17g},{y:.17g},{s:.17g}\n" for i, (x, y), s in zip(ids, dst, sigma))
    a = _write(tmp_path, "a.csv", "id,x,y\n" + s_lines)
    b = _write(tmp_path, "b.csv", "id,X,Y,sigma\n" + d_lines)
    code, out, err = cli("transform", "estimate", "affine2d", a, b, "--json")
    assert code == 0, err
    got = [v["value"] for v in json.loads(out)["parameters"].values()]
    want = estimate_transform("affine2d", src, dst, weights=1 / sigma**2).parameters
    unweighted = estimate_transform("affine2d", src, dst).parameters
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert not np.allclose(got, unweighted, rtol=1e-9, atol=1e-9)


def test_sigma_column_with_an_a_priori_sigma0(tmp_path, cli):
    """Sigmas of a sigma column are standard deviations: with --sigma0-prior s0 the weights
    are s0^2 / sigma^2 (the library's P = s0^2 Cll^-1), so that noise as stated gives sigma0
    near s0 and the statistics equal the library's with that covariance."""
    from photogeom.estimation import estimate_transform

    rng = np.random.default_rng(8)
    n = 300
    src = rng.uniform(0, 100, (n, 2))
    sigma = rng.uniform(0.05, 0.3, n)
    dst = src @ np.array([[0.9, 0.1], [-0.1, 0.9]]).T + [5.0, 7.0]
    dst = dst + rng.normal(0, 1, (n, 2)) * sigma[:, None]
    ids = [f"P{k}" for k in range(n)]
    s_lines = "".join(f"{i},{x:.17g},{y:.17g}\n" for i, (x, y) in zip(ids, src))
    d_lines = "".join(f"{i},{x:.17g},{y:.17g},{s:.17g}\n" for i, (x, y), s in zip(ids, dst, sigma))
    a = _write(tmp_path, "a.csv", "id,x,y\n" + s_lines)
    b = _write(tmp_path, "b.csv", "id,X,Y,sigma\n" + d_lines)
    code, out, err = cli(
        "transform", "estimate", "affine2d", a, b, "--sigma0-prior", "0.5", "--json"
    )
    assert code == 0, err
    data = json.loads(out)
    # sigma0 estimates the a-priori 0.5: relative standard error 1 / sqrt(2 r), r = 594
    assert abs(data["sigma0"] / 0.5 - 1) < 4 / np.sqrt(2 * (2 * n - 6))
    cov = np.repeat(sigma**2, 2)
    lib = estimate_transform("affine2d", src, dst, covariance=np.diag(cov), sigma0_prior=0.5)
    np.testing.assert_allclose(data["sigma0"], lib.sigma0, rtol=1e-9)
    got = {k: v["std"] for k, v in data["parameters"].items()}
    want = lib.std_errors
    np.testing.assert_allclose([got[k] for k in want], list(want.values()), rtol=1e-9)


def test_errors_in_both_refuses_a_sigma_column_in_another_unit(tmp_path, cli):
    """A sigma column holds target-unit standard deviations; with errors in both point sets
    they would weigh the source coordinates too: refused when the units differ, accepted
    when both sets are in one unit or the column holds unitless weights."""
    rng = np.random.default_rng(5)
    src = rng.uniform(0, 1000, (8, 2))
    H = np.array([[1.01, 0.02, 3.0], [-0.01, 0.99, -2.0], [1e-5, 2e-5, 1.0]])
    h = np.column_stack([src, np.ones(8)]) @ H.T
    dst = h[:, :2] / h[:, 2:] + rng.normal(0, 0.01, (8, 2))
    lines = "".join(
        f"P{k},{a:.17g},{b:.17g},{c:.17g},{d:.17g},0.01\n" for k, (a, b, c, d) in
        enumerate(np.column_stack([src, dst]))
    )
    f = _write(tmp_path, "p.csv", "id,x,y,X,Y,sigma\n" + lines)
    base = ("transform", "estimate", "projective2d", f, "--errors-in", "both")
    code, _, err = cli(*base, "--unit", "mm", "--source-unit", "px")
    assert code == 2 and "--errors-in both with a sigma column" in err and "--weights-col" in err
    code, _, err = cli(*base, "--source-system", "pixel", "--unit", "mm")
    assert code == 2 and "(px)" in err
    code, _, err = cli(*base, "--unit", "mm", "--source-unit", "mm", "--json")
    assert code == 0, err
    g = _write(tmp_path, "w.csv", "id,x,y,X,Y,weight\n" + lines)
    code, _, err = cli("transform", "estimate", "projective2d", g, "--errors-in", "both",
                       "--unit", "mm", "--source-unit", "px", "--json")  # fmt: skip
    assert code == 0, err
