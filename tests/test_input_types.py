"""Masked arrays, complex values and low-precision floats: never a silent wrong answer."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, PrecisionWarning


def _pairs(n=12, offset=(0.0, 0.0, 0.0), seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-500, 500, (n, 3))
    R = pg.rotation_from_angles(0.1, 0.2, 0.3)
    X = 1.0001 * x @ R.T + np.asarray(offset) + rng.normal(scale=0.01, size=(n, 3))
    return x, X


def _camera_problem():
    io = pg.InteriorOrientation(100.0)
    eo = pg.ExteriorOrientation.from_degrees(10.0, 20.0, 800.0, 2.0, -3.0, 40.0)
    rng = np.random.default_rng(1)
    g = np.column_stack([rng.uniform(-300, 300, (10, 2)), rng.uniform(0, 80, 10)])
    return io, eo, g, pg.project(g, io, eo)


ESTIMATORS = {
    "absolute_orientation": lambda x, X: pg.absolute_orientation(x, X),
    "closed-form": lambda x, X: pg.absolute_orientation(x, X, "closed-form"),
    "gauss-helmert": lambda x, X: pg.absolute_orientation(x, X, "gauss-helmert"),
    "estimate_transform": lambda x, X: pg.estimate_transform("affine3d", x, X),
    "batch": lambda x, X: pg.absolute_orientation_batch(x[None], X[None]),
}


@pytest.mark.parametrize("name", ESTIMATORS)
@pytest.mark.parametrize("side", ["source", "target"])
def test_masked_entries_are_refused(name, side):
    x, X = _pairs()
    mask = np.zeros_like(x, dtype=bool)
    mask[3, 1] = True
    if side == "source":
        x = np.ma.masked_array(x, mask=mask)
        x.data[3, 1] = 1e9  # the hidden value would ruin the estimate if it were used
    else:
        X = np.ma.masked_array(X, mask=mask)
        X.data[3, 1] = 1e9
    where = "masked" if name == "batch" else r"masked .*row index 3"  # batch: problem 0
    with pytest.raises(InputError, match=where):
        ESTIMATORS[name](x, X)


def test_masked_array_without_masked_entries_is_read():
    x, X = _pairs()
    ref = pg.absolute_orientation(x, X)
    fit = pg.absolute_orientation(np.ma.masked_array(x), np.ma.masked_array(X, mask=False))
    np.testing.assert_array_equal(fit.parameters, ref.parameters)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_complex_values_are_refused(name):
    x, X = _pairs()
    with pytest.raises(InputError, match="complex"):
        ESTIMATORS[name](x + 0j, X)


def test_camera_estimators_refuse_masked_and_complex_input():
    io, eo, g, xy = _camera_problem()
    gm = np.ma.masked_array(g, mask=np.zeros_like(g, dtype=bool))
    gm.mask[2, 2] = True
    with pytest.raises(InputError, match="masked"):
        pg.space_resection(gm, xy, io)
    with pytest.raises(InputError, match="complex"):
        pg.space_resection(g, xy + 0j, io)
    with pytest.raises(InputError, match="masked"):
        pg.estimate_dlt(gm, xy)
    with pytest.raises(InputError, match="complex"):
        pg.space_resection_batch(g, (xy + 0j)[None], io, eo)


def test_float32_with_large_offsets_warns_and_is_computed_in_float64():
    x, X = _pairs(n=50, offset=(4e6, 1e7, 100.0))
    x32, X32 = x.astype(np.float32), X.astype(np.float32)
    with pytest.warns(PrecisionWarning, match=r"target: float32 .* resolution of 1\b"):
        fit = pg.absolute_orientation(x32, X32)
    # the same numbers as float64 input holding the float32-rounded values
    ref = pg.absolute_orientation(x32.astype(np.float64), X32.astype(np.float64))
    np.testing.assert_array_equal(fit.parameters, ref.parameters)
    assert fit.sigma0 > 10 * pg.absolute_orientation(x, X).sigma0  # the digits were lost


def test_float32_without_large_offsets_does_not_warn():
    x, X = _pairs()
    with warnings.catch_warnings():
        warnings.simplefilter("error", PrecisionWarning)
        fit = pg.absolute_orientation(x.astype(np.float32), X.astype(np.float32))
    assert fit.parameters.dtype == np.float64


@pytest.mark.parametrize(
    "method",
    ["closed-form", "svd", "quaternion", "dual-quaternion", "gauss-markov", "gauss-helmert"],
)
@pytest.mark.parametrize("side", ["source", "target"])
def test_coordinates_near_1e200_give_the_named_overflow_error(method, side):
    x, X = _pairs()
    if side == "source":
        x = x * 1e200
    else:
        X = X * 1e200
    with pytest.raises(InputError, match="overflow"):
        pg.absolute_orientation(x, X, method)


def test_camera_and_transform_estimators_name_the_overflow():
    io, _, g, xy = _camera_problem()
    with pytest.raises(InputError, match="overflow"):
        pg.space_resection(g * 1e200, xy, io)  # was numpy's LinAlgError
    with pytest.raises(InputError, match="overflow"):
        pg.estimate_dlt(g * 1e200, xy)
    x, X = _pairs()
    for model in ("affine3d", "similarity3d"):
        with pytest.raises(InputError, match="overflow"):
            pg.estimate_transform(model, x * 1e200, X)


def test_gauss_helmert_scale_without_overflow_at_large_coordinates():
    # d^2 + 4 c^2 overflowed at 1e100 (scale reported as 0); hypot(d, 2 c) does not
    x, X = _pairs()
    fit = pg.absolute_orientation(x * 1e100, X, "gauss-helmert")
    ref = pg.absolute_orientation(x, X, "gauss-helmert")
    assert fit.scale == pytest.approx(ref.scale * 1e-100, rel=1e-9)


def test_float32_weights_are_not_reported_as_coordinates():
    x, X = _pairs()
    with warnings.catch_warnings():
        warnings.simplefilter("error", PrecisionWarning)
        fit = pg.absolute_orientation(x, X, weights=np.ones(len(x), dtype=np.float32))
    assert np.isfinite(fit.sigma0)
