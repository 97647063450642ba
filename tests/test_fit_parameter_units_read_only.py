"""``Fit.parameter_units`` is read-only.

Before: a plain dict shared by the copies :meth:`Fit.with_crs`, :meth:`Fit.with_checks` and
:func:`dataclasses.replace` make. ``fit.with_crs("EPSG:25832").parameter_units["omega"] =
"1"`` turned the original's parameter table row of omega from 5.7301 deg (the estimate
converted from radians) into 0.100009 with unit "1", and its summary with it.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle

import numpy as np
import pytest

import photogeom as pg


def _fit(**kw):
    rng = np.random.default_rng(0)
    x = rng.uniform(-500, 500, (12, 3))
    R = pg.rotation_from_angles(0.1, 0.2, 0.3)
    X = 1.0001 * x @ R.T + [10.0, -20.0, 5.0] + rng.normal(scale=0.01, size=(12, 3))
    return pg.absolute_orientation(x, X, unit="m", **kw)


def _omega(fit):
    return next(row for row in fit.parameter_table() if row[0] == "omega")


@pytest.mark.parametrize(
    "derive",
    [
        lambda f: f.with_crs("EPSG:25832"),
        lambda f: f.with_checks(np.zeros((1, 3)), ["c"]),
        lambda f: dataclasses.replace(f, notes=("x",)),
        copy.deepcopy,
        lambda f: pickle.loads(pickle.dumps(f)),
    ],
)
def test_units_of_a_fit_or_its_copies_cannot_be_written(derive):
    fit = _fit()
    before, summary = _omega(fit), fit.summary()
    assert before[3] == "deg" and before[1] == pytest.approx(np.degrees(0.1), abs=1e-3)
    other = derive(fit)
    with pytest.raises(TypeError):
        other.parameter_units["omega"] = "1"
    with pytest.raises(TypeError):
        fit.parameter_units["omega"] = "1"
    assert _omega(fit) == before and fit.summary() == summary
    assert _omega(other)[1:] == before[1:]


def test_units_read_as_before():
    fit = _fit()
    units = {"tx": "m", "ty": "m", "tz": "m", "omega": "rad", "phi": "rad", "kappa": "rad",
             "scale": "1"}  # fmt: skip
    assert fit.parameter_units == units and dict(fit.parameter_units) == units
    assert json.loads(json.dumps(fit.to_dict()))["parameters"]["omega"]["unit"] == "rad"
    mine = dict(fit.parameter_units)
    mine["omega"] = "deg"
    assert fit.parameter_units["omega"] == "rad"
    bare = _fit(statistics=False)
    with pytest.raises(TypeError):
        bare.parameter_units["tx"] = "km"
