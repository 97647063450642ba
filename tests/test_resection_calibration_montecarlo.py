"""Self-calibrating space resection (f, x0, y0 with the orientation) against 150 redraws of
the image noise: the spread of every parameter is its reported a-priori standard deviation
(sampling error about 6 %, 20 % allowed), the mean sigma0^2 is 1 (about 2.6 %, 0.08
allowed) and Baarda's w-test rejects 5 % of clean coordinates. A close-range camera in
pixels, oblique (phi 35 deg), turned by kappa 179 deg, with per-point standard deviations
given in pixels (system="pixel")."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

TRIALS = 150


def test_self_calibrating_resection_std_match_monte_carlo():
    rng = np.random.default_rng(31)
    io = pg.InteriorOrientation.digital(3000.0, 2000.0, 1500.0, image_size=(4000, 3000))
    eo = pg.ExteriorOrientation(5.0, -3.0, 20.0, *np.radians([-20.0, 35.0, 179.0]))
    n = 14
    xn = rng.uniform(-0.6, 0.6, (n, 2))
    rays = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * rng.uniform(4.0, 16.0, (n, 1))
    g = eo.position + rays @ eo.matrix
    cr = io.image_to_pixel(pg.project(g, io, eo))
    sigma = rng.uniform(0.3, 0.8, n)  # px, per point
    start = pg.InteriorOrientation.digital(2950.0, 2010.0, 1490.0, image_size=(4000, 3000))
    calibrate = ("f", "x0", "y0")
    fits = [
        pg.space_resection(g, cr + rng.normal(size=(n, 2)) * sigma[:, None], start,
                           calibrate=calibrate, sigma=sigma, system="pixel", initial=eo)
        for _ in range(TRIALS)
    ]  # fmt: skip
    f0 = fits[0]
    assert f0.parameter_names == ("X0", "Y0", "Z0", "omega", "phi", "kappa", "f", "x0", "y0")
    assert f0.redundancy == 2 * n - 9
    P = np.array([f.parameters for f in fits])
    P[:, 3:6] = P[0, 3:6] + (P[:, 3:6] - P[0, 3:6] + np.pi) % (2 * np.pi) - np.pi
    # unbiased recovery of the truth (each mean within 4 of its standard errors)
    # the principal point in the image system of the start values (origin at its guess)
    truth = np.r_[eo.position, eo.angles, io.f, start.pixel_to_image(io.image_to_pixel([0, 0]))]
    sd = np.sqrt(np.mean([np.diag(f.covariance_prior) for f in fits], axis=0))
    d = P.mean(axis=0) - truth
    d[3:6] = (d[3:6] + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(d) < 4 * sd / np.sqrt(TRIALS) + 1e-9), d / sd
    ratio = P.std(axis=0, ddof=1) / sd
    assert np.all((ratio > 0.8) & (ratio < 1.2)), dict(zip(f0.parameter_names, ratio.round(3)))
    assert np.mean([f.sigma0**2 for f in fits]) == pytest.approx(1.0, abs=0.08)
    w = np.abs(np.array([f.normalized_residuals for f in fits]))
    assert np.mean(w > 1.959964) == pytest.approx(0.05, abs=0.015)
