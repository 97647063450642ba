"""sigma0_prior of the bundle adjustment: the weights are P = sigma0_prior^2 / sigma^2 for
observations of standard deviation sigma (the convention of every adjustment in the library),
so with the right sigmas sigma0 is about sigma0_prior, and the standard deviations, the
chi-square test of v'Pv / sigma0_prior^2 and Baarda's w do not depend on sigma0_prior.
Checked against the same block adjusted with the default 1 and against redraws of the noise.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.bundle import bundle_adjust

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

SIGMA = 0.5  # px


def _block(seed):
    ideal = grid_block(0, noise=0.0, rows=2, cols=3, n_points=60)
    ctrl = ideal.role == "control"
    rng = np.random.default_rng(seed)
    xyz = ideal.xyz.copy()
    xyz[ctrl] += rng.normal(0.0, 0.01, (int(ctrl.sum()), 3))  # the control sigma (1 cm)
    uv = ideal.observations.uv + rng.normal(0.0, SIGMA, ideal.observations.uv.shape)
    return ideal.with_observations(uv=uv, sigma=SIGMA).replace(xyz=xyz)


@pytest.mark.parametrize("k", [0.01, 7.0])
def test_only_sigma0_scales_with_sigma0_prior(k):
    block = _block(1)
    one = bundle_adjust(block, point_covariance=True)
    r = bundle_adjust(block, point_covariance=True, sigma0_prior=k)
    assert r.sigma0_prior == k
    assert r.sigma0 == pytest.approx(k * one.sigma0, rel=1e-9)
    for key in ("statistic", "p_value", "passed"):
        assert r.chi2[key] == pytest.approx(one.chi2[key], rel=1e-9)
    np.testing.assert_allclose(r.snooping["w"], one.snooping["w"], rtol=1e-9, equal_nan=True)
    assert r.snooping["flagged"] == one.snooping["flagged"]
    np.testing.assert_allclose(r.exterior_std, one.exterior_std, rtol=1e-9)
    np.testing.assert_allclose(r.point_std, one.point_std, rtol=1e-9)
    for name, std in one.calibration_std["cam"].items():
        assert r.calibration_std["cam"][name] == pytest.approx(std, rel=1e-9, nan_ok=True)


def test_sigma0_estimates_sigma0_prior_and_the_test_statistic_follows():
    """20 redraws with the right sigmas and sigma0_prior = 2: the mean of (sigma0 / 2)^2 is 1
    (r = 182: sampling error sqrt(2 / (20 r)) = 2.3 %; 0.08 allowed) and the chi-square
    statistic is r (sigma0 / sigma0_prior)^2 of every redraw (its mean r)."""
    ratios = []
    for seed in range(20):
        r = bundle_adjust(_block(100 + seed), snooping=False, sigma0_prior=2.0)
        ratios.append((r.sigma0 / r.sigma0_prior) ** 2)
        assert r.chi2["statistic"] == pytest.approx(r.redundancy * ratios[-1], rel=1e-9)
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.08)
