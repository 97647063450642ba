"""The nested results of a bundle adjustment and of a residual grid are read-only.

Before: the arrays of ``BundleFit.check``, ``.control``, ``.snooping`` and
``.calibration_correlation`` were writable, and the mappings plain dicts, although the
record's own arrays were read-only views. ``fit.check["rmse"] *= 0`` (an analysis working in
place) turned the check-point line of ``fit.summary()`` from "RMSE X 0.01167, Y 0.01232, Z
0.02413" into "RMSE X 0, Y 0, Z 0"; ``fit.snooping["w"][:] = 0`` emptied the flagged list of
the result record (``bundle_result_data``: 5 flagged, then 0); ``fit.calibration[g]["f"] = 0``
changed the calibration of ``to_dict()``; and copies made by :func:`dataclasses.replace`
shared all of it.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_grid
from photogeom.report.bundle import bundle_result_data


@pytest.fixture(scope="module")
def fit():
    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)
    return pg.bundle_adjust(sim.block)


def _nested(value, path=""):
    """(path, leaf) of every array, mapping and sequence under ``value``."""
    if isinstance(value, np.ndarray):
        yield path, value
    elif hasattr(value, "items"):
        yield path, value
        for k, v in value.items():
            yield from _nested(v, f"{path}[{k!r}]")
    elif isinstance(value, (list, tuple)):
        yield path, value
        for k, v in enumerate(value):
            yield from _nested(v, f"{path}[{k}]")


NESTED = (
    "calibration",
    "calibration_std",
    "calibration_correlation",
    "high_correlations",
    "check",
    "control",
    "snooping",
    "chi2",
    "solver",
)


def _assert_read_only(record, names):
    seen = 0
    for name in names:
        for path, leaf in _nested(getattr(record, name), name):
            seen += 1
            if isinstance(leaf, np.ndarray):
                assert not leaf.flags.writeable, path
            else:
                assert not isinstance(leaf, (list, dict)), path
                assert not hasattr(leaf, "__setitem__"), path
    return seen


def test_every_nested_array_and_mapping_is_read_only(fit):
    assert fit.check["ids"] and fit.snooping["flagged"]  # the block has both
    assert _assert_read_only(fit, NESTED) > 50


def test_writing_in_place_is_refused_and_the_reports_keep_their_numbers(fit):
    summary, record = fit.summary(), json.dumps(bundle_result_data(fit))
    g = fit.block.camera_ids.tolist()[0]
    with pytest.raises(ValueError, match="read-only"):
        fit.check["rmse"] *= 0
    with pytest.raises(ValueError, match="read-only"):
        fit.snooping["w"][:] = 0
    with pytest.raises(ValueError, match="read-only"):
        fit.calibration_correlation[g][1][0, 1] = 1.0
    with pytest.raises(TypeError):
        fit.calibration[g]["f"] = 0.0
    with pytest.raises(TypeError):
        fit.chi2["passed"] = True
    with pytest.raises(AttributeError):
        fit.snooping["flagged"].append(("x", "y", 99.0))
    assert fit.summary() == summary
    assert json.dumps(bundle_result_data(fit)) == record
    assert bundle_result_data(fit)["n_flagged"] == 5


def test_a_copy_of_ones_own_stays_writable(fit):
    mine = dict(fit.check)
    mine["note"] = 1
    errors = np.array(fit.check["errors"])
    errors[:] = 0
    assert "note" not in fit.check and np.all(fit.check["errors"] != 0)


@pytest.mark.parametrize(
    "clone",
    [copy.deepcopy, lambda f: pickle.loads(pickle.dumps(f)), dataclasses.replace],
)
def test_copies_stay_read_only_and_equal(fit, clone):
    other = clone(fit)
    _assert_read_only(other, NESTED)
    assert other.to_dict() == fit.to_dict()


def test_residual_grid_snooping_is_read_only():
    rng = np.random.default_rng(9)
    uv = rng.uniform(0, [999, 799], (400, 2))
    res = rng.normal(scale=0.5, size=(400, 2))
    res[:40, 0] += 20.0
    g = fit_grid(uv, res, (1000, 800), 100.0, sigma_obs=0.5, sigma_constraint=0.2266,
                 snooping=True, folds=0, max_snooping_rounds=2)  # fmt: skip
    flagged = int(g.snooping["still_flagged"].sum())
    assert flagged > 0
    with pytest.raises(ValueError, match="read-only"):
        g.snooping["still_flagged"][:] = False
    for clone in (copy.deepcopy, lambda x: pickle.loads(pickle.dumps(x))):
        _assert_read_only(clone(g), ("snooping",))
    assert int(g.snooping["still_flagged"].sum()) == flagged
