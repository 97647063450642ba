"""Invariance: absolute orientation estimates do not depend on the order of the
point pairs."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg


def _noisy_target(x, seed):
    rng = np.random.default_rng(seed)
    R = pg.opk_matrix(0.3, -0.2, 1.1).T
    return 1.7 * x @ R.T + np.array([500.0, 300.0, 20.0]) + rng.normal(0, 0.05, x.shape)


def _grid():
    g = np.arange(5) * 10.0
    return np.array([(a, b, 0.0) for a in g for b in g])  # a regular planar 5 x 5 grid


def _flat(n, seed):
    return np.random.default_rng(seed).normal(size=(n, 3)) * [50.0, 50.0, 1.0]


@pytest.mark.parametrize("source", [_grid(), _flat(100, 4)], ids=["grid-25", "flat-100"])
@pytest.mark.parametrize("nearest", [False, True])
def test_closed_form_of_a_coplanar_set_does_not_depend_on_the_point_order(source, nearest):
    # the plane-normal augmentation took the first of several equally perpendicular pairs of
    # a regular grid, and for n > 64 the first usable point: shuffling the 25 grid points
    # changed R by 1.4e-3 (sigma0 0.0421984 -> 0.0421983), the 100 flat points by 1.1e-3
    x = source
    X = _noisy_target(x, 5)
    ref = pg.absolute_orientation(x, X, "closed-form", nearest_rotation=nearest)
    se = np.array([ref.std_errors[k] for k in sorted(ref.std_errors)])
    for seed in range(3):
        perm = np.random.default_rng(seed).permutation(len(x))
        fit = pg.absolute_orientation(x[perm], X[perm], "closed-form", nearest_rotation=nearest)
        np.testing.assert_allclose(fit.rotation, ref.rotation, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fit.translation, ref.translation, rtol=1e-12)
        assert fit.scale == pytest.approx(ref.scale, rel=1e-12)
        assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
        got = np.array([fit.std_errors[k] for k in sorted(fit.std_errors)])
        np.testing.assert_allclose(got, se, rtol=1e-8)
        np.testing.assert_allclose(fit.residuals, ref.residuals[perm], rtol=0, atol=1e-9)


def test_batch_closed_form_does_not_depend_on_the_point_order():
    x = np.stack([_grid(), _grid() * 2.0 + 1.0])
    X = np.stack([_noisy_target(x[0], 6), _noisy_target(x[1], 7)])
    ref = pg.absolute_orientation_batch(x, X, "closed-form")
    perm = np.random.default_rng(1).permutation(x.shape[1])
    got = pg.absolute_orientation_batch(x[:, perm], X[:, perm], "closed-form")
    np.testing.assert_allclose(got.rotation, ref.rotation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.translation, ref.translation, rtol=1e-12)


def test_chunked_closed_form_of_a_flat_set_does_not_depend_on_the_point_order():
    # from CLOSED_FORM_CHUNKED_N points on the pair is searched in chunks: it was the first
    # usable point and the one closest to perpendicular to it
    from photogeom.orientation import absolute_direct as ad

    n = ad.CLOSED_FORM_CHUNKED_N + 5000
    rng = np.random.default_rng(3)
    x = rng.uniform(-60.0, 60.0, (n, 3)) * [1.0, 0.7, 0.05]
    X = _noisy_target(x, 8) + np.array([512_000.0, 4_215_000.0, 0.0])
    ref = pg.absolute_orientation(x, X, "closed-form", statistics=False)
    assert any("plane-normal" in note for note in ref.notes)
    perm = rng.permutation(n)
    fit = pg.absolute_orientation(x[perm], X[perm], "closed-form", statistics=False)
    np.testing.assert_allclose(fit.rotation, ref.rotation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fit.translation, ref.translation, rtol=1e-13)


@pytest.mark.parametrize("offset", [[512_000.0, 5_000_000.0, 100.0], [4.1e6, 1.2e6, 4.7e6]])
def test_closed_form_std_errors_of_a_far_away_target_equal_the_reduced_ones(offset):
    # the closed form's standard deviations come from central differences of t = Xg - s R xg:
    # with the target 5e6 m from the origin, t's rounding (~1e-9 m) over steps of 1e-7 |xg|
    # put the std error of ty 1.7e-6 (relative) off the reduced problem's; now ~1e-9, as
    # sigma0 (the data's own precision at that offset)
    rng = np.random.default_rng(1)
    x = rng.normal(size=(12, 3)) * 50.0
    x = x - x.mean(axis=0) + 0.3  # a source centroid near its origin: t hangs on Xg alone
    X = _noisy_target(x, 2)
    ref = pg.absolute_orientation(x, X, "closed-form")
    far = pg.absolute_orientation(x, X + np.array(offset), "closed-form")
    assert far.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    for key, value in ref.std_errors.items():
        assert far.std_errors[key] == pytest.approx(value, rel=1e-8), key


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(4, 120),
    flat=st.sampled_from([0.0, 0.01, 0.2, 1.0]),
    grid=st.booleans(),
)
def test_closed_form_is_invariant_to_the_order_of_the_pairs(seed, n, flat, grid):
    rng = np.random.default_rng(seed)
    if grid:  # regular layouts tie many pairs in the source alone
        k = max(2, int(np.sqrt(n)))
        g = np.arange(k) * 10.0
        x = np.array([(a, b, 0.0) for a in g for b in g])
        x[:, 2] = flat * rng.normal(size=len(x))
    else:
        x = rng.normal(size=(n, 3)) * [50.0, 40.0, 50.0 * flat]
    X = _noisy_target(x, seed % 1000)
    ref = pg.absolute_orientation(x, X, "closed-form", statistics=False)
    perm = rng.permutation(len(x))
    got = pg.absolute_orientation(x[perm], X[perm], "closed-form", statistics=False)
    np.testing.assert_allclose(got.rotation, ref.rotation, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got.translation, ref.translation, rtol=0, atol=1e-8)
