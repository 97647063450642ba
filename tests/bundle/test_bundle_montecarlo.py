"""Reported standard deviations of the bundle adjustment against the Monte-Carlo spread.

Each trial draws new image noise (0.5 px) and new control-point coordinates (their 1 cm
standard deviation), adjusts, and records calibration, one image's orientation and one tie
point. The full version (400 trials, 10 % agreement) is benchmarks/bundle_montecarlo.py;
here 120 trials and a bound that allows for their sampling error (about 6.5 % per std).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.bundle import bundle_adjust

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block


@pytest.mark.slow
def test_standard_deviations_match_the_monte_carlo_spread():
    ideal = grid_block(0, noise=0.0, rows=2, cols=3, n_points=150)
    ctrl = ideal.role == "control"
    est, std, s02 = [], [], []
    for k in range(120):
        rng = np.random.default_rng(1000 + k)
        xyz = ideal.xyz.copy()
        xyz[ctrl] += rng.normal(0, 0.01, (int(ctrl.sum()), 3))
        uv = ideal.observations.uv + rng.normal(0, 0.5, ideal.observations.uv.shape)
        b = ideal.with_observations(uv=uv, sigma=0.5).replace(xyz=xyz)
        r = bundle_adjust(b, snooping=False, point_covariance=True)
        c, cs = r.calibration["cam"], r.calibration_std["cam"]
        est.append([c["f"], c["cx"], c["k1"], *r.block.exterior[2], *r.block.xyz[10]])
        std.append([cs["f"], cs["cx"], cs["k1"], *r.exterior_std[2], *r.point_std[10]])
        s02.append(r.sigma0**2)
    ratio = np.std(est, axis=0, ddof=1) / np.mean(std, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.2), ratio
    assert abs(np.mean(ratio) - 1) < 0.06, ratio
    assert np.mean(s02) == pytest.approx(1.0, abs=0.03)
