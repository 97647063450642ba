"""Statistics of camera models and image orientation against Monte Carlo (review 6)."""

from __future__ import annotations

import numpy as np

import photogeom as pg


def _three_images(k1: float):
    io_film = pg.InteriorOrientation(153.0, distortion=pg.BrownDistortion(k1=k1))
    io_digital = pg.InteriorOrientation.digital(4000.0, 2000.0, 1500.0)
    eos = [
        pg.ExteriorOrientation(0.0, 0.0, 1000.0, 0.02, -0.01, 0.1),
        pg.ExteriorOrientation(600.0, 0.0, 1000.0, -0.01, 0.03, -0.1),
        pg.ExteriorOrientation(300.0, 500.0, 1100.0, 0.01, 0.02, 1.0),
    ]
    return list(zip([io_film, io_digital, io_film], eos))


def test_intersection_std_with_distortion_matches_monte_carlo():
    # The measured (distorted) coordinates carry sigma; after undistortion a point at
    # normalised radius 0.31 with k1 = -0.3 has its noise scaled by about 1 / 0.8, which the
    # weights must carry (before: spread / reported std 1.05, 1.11, 1.13 for X, Y, Z).
    rng = np.random.default_rng(3)
    cams = _three_images(-0.3)
    sigma = np.array([0.006, 0.8, 0.002])  # mm, px, mm
    trials = 3000
    g = np.tile([350.0, 200.0, 100.0], (trials, 1))
    obs = np.stack([pg.project(g, io, eo) for io, eo in cams])
    obs = obs + rng.normal(size=obs.shape) * sigma[:, None, None]
    res = pg.space_intersection(obs, cams, sigma=sigma)
    # relative sampling error of a standard deviation from 3000 trials: 1 / sqrt(2 * 2999)
    # = 1.3 %; 5 % is about four of them
    ratio = res.points.std(axis=0, ddof=1) / res.std_prior.mean(axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.05)
    # E[sigma0^2] = 1; the mean of 3000 chi-square(3)/3 values has sampling error 1.5 %
    assert abs(np.mean(res.sigma0**2) - 1.0) < 0.06
