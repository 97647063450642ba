"""The bundle adjustment's statistics: defects found by measurement.

Monte-Carlo tolerances are derived from the sampling error of a standard deviation
estimated from N trials, about 1 / sqrt(2 N) per ratio; ratios averaged over the images of
a block scatter less (they are correlated, so not by the full sqrt(m)).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import photogeom as pg

# --- image-variant calibration: the per-image offsets of f, cx, cy ------------------------------


def _iv_sim(seed: int = 3):
    return pg.simulate.uav_block(
        "FC300S",
        seed=seed,
        strips=2,
        images_per_strip=5,
        local_field=0.0,
        sigma=0.5,
        calibration_variation=(2.0, 1.0, 1.0),
    )


def test_image_variant_offsets_have_standard_deviations_everywhere():
    """Before: the images' f, cx, cy offsets were estimated but had no standard deviation
    anywhere, and summary() / the report called f, cx, cy 'fixed'."""
    sim = _iv_sim()
    fit = pg.bundle_adjust(sim.block, snooping=False)
    std = fit.image_calibration_std
    assert std.shape == (sim.block.n_images, 3)
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    text = fit.summary()
    f_line = next(line for line in text.splitlines() if line.split()[:1] == ["f"])  # its row
    assert "fixed" not in f_line and "per image" in f_line
    d = json.loads(json.dumps(fit.to_dict()))
    row = d["images"][0]
    assert row["sf_offset"] == pytest.approx(std[0, 0])
    assert row["f_offset"] == pytest.approx(fit.block.calibration_offset[0, 0])
    ic = d["image_calibration"][str(sim.block.camera_ids[0])]
    assert ic["f"]["rms_std"] == pytest.approx(math.sqrt(np.mean(std[:, 0] ** 2)))
    from photogeom.report import bundle_report

    html = bundle_report(fit).to_html()
    assert "per image: offsets RMS" in html
    # held offsets (free=() holds the whole calibration): NaN, none reported
    held = pg.bundle_adjust(
        sim.block.replace(
            calibrations=sim.truth.calibrations, calibration_offset=sim.truth.calibration_offset
        ),
        free=(),
        snooping=False,
    )
    assert np.all(np.isnan(held.image_calibration_std))
    assert held.to_dict()["image_calibration"] == {}


def test_image_variant_focal_lengths_of_a_flat_block_without_gnss_get_a_note():
    """Flat terrain, nadir images, no GNSS: the group's f gets the note 'the focal length is
    poorly determined'; estimated per image, the offsets were determined only to 5.9e3 px
    (of 2034 px) and nothing said so. Both from the truth (three iterations: the statistics
    are those of the geometry)."""
    from photogeom.bundle.result import F_STD_MAX

    sim = pg.simulate.uav_block(
        "FC300S",
        seed=2,
        terrain="flat",
        gnss_sigma=None,
        imu_sigma_deg=None,
        attitude_jitter_deg=0.2,
        strips=2,
        images_per_strip=5,
        local_field=0.0,
        calibration_variation=(2.0, 1.0, 1.0),
    )
    start = sim.block.replace(exterior=sim.truth.exterior, xyz=sim.truth.xyz)
    group = start.replace(image_variant={g: () for g in start.camera_ids.tolist()})
    fit = pg.bundle_adjust(group, snooping=False, max_iterations=3)
    assert any("the focal length is poorly determined" in n for n in fit.notes)
    fit = pg.bundle_adjust(start, snooping=False, max_iterations=3)
    assert np.all(fit.image_calibration_std[:, 0] > F_STD_MAX)
    (note,) = [n for n in fit.notes if "image-variant f" in n]
    assert "poorly determined in 10 of its 10 images" in note
    assert "hold f (leave it out of the free parameters)" in note


def test_image_variant_focal_lengths_of_a_block_with_gnss_get_no_note():
    sim = _iv_sim()
    fit = pg.bundle_adjust(sim.block, snooping=False)
    assert np.all(fit.image_calibration_std[:, 0] < 10.0)
    assert not any("image-variant f" in n for n in fit.notes)


@pytest.mark.slow
def test_image_variant_offset_std_matches_the_monte_carlo_spread():
    """80 redraws of image noise, survey, GNSS and IMU: the spread of each image's offsets
    against the reported standard deviations. Measured 0.98, 0.98, 1.00 (150 trials, 21
    images). One ratio from 80 trials scatters by 1/sqrt(160) = 8 %; the mean over the
    images by less: bounds 0.15 for the mean, 0.35 for every image."""
    sim = _iv_sim()
    truth, start = sim.truth, sim.block
    ideal = truth.observations.uv
    sig = truth.observations.sigma
    known = truth.role != "tie"
    off, std = [], []
    for k in range(80):
        rng = np.random.default_rng(7000 + k)
        uv = ideal + rng.normal(0.0, 1.0, ideal.shape) * sig[:, None]
        xyz = start.xyz.copy()
        xyz[known] = (
            truth.xyz[known]
            + rng.normal(0.0, 1.0, (int(known.sum()), 3)) * (truth.point_sigma[known])
        )
        gn = truth.exterior[:, :3] + rng.normal(0, 1, (truth.n_images, 3)) * start.gnss_sigma
        imu = truth.exterior[:, 3:] + rng.normal(0, 1, (truth.n_images, 3)) * start.imu_sigma
        b = start.with_observations(uv=uv).replace(xyz=xyz, gnss=gn, imu=imu)
        fit = pg.bundle_adjust(b, snooping=False)
        off.append(fit.block.calibration_offset.copy())
        std.append(fit.image_calibration_std)
    ratio = np.std(off, axis=0, ddof=1) / np.mean(std, axis=0)
    assert np.all(np.abs(ratio.mean(axis=0) - 1) < 0.15), ratio.mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.35), ratio


# --- check points under variance-component estimation -------------------------------------------


def _gcp_noise_block(true_gcp_sigma: float, seed: int = 20_025):
    """The simulated block with the image observations of control and check points drawn
    with ``true_gcp_sigma`` px while their a-priori sigma stays 0.5 px."""
    sim = pg.simulate.uav_block("FC300S", seed=3, local_field=0.0, sigma=0.5, gcp_sigma=0.5)
    truth = sim.truth
    o = truth.observations
    surveyed = np.isin(o.point_ids, truth.point_ids[truth.role != "tie"])
    noise = np.where(surveyed, true_gcp_sigma, o.sigma)
    rng = np.random.default_rng(seed)
    uv = o.uv + rng.normal(0.0, 1.0, o.uv.shape) * noise[:, None]
    return sim.block.with_observations(uv=uv), surveyed


def test_check_point_std_uses_the_estimated_variance_of_control_measurements():
    """Check points are measured in the images like control points: under variance-
    component estimation their image observations take the factor estimated for the
    control points' (``image_control``), not the tie points'. Before: with GCP image noise
    twice its a-priori sigma (factor 2.0 estimated) the check points' std came from the
    tie factor (1.0): over 100 Monte-Carlo redraws their spread was 1.26, 1.32, 1.21 times
    the reported std in X, Y, Z; now 0.97, 0.99, 0.97.

    Exact form of the test: the adjustment with the estimated factors built into the
    sigmas gives the same check-point covariance as the one that estimated them."""
    block, surveyed = _gcp_noise_block(1.0)
    vce = pg.bundle_adjust(block, variance_components=True, snooping=False, point_covariance=True)
    f = vce.variance_components["factors"]
    assert f["image_control"] > 1.5  # the GCP measurements are found worse than said
    s = block.observations.sigma * np.where(surveyed, f["image_control"], f["image_tie"])
    baked = block.with_observations(sigma=s).replace(
        point_sigma=block.point_sigma * f["control"],
        gnss_sigma=block.gnss_sigma * f["gnss"],
        imu_sigma=block.imu_sigma * f["imu"],
    )
    ref = pg.bundle_adjust(baked, snooping=False, point_covariance=True)
    assert ref.sigma0 == pytest.approx(vce.sigma0, rel=0.01)
    chk = block.role == "check"
    # the VCE stops at ratios within 1 % of 1: standard deviations agree to about 0.5 %
    np.testing.assert_allclose(vce.point_std[chk], ref.point_std[chk], rtol=0.01)
    np.testing.assert_allclose(vce.point_std[~chk], ref.point_std[~chk], rtol=0.01)


# --- variance-component estimation whose estimate of a group runs to zero -----------------------


def test_collapsing_variance_component_is_held_and_named():
    """A redraw of the simulated block (GCP image noise 1.5 px, a-priori 0.5 px) on which the
    iterated estimate of the control coordinates' variance runs to zero (factor 0.52, 0.11,
    0.026, ... per round; it happens in about 1 of 25 such redraws: 7 degrees of freedom).
    Before: after 16 rounds InputError 'a group has no redundancy (its observations are not
    controlled by the others)', naming no group and the wrong cause, and no adjustment (on
    other blocks the 20 rounds ran out first and the collapsed factor was used: control
    weights 1000 times too large). Now the group is held at its a-priori sigmas, named in
    ``not_estimated`` and the notes, and the other groups are estimated."""
    sim = pg.simulate.uav_block("FC300S", seed=3, local_field=0.0, sigma=0.5, gcp_sigma=0.5)
    truth, start = sim.truth, sim.block
    o = truth.observations
    known = truth.role != "tie"
    noise = np.where(np.isin(o.point_ids, truth.point_ids[known]), 1.5, o.sigma)
    rng = np.random.default_rng(20_025)
    uv = o.uv + rng.normal(0.0, 1.0, o.uv.shape) * noise[:, None]
    xyz = start.xyz.copy()
    xyz[known] = (
        truth.xyz[known] + rng.normal(0.0, 1.0, (int(known.sum()), 3)) * (truth.point_sigma[known])
    )
    gn = truth.exterior[:, :3] + rng.normal(0, 1, (truth.n_images, 3)) * start.gnss_sigma
    imu = truth.exterior[:, 3:] + rng.normal(0, 1, (truth.n_images, 3)) * start.imu_sigma
    b = start.with_observations(uv=uv).replace(xyz=xyz, gnss=gn, imu=imu)
    fit = pg.bundle_adjust(b, variance_components=True, snooping=False)
    vc = fit.variance_components
    assert list(vc["not_estimated"]) == ["control"]
    assert "runs to zero" in vc["not_estimated"]["control"]
    assert vc["factors"]["control"] == 1.0
    assert vc["converged"]
    # the GCP image observations: 1.5 px against 0.5 px a priori (about 70 degrees of freedom)
    assert vc["factors"]["image_control"] == pytest.approx(3.0, rel=0.2)
    assert vc["factors"]["image_tie"] == pytest.approx(1.0, abs=0.03)
    assert fit.sigma0 == pytest.approx(1.0, abs=0.02)
    assert any("'control' is not estimated" in n for n in fit.notes)
    assert "(not estimated: a-priori)" in fit.summary()
    from photogeom.report import bundle_report

    assert "control (not estimated: a-priori sigmas)" in bundle_report(fit).to_html()


def test_variance_components_converge_with_overstated_sigmas():
    """Not a collapse: GNSS and IMU sigmas 100 times too large give factors about 0.011."""
    sim = pg.simulate.uav_block("FC300S", seed=3, local_field=0.0, sigma=0.5)
    b = sim.block
    b = b.replace(gnss_sigma=b.gnss_sigma * 100, imu_sigma=b.imu_sigma * 100)
    fit = pg.bundle_adjust(b, variance_components=True, snooping=False)
    f = fit.variance_components["factors"]
    assert fit.variance_components["converged"]
    assert 0.005 < f["gnss"] < 0.02 and 0.005 < f["imu"] < 0.02


# --- data snooping with a robust loss ------------------------------------------------------------


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_w_test_false_alarms_with_a_robust_loss(loss):
    """Clean data, noise of exactly the a-priori sigma: the share of |w| above the critical
    value of alpha = 0.001 is alpha. Before, w divided by sqrt(1 - h / weight) (the
    leverage as if at full weight), too small for down-weighted observations: 4.4 (Huber)
    and 6.5 (Cauchy) times alpha over 20 redraws; now 0.76 and 0.61 times (the variance of
    the prediction is bounded from above). 10 redraws hold 53 640 tests: about 54
    expected at alpha (Poisson sd 7); bounds 0.3 and 1.8 times that."""
    sim = pg.simulate.uav_block("FC300S", seed=3, local_field=0.0, sigma=0.5)
    o = sim.truth.observations
    above, tests = 0, 0
    for k in range(10):
        rng = np.random.default_rng(900 + k)
        uv = o.uv + rng.normal(0.0, 1.0, o.uv.shape) * o.sigma[:, None]
        fit = pg.bundle_adjust(sim.block.with_observations(uv=uv), loss=loss)
        w = fit.snooping["w"][fit.in_adjustment]
        assert np.all(np.isfinite(w))
        above += int(np.sum(np.abs(w) > fit.snooping["critical_value"]))
        tests += w.size
    rate = above / tests
    assert 0.3 * 0.001 < rate < 1.8 * 0.001, rate


def test_cauchy_w_test_names_the_blunder_first():
    """Blunders of 5 px (10 sigma): the largest |w| is a blunder. Before, with the Cauchy
    loss, it was one in 4 of 10 simulated blocks (inflated w of down-weighted clean
    observations came first); now in 10 of 10."""
    for seed in range(5):
        sim = pg.simulate.uav_block(
            "FC300S", seed=seed, local_field=0.0, sigma=0.5, blunders=3, blunder_size=5.0
        )
        fit = pg.bundle_adjust(sim.block, loss="cauchy")
        o = sim.block.observations
        planted = {(o.image_ids[k].item(), o.point_ids[k].item()) for k in sim.blunder_rows}
        top = fit.snooping["flagged"][0]
        assert (top[0], top[1]) in planted, seed
