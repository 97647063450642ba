"""Bias compensation of vendor RPCs: recovery of a simulated bias, Monte-Carlo statistics."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, InputError, TooFewPointsError
from photogeom.rpc import RPC, refine_rpc

SHIFT = (10.0, -7.0)  # px
DRIFT = 1e-4  # px per px of row (along-track drift)
SIGMA = 0.3  # px


@pytest.fixture(scope="module")
def scene():
    """A WorldView-2 RPC, 4 control and 20 check points, and their true image positions."""
    rpc = RPC.from_file(pg.datasets.path("worldview2"))
    rng = np.random.default_rng(2024)
    c0, c1, r0, r1 = rpc.image_bounds
    # control near the corners (a usual layout), check points anywhere
    cc = np.array([0.1, 0.9, 0.1, 0.9]) * (c1 - c0) + c0
    rc = np.array([0.1, 0.15, 0.85, 0.9]) * (r1 - r0) + r0
    ck_c, ck_r = rng.uniform(c0, c1, 20), rng.uniform(r0, r1, 20)
    cols, rows = np.concatenate([cc, ck_c]), np.concatenate([rc, ck_r])
    h = rng.uniform(0.0, 300.0, cols.size)
    lon, lat = rpc.localize(cols, rows, h)
    ground = np.column_stack([lon, lat, h])
    c, r = rpc.project(lon, lat, h)
    true = np.column_stack([c + SHIFT[0] + DRIFT * r, r + SHIFT[1] + DRIFT * r])
    return rpc, ground, true


def test_four_points_remove_shift_and_drift_exactly_without_noise(scene):
    rpc, ground, true = scene
    fit = refine_rpc(rpc, ground[:4], true[:4], model="shift+drift",
                     check_ground=ground[4:], check_image=true[4:])  # fmt: skip
    p = fit.params
    assert p["a0"] == pytest.approx(SHIFT[0], abs=1e-7)
    assert p["b0"] == pytest.approx(SHIFT[1], abs=1e-7)
    assert p["a2"] == pytest.approx(DRIFT, abs=1e-11)
    assert p["b2"] == pytest.approx(DRIFT, abs=1e-11)
    assert np.max(np.abs(fit.check_residuals)) < 1e-6
    # the corrected model localises the true image positions to the true ground points
    lon, lat = fit.model.localize(true[:, 0], true[:, 1], ground[:, 2])
    assert np.max(np.abs(lon - ground[:, 0])) < 1e-10
    assert np.max(np.abs(lat - ground[:, 1])) < 1e-10
    # an affine correction contains shift+drift
    fa = refine_rpc(rpc, ground[:4], true[:4], model="affine")
    assert fa.params["a1"] == pytest.approx(0.0, abs=1e-11)
    assert fa.params["a2"] == pytest.approx(DRIFT, abs=1e-11)


def test_with_noise_the_bias_is_removed_to_the_noise_level(scene):
    rpc, ground, true = scene
    rng = np.random.default_rng(1)
    obs = true + rng.normal(0.0, SIGMA, true.shape)
    raw = np.column_stack(rpc.project(*ground[4:].T)) - true[4:]
    assert np.sqrt(np.mean(raw**2)) > 5.0  # the vendor model is off by ~10 px
    for model in ("shift+drift", "affine"):
        fit = refine_rpc(rpc, ground[:4], obs[:4], model=model, sigma=SIGMA,
                         check_ground=ground[4:], check_image=true[4:])  # fmt: skip
        # check points against their true positions: only the propagated noise remains
        assert fit.check_rmse < 4 * SIGMA
    # a shift alone leaves the drift (up to ~1 px over 20000 rows)
    fs = refine_rpc(rpc, ground[:4], obs[:4], model="shift", check_ground=ground[4:],
                    check_image=true[4:])  # fmt: skip
    assert fs.check_rmse > fit.check_rmse


@pytest.mark.parametrize("model", ["shift", "shift+drift", "affine"])
def test_standard_deviations_match_monte_carlo_spread(scene, model):
    rpc, ground, true = scene
    fit = refine_rpc(rpc, ground[:4], true[:4], model=model, sigma=SIGMA)
    names = fit.parameter_names
    std_prior = np.array([fit.std_errors_prior[n] for n in names])
    # the estimator is linear in the observations: batch all trials in one least-squares
    # solve with the same design (independent of the library's solver), seeded
    c, r = rpc.project(*ground[:4].T)
    cols = {"a0": (1, 0), "a1": (c, 0), "a2": (r, 0), "b0": (0, 1), "b1": (0, c), "b2": (0, r)}
    A = np.column_stack([
        np.concatenate([np.broadcast_to(cols[p][0], 4), np.broadcast_to(cols[p][1], 4)])
        for p in names
    ])  # fmt: skip
    trials = 6000
    rng = np.random.default_rng(77)
    noise = rng.normal(0.0, SIGMA, (trials, 8))
    # observations that the model fits exactly (the shift model cannot fit a drift)
    L = (A @ fit.parameters)[None, :] + noise
    est, *_ = np.linalg.lstsq(A, L.T, rcond=None)
    mc_std = est.std(axis=1, ddof=1)
    np.testing.assert_allclose(std_prior, mc_std, rtol=0.10)
    # the library's estimate for one realisation is the same linear estimate
    one = refine_rpc(rpc, ground[:4], np.column_stack([c, r]) + L[0].reshape(2, 4).T, model=model,
                     sigma=SIGMA)  # fmt: skip
    np.testing.assert_allclose(one.parameters, est[:, 0], rtol=1e-7, atol=1e-10)
    # sigma0^2 is unbiased: its mean over the trials is 1 (a-priori sigma given)
    red = 8 - len(names)
    v = A @ est - L.T
    s0sq = np.sum(v**2, axis=0) / SIGMA**2 / red
    assert np.mean(s0sq) == pytest.approx(1.0, abs=0.06)
    assert fit.redundancy == red


def test_bad_input(scene):
    rpc, ground, true = scene
    with pytest.raises(InputError, match="unknown bias-compensation model"):
        refine_rpc(rpc, ground[:4], true[:4], model="quadratic")
    with pytest.raises(TooFewPointsError, match="at least 3"):
        refine_rpc(rpc, ground[:2], true[:2], model="affine")
    with pytest.raises(TooFewPointsError, match="at least 1"):
        refine_rpc(rpc, ground[:0], true[:0], model="shift")
    line = true[:4].copy()
    line[:, 1] = 5000.0
    g = ground[:4].copy()
    g[:, :2] = np.column_stack(rpc.localize(line[:, 0], line[:, 1], g[:, 2]))
    with pytest.raises(DegenerateGeometryError, match="one image row"):
        refine_rpc(rpc, g, line, model="shift+drift")
    with pytest.raises(DegenerateGeometryError, match="one line"):
        refine_rpc(rpc, g, line, model="affine")
    with pytest.raises(InputError, match="sigma"):
        refine_rpc(rpc, ground[:4], true[:4], sigma=-1.0)
    with pytest.raises(InputError, match="check_image"):
        refine_rpc(rpc, ground[:4], true[:4], check_ground=ground[4:])
    with pytest.raises(InputError, match="4 point"):
        refine_rpc(rpc, ground[:4], true[:3])
