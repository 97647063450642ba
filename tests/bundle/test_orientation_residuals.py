"""GNSS and IMU residuals of a bundle adjustment (computed minus observed, per image)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def fit():
    sim = pg.simulate.uav_block("FC300S", seed=4, strips=2, images_per_strip=5)
    return pg.bundle_adjust(sim.block, snooping=False)


def test_every_residual_accounts_for_the_weighted_square_sum(fit):
    """Image, GNSS, IMU and control residuals, whitened by their sigmas, add up to
    sigma0^2 times the redundancy: the reported residuals are the adjustment's own."""
    b = fit.block
    r = fit.residuals[fit.in_adjustment] / b.observations.sigma[fit.in_adjustment, None]
    total = float(np.sum(r * r))
    g = fit.gnss_residuals / b.gnss_sigma
    a = fit.imu_residuals / b.imu_sigma
    total += float(np.nansum(g * g) + np.nansum(a * a))
    c = fit.control
    if c["ids"]:
        total += float(np.sum((c["errors"] / c["sigma"]) ** 2))
    assert total == pytest.approx(fit.sigma0**2 * fit.redundancy, rel=1e-6)


def test_residuals_in_the_summary_and_json(fit):
    orr = fit.orientation_residual_rms()
    assert orr["gnss_images"] == fit.block.n_images and orr["imu_images"] == fit.block.n_images
    # the GNSS noise was drawn with its sigmas: the residuals are of that size, not zero
    assert np.all(orr["gnss"] > 0.1 * fit.block.gnss_sigma.mean(axis=0))
    assert np.all(orr["gnss"] < 3 * fit.block.gnss_sigma.mean(axis=0))
    text = fit.summary()
    assert "GNSS residuals (adjusted - GNSS)" in text and "IMU residuals" in text
    d = json.loads(json.dumps(fit.to_dict(angle_unit="gon")))
    img = d["images"][0]
    np.testing.assert_allclose(img["gnss_residual"], fit.gnss_residuals[0], rtol=1e-12)
    np.testing.assert_allclose(
        img["imu_residual"], np.degrees(fit.imu_residuals[0]) * 400 / 360, rtol=1e-9
    )
    assert d["orientation_residual_rms"]["gnss_images"] == fit.block.n_images


def test_images_without_gnss_have_no_residual():
    sim = pg.simulate.uav_block(
        "FC300S", seed=4, strips=2, images_per_strip=5, gnss_sigma=None, imu_sigma_deg=None
    )
    fit = pg.bundle_adjust(sim.block, snooping=False)
    assert np.all(np.isnan(fit.gnss_residuals)) and np.all(np.isnan(fit.imu_residuals))
    assert fit.orientation_residual_rms() == {}
    assert "GNSS residuals" not in fit.summary()
    d = json.loads(json.dumps(fit.to_dict()))
    assert d["images"][0]["gnss_residual"] == [None, None, None]


def test_fixed_exterior_says_so():
    sim = pg.simulate.uav_block("FC300S", seed=4, strips=2, images_per_strip=5)
    fit = pg.bundle_adjust(sim.block, snooping=False)
    re = pg.bundle_adjust(fit.block, fix_exterior=True, free=(), snooping=False)
    assert "exterior orientation: held fixed" in re.summary()
    assert "RMS of the standard deviations: X0" not in re.summary()


def test_report_shows_the_orientation_residuals(fit, tmp_path):
    from photogeom.report.bundle import bundle_report

    path = bundle_report(fit, angle_unit="gon").write(tmp_path / "r.html")
    html = path.read_text()
    assert "RMS GNSS residual (adjusted - GNSS, 10 images)" in html
    assert "RMS IMU residual (adjusted - IMU, 10 images)" in html and "gon" in html
