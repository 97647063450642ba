"""sigma0 and redundancy in the evaluation of residual grids (``evaluate_readjustment``,
``photogeom grid evaluate``): before, the table and its JSON compared residuals and steps
only. Checked against sigma0 computed independently, ``sqrt(v'Pv / r)`` from the fits'
residuals: image residuals over their sigmas, GNSS centres, IMU angles and control points
against their observations over theirs."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import evaluate_readjustment, fit_residual_grids, readjust


def _vpv(fit) -> float:
    """v'Pv of ``fit`` from its residuals and its block's observations (unit weight 1)."""
    b = fit.block
    sig = np.broadcast_to(np.asarray(b.observations.sigma, float), (len(fit.residuals),))
    v = fit.residuals[fit.in_adjustment] / sig[fit.in_adjustment, None]
    g = np.all(np.isfinite(b.gnss), axis=1)
    i = np.all(np.isfinite(b.imu), axis=1)
    c = b.role == "control"
    dg = (b.exterior[g, :3] - b.gnss[g]) / b.gnss_sigma[g]
    di = np.angle(np.exp(1j * (b.exterior[i, 3:] - b.imu[i]))) / b.imu_sigma[i]
    dc = (b.xyz[c] - b.surveyed_xyz[c]) / b.point_sigma[c]
    return sum(float(np.sum(x * x)) for x in (v, dg, di, dc))


@pytest.fixture(scope="module")
def fits():
    """The CLI's pipeline of ``grid evaluate --preset ILCE-7RM2 --strips 2 --images 4
    --spacing 500``: first adjustment, grids fitted to its residuals, re-adjustment."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    ba = pg.bundle_adjust(sim.block, snooping=False)
    grids = fit_residual_grids(ba.block, 500.0, folds=0)
    return ba, readjust(ba.block, grids, snooping=False)


def test_evaluation_gives_sigma0_over_the_redundancy_of_each_fit(fits):
    ba, re = fits
    adj = evaluate_readjustment(ba, re)["adjustment"]
    before, after = adj["before"], adj["after"]
    # the first adjustment: over observations minus unknowns
    assert not before["effective"]
    assert before["redundancy"] == before["observations"] - before["unknowns"] == 890
    assert before["sigma0"] == pytest.approx(np.sqrt(_vpv(ba) / 890), rel=1e-9)
    # the re-adjustment with grids fitted to these residuals: over the chain's effective
    # redundancy (154.7), below half its count
    assert after["effective"]
    r = after["redundancy"]
    assert r == re.effective_redundancy["value"] and r < 0.5 * (
        after["observations"] - after["unknowns"]
    )
    assert after["sigma0"] == pytest.approx(np.sqrt(_vpv(re) / r), rel=1e-9)


def test_grid_evaluate_prints_and_writes_sigma0_and_redundancy(cli, fits):
    ba, re = fits
    args = ("grid", "evaluate", "--preset", "ILCE-7RM2", "--strips", "2", "--images", "4",
            "--spacing", "500")  # fmt: skip
    code, text, err = cli(*args, "--json")
    assert code == 0, err
    d = json.loads(text)
    assert d["units"]["sigma0"] == "1" and d["units"]["redundancy"] == "1"
    after = d["adjustment"]["after"]
    assert after["effective"] is True
    assert after["sigma0"] == pytest.approx(np.sqrt(_vpv(re) / after["redundancy"]), rel=1e-9)
    before = d["adjustment"]["before"]
    assert before["sigma0"] == pytest.approx(np.sqrt(_vpv(ba) / before["redundancy"]), rel=1e-9)
    code, text, err = cli(*args)
    assert code == 0, err
    row = next(line for line in text.splitlines() if "sigma0 (unitless)" in line)
    assert f"{before['sigma0']:.4f}" in row and f"{after['sigma0']:.4f}" in row
    row = next(line for line in text.splitlines() if "redundancy" in line and "│" in line)
    assert f"{after['redundancy']:.1f} (effective)" in row and "890" in row


def test_a_block_read_as_adjusted_has_no_first_statistics(cli, fits, tmp_path):
    ba, _ = fits
    pg.bundle.write_block(ba.block, tmp_path / "b", kind="csv", angle_unit="rad")
    code, text, err = cli("grid", "evaluate", tmp_path / "b", "--spacing", "500", "--json")
    assert code == 0, err
    d = json.loads(text)
    assert d["adjustment"]["before"] is None
    assert d["adjustment"]["after"]["sigma0"] > 0
    code, text, err = cli("grid", "evaluate", tmp_path / "b", "--spacing", "500")
    assert code == 0, err
    assert "n/a (BLOCK read as adjusted)" in text


def test_the_grid_report_block_table_gives_sigma0_and_redundancy(fits, tmp_path, monkeypatch):
    """The report handed on had the residuals and steps of ``grid evaluate`` but not its
    sigma0 and redundancy rows; they are in its Block table now, against ``sqrt(v'Pv / r)``."""
    import html
    import re as regex

    from photogeom.report.grid_study import grid_study_report

    monkeypatch.setattr("photogeom.report.html.figure_to_png", lambda fig, dpi=110: b"")
    ba, re = fits
    grids = fit_residual_grids(ba.block, 500.0, folds=0)
    ev = evaluate_readjustment(ba, re)
    text = grid_study_report(
        {"fit": ba, "refit": re, "grids": grids, "evaluation": ev}, tmp_path / "g.html"
    ).read_text(encoding="utf-8")
    cells = {
        row[0]: row[1:]
        for row in (
            [html.unescape(c) for c in regex.findall(r"<td[^>]*>(.*?)</td>", tr, flags=regex.S)]
            for tr in regex.findall(r"<tr>(.*?)</tr>", text, flags=regex.S)
        )
        if row
    }
    r = re.effective_redundancy["value"]
    assert cells["redundancy"][:2] == ["890", f"{r:.1f} (effective)"]
    s0 = [float(x) for x in cells["sigma0 (unitless)"][:2]]
    assert s0[0] == pytest.approx(np.sqrt(_vpv(ba) / 890), abs=6e-5)
    assert s0[1] == pytest.approx(np.sqrt(_vpv(re) / r), abs=6e-5)
