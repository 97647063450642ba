"""Weights against replicated observations: a point pair of weight k (or standard deviation
sigma / sqrt(k)) is the same pair given k times at weight 1 (sigma). The estimate, the cofactor
matrix and v'Pv of every estimator must agree (the redundancy differs, so sigma0 is compared
through v'Pv = sigma0^2 r). An independent check of each estimator's weight handling: the
replicated problem has no weights at all.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

N = 10


def _weights(rng, n=N):
    k = rng.integers(1, 4, n)
    return k, np.repeat(np.arange(n), k)


def _same(a, b, rtol=1e-9):
    np.testing.assert_allclose(a.parameters, b.parameters, rtol=rtol, atol=1e-9)
    scale = np.abs(b.cofactor).max()
    np.testing.assert_allclose(a.cofactor, b.cofactor, rtol=0, atol=rtol * scale)
    assert a.sigma0**2 * a.redundancy == pytest.approx(b.sigma0**2 * b.redundancy, rel=1e-8)


@pytest.mark.parametrize(
    "method", ["svd", "quaternion", "dual-quaternion", "gauss-markov", "gauss-helmert"]
)
def test_absolute_orientation(method):
    rng = np.random.default_rng(3)
    x = rng.uniform(-50.0, 50.0, (N, 3))
    R = pg.opk_matrix(*np.radians([30.0, -50.0, 160.0])).T
    X = 1.3 * x @ R.T + np.array([4.0e5, 5.1e6, 300.0]) + rng.normal(0.0, 0.02, (N, 3))
    k, rep = _weights(rng)
    _same(pg.absolute_orientation(x, X, method, weights=k),
          pg.absolute_orientation(x[rep], X[rep], method))  # fmt: skip
    if method in ("gauss-markov", "gauss-helmert"):
        both = method == "gauss-helmert"
        a = pg.absolute_orientation(x, X, method, sigma_target=0.02 / np.sqrt(k),
                                    sigma_source=0.01 / np.sqrt(k) if both else None)
        b = pg.absolute_orientation(x[rep], X[rep], method, sigma_target=0.02,
                                    sigma_source=0.01 if both else None)  # fmt: skip
        _same(a, b)


@pytest.mark.parametrize(
    "model, errors_in",
    [("similarity2d", "target"), ("affine2d", "target"), ("projective2d", "target"),
     ("projective2d", "both"), ("similarity3d", "target"), ("rigid3d", "target"),
     ("affine3d", "target"), ("projective3d", "both")],
)  # fmt: skip
def test_transformations(model, errors_in):
    rng = np.random.default_rng(4)
    d = 3 if model.endswith("3d") else 2
    n = 14
    src = rng.uniform(0.0, 100.0, (n, d))
    H = np.eye(d + 1)
    H[:d, :d] += rng.uniform(-0.1, 0.1, (d, d))
    H[:d, d] = rng.uniform(-5.0, 5.0, d)
    if model.startswith("projective"):
        H[d, :d] = rng.uniform(-1e-3, 1e-3, d)
    h = np.c_[src, np.ones(n)] @ H.T
    dst = h[:, :d] / h[:, d:] + rng.normal(0.0, 0.05, (n, d))
    k, rep = _weights(rng, n)
    w = k if errors_in == "target" else np.repeat(k[:, None], 2 * d, axis=1)
    a = pg.estimate_transform(model, src, dst, weights=w, errors_in=errors_in)
    b = pg.estimate_transform(model, src[rep], dst[rep], errors_in=errors_in)
    np.testing.assert_allclose(a.model.apply(src), b.model.apply(src), atol=1e-9)
    if not model.startswith("projective"):  # the others are solved in reduced coordinates
        return  # whose centroid is that of the (replicated) points: parameters differ
    _same(a, b, rtol=1e-7)


def _frame(rng, n=N):
    io = pg.InteriorOrientation(100.0, 0.01, -0.02, distortion=pg.BrownDistortion(k1=-0.02))
    eo = pg.ExteriorOrientation(100.0, 200.0, 900.0, *np.radians([5.0, -10.0, 120.0]))
    xn = rng.uniform(-0.4, 0.4, (n, 2))
    d = rng.uniform(300.0, 900.0, n)
    rays = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * d[:, None]
    g = eo.position + rays @ eo.matrix
    return io, eo, g


def test_space_resection_with_and_without_self_calibration():
    rng = np.random.default_rng(5)
    io, eo, g = _frame(rng, 12)
    xy = pg.project(g, io, eo) + rng.normal(0.0, 0.004, (12, 2))
    k, rep = _weights(rng, 12)
    for calibrate in ((), ("f", "x0", "y0")):
        _same(pg.space_resection(g, xy, io, sigma=0.004 / np.sqrt(k), calibrate=calibrate),
              pg.space_resection(g[rep], xy[rep], io, sigma=0.004, calibrate=calibrate))


@pytest.mark.parametrize("constrained", [False, True])
def test_dlt(constrained):
    rng = np.random.default_rng(6)
    io, eo, g = _frame(rng, 12)
    io = io.with_distortion(None)
    xy = pg.project(g, io, eo) + rng.normal(0.0, 0.004, (12, 2))
    k, rep = _weights(rng, 12)
    _same(pg.estimate_dlt(g, xy, sigma=0.004 / np.sqrt(k), constrained=constrained),
          pg.estimate_dlt(g[rep], xy[rep], sigma=0.004, constrained=constrained))


def test_affine_camera():
    rng = np.random.default_rng(7)
    g = np.c_[rng.uniform(0, 100, 12), rng.uniform(0, 100, 12), rng.uniform(0, 20, 12)]
    cam = pg.AffineCamera(np.array([2.0, 0.1, 0.3, 50.0]), np.array([-0.05, 1.9, 0.4, 30.0]),
                          "px")  # fmt: skip
    im = cam.project(g) + rng.normal(0.0, 0.5, (12, 2))
    k, rep = _weights(rng, 12)
    _same(pg.estimate_affine_camera(g, im, sigma=0.5 / np.sqrt(k)),
          pg.estimate_affine_camera(g[rep], im[rep], sigma=0.5))


@pytest.mark.parametrize("method", ["dependent", "independent"])
def test_relative_orientation(method):
    rng = np.random.default_rng(8)
    io = pg.InteriorOrientation(100.0, x0=0.01, y0=-0.02, unit="mm")
    e1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, *np.radians([1.0, -2.0, 3.0]))
    e2 = pg.ExteriorOrientation(60.0, 2.0, 101.0, *np.radians([-2.0, 3.0, 5.0]))
    ground = np.c_[rng.uniform(-35.0, 95.0, 15), rng.uniform(-35.0, 35.0, 15),
                   rng.uniform(-15.0, 15.0, 15)]  # fmt: skip
    xy1 = pg.project(ground, io, e1) + rng.normal(0.0, 0.004, (15, 2))
    xy2 = pg.project(ground, io, e2) + rng.normal(0.0, 0.004, (15, 2))
    k, rep = _weights(rng, 15)
    _same(pg.relative_orientation(xy1, xy2, io, method=method, sigma=0.004 / np.sqrt(k),
                                  robust=False),
          pg.relative_orientation(xy1[rep], xy2[rep], io, method=method, sigma=0.004,
                                  robust=False))  # fmt: skip
