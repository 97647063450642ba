"""Absolute orientation: every kind of bad input gets a clear error (or a flagged result)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.orientation import METHODS
from photogeom.rotation import rotation_from_angles
from photogeom.transforms import Similarity3D


def _good(n=8, seed=1):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-10, 10, (n, 3))
    X = 2.0 * x @ rotation_from_angles(0.3, 0.2, 1.0).T + 5
    X = X + rng.normal(scale=0.01, size=(n, 3))
    return x, X


@pytest.mark.parametrize("method", METHODS)
def test_too_few_points(method):
    x, X = _good()
    with pytest.raises(pg.TooFewPointsError, match=r"2 point.*at least 3"):
        pg.absolute_orientation(x[:2], X[:2], method)


@pytest.mark.parametrize("method", METHODS)
def test_nan_and_inf_rows_are_named(method):
    x, X = _good()
    X[4, 1] = np.nan
    with pytest.raises(pg.InputError, match=r"target: 1 row\(s\).*NaN.*row index 4"):
        pg.absolute_orientation(x, X, method)
    x[2, 0] = np.inf
    with pytest.raises(pg.InputError, match=r"source: .*row index 2"):
        pg.absolute_orientation(x, _good()[1], method)


def test_nan_in_large_fast_path():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(70000, 3))
    X = x + 1
    X[69999, 2] = np.nan
    with pytest.raises(pg.InputError, match="row index 69999"):
        pg.absolute_orientation(x, X, statistics=False)


def test_shape_mismatch():
    x, X = _good()
    with pytest.raises(pg.InputError, match=r"shape \(n, 3\)"):
        pg.absolute_orientation(x[:, :2], X)
    with pytest.raises(pg.InputError, match=r"8 point.*7.*correspond"):
        pg.absolute_orientation(x, X[:7])
    with pytest.raises(pg.InputError, match="ids: 3 id"):
        pg.absolute_orientation(x, X, ids=["a", "b", "c"])


@pytest.mark.parametrize("method", METHODS)
def test_collinear_and_coincident_points(method):
    x = np.outer(np.arange(6.0), [1.0, 2.0, -1.0]) + np.array([3.0, 4.0, 5.0])
    X = 2 * x + 1
    with pytest.raises(pg.DegenerateGeometryError, match=r"collinear.*undetermined"):
        pg.absolute_orientation(x, X, method)
    same = np.tile([1.0, 2.0, 3.0], (5, 1))
    with pytest.raises(pg.DegenerateGeometryError, match="coincide"):
        pg.absolute_orientation(same, same + 1, method)


@pytest.mark.parametrize("method", METHODS)
def test_reflection_is_reported_not_returned(method):
    x, _ = _good(10)
    X = (x * [1, 1, -1]) @ rotation_from_angles(0.5, -0.4, 2.0).T + 3  # mirror image
    with pytest.raises(pg.ReflectionError, match=r"reflection.*handedness"):
        pg.absolute_orientation(x, X, method)


def test_reflection_from_naive_start_is_still_reported():
    x, _ = _good(10)
    X = x * [1, 1, -1]
    with pytest.raises(pg.ReflectionError):
        pg.absolute_orientation(x, X, "gauss-markov", initial="zeros")


def test_points_at_centroid_closed_form():
    x, X = _good(6)
    x = np.vstack([x, x.mean(0)])  # one point exactly at the centroid
    X = np.vstack([X, 2.0 * x[-1] @ rotation_from_angles(0.3, 0.2, 1.0).T + 5])
    fit = pg.absolute_orientation(x, X, "closed-form")
    assert np.isfinite(fit.scale)
    assert any("1 point(s) at the centroid" in n for n in fit.notes)
    # every point but the centroid one on a line through the centroid: undetermined
    y = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0.0, 0, 0]])
    with pytest.raises(pg.DegenerateGeometryError):
        pg.absolute_orientation(y, y, "closed-form")


def test_non_convergence_is_an_error_or_flagged():
    x, X = _good()
    with pytest.raises(pg.ConvergenceError, match="iteration limit 1") as exc:
        pg.absolute_orientation(x, X, "gauss-markov", initial="zeros", max_iter=1)
    assert exc.value.iterations == 1
    fit = pg.absolute_orientation(
        x, X, "gauss-markov", initial="zeros", max_iter=1, raise_on_failure=False
    )
    assert not fit.converged
    assert any("NOT CONVERGED" in n for n in fit.notes)
    with pytest.raises(pg.ConvergenceError):
        pg.absolute_orientation(x, X, "gauss-helmert", iterate=True, max_iter=1, initial="zeros")


def test_negative_scale_solution_is_never_returned():
    from scipy.spatial.transform import Rotation

    x, X = _good(12)
    ref = pg.absolute_orientation(x, X)
    flipped = Rotation.from_rotvec([np.pi, 0, 0]).as_matrix() @ ref.rotation
    with pytest.raises(pg.ConvergenceError, match=r"scale .* <= 0"):
        pg.absolute_orientation(
            x, X, "gauss-markov", initial=Similarity3D(ref.scale, flipped, ref.translation),
            raise_on_failure=False,
        )


def test_option_errors():
    x, X = _good()
    with pytest.raises(pg.InputError, match="unknown absolute orientation method 'lsq'"):
        pg.absolute_orientation(x, X, "lsq")
    with pytest.raises(pg.InputError, match="gauss-helmert"):
        pg.absolute_orientation(x, X, "svd", sigma_source=0.1)
    with pytest.raises(pg.InputError, match="no weights as published"):
        pg.absolute_orientation(x, X, "closed-form", weights=np.arange(1.0, 9.0))
    with pytest.raises(pg.InputError, match="gauss-markov"):
        pg.absolute_orientation(x, X, "svd", weights=np.ones((8, 3)))
    with pytest.raises(pg.InputError, match="weight must be finite and > 0"):
        pg.absolute_orientation(x, X, weights=-np.ones(8))
    with pytest.raises(pg.InputError, match="weights: expected shape"):
        pg.absolute_orientation(x, X, weights=np.ones(5))
    with pytest.raises(pg.InputError, match="scale_method"):
        pg.absolute_orientation(x, X, scale_method="median")
    with pytest.raises(pg.InputError, match="initial values apply"):
        pg.absolute_orientation(x, X, "svd", initial="zeros")
    with pytest.raises(pg.InputError, match="initial values: expected 7"):
        pg.absolute_orientation(x, X, "gauss-markov", initial=[1, 2, 3])
    with pytest.raises(pg.InputError, match=r"options of method=.closed-form. only"):
        pg.absolute_orientation(x, X, "svd", nearest_rotation=True)
    with pytest.raises(pg.InputError, match="covariance_source: expected shape"):
        pg.absolute_orientation(x, X, "gauss-helmert", covariance_source=np.eye(3))
    with pytest.raises(pg.InputError, match="direct solution needs at most one sigma"):
        pg.absolute_orientation(x, X, "gauss-helmert", sigma_source=np.ones(8), iterate=False)
    with pytest.raises(pg.InputError, match="sigma_target must be a positive"):
        pg.absolute_orientation(x, X, "gauss-markov", sigma_target=0.0)
