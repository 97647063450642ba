"""`photogeom grid evaluate | sweep | report` on an adjusted block folder and on a preset."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def adjusted(tmp_path_factory):
    """A simulated block, its first adjustment and the adjusted block's CSV folder."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=4, strips=1, images_per_strip=5)
    fit = pg.bundle_adjust(sim.block, snooping=False)
    d = tmp_path_factory.mktemp("block") / "adjusted"
    pg.bundle.write_csv_block(fit.block, d)
    return sim, fit, d


@pytest.fixture(scope="module")
def block_folder(adjusted):
    return adjusted[2]


def test_evaluate_block_folder_json(cli, block_folder):
    code, text, err = cli("grid", "evaluate", str(block_folder), "--spacing", "200", "--json")
    assert code == 0, err
    data = json.loads(text)
    assert data["residuals"]["block"]["reduction_rms"] > 0.3
    assert data["mean_step_after"] < data["mean_step_before"]
    assert set(data["steps_before"]) == {"0-1", "1-2", "2-3"}


def test_sweep_and_report(cli, block_folder, tmp_path):
    code, text, err = cli("grid", "sweep", str(block_folder), "--spacings", "200,1000", "--json")
    assert code == 0, err
    data = json.loads(text)
    assert data["spacing"] in (200.0, 1000.0)
    out = tmp_path / "grid.html"
    code, text, err = cli(
        "grid", "report", str(block_folder), "--spacings", "200,1000", "-o", str(out)
    )
    assert code == 0, err
    html = out.read_text()
    assert html.count("<img") == 4


def test_bad_input(cli, block_folder):
    code, _, err = cli("grid", "evaluate", str(block_folder), "--preset", "FC300S")
    assert code == 2 and "either a BLOCK" in err
    code, _, err = cli("grid", "evaluate", str(block_folder), "--spacing", "0")
    assert code == 2 and "--spacing" in err
    code, _, err = cli("grid", "sweep", str(block_folder), "--spacings", "200")
    assert code == 2 and "--spacings" in err
    code, _, err = cli("grid", "evaluate", str(block_folder / "nowhere"))
    assert code == 2 and "does not exist" in err


def test_evaluate_in_adjustment(cli, block_folder):
    code, text, err = cli(
        "grid", "evaluate", str(block_folder), "--spacing", "2000", "--sigma-constraint", "1",
        "--in-adjustment", "--sigma-temporal", "0.3", "--json",
    )  # fmt: skip
    assert code == 0, err
    data = json.loads(text)
    assert data["residuals"]["block"]["reduction_rms"] > 0
    code, _, err = cli("grid", "evaluate", str(block_folder), "--per", "camera")
    assert code == 2 and "--in-adjustment only" in err
    code, _, err = cli("grid", "evaluate", str(block_folder), "--post-spacing", "300")
    assert code == 2 and "--in-adjustment only" in err
    code, text, err = cli(
        "grid", "evaluate", str(block_folder), "--spacing", "2000", "--sigma-constraint", "1",
        "--in-adjustment", "--post-spacing", "500", "--json",
    )  # fmt: skip
    assert code == 0, err
    both = json.loads(text)
    assert both["residuals"]["block"]["reduction_rms"] > data["residuals"]["block"]["reduction_rms"]
    code, _, err = cli(
        "grid", "evaluate", str(block_folder), "--in-adjustment", "--per", "camera",
        "--sigma-temporal", "0.3",
    )  # fmt: skip
    assert code == 2 and "--sigma-temporal needs --per image" in err


def test_evaluate_in_adjustment_amplitude(cli, block_folder):
    """--sigma-amplitude reaches the adjustment: a tiny one holds the grids at zero (the
    residuals of the first adjustment stay), the default takes up less than none."""
    args = ("grid", "evaluate", str(block_folder), "--spacing", "2000", "--in-adjustment")
    red = {}
    for sa in ("1e-6", "none", "residuals"):
        code, text, err = cli(*args, "--sigma-constraint", "1", "--sigma-amplitude", sa, "--json")
        assert code == 0, err
        red[sa] = json.loads(text)["residuals"]["block"]["reduction_rms"]
    assert abs(red["1e-6"]) < 0.01 < 0.1 < red["residuals"] < red["none"]
    code, _, err = cli(*args, "--sigma-amplitude", "large")
    assert code == 2 and "--sigma-amplitude must be a number of pixels" in err
    code, _, err = cli(*args, "--sigma-amplitude", "-1")
    assert code == 2 and "--sigma-amplitude must be a positive number" in err
    code, _, err = cli("grid", "evaluate", str(block_folder), "--sigma-amplitude", "1")
    assert code == 2 and "--in-adjustment only" in err


def test_report_in_adjustment(cli, tmp_path):
    out = tmp_path / "grid.html"
    code, _, err = cli(
        "grid", "report", "--preset", "FC300S", "--strips", "1", "--images", "5",
        "--spacing", "1000", "--spacings", "500,1000", "--in-adjustment",
        "--sigma-temporal", "0.3", "-o", str(out),
    )  # fmt: skip
    assert code == 0, err
    html = out.read_text()
    assert "grids in the adjustment" in html and html.count("<img") == 4


def test_in_adjustment_shows_its_iterations_on_a_terminal_only(cli, block_folder, terminal_stderr):
    args = ("grid", "evaluate", str(block_folder), "--spacing", "2000", "--in-adjustment")
    code, _out, err = cli(*args, "--sigma-constraint", "1")
    assert code == 0 and err == ""  # not a terminal: no progress display
    buf = terminal_stderr()
    code, _out, err = cli(*args, "--sigma-constraint", "1")
    assert code == 0, err
    assert "adjusting with grids" in buf.getvalue() and "cost" in buf.getvalue()


def test_evaluate_on_a_preset_prints_the_check_points_against_the_truth(cli, block_folder):
    code, text, err = cli(
        "grid", "evaluate", "--preset", "FC300S", "--strips", "1", "--images", "5",
        "--spacing", "1000",
    )  # fmt: skip
    assert code == 0, err
    assert "check-point RMSE (GSD)" in text and "against the simulated truth" in text
    assert "tie-point RMSE (GSD), all" in text
    code, text, err = cli(
        "grid", "evaluate", "--preset", "FC300S", "--strips", "1", "--images", "5",
        "--spacing", "1000", "--json",
    )  # fmt: skip
    data = json.loads(text)
    assert len(data["tie_rmse_gsd_before"]) == 3 and len(data["tie_rmse_gsd_after"]) == 3
    code, text, err = cli("grid", "evaluate", str(block_folder), "--spacing", "1000")
    # a block folder: against the survey it keeps (surveyed_X, _Y, _Z), not a truth
    assert code == 0 and "against surveyed" in text and "simulated truth" not in text


@pytest.fixture(scope="module")
def folder_and_survey(adjusted, tmp_path_factory):
    """An adjusted block folder (check points triangulated) and the surveyed check-point
    coordinates as a point CSV."""
    sim, fit, folder = adjusted
    d = tmp_path_factory.mktemp("surveyed")
    b = sim.block
    rows = [
        f"{k},{float(x)!r},{float(y)!r},{float(z)!r}"
        for k, (x, y, z) in zip(b.point_ids.tolist(), b.xyz)
        if k in fit.check["ids"]
    ]
    (d / "checks.csv").write_text("id,X,Y,Z\n" + "\n".join(rows) + "\n")
    return folder, d / "checks.csv", fit


def test_check_points_of_a_block_folder_against_surveyed_coordinates(cli, folder_and_survey):
    folder, checks, fit = folder_and_survey
    args = ("grid", "evaluate", str(folder), "--spacing", "1000")
    code, text, err = cli(*args, "--check-points", str(checks), "--json")
    assert code == 0, err
    data = json.loads(text)
    np.testing.assert_allclose(
        data["check_rmse_gsd_before"], fit.check["rmse"] / fit.block.gsd(), rtol=1e-6
    )
    assert len(data["check_rmse_gsd_after"]) == 3
    code, text, err = cli(*args, "--check-points", str(checks))
    assert code == 0 and "against surveyed" in text
    code, _, err = cli(*args, "--check-points", str(checks.with_name("missing.csv")))
    assert code == 2 and "--check-points" in err and "does not exist" in err
    other = checks.with_name("other.csv")
    other.write_text("id,X,Y,Z\nnowhere,1,2,3\n")
    code, _, err = cli(*args, "--check-points", str(other))
    assert code == 2 and "--check-points: none of the block's check points" in err
    code, _, err = cli("grid", "evaluate", "--preset", "FC300S", "--check-points", str(checks))
    assert code == 2 and "applies to a BLOCK folder" in err
