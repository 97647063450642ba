"""Residual grids against checks written independently of the grid code: cross-validation
by refitting without each fold by hand, the support map by counting points cell by cell,
and bilinear fields (with their twist term) on images and spacings of any size."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.calibration import fit_grid
from photogeom.calibration.grid import _fold_of, evaluate_nodes


def _scattered(rng, n, w, h):
    return np.column_stack([rng.uniform(-0.5, w - 0.5, n), rng.uniform(-0.5, h - 0.5, n)])


@pytest.mark.parametrize("border", ["mean", "linear"])
@pytest.mark.parametrize("sigma_constraint", [0.1, "vce"])
def test_cross_validation_equals_fits_without_each_fold(border, sigma_constraint):
    """rms_cv_after is the RMS length of the residuals of each fold minus the field of a
    grid fitted without that fold (here: fit_grid on the other points, with the weights of
    the fit), rms_cv_before that of the residuals themselves."""
    rng = np.random.default_rng(3)
    w, h, g, n = 600, 400, 100, 200
    uv = _scattered(rng, n, w, h)
    l = np.column_stack([np.sin(uv[:, 0] / 150), np.cos(uv[:, 1] / 130)])
    l += rng.normal(0, 0.3, (n, 2))
    s_obs = rng.uniform(0.2, 0.5, n)
    kw = dict(border=border, sigma_obs=s_obs, sigma_constraint=sigma_constraint)
    grid = fit_grid(uv, l, (w, h), g, folds=5, seed=4, **kw)
    fold = _fold_of(uv, l, 5, 4)
    assert np.bincount(fold).tolist() == [40] * 5
    pred = np.empty_like(l)
    for f in range(5):
        out = fold == f
        part = fit_grid(
            uv[~out],
            l[~out],
            (w, h),
            g,
            border=border,
            sigma_obs=grid.sigma_obs[~out],
            sigma_constraint=grid.sigma_constraint,
            folds=0,
        )
        pred[out] = part.evaluate(uv[out])
    rms = lambda v: math.sqrt(np.mean(np.sum(v * v, axis=1)))  # noqa: E731
    assert grid.rms_cv_after == pytest.approx(rms(l - pred), rel=1e-9)
    assert grid.rms_cv_before == pytest.approx(rms(l), rel=1e-12)


def test_support_counts_the_points_of_the_cells_around_each_node():
    """Counts and support against a count point by point (each point adds 1 to the four
    nodes of the element that evaluates it, the last cell taking the points past the last
    node row or column), on random image sizes and spacings, points on the image edges."""
    rng = np.random.default_rng(0)
    for _ in range(40):
        w, h = (int(x) for x in rng.integers(50, 700, 2))
        g = float(rng.uniform(20, min(w, h)))
        n = int(rng.integers(5, 80))
        uv = _scattered(rng, n, w, h)
        uv[:3] = [[-0.5, -0.5], [w - 0.5, h - 0.5], [w - 0.5, -0.5]]
        grid = fit_grid(uv, rng.normal(0, 1, (n, 2)), (w, h), g, folds=0, min_support=2)
        ny, nx = grid.layout.shape
        # the last node at or past the outer edge of the last pixel, the one before not
        assert (nx - 2) * g < w - 0.5 <= (nx - 1) * g
        assert (ny - 2) * g < h - 0.5 <= (ny - 1) * g
        counts = np.zeros((ny, nx), int)
        for u, v in uv:  # points, in a test
            j = min(max(math.floor(u / g), 0), nx - 2)
            i = min(max(math.floor(v / g), 0), ny - 2)
            counts[i : i + 2, j : j + 2] += 1
        np.testing.assert_array_equal(grid.counts, counts)
        np.testing.assert_array_equal(grid.support, counts >= 2)


@settings(max_examples=40, deadline=None)
@given(
    w=st.integers(40, 900),
    h=st.integers(40, 900),
    fraction=st.floats(0.05, 1.0),
    seed=st.integers(0, 10**6),
    coef=st.lists(st.floats(-1, 1), min_size=8, max_size=8),
)
def test_a_bilinear_field_is_recovered_exactly(w, h, fraction, seed, coef):
    """r = a + b u + c v + d u v satisfies every constraint of border="linear" (each node
    the mean of its pair along each axis), so noise-free residuals give the field exactly:
    the nodes, the field between them and the residuals left, for any image size and
    spacing (here up to the shorter side, at most 31 x 31 nodes)."""
    g = max(fraction * min(w, h), max(w, h) / 30)
    rng = np.random.default_rng(seed)
    a = np.asarray(coef).reshape(2, 4)

    def field(p):
        x, y = p[:, :1] / w, p[:, 1:] / h
        return a[:, 0] + a[:, 1] * x + a[:, 2] * y + a[:, 3] * x * y

    n = 60
    uv = _scattered(rng, n, w, h)
    grid = fit_grid(uv, field(uv), (w, h), g, border="linear", sigma_constraint=0.5, folds=0)
    un, vn = grid.layout.node_coordinates()
    nodes = field(np.column_stack([un.ravel(), vn.ravel()]))
    np.testing.assert_allclose(grid.nodes.reshape(-1, 2), nodes, atol=1e-8)
    test = _scattered(rng, 50, w, h)
    np.testing.assert_allclose(grid.evaluate(test), field(test), atol=1e-8)
    assert grid.rms_after < 1e-8
    # the field is linear in the node values
    z1, z2 = rng.normal(size=(2, *grid.nodes.shape))
    np.testing.assert_allclose(
        evaluate_nodes(grid.layout, 2.0 * z1 - 3.0 * z2, test),
        2.0 * evaluate_nodes(grid.layout, z1, test) - 3.0 * evaluate_nodes(grid.layout, z2, test),
        atol=1e-12,
    )
