"""Estimates do not depend on where the coordinates are (UTM, geocentric offsets).

Every estimator is run on a problem and on the same problem translated by a UTM-like and by
a geocentric offset; predictions (after undoing the shift) and sigma0 must agree. The floor
is the representation of the shifted coordinates themselves (1e-9 m at 6e6 m), so sigma0 of
residuals of ~0.01 may differ by ~1e-7 relative.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project

SHIFTS = [np.array([500000.0, 5000000.0, 300.0]), np.array([4.2e6, 1.1e6, 4.7e6])]
IO = InteriorOrientation(f=35.0, x0=0.1, y0=-0.05, unit="mm")
EO = ExteriorOrientation(100.0, -50.0, 400.0, 0.02, -0.03, 0.4)


def _close(a: float, b: float, rel: float = 1e-7) -> bool:
    return abs(a / b - 1.0) < rel


@pytest.mark.parametrize("shift", SHIFTS)
@pytest.mark.parametrize(
    "model", ["rigid3d", "similarity3d", "affine3d", "projective3d", "polynomial3d"]
)
def test_3d_transformations_do_not_depend_on_the_offset(model, shift):
    rng = np.random.default_rng(1)
    src = rng.uniform(-500, 500, (30, 3))
    dst = src * 1.0001 + [10.0, 20.0, 30.0] + rng.normal(0, 0.01, src.shape)
    order = 2 if model == "polynomial3d" else None
    f0 = pg.estimate_transform(model, src, dst, order=order)
    f1 = pg.estimate_transform(model, src + shift, dst + shift, order=order)
    assert _close(f1.sigma0, f0.sigma0)
    assert np.max(np.abs(f1.transform(src + shift) - shift - f0.transform(src))) < 1e-7


@pytest.mark.parametrize("shift", SHIFTS)
@pytest.mark.parametrize("method", ["svd", "quaternion", "gauss-markov", "gauss-helmert"])
def test_absolute_orientation_does_not_depend_on_the_offsets(method, shift):
    rng = np.random.default_rng(7)
    x = rng.uniform(-300, 300, (25, 3))
    X = 1.0003 * x @ pg.opk_matrix(0.1, -0.2, 0.7) + [10, 20, 30] + rng.normal(0, 0.01, x.shape)
    f0 = pg.absolute_orientation(x, X, method=method)
    f1 = pg.absolute_orientation(x + shift, X + shift[::-1], method=method)
    assert _close(f1.sigma0, f0.sigma0)
    s0, s1 = f0.std_errors, f1.std_errors
    for name in ("scale", "omega", "phi", "kappa"):
        assert _close(s1[name], s0[name]), name


@pytest.mark.parametrize("shift", SHIFTS)
def test_camera_estimators_do_not_depend_on_the_offset(shift):
    rng = np.random.default_rng(2)
    g = np.c_[rng.uniform(-200, 300, 40), rng.uniform(-250, 150, 40), rng.uniform(0, 60, 40)]
    im = project(g, IO, EO) + rng.normal(0, 0.002, (40, 2))
    r0, r1 = pg.space_resection(g, im, IO), pg.space_resection(g + shift, im, IO)
    assert _close(r1.sigma0, r0.sigma0)
    assert np.max(np.abs(r1.exterior.position - shift - r0.exterior.position)) < 1e-7
    for name in ("X0", "omega", "kappa"):
        assert _close(r1.std_errors[name], r0.std_errors[name]), name
    for constrained in (False, True):
        d0 = pg.estimate_dlt(g, im, constrained=constrained)
        d1 = pg.estimate_dlt(g + shift, im, constrained=constrained)
        assert _close(d1.sigma0, d0.sigma0)
        assert np.max(np.abs(d1.model.project(g + shift) - d0.model.project(g))) < 1e-8
    a0, a1 = pg.estimate_affine_camera(g, im), pg.estimate_affine_camera(g + shift, im)
    assert _close(a1.sigma0, a0.sigma0)


@pytest.mark.parametrize("shift", SHIFTS)
def test_space_intersection_does_not_depend_on_the_offset(shift):
    rng = np.random.default_rng(3)
    g = np.c_[rng.uniform(-200, 300, 20), rng.uniform(-250, 150, 20), rng.uniform(0, 60, 20)]
    eo2 = ExteriorOrientation(250.0, -40.0, 410.0, -0.01, 0.02, 0.35)
    obs = np.stack([project(g, IO, e) + rng.normal(0, 0.002, (20, 2)) for e in (EO, eo2)])

    def moved(e):
        return ExteriorOrientation(*(e.position + shift), e.omega, e.phi, e.kappa)

    r0 = pg.space_intersection(obs, [(IO, EO), (IO, eo2)])
    r1 = pg.space_intersection(obs, [(IO, moved(EO)), (IO, moved(eo2))])
    assert np.max(np.abs(r1.points - shift - r0.points)) < 1e-7
    assert np.allclose(r1.std, r0.std, rtol=1e-7)
