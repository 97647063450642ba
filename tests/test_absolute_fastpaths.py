"""Absolute orientation: one-pass moments about a reference, the spread check of both point
sets, chunked per-point statistics of many points, and the lean construction of results."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.adjust import Fit
from photogeom.orientation.absolute import AbsoluteOrientationFit
from photogeom.orientation.absolute_direct import CHUNK_POINTS, PairMoments, large_moments


def _utm_problem(n, seed=0, sort=False):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n, 3))
    if sort:  # the first chunk lies at one end: not representative of the whole set
        x = x[np.argsort(x[:, 0])] * [400.0, 1.0, 1.0]
    R = Rotation.random(random_state=seed).as_matrix()
    X = 250.0 * x @ R.T + [512_000.0, 4_215_000.0, 350.0] + rng.normal(0, 0.01, (n, 3))
    return x, X


@pytest.mark.parametrize("sort", [False, True])
def test_one_pass_moments_of_utm_coordinates_are_exact(sort):
    x, X = _utm_problem(3 * CHUNK_POINTS + 3, seed=2, sort=sort)
    w = np.random.default_rng(3).uniform(0.5, 2.0, x.shape[0])
    for ww in (None, w):
        m = large_moments(x, X, ww, scatter=True)
        a = PairMoments.from_moments(m)
        b = PairMoments.of(x, X, ww)
        np.testing.assert_allclose(a.H, b.H, rtol=1e-11, atol=1e-11 * np.abs(b.H).max())
        np.testing.assert_allclose(a.S, b.S, rtol=1e-11, atol=1e-11 * np.abs(b.S).max())
        assert a.a == pytest.approx(b.a, rel=1e-11)
        assert a.b == pytest.approx(b.b, rel=1e-10)
        # the centroids agree far below the spread (250 m)
        np.testing.assert_allclose(a.target_centroid, b.target_centroid, rtol=0, atol=1e-6)


def test_many_points_statistics_equal_the_engine():
    """The chunked closed-form statistics of 70 000 points (one-pass moments) equal those of
    the Gauss-Markov engine with the full Jacobian."""
    x, X = _utm_problem(70_001, seed=4)
    svd = pg.absolute_orientation(x, X, "svd")
    ref = pg.absolute_orientation(x, X, "gauss-markov")
    np.testing.assert_allclose(svd.parameters, ref.parameters, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(svd.cofactor, ref.cofactor, rtol=1e-7, atol=1e-18)
    assert svd.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    np.testing.assert_allclose(svd.residuals, ref.residuals, atol=1e-9)
    np.testing.assert_allclose(svd.redundancy_numbers, ref.redundancy_numbers, atol=1e-10)
    np.testing.assert_allclose(svd.normalized_residuals, ref.normalized_residuals, rtol=1e-6,
                               atol=1e-8)
    fast = pg.absolute_orientation(x, X, "svd", statistics=False)
    np.testing.assert_array_equal(fast.parameters, svd.parameters)


def test_weighted_many_points_statistics_equal_the_engine():
    x, X = _utm_problem(70_001, seed=5)
    w = np.random.default_rng(6).uniform(0.3, 3.0, x.shape[0])
    svd = pg.absolute_orientation(x, X, "svd", weights=w)
    ref = pg.absolute_orientation(x, X, "gauss-markov", weights=w)
    np.testing.assert_allclose(svd.cofactor, ref.cofactor, rtol=1e-7, atol=1e-18)
    np.testing.assert_allclose(svd.redundancy_numbers, ref.redundancy_numbers, atol=1e-10)
    np.testing.assert_allclose(svd.normalized_residuals, ref.normalized_residuals, rtol=1e-6,
                               atol=1e-8)


@pytest.mark.parametrize("side", ["source", "target"])
def test_one_collinear_set_is_refused_naming_its_side(side):
    rng = np.random.default_rng(7)
    spread = rng.normal(size=(12, 3))
    t = rng.normal(size=12)
    line = np.c_[t, -2 * t, 0.5 * t] * 100 + 1e-10 * rng.normal(size=(12, 3))
    x, X = (line, spread) if side == "source" else (spread, line)
    for method in ("svd", "quaternion", "dual-quaternion", "gauss-helmert", "gauss-markov"):
        with pytest.raises(pg.DegenerateGeometryError, match=f"12 {side} points are collinear"):
            pg.absolute_orientation(x, X, method)


def test_lean_fit_construction_equals_the_constructor():
    x, X = _utm_problem(20, seed=8)
    fit = pg.absolute_orientation(x, X, statistics=False)
    again = AbsoluteOrientationFit(**{f.name: getattr(fit, f.name) for f in fields(fit)})
    for f in fields(fit):
        a, b = getattr(fit, f.name), getattr(again, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        elif isinstance(a, float) and np.isnan(a):
            assert np.isnan(b), f.name
        else:
            assert a == b, f.name
    with pytest.raises(TypeError, match="missing field"):
        Fit._construct(model=None)
    with pytest.raises(AttributeError):
        fit.sigma0 = 1.0  # still frozen


def test_closed_form_perturbation_map_equals_the_derivatives():
    """``G`` (angle rates -> rotation perturbation) in closed form equals the one built from
    the derivative matrices, over the whole angle range, and its inverse is exact."""
    from photogeom.orientation.absolute_stats import (
        _rotation_and_perturbation,
        angle_to_perturbation,
        rotation_derivatives,
    )

    rng = np.random.default_rng(9)
    for _ in range(500):
        w, k = rng.uniform(-np.pi, np.pi, 2)
        p = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6)
        R, G, Ginv = _rotation_and_perturbation(w, p, k)
        R2, dR = rotation_derivatives(w, p, k)
        np.testing.assert_allclose(R, R2, atol=1e-15)
        np.testing.assert_allclose(G, angle_to_perturbation(R2, dR), atol=1e-14)
        np.testing.assert_allclose(Ginv @ G, np.eye(3), atol=1e-9)
    assert _rotation_and_perturbation(0.3, np.pi / 2, 0.1)[2] is None  # gimbal lock
