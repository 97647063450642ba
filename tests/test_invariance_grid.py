"""Invariance: residual grids do not depend on the order of the residual rows."""

import numpy as np
import pytest

from photogeom.calibration import fit_grid


def _residuals(seed: int, n: int = 400):
    rng = np.random.default_rng(seed)
    uv = np.column_stack([rng.uniform(0, 1000, n), rng.uniform(0, 800, n)])
    res = np.column_stack(
        [0.3 * np.sin(uv[:, 0] / 300), 0.2 * np.cos(uv[:, 1] / 250)]
    ) + rng.normal(0, 0.1, (n, 2))
    return uv, res


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cross_validated_rms_does_not_depend_on_the_order_of_the_rows(seed):
    # the folds were a random permutation of the row numbers: the same 400 residuals
    # shuffled gave rms_cv_after 0.1396 px or 0.1408 px
    uv, res = _residuals(seed)
    ref = fit_grid(uv, res, (1001, 801), 200.0, folds=5, seed=7)
    for k in range(3):
        p = np.random.default_rng(100 + k).permutation(uv.shape[0])
        got = fit_grid(uv[p], res[p], (1001, 801), 200.0, folds=5, seed=7)
        assert got.rms_cv_after == pytest.approx(ref.rms_cv_after, rel=1e-12)
        assert got.rms_after == pytest.approx(ref.rms_after, rel=1e-12)
        assert got.sigma0 == pytest.approx(ref.sigma0, rel=1e-12)
        np.testing.assert_allclose(got.nodes, ref.nodes, rtol=0, atol=1e-12)


def test_the_seed_still_chooses_the_folds():
    uv, res = _residuals(3)
    a = fit_grid(uv, res, (1001, 801), 200.0, folds=5, seed=7)
    b = fit_grid(uv, res, (1001, 801), 200.0, folds=5, seed=7)
    c = fit_grid(uv, res, (1001, 801), 200.0, folds=5, seed=8)
    assert a.rms_cv_after == b.rms_cv_after
    assert c.rms_cv_after != a.rms_cv_after
    assert c.rms_cv_after == pytest.approx(a.rms_cv_after, rel=0.05)


def test_folds_are_balanced_and_follow_their_points():
    from photogeom.calibration.grid import _fold_of

    uv, res = _residuals(4, 1003)
    a = _fold_of(uv, res, 5, 0)
    p = np.random.default_rng(5).permutation(uv.shape[0])
    np.testing.assert_array_equal(_fold_of(uv[p], res[p], 5, 0), a[p])
    assert sorted(np.bincount(a)) == [200, 200, 201, 201, 201]
