"""The residual grid's cached node cofactors cannot be changed through the array returned."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg


def test_node_cofactor_is_read_only_and_node_std_stays():
    # before: grid.node_cofactor returned the cache itself, writable: node_cofactor[...] = 0
    # made every later node_std 0
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 999, (300, 2))
    grid = pg.calibration.fit_grid(uv, rng.normal(size=(300, 2)), (1000, 1000), 250.0, folds=0)
    std = grid.node_std.copy()
    cof = grid.node_cofactor
    assert not cof.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        cof[...] = 0.0
    np.testing.assert_array_equal(grid.node_std, std)
    assert grid.node_cofactor is cof
