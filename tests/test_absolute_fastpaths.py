"""Absolute orientation: one-pass moments about a reference, the spread check of both point
sets, chunked per-point statistics of many points, and the lean construction of results."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import photogeom as pg
from photogeom.adjust import Fit
from photogeom.orientation.absolute import AbsoluteOrientationFit
from photogeom.orientation.absolute_direct import CHUNK_POINTS, PairMoments, large_moments


def _utm_problem(n, seed=0, sort=False):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n, 3))
    if sort:  # the first chunk lies at one end: not representative of the whole set
        x = x[np.argsort(x[:, 0])] * [400.0, 1.0, 1.0]
    R = Rotation.random(random_state=seed).as_matrix()
    X = 250.0 * x @ R.T + [512_000.0, 4_215_000.0, 350.0] + rng.normal(0, 0.01, (n, 3))
    return x, X


@pytest.mark.parametrize("sort", [False, True])
def test_one_pass_moments_of_utm_coordinates_are_exact(sort):
    x, X = _utm_problem(3 * CHUNK_POINTS + 3, seed=2, sort=sort)
    w = np.random.default_rng(3).uniform(0.5, 2.0, x.shape[0])
    for ww in (None, w):
        m = large_moments(x, X, ww, scatter=True)
        a = PairMoments.from_moments(m)
        b = PairMoments.of(x, X, ww)
        np.testing.assert_allclose(a.H, b.H, rtol=1e-11, atol=1e-11 * np.abs(b.H).max())
        np.testing.assert_allclose(a.S, b.S, rtol=1e-11, atol=1e-11 * np.abs(b.S).max())
        assert a.a == pytest.approx(b.a, rel=1e-11)
        assert a.b == pytest.approx(b.b, rel=1e-10)
        # the centroids agree far below the spread (250 m)
        np.testing.assert_allclose(a.target_centroid, b.target_centroid, rtol=0, atol=1e-6)


def test_many_points_statistics_equal_the_engine():
    """The chunked closed-form statistics of 70 000 points (one-pass moments) equal those of
    the Gauss-Markov engine with the full Jacobian."""
    x, X = _utm_problem(70_001, seed=4)
    svd = pg.absolute_orientation(x, X, "svd")
    ref = pg.absolute_orientation(x, X, "gauss-markov")
    np.testing.assert_allclose(svd.parameters, ref.parameters, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(svd.cofactor, ref.cofactor, rtol=1e-7, atol=1e-18)
    assert svd.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    np.testing.assert_allclose(svd.residuals, ref.residuals, atol=1e-9)
    np.testing.assert_allclose(svd.redundancy_numbers, ref.redundancy_numbers, atol=1e-10)
    np.testing.assert_allclose(
        svd.normalized_residuals, ref.normalized_residuals, rtol=1e-6, atol=1e-8
    )
    fast = pg.absolute_orientation(x, X, "svd", statistics=False)
    np.testing.assert_array_equal(fast.parameters, svd.parameters)


def test_weighted_many_points_statistics_equal_the_engine():
    x, X = _utm_problem(70_001, seed=5)
    w = np.random.default_rng(6).uniform(0.3, 3.0, x.shape[0])
    svd = pg.absolute_orientation(x, X, "svd", weights=w)
    ref = pg.absolute_orientation(x, X, "gauss-markov", weights=w)
    np.testing.assert_allclose(svd.cofactor, ref.cofactor, rtol=1e-7, atol=1e-18)
    np.testing.assert_allclose(svd.redundancy_numbers, ref.redundancy_numbers, atol=1e-10)
    np.testing.assert_allclose(
        svd.normalized_residuals, ref.normalized_residuals, rtol=1e-6, atol=1e-8
    )


@pytest.mark.parametrize("side", ["source", "target"])
def test_one_collinear_set_is_refused_naming_its_side(side):
    rng = np.random.default_rng(7)
    spread = rng.normal(size=(12, 3))
    t = rng.normal(size=12)
    line = np.c_[t, -2 * t, 0.5 * t] * 100 + 1e-10 * rng.normal(size=(12, 3))
    x, X = (line, spread) if side == "source" else (spread, line)
    for method in ("svd", "quaternion", "dual-quaternion", "gauss-helmert", "gauss-markov"):
        with pytest.raises(pg.DegenerateGeometryError, match=f"12 {side} points are collinear"):
            pg.absolute_orientation(x, X, method)


def test_lean_fit_construction_equals_the_constructor():
    x, X = _utm_problem(20, seed=8)
    fit = pg.absolute_orientation(x, X, statistics=False)
    again = AbsoluteOrientationFit(**{f.name: getattr(fit, f.name) for f in fields(fit)})
    for f in fields(fit):
        a, b = getattr(fit, f.name), getattr(again, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        elif isinstance(a, float) and np.isnan(a):
            assert np.isnan(b), f.name
        else:
            assert a == b, f.name
    with pytest.raises(TypeError, match="missing field"):
        Fit._construct(model=None)
    with pytest.raises(AttributeError):
        fit.sigma0 = 1.0  # still frozen


def test_closed_form_perturbation_map_equals_the_derivatives():
    """``G`` (angle rates -> rotation perturbation) in closed form equals the one built from
    the derivative matrices, over the whole angle range, and its inverse is exact."""
    from photogeom.orientation.absolute_stats import (
        _rotation_and_perturbation,
        angle_to_perturbation,
        rotation_derivatives,
    )

    rng = np.random.default_rng(9)
    for _ in range(500):
        w, k = rng.uniform(-np.pi, np.pi, 2)
        p = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6)
        R, G, Ginv = _rotation_and_perturbation(w, p, k)
        R2, dR = rotation_derivatives(w, p, k)
        np.testing.assert_allclose(R, R2, atol=1e-15)
        np.testing.assert_allclose(G, angle_to_perturbation(R2, dR), atol=1e-14)
        np.testing.assert_allclose(Ginv @ G, np.eye(3), atol=1e-9)
    assert _rotation_and_perturbation(0.3, np.pi / 2, 0.1)[2] is None  # gimbal lock


@pytest.mark.parametrize("weighted", [False, True])
def test_large_n_gauss_markov_from_moments_equals_the_general_adjustment(weighted, monkeypatch):
    # from LARGE_N points on, method E builds its normal equations from the moments (no dense
    # 3n x 7 Jacobian, memory of the outputs only); the general engine gives the same fit
    from photogeom.orientation import absolute as ao

    x, X = _utm_problem(ao.LARGE_N + 500, seed=4)
    w = np.random.default_rng(5).uniform(0.5, 2.0, x.shape[0]) if weighted else None
    big = pg.absolute_orientation(x, X, "gauss-markov", weights=w)
    assert any("from the moments" in note for note in big.notes) and big.converged
    zeros = pg.absolute_orientation(
        x, X, "gauss-markov", weights=w, initial=[0, 0, 0, 1, 0.1, 0, 0]
    )
    monkeypatch.setattr(ao, "LARGE_N", 10**9)
    ref = pg.absolute_orientation(x, X, "gauss-markov", weights=w)
    assert not any("from the moments" in note for note in ref.notes)
    for fit in (big, zeros):
        np.testing.assert_allclose(fit.parameters, ref.parameters, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(big.cofactor, ref.cofactor, rtol=1e-9, atol=1e-18)
    assert big.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    np.testing.assert_allclose(big.residuals, ref.residuals, atol=1e-8)
    np.testing.assert_allclose(big.redundancy_numbers, ref.redundancy_numbers, atol=1e-9)


@pytest.mark.parametrize("flat", [1.0, 0.05])
def test_chunked_closed_form_equals_the_single_pass_arrays(flat, monkeypatch):
    # from CLOSED_FORM_CHUNKED_N points on the closed form (and its propagated covariance)
    # runs in chunks without n-row temporaries; same estimate as the array version
    from photogeom.orientation import absolute_direct as ad
    from photogeom.orientation.absolute_stats import _closed_form_setup, _closed_form_sums

    x, X = _utm_problem(ad.CLOSED_FORM_CHUNKED_N + 700, seed=6)
    x = x * [1.0, 1.0, flat]
    x[7] = (x.sum(axis=0) - x[7]) / (x.shape[0] - 1)  # one point at the centroid
    fits = [pg.absolute_orientation(x, X, "closed-form", nearest_rotation=nr) for nr in (0, 1)]
    monkeypatch.setattr(ad, "CLOSED_FORM_CHUNKED_N", 10**9)
    for nr, fit in zip((False, True), fits):
        ref = pg.absolute_orientation(x, X, "closed-form", nearest_rotation=nr)
        assert fit.scale == pytest.approx(ref.scale, rel=1e-11)
        np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-12)
        np.testing.assert_allclose(fit.translation, ref.translation, rtol=1e-13)
        assert fit.notes == ref.notes  # augmentation and the point at the centroid
        # the cofactor of both paths against the parameters' Jacobians summed directly
        # (sum_i J_i J_i', not through the intermediate quantities' cofactor)
        cf = _closed_form_setup(x, X, nr, True, None)
        Qa, _ = _closed_form_sums(cf, cf.Jz)
        sd = np.sqrt(np.diag(Qa))
        sd = np.where(sd > 0, sd, 1.0)  # no variance: its zeros are compared as they are
        # (raw R far from a rotation, flat=0.05 without nearest_rotation: angles undefined,
        # their rows NaN in both paths, as the notes say)
        ok = np.isfinite(np.diag(ref.cofactor))
        assert ok[:4].all() and (ok.all() or any("no standard deviations" in t for t in ref.notes))
        a = np.ix_(ok, ok)
        for Q in (fit.cofactor, ref.cofactor):
            assert np.array_equal(np.isfinite(np.diag(Q)), ok)
            np.testing.assert_allclose(
                (Q / np.outer(sd, sd))[a], (Qa / np.outer(sd, sd))[a], atol=1e-6
            )


def _shifted_closed_form(x, X, x0, X0, **kw):
    """The in-memory closed form of ``x - x0``, ``X - X0`` (exact differences: well-conditioned
    sums) taken back to the original frame: centroid-based, so only t changes."""
    f = pg.absolute_orientation(x - x0, X - X0, "closed-form", statistics=False, **kw)
    return f.scale, f.rotation, f.translation + X0 - f.scale * (f.rotation @ x0), f.notes


@pytest.mark.parametrize(
    ("seed", "flat", "offset"),
    [(11, 1.0, 0.0), (12, 0.02, 0.0), (13, 1.0, 1.0), (14, 0.02, 1.0), (15, 0.0, 1.0)],
)
def test_chunked_closed_form_equals_the_in_memory_reference(seed, flat, offset, monkeypatch):
    # any rotation, thick, flat (the plane-normal augmentation) and exactly planar sets, with
    # coordinates offset by ~1e6 m (raw moments would lose digits there): the chunked passes
    # (centroids about a first-chunk reference, then one product per chunk) give the
    # in-memory estimate to ~1e-12; the raw R of the exactly planar set amplifies rounding
    # (the in-memory estimates of 30 exact shifts of that data scatter by up to 1.6e-11), so
    # there the bound is 5e-11
    from photogeom.orientation import absolute_direct as ad

    rng = np.random.default_rng(seed)
    n = ad.CLOSED_FORM_CHUNKED_N + 3 * ad.CLOSED_FORM_CHUNK + 3  # a tail chunk, n % 4 != 0
    R = Rotation.random(random_state=seed).as_matrix()
    assert np.degrees(np.arccos((np.trace(R) - 1) / 2)) > 20
    x = rng.uniform(-60.0, 60.0, (n, 3)) * [1.0, 0.7, flat]
    X = 0.83 * x @ R.T + rng.normal(0.0, 0.02, (n, 3))
    x = x + offset * np.array([731_000.0, -1_250_000.0, 412.0])
    X = X + offset * np.array([512_000.0, 4_215_000.0, 350.0])
    for nearest in (False, True):
        fit = pg.absolute_orientation(
            x, X, "closed-form", statistics=False, nearest_rotation=nearest
        )
        with monkeypatch.context() as mp:
            mp.setattr(ad, "CLOSED_FORM_CHUNKED_N", 10**9)
            s, Rr, t, notes = _shifted_closed_form(x, X, x[0], X[0], nearest_rotation=nearest)
        tol = 5e-11 if flat == 0.0 else 1e-12
        assert fit.scale == pytest.approx(s, rel=1e-12)
        np.testing.assert_allclose(fit.rotation, Rr, rtol=0, atol=tol)
        # t = Xg - s R xg: the rotation's tolerance times the offset of the source
        np.testing.assert_allclose(
            fit.translation, t, rtol=1e-12, atol=1e-9 + 3 * tol * np.linalg.norm(x[0])
        )
        assert fit.notes == notes  # the augmentation is used alike
        assert any("plane-normal" in note for note in notes) == (flat < 0.3)


def chunked_centroid(p):
    from photogeom.orientation.absolute_direct import centroid_about_reference

    ref, c = centroid_about_reference(p)
    return c if ref is None else ref + c


def test_chunked_centroid_keeps_the_digits_of_offset_coordinates():

    rng = np.random.default_rng(21)
    base = rng.uniform(-50.0, 50.0, (200_003, 3))
    off = np.array([512_000.0, 4_215_000.0, 350.0])
    exact = base.mean(axis=0)  # of the small numbers: no digits lost
    np.testing.assert_allclose(chunked_centroid(base + off) - off, exact, rtol=0, atol=2e-9)
    np.testing.assert_allclose(chunked_centroid(base), exact, rtol=0, atol=1e-13)


def _gauss_helmert_dense(x, X, fit, sx, sX):
    """The Gauss-Helmert statistics written out on whole arrays (n x 3 x 3 blocks)."""
    from photogeom.orientation.absolute_stats import linearised_statistics

    s, R, t = fit.scale, fit.rotation, fit.translation
    xg, Xg = x.mean(axis=0), X.mean(axis=0)
    g = s * (x - xg) @ R.T - (X - Xg) + (s * (R @ xg) + t - Xg)
    mm = s * s * sx * sx + sX * sX
    vx = -(sx * sx * s / mm) * (g @ R)
    vX = (sX * sX / mm) * g
    st = linearised_statistics(
        x - xg + vx,
        g,
        scale=s,
        angles=fit.angles(),
        source_centroid=xg,
        weights=np.full(x.shape[0], 1 / mm),
        with_scale=True,
        blocks=True,
    )
    C = st.point_blocks
    red_t = (sX * sX / mm**2) * (mm - np.diagonal(C, axis1=1, axis2=2))
    qs = mm - np.einsum("ji,njk,ki->ni", R, C, R)
    red_s = (s * s * sx * sx / mm**2) * qs
    wn_s = np.where(qs > 1e-12 * mm, -(g @ R) / np.sqrt(np.abs(qs)), np.nan)
    return dict(
        cofactor=st.cofactor,
        residuals=vX,
        redundancy_numbers=red_t,
        normalized_residuals=st.normalized_residuals,
        misclosures=g,
        source_residuals=vx,
        source_redundancy_numbers=red_s,
        source_normalized_residuals=wn_s,
        corrected_source=x + vx,
        corrected_target=X + vX,
    )


def test_chunked_gauss_helmert_statistics_equal_the_dense_formulas():
    # per-point statistics of both systems in chunks (several, and a tail) against the same
    # formulas on whole arrays with the n x 3 x 3 blocks
    from photogeom.orientation.absolute_stats import CHUNK_POINTS as STAT_CHUNK

    x, X = _utm_problem(2 * STAT_CHUNK + 17, seed=8)
    x = x * 40.0
    sx, sX = 0.004, 0.02
    fit = pg.absolute_orientation(x, X, "gauss-helmert", sigma_source=sx, sigma_target=sX)
    ref = _gauss_helmert_dense(x, X, fit, sx, sX)
    sd = np.sqrt(np.diag(ref["cofactor"]))
    np.testing.assert_allclose(
        fit.cofactor / np.outer(sd, sd), ref["cofactor"] / np.outer(sd, sd), rtol=0, atol=1e-12
    )
    for key in ("residuals", "redundancy_numbers", "normalized_residuals"):
        np.testing.assert_allclose(getattr(fit, key), ref[key], rtol=1e-9, atol=1e-11)
    for key in (
        "misclosures",
        "source_residuals",
        "source_redundancy_numbers",
        "source_normalized_residuals",
        "corrected_source",
        "corrected_target",
    ):
        np.testing.assert_allclose(fit.extras[key], ref[key], rtol=1e-9, atol=1e-11)
    # the redundancy numbers of all 6n coordinates add up to the redundancy 3n - 7
    total = fit.redundancy_numbers.sum() + fit.extras["source_redundancy_numbers"].sum()
    assert total == pytest.approx(3 * x.shape[0] - 7, rel=1e-9)
