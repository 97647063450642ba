"""A residual grid's arrays and its kept node cofactors.

Before: ``dataclasses.replace`` handed the original's cofactor cache to the new grid, so a
grid with other weights reported the original's node standard deviations (3 times the
observation sigmas: 0.0119 px instead of 0.0229 px at node (2, 2)); the grid's arrays were
writable and ``uv`` was the caller's own array, so changing it after the fit changed
``node_std`` computed later (0.0096 px instead of 0.0119 px).
"""

from __future__ import annotations

import copy
import pickle
from dataclasses import replace

import numpy as np
import pytest

from photogeom.calibration import fit_grid
from photogeom.calibration.gridfile import load_grids, save_grids
from photogeom.errors import InputError

ARRAYS = ("nodes", "sigma_obs", "support", "counts", "outliers", "uv")


def _inputs():
    rng = np.random.default_rng(3)
    uv = np.column_stack([rng.uniform(0, 1599, 400), rng.uniform(0, 999, 400)])
    res = np.column_stack([np.sin(uv[:, 0] / 500), np.cos(uv[:, 1] / 300)])
    return uv, res


def _grid():
    uv, res = _inputs()
    return fit_grid(uv, res, (1600, 1000), 200, folds=0, snooping=True)


def test_replace_with_other_weights_computes_its_own_cofactors():
    g = _grid()
    before = g.node_std.copy()
    g2 = replace(g, sigma_obs=g.sigma_obs * 3)
    fresh = replace(g, sigma_obs=g.sigma_obs * 3, _std=[])
    np.testing.assert_allclose(g2.node_std, fresh.node_std, rtol=1e-12)
    assert not np.allclose(g2.node_std, before)
    np.testing.assert_array_equal(g.node_std, before)  # the original keeps its own


@pytest.mark.parametrize(
    "change",
    [
        lambda g: {"uv": g.uv + 1.0},
        lambda g: {"sigma_constraint": 2 * g.sigma_constraint},
        lambda g: {"border": "linear"},
        lambda g: {"outliers": np.arange(len(g.uv)) < 50, "sigma_obs": np.ones(len(g.uv) - 50)},
    ],
)
def test_replace_of_any_input_drops_the_kept_cofactors(change):
    g = _grid()
    g.node_cofactor  # noqa: B018 - computed and kept
    g2 = replace(g, **change(g))
    fresh = replace(g2, _std=[])
    np.testing.assert_allclose(g2.node_cofactor, fresh.node_cofactor, rtol=1e-12)


def test_replace_of_other_fields_keeps_the_cofactors():
    g = _grid()
    cof = g.node_cofactor
    g2 = replace(g, nodes=np.zeros_like(g.nodes), sigma0=2 * g.sigma0)
    assert g2.node_cofactor is cof
    np.testing.assert_allclose(g2.node_std, 2 * g.node_std)


def test_read_grid_with_other_weights_has_no_stale_cofactors(tmp_path):
    # a file without the pixel positions of the fit (as written before they were stored)
    import json

    path = save_grids(tmp_path / "g.json", {1: _grid()})
    d = json.loads(path.read_text())
    del d["images"][0]["uv"]
    path.write_text(json.dumps(d))
    g = load_grids(path)[1]
    assert g.uv is None
    same = replace(g, nodes=g.nodes * 2)
    np.testing.assert_array_equal(same.node_cofactor, g.node_cofactor)
    other = replace(g, sigma_obs=g.sigma_obs * 3)
    with pytest.raises(InputError, match="weights or layout replaced"):
        other.node_std  # noqa: B018
    # a file with them: the cofactors of the new weights, computed from the positions
    fitted = _grid()
    g = load_grids(save_grids(tmp_path / "p.npz", {1: fitted}))[1]
    assert np.array_equal(g.uv, fitted.uv)
    other = replace(g, sigma_obs=g.sigma_obs * 3)
    expected = replace(fitted, sigma_obs=fitted.sigma_obs * 3).node_cofactor
    np.testing.assert_allclose(other.node_cofactor, expected, rtol=1e-12)
    assert not np.allclose(other.node_cofactor, g.node_cofactor)


@pytest.mark.parametrize("name", ARRAYS)
def test_grid_arrays_are_read_only(name):
    g = _grid()
    with pytest.raises(ValueError, match="read-only"):
        getattr(g, name)[...] = 0


def test_fit_keeps_its_own_uv():
    uv, res = _inputs()
    g = fit_grid(uv, res, (1600, 1000), 200, folds=0)
    expected = fit_grid(uv.copy(), res, (1600, 1000), 200, folds=0).node_std
    assert not np.shares_memory(g.uv, uv)
    uv[:, 0] /= 4  # the caller reuses its array
    np.testing.assert_allclose(g.node_std, expected, rtol=1e-12)


def test_grid_from_callers_arrays_leaves_them_writable():
    g = _grid()
    nodes = np.array(g.nodes)
    g2 = replace(g, nodes=nodes)
    assert nodes.flags.writeable
    assert not g2.nodes.flags.writeable


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda g: pickle.loads(pickle.dumps(g))])
def test_copies_stay_read_only_and_keep_their_cofactors(clone):
    g = _grid()
    cof = g.node_cofactor
    c = clone(g)
    for name in ARRAYS:
        assert not getattr(c, name).flags.writeable
    assert not c.node_cofactor.flags.writeable
    np.testing.assert_array_equal(c.node_cofactor, cof)
    assert replace(c, nodes=c.nodes * 0).node_cofactor is c.node_cofactor
