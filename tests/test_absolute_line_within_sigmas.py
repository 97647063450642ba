"""Gauss-Helmert absolute orientation of points on one line within their standard
deviations: the rotation about the line is set by noise; refused by name."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError

UTM = np.array([500000.0, 5000000.0, 300.0])


def _pairs(off_line: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    t = np.linspace(-100.0, 100.0, 8)
    x = np.c_[t, 0.5 * t, 0.2 * t] + rng.normal(0.0, 0.005, (8, 3))
    x[::2, 2] += off_line
    R = pg.opk_matrix(0.1, -0.2, 0.7)
    X = x @ R.T + UTM + rng.normal(0.0, 0.01, (8, 3))
    return x, X


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_source_on_a_line_within_sigma_source_is_refused(seed):
    # before: a fit with sigma0 0.57 and omega +-29 deg (seed 0), nothing said
    x, X = _pairs(0.0, seed)
    with pytest.raises(DegenerateGeometryError, match=r"8 source points lie on one line within "
                       r"their accuracy \(RMS distance from the line 0\.00\d+, [\d.]+ times "
                       r"sigma_source"):
        pg.absolute_orientation(x, X, method="gauss-helmert", sigma_source=0.01,
                                sigma_target=0.01)


def test_target_on_a_line_within_sigma_target_is_refused():
    x, X = _pairs(0.0)
    with pytest.raises(DegenerateGeometryError, match="target points lie on one line"):
        pg.absolute_orientation(X - UTM, x + UTM, method="gauss-helmert",
                                sigma_source=np.full(8, 0.001), sigma_target=0.01)


def test_points_a_metre_off_the_line_give_the_orientation():
    x, X = _pairs(1.0)
    fit = pg.absolute_orientation(x, X, method="gauss-helmert", sigma_source=0.01,
                                  sigma_target=0.01)
    assert np.degrees(max(fit.std_errors[k] for k in ("omega", "phi", "kappa"))) < 1.0


def test_relative_weights_are_not_compared_with_distances():
    # weights give no standard deviations in object units: the line is not judged by them
    x, X = _pairs(0.3)
    fit = pg.absolute_orientation(x, X, method="gauss-helmert", weights=np.ones(8))
    assert fit.converged
