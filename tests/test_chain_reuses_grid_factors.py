"""The chain's effective redundancy solves with the factors of the grid fits themselves
(kept with the grids fitted in this process) instead of factorising every grid again."""

import dataclasses

import numpy as np
import pytest

import photogeom as pg
import photogeom.calibration.chain as chain_module
from photogeom.calibration import fit_residual_grids
from photogeom.calibration.chain import chain_redundancy
from photogeom.calibration.grid import fitted_solver


@pytest.fixture(scope="module")
def fitted():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4, local_field=0.0)
    ba = pg.bundle_adjust(sim.block, snooping=False)
    return ba.block, fit_residual_grids(ba.block, 200, folds=0)


def _counting(monkeypatch):
    built = []
    real = chain_module.FiniteElementSystem

    def count(*args, **kwargs):
        built.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(chain_module, "FiniteElementSystem", count)
    return built


def test_fitted_grids_are_not_factorised_again(fitted, monkeypatch):
    block, grids = fitted
    built = _counting(monkeypatch)
    kept = chain_redundancy(block, grids, exact=True)
    # before: one factorisation per image (8 here; 250 on the study block: +5.4 s at 100 px)
    assert built == []
    # grids without their factor (a new object, as read from a file): factorised again,
    # the same trace to rounding
    fresh = {k: dataclasses.replace(g) for k, g in grids.items()}
    assert all(fitted_solver(g) is None for g in fresh.values())
    again = chain_redundancy(block, fresh, exact=True)
    assert len(built) == len(grids)
    assert kept["value"] == pytest.approx(again["value"], rel=1e-10)


def test_the_kept_factor_solves_the_grids_own_fit(fitted):
    # the nodes from the kept factor and the grid's residuals are the grid's own nodes
    block, grids = fitted
    per = pg.calibration.block_residuals(block)
    key = next(iter(grids))
    g = grids[key]
    solve = fitted_solver(g)
    used = ~g.outliers if g.outliers.size else np.ones(len(g.uv), bool)
    uv, v = per[key]
    assert np.array_equal(uv[used], g.uv[used])
    np.testing.assert_allclose(solve(v[used]), g.nodes.reshape(-1, 2), rtol=1e-9, atol=1e-12)


def test_a_grid_with_other_weights_is_factorised_again(fitted):
    _, grids = fitted
    g = next(iter(grids.values()))
    other = dataclasses.replace(g, sigma_constraint=2.0 * g.sigma_constraint)
    assert fitted_solver(other) is None


def test_the_kept_factors_stay_within_their_limit_and_leave_with_their_grids(monkeypatch):
    # before: every fitted grid kept its factor, as long as it lived (250 grids at 100 px:
    # 0.9 GB more than the fit's 0.19 GB; 2000 images 7.6 GB)
    import gc

    import photogeom.calibration.grid as grid_module

    rng = np.random.default_rng(5)

    def residuals():
        uv = rng.uniform([0, 0], [3999, 2999], (600, 2))
        return uv, rng.normal(0, 0.3, (600, 2))

    gc.collect()
    base = grid_module._KEPT["bytes"]
    g0 = grid_module.fit_grid(*residuals(), (4000, 3000), 500.0, folds=0)
    per_grid = grid_module._KEPT["bytes"] - base
    assert per_grid > 0 and fitted_solver(g0) is not None
    monkeypatch.setattr(grid_module, "kept_factor_limit", lambda: base + 2.5 * per_grid)
    grids = [grid_module.fit_grid(*residuals(), (4000, 3000), 500.0, folds=0) for _ in range(4)]
    kept = [fitted_solver(g) is not None for g in [g0, *grids]]
    assert kept == [True, True, False, False, False]
    assert grid_module._KEPT["bytes"] == pytest.approx(base + 2 * per_grid)
    del g0, grids
    gc.collect()
    assert grid_module._KEPT["bytes"] == pytest.approx(base)
