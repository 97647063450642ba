"""Bad input to estimate_transform: clear errors naming the problem and the minimum."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, InputError, TooFewPointsError

MINIMUM = {
    "similarity2d": 2,
    "affine2d": 3,
    "projective2d": 4,
    "affine3d": 4,
    "projective3d": 5,
    "rigid3d": 3,
    "similarity3d": 3,
}


def good(dim, n=12, seed=0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(-10, 10, (n, dim))
    return src, src * 1.5 + 2.0


@pytest.mark.parametrize("model, need", sorted(MINIMUM.items()))
def test_too_few_points_names_the_minimum(model, need):
    dim = 2 if model.endswith("2d") else 3
    src, dst = good(dim, need - 1)
    with pytest.raises(TooFewPointsError, match=f"at least {need} needed") as err:
        pg.estimate_transform(model, src, dst)
    assert model in str(err.value) and err.value.need == need and err.value.have == need - 1


@pytest.mark.parametrize("dim, order, need", [(2, 1, 3), (2, 2, 6), (2, 3, 10), (3, 2, 10)])
def test_too_few_points_polynomial(dim, order, need):
    src, dst = good(dim, need - 1)
    with pytest.raises(TooFewPointsError, match=f"at least {need} needed") as err:
        pg.estimate_transform(f"polynomial{dim}d", src, dst, order=order)
    assert f"order {order}" in str(err.value)


def test_check_points_do_not_count_towards_the_minimum():
    src, dst = good(2, 4)
    with pytest.raises(TooFewPointsError, match="check points"):
        pg.estimate_transform("affine2d", src, dst, check=[True, True, False, False])


def test_coincident_points():
    src = np.tile([[3.0, 4.0]], (5, 1))
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        pg.estimate_transform("similarity2d", src, src + 1)


@pytest.mark.parametrize("model", ["affine2d", "projective2d"])
def test_collinear_points_2d(model):
    t = np.linspace(0, 10, 8)
    src = np.c_[t, 2 * t + 1]
    dst = np.c_[t + 0.3 * t**2, -t]
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        pg.estimate_transform(model, src, dst)


def test_collinear_points_polynomial():
    t = np.linspace(0, 10, 12)
    src = np.c_[t, -t]
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        pg.estimate_transform("polynomial2d", src, src * 2, order=2)


def test_coplanar_points_3d():
    rng = np.random.default_rng(1)
    src = np.c_[rng.uniform(-1, 1, (10, 2)), np.full(10, 5.0)]
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        pg.estimate_transform("affine3d", src, src * 2)
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        pg.estimate_transform("projective3d", src, src * 2)


def test_projective_minimum_needs_general_position():
    src = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0]])  # three on one line
    dst = np.array([[0.0, 0.0], [1.0, 0.1], [2.0, 0.3], [0.2, 1.0]])
    with pytest.raises(DegenerateGeometryError, match="three of the four points are collinear"):
        pg.estimate_transform("projective2d", src, dst)


def test_collinear_target_for_projective():
    src, _ = good(2, 8)
    dst = np.c_[src[:, 0], 3 * src[:, 0]]
    with pytest.raises(DegenerateGeometryError, match="target points are collinear"):
        pg.estimate_transform("projective2d", src, dst)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf(bad):
    src, dst = good(2)
    src[3, 1] = bad
    with pytest.raises(InputError, match="NaN or infinite") as err:
        pg.estimate_transform("affine2d", src, dst)
    assert "source" in str(err.value) and "3" in str(err.value)
    src, dst = good(2)
    dst[5, 0] = bad
    with pytest.raises(InputError, match="target"):
        pg.estimate_transform("affine2d", src, dst)


@pytest.mark.parametrize("model", sorted(MINIMUM))
@pytest.mark.parametrize("n", [12, 6001])  # the projective check proves finiteness up to 5000
@pytest.mark.parametrize("statistics", [True, False])
def test_nan_and_inf_named_for_every_model(model, n, statistics):
    """Every model names the side and the row of a NaN / infinite coordinate, whether the
    values are checked on reading or in the geometry check's scatter (projective models)."""
    dim = 2 if model.endswith("2d") else 3
    for side, bad in (("source", np.nan), ("target", np.inf), ("source", -np.inf)):
        src, dst = good(dim, n, seed=3)
        dst = dst + np.random.default_rng(4).normal(0, 1e-3, dst.shape)
        (src if side == "source" else dst)[n // 2, dim - 1] = bad
        with pytest.raises(InputError, match="NaN or infinite") as err:
            pg.estimate_transform(model, src, dst, statistics=statistics)
        assert side in str(err.value) and f"row index {n // 2}" in str(err.value)


def test_nan_in_projective_with_both_errors_and_few_points():
    src, dst = good(2, 4)
    src[0, 0] = np.nan
    with pytest.raises(InputError, match=r"source: 1 row\(s\) contain NaN"):
        pg.estimate_transform("projective2d", src, dst, errors_in="both")


def test_shape_mismatch():
    src, dst = good(2)
    with pytest.raises(InputError, match="12 point"):
        pg.estimate_transform("affine2d", src, dst[:-1])
    with pytest.raises(InputError, match=r"shape \(n, 3\)"):
        pg.estimate_transform("affine3d", src, dst)
    with pytest.raises(InputError, match="check"):
        pg.estimate_transform("affine2d", src, dst, check=[True, False])
    with pytest.raises(InputError, match="weights"):
        pg.estimate_transform("affine2d", src, dst, weights=np.ones(5))
    with pytest.raises(InputError, match="weights"):
        pg.estimate_transform("affine2d", src, dst, weights=-np.ones(12))
    with pytest.raises(InputError, match="covariance"):
        pg.estimate_transform("affine2d", src, dst, covariance=np.ones((12, 3, 3)))
    with pytest.raises(InputError, match="ids"):
        pg.estimate_transform("affine2d", src, dst, ids=list(range(11)))
    with pytest.raises(InputError, match="duplicate"):
        pg.estimate_transform("affine2d", src, dst, ids=[1] * 12)


def test_options():
    src, dst = good(2)
    with pytest.raises(InputError, match="unknown transformation model"):
        pg.estimate_transform("helmert2d", src, dst)
    with pytest.raises(InputError, match="order"):
        pg.estimate_transform("polynomial2d", src, dst)
    with pytest.raises(InputError, match="order applies only"):
        pg.estimate_transform("affine2d", src, dst, order=2)
    with pytest.raises(InputError, match="errors_in"):
        pg.estimate_transform("affine2d", src, dst, errors_in="both")
    with pytest.raises(InputError, match="both source_system and target_system"):
        pg.estimate_transform("affine2d", src, dst, source_system="pixel")
    with pytest.raises(InputError, match="unknown coordinate system"):
        pg.estimate_transform("affine2d", src, dst, source_system="pixel", target_system="mars")
    s3, d3 = good(3)
    with pytest.raises(InputError, match="2D models only"):
        pg.estimate_transform("affine3d", s3, d3, source_system="pixel", target_system="image")
    with pytest.raises(InputError, match="weights or a covariance"):
        pg.estimate_transform("affine2d", src, dst, weights=np.ones(12),
                              covariance=np.ones((12, 2, 2)))


def test_shape_only_point_check():
    """``as_points(..., finite=False)`` checks the shape and lets NaN through (for callers that
    find non-finite values in their sums); the default refuses them, naming the row."""
    from photogeom.validation import as_points

    pts = [[0.0, 1.0, 2.0], [np.nan, 1.0, 2.0]]
    assert np.isnan(as_points(pts, 3, "source", finite=False)[1, 0])
    with pytest.raises(InputError, match=r"source: 1 row\(s\).*row index 1"):
        as_points(pts, 3, "source")
    with pytest.raises(InputError, match=r"source: expected an array of shape \(n, 3\)"):
        as_points([[0.0, 1.0]], 3, "source", finite=False)
    with pytest.raises(InputError, match="cannot be read as numbers"):
        as_points([["a", 1.0, 2.0]], 3, "source", finite=False)
