"""Data hygiene of the Python API: results pickle and copy, inputs are not kept or changed."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import photogeom as pg


def _pairs(n=12, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-500, 500, (n, 3))
    R = pg.rotation_from_angles(0.1, 0.2, 0.3)
    X = 1.0001 * x @ R.T + [10.0, -20.0, 5.0] + rng.normal(scale=0.01, size=(n, 3))
    return x, X


ABSOLUTE = {
    "svd": lambda x, X: pg.absolute_orientation(x, X),
    "gauss-helmert": lambda x, X: pg.absolute_orientation(x, X, "gauss-helmert"),
    "closed-form": lambda x, X: pg.absolute_orientation(x, X, "closed-form"),
    "no statistics": lambda x, X: pg.absolute_orientation(x, X, statistics=False),
    "ransac": lambda x, X: pg.ransac_absolute_orientation(x, X, threshold=0.1),
    "snooping": lambda x, X: pg.snooping_absolute_orientation(x, X),
    "compare": lambda x, X: pg.compare_absolute_methods(x, X),
}


@pytest.mark.parametrize("name", ABSOLUTE)
def test_absolute_orientation_results_pickle_and_deepcopy(name):
    # parameter_units was a shared types.MappingProxyType: "cannot pickle 'mappingproxy'"
    x, X = _pairs()
    fit = ABSOLUTE[name](x, X)
    for twin in (pickle.loads(pickle.dumps(fit)), copy.deepcopy(fit)):
        assert type(twin) is type(fit)
        if name != "compare":
            np.testing.assert_array_equal(twin.parameters, fit.parameters)
            assert dict(twin.parameter_units) == dict(fit.parameter_units)
            np.testing.assert_array_equal(twin.transform.apply(x), fit.transform.apply(x))


def test_absolute_orientation_parameter_units_are_not_shared_between_fits():
    x, X = _pairs()
    a = pg.absolute_orientation(x, X, unit="m")
    b = pg.absolute_orientation(x, X, unit="m")
    assert a.parameter_units == {
        "tx": "m", "ty": "m", "tz": "m", "omega": "rad", "phi": "rad", "kappa": "rad",
        "scale": "1",
    }
    assert a.parameter_units is not b.parameter_units
