"""Names of the spec's public API contract called exactly as the spec writes them."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError


@pytest.fixture(scope="module")
def grid():
    """A small residual grid of a 400 x 300 px image (node spacing 100 px)."""
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [399, 299], (200, 2))
    res = np.c_[np.sin(uv[:, 0] / 150), np.cos(uv[:, 1] / 120)]
    return pg.calibration.fit_grid(uv, res, (400, 300), 100, folds=0)


def test_grid_evaluate_with_nan_names_evaluating_not_fitting(grid):
    # grids[image_id].evaluate(uv) of 05-residual-grid.md: a NaN row is refused with advice
    # in the words of the call (it said "remove them before fitting" on an evaluation)
    with pytest.raises(InputError, match="before evaluating the grid") as err:
        grid.evaluate([[10.0, 20.0], [np.nan, 5.0]])
    assert "fitting" not in str(err.value) and "row 1" in str(err.value)
    with pytest.raises(InputError, match="before correcting them") as err:
        grid.correct([[np.inf, 5.0]])
    assert "fitting" not in str(err.value)


def test_correct_observations_with_nan_names_the_image_and_correcting(grid):
    with pytest.raises(InputError, match=r"image A: uv: 1 row.*before correcting them") as err:
        pg.calibration.correct_observations({"A": [[1.0, 2.0], [3.0, np.nan]]}, {"A": grid})
    assert "fitting" not in str(err.value)


def test_fit_grid_with_nan_still_says_fitting():
    with pytest.raises(InputError, match="before fitting"):
        pg.calibration.fit_grid([[1.0, np.nan]] * 5, np.zeros((5, 2)), (400, 300), 100)


def test_opk_from_matrix_phi_formula_as_documented():
    # the docstring said phi = asin(m31); the code reads atan2(m31, hypot(m32, m33)), which
    # differs for a non-orthogonal matrix (the raw closed form): 1.2358377 vs 1.2359117 rad
    x = np.array([[-6.052, 46.443, -45.009], [-11.310, 21.491, -45.041],
                  [-9.814, 70.725, -21.516]])
    X = np.array([[99.997, 99.986, 100.027], [99.996, 199.988, 119.994],
                  [199.983, 9.978, 80.051]])
    fit = pg.absolute_orientation(x, X, method="closed-form")
    M = fit.rotation.T
    omega, phi, kappa = pg.opk_from_matrix(M)
    assert phi == np.arctan2(M[2, 0], np.hypot(M[2, 1], M[2, 2]))
    assert omega == np.arctan2(-M[2, 1], M[2, 2]) and kappa == np.arctan2(-M[1, 0], M[0, 0])
    assert np.degrees(fit.angles()[1] - phi) == pytest.approx(0.0042, abs=5e-5)
    assert abs(phi - np.arcsin(M[2, 0])) > 1e-5
    assert fit.angles()[1] == np.arcsin(M[2, 0])  # the published reading of the raw matrix
    assert "atan2(m31, hypot(m32, m33))" in pg.opk_from_matrix.__doc__
    # for a rotation both readings agree
    R = pg.opk_matrix(0.3, -1.2, 2.5)
    assert pg.opk_from_matrix(R)[1] == pytest.approx(np.arcsin(R[2, 0]), abs=1e-15)
