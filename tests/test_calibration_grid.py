"""Finite-element residual grids: recovery, an independent dense solve, Monte Carlo,
properties, variance components, data snooping and bad input."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.adjust.selected_inverse import BlockSelectedInverse
from photogeom.adjust.variance_components import update_variance_factors
from photogeom.calibration import FiniteElementSystem, GridLayout, fit_grid, fit_grids
from photogeom.errors import InputError, TooFewPointsError


def smooth_field(uv, w, h, amp=1.0):
    """A smooth local displacement field (px): a few waves over the sensor."""
    x, y = uv[:, 0] / w, uv[:, 1] / h
    return amp * np.column_stack(
        [np.sin(2.5 * x + 0.3) * np.cos(1.7 * y), 0.6 * np.cos(3.1 * x * y) + 0.4 * y - 0.2]
    )


def scattered(rng, n, w, h):
    return np.column_stack([rng.uniform(-0.5, w - 0.5, n), rng.uniform(-0.5, h - 0.5, n)])


# ------------------------------------------------------------------ recovery of a known field
def test_recovers_smooth_field_where_supported():
    rng = np.random.default_rng(7)
    w, h, g = 1600, 1000, 100
    uv = scattered(rng, 4000, w, h)
    d = smooth_field(uv, w, h)
    observed_residuals = -d + rng.normal(0, 0.3, d.shape)  # computed - observed = -field
    grid = fit_grid(uv, observed_residuals, (w, h), g, sigma_obs=0.3, sigma_constraint=0.05)
    # compare at pixels inside supported cells
    test = scattered(rng, 5000, w, h)
    nodes = np.stack(np.nonzero(grid.support), axis=1)  # (i, j)
    cell_ok = grid.support[:-1, :-1] & grid.support[1:, :-1] & grid.support[:-1, 1:]
    cell_ok &= grid.support[1:, 1:]
    ci = grid.layout.cell_index(test)
    keep = cell_ok.ravel()[ci]
    assert nodes.size and keep.mean() > 0.8
    diff = grid.evaluate(test[keep]) + smooth_field(test[keep], w, h)
    truth_rms = math.sqrt(np.mean(np.sum(smooth_field(test[keep], w, h) ** 2, axis=1)))
    assert math.sqrt(np.mean(np.sum(diff**2, axis=1))) < 0.2 * truth_rms
    # the correction moves observations onto the ideal positions: corrected = observed - field
    ideal = uv[:50]
    obs = ideal + smooth_field(ideal, w, h)
    assert np.sqrt(np.mean((grid.correct(obs) - ideal) ** 2)) < 0.2 * truth_rms
    # what is left on the points is the noise (0.3 px per axis)
    assert grid.rms_after == pytest.approx(0.3 * math.sqrt(2), rel=0.1)
    assert grid.rms_cv_after == pytest.approx(0.3 * math.sqrt(2), rel=0.15)
    assert grid.reduction > 0.3 and grid.reduction_cv > 0.3
    assert grid.rms_cv_after >= grid.rms_after * 0.98


# ------------------------------------------------------------------ independent dense solve
def _dense_system(uv, w, h, g, border):
    """The same least-squares problem written out independently: hat functions, loops."""
    nx = math.ceil((w - 0.5) / g) + 1
    ny = math.ceil((h - 0.5) / g) + 1
    A = np.zeros((len(uv), nx * ny))
    for k, (u, v) in enumerate(uv):
        for i in range(ny):
            for j in range(nx):
                A[k, i * nx + j] = max(0.0, 1 - abs(u / g - j)) * max(0.0, 1 - abs(v / g - i))
    rows = []
    for i in range(ny):
        for j in range(nx):
            nb = [(i + di, j + dj) for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1))]
            nb = [(a, b) for a, b in nb if 0 <= a < ny and 0 <= b < nx]
            if border == "linear":
                pairs = []
                if 0 < j < nx - 1:
                    pairs += [(i, j - 1), (i, j + 1)]
                if 0 < i < ny - 1:
                    pairs += [(i - 1, j), (i + 1, j)]
                nb = pairs
            if not nb:
                continue
            r = np.zeros(nx * ny)
            r[i * nx + j] = 1.0
            for a, b in nb:
                r[a * nx + b] -= 1.0 / len(nb)
            rows.append(r)
    return A, np.array(rows), (ny, nx)


@pytest.mark.parametrize("border", ["mean", "linear"])
def test_matches_dense_least_squares(border):
    rng = np.random.default_rng(3)
    w, h, g = 500, 300, 70
    uv = np.column_stack([rng.uniform(0, w - 1, 120), rng.uniform(0, h - 1, 120)])
    l = rng.normal(0, 1, (120, 2))
    s_obs = rng.uniform(0.5, 2.0, 120)
    s_c = 0.4
    grid = fit_grid(uv, l, (w, h), g, sigma_obs=s_obs, sigma_constraint=s_c, border=border, folds=0)
    A, C, _shape = _dense_system(uv, w, h, g, border)
    # stacked whitened system solved by an orthogonal factorisation (lstsq), x and y apart
    M = np.vstack([A / s_obs[:, None], C / s_c])
    z = np.column_stack(
        [
            np.linalg.lstsq(M, np.concatenate([l[:, c] / s_obs, np.zeros(len(C))]), rcond=None)[0]
            for c in range(2)
        ]
    )
    np.testing.assert_allclose(grid.nodes.reshape(-1, 2), z, atol=1e-9)
    v = A @ z - l
    vtpv = np.sum(v**2 / s_obs[:, None] ** 2) + np.sum((C @ z) ** 2) / s_c**2
    # the independent constraints: with border "mean" one combination of the rows is zero
    r = 2 * (len(uv) + np.linalg.matrix_rank(C) - A.shape[1])
    assert grid.redundancy == r
    assert grid.sigma0 == pytest.approx(math.sqrt(vtpv / r), rel=1e-9)
    Q = np.linalg.inv(M.T @ M)
    np.testing.assert_allclose(grid.node_cofactor.ravel(), np.diag(Q), rtol=1e-8)
    np.testing.assert_allclose(grid.node_std.ravel(), grid.sigma0 * np.sqrt(np.diag(Q)), rtol=1e-8)
    system = FiniteElementSystem(grid.layout, uv, 1 / s_obs**2, 1 / s_c**2, border)
    np.testing.assert_allclose(
        system.observation_cofactors(), np.einsum("ki,ij,kj->k", A, Q, A), rtol=1e-8
    )
    np.testing.assert_allclose(grid.evaluate(uv), A @ z, atol=1e-9)


def test_selected_inverse_matches_dense_inverse():
    rng = np.random.default_rng(0)
    n, s = 23, 4
    B = sp.random(n, n, density=0.3, random_state=1).toarray()
    band = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) < s
    B = B * band
    N = B @ B.T + n * np.eye(n)
    N *= np.abs(np.subtract.outer(np.arange(n) // s, np.arange(n) // s)) <= 1  # block band
    N = N + n * np.eye(n)
    perm = rng.permutation(n)
    Np = np.zeros_like(N)
    Np[np.ix_(perm, perm)] = N  # Np[perm][:, perm] == N, so perm brings it back to N's band
    Z = np.linalg.inv(Np)
    si = BlockSelectedInverse(sp.csr_matrix(Np), s, perm)
    np.testing.assert_allclose(si.diagonal(), np.diag(Z), rtol=1e-10)
    i, j = np.nonzero(Np)
    np.testing.assert_allclose(si.entries(i, j), Z[i, j], rtol=1e-9, atol=1e-14)


# ------------------------------------------------------------------ Monte Carlo
def test_node_standard_deviations_match_monte_carlo():
    rng = np.random.default_rng(11)
    w, h, g = 400, 300, 100
    uv = scattered(rng, 60, w, h)
    s_o, s_c = 0.5, 0.2
    grid = fit_grid(
        uv, rng.normal(0, 0.5, (60, 2)), (w, h), g, sigma_obs=s_o, sigma_constraint=s_c, folds=0
    )
    layout = grid.layout
    system = FiniteElementSystem(layout, uv, np.full(60, 1 / s_o**2), 1 / s_c**2)
    z_true = rng.normal(0, 1, layout.n_nodes)
    trials = 4000
    l = (system.A @ z_true)[:, None] + rng.normal(0, s_o, (60, trials))
    lc = (system.C @ z_true)[:, None] + rng.normal(0, s_c, (system.C.shape[0], trials))
    est = system.solve(l, lc)
    spread = est.std(axis=1, ddof=1)
    predicted = np.sqrt(grid.node_cofactor.ravel())  # sigma0 a priori = 1
    # the std of a std estimate from 4000 samples is about 1.1 %: 5 % is > 4 sigma
    np.testing.assert_allclose(spread, predicted, rtol=0.05)
    assert abs(np.mean(est, axis=1) - z_true).max() < 5 * predicted.max() / math.sqrt(trials)


# ------------------------------------------------------------------ properties
@settings(max_examples=25)
@given(
    c=st.tuples(st.floats(-5, 5), st.floats(-5, 5)),
    g=st.floats(37, 250),
    n=st.integers(1, 200),
    seed=st.integers(0, 10_000),
    border=st.sampled_from(["mean", "linear"]),
)
def test_constant_field_reproduced_exactly(c, g, n, seed, border):
    rng = np.random.default_rng(seed)
    w, h = 640, 480
    n = max(n, 4)
    uv = scattered(rng, n, w, h)
    l = np.tile(np.asarray(c, float), (n, 1))
    grid = fit_grid(uv, l, (w, h), g, folds=0, border=border, min_observations=4)
    np.testing.assert_allclose(
        grid.nodes.reshape(-1, 2), l[:1].repeat(grid.layout.n_nodes, 0), atol=1e-9
    )
    assert grid.rms_after < 1e-9


@settings(max_examples=25)
@given(
    coef=st.lists(st.floats(-3e-3, 3e-3), min_size=6, max_size=6),
    g=st.floats(40, 200),
    seed=st.integers(0, 10_000),
)
def test_linear_field_reproduced(coef, g, seed):
    rng = np.random.default_rng(seed)
    w, h = 700, 500
    uv = scattered(rng, 300, w, h)
    a = np.asarray(coef).reshape(2, 3)

    def lin(p):  # r = a0 + a1 u + a2 v, per component (offsets of a few tenths of a px)
        return a[:, 0] * 100 + p[:, :1] * a[:, 1] + p[:, 1:] * a[:, 2]

    l = lin(uv)
    # border "linear": bilinear fields satisfy every constraint, so the fit is exact
    grid = fit_grid(uv, l, (w, h), g, folds=0, border="linear")
    un, vn = grid.layout.node_coordinates()
    np.testing.assert_allclose(
        grid.nodes.reshape(-1, 2), lin(np.column_stack([un.ravel(), vn.ravel()])), atol=1e-8
    )
    # border "mean": exact in the interior as the constraint weight goes to zero, where the
    # data alone determine the nodes (dense points)
    uv = scattered(rng, 3000, w, h)
    l = lin(uv)
    grid = fit_grid(uv, l, (w, h), g, folds=0, sigma_obs=1.0, sigma_constraint=1e3)
    interior = grid.support.copy()
    interior[[0, -1], :] = False
    interior[:, [0, -1]] = False
    pts = np.column_stack([un[interior], vn[interior]])
    np.testing.assert_allclose(grid.nodes[interior], lin(pts), atol=1e-4)


# ------------------------------------------------------------------ variance components
def test_variance_factor_update():
    f, ratio = update_variance_factors([1.0, 2.0], [8.0, 3.0], [4.0, 6.0])
    np.testing.assert_allclose(ratio, [2.0, 0.5])
    np.testing.assert_allclose(f, [2.0, 1.0])
    with pytest.raises(InputError, match="no redundancy"):
        update_variance_factors([1.0, 1.0], [1.0, 2.0], [3.0, 0.0])


def test_vce_recovers_observation_sigma():
    rng = np.random.default_rng(5)
    w, h = 1200, 900
    uv = scattered(rng, 3000, w, h)
    true_sigma = 0.25
    l = -smooth_field(uv, w, h, 0.8) + rng.normal(0, true_sigma, (3000, 2))
    grid = fit_grid(uv, l, (w, h), 100, sigma_obs=1.0, sigma_constraint="vce", folds=0)
    assert grid.vce_iterations >= 2
    assert grid.sigma_obs[0] == pytest.approx(true_sigma, rel=0.1)
    assert grid.sigma0 == pytest.approx(1.0, abs=1e-2)
    # the sum of the groups' redundancy contributions is the total redundancy (checked by
    # the final factors being 1 for both groups: sigma0 is then exactly 1)
    assert 0 < grid.sigma_constraint < 1


def _foerstner(uv, l, w, h, spacing, s_obs, s_c, iterations):
    """The plain Förstner iteration (both groups' factors updated each step), run long."""
    L = GridLayout(w, h, spacing)
    A, C = L.design_matrix(uv), L.constraint_matrix("mean")
    # m: the independent constraints (the rows of border "mean" have one dependency)
    n, m, u = uv.shape[0], np.linalg.matrix_rank(C.toarray()), L.n_nodes
    for _ in range(iterations):
        p = np.full(n, 1.0 / s_obs**2)
        sysm = FiniteElementSystem(L, uv, p, 1.0 / s_c**2, "mean", A=A, C=C)
        z = sysm.solve(l)
        v, wc = A @ z - l, C @ z
        t = float(np.sum(p * sysm.observation_cofactors()))
        f_o = float(np.sum(p[:, None] * v * v)) / (2 * (n - t))
        f_c = float(np.sum(wc * wc)) / s_c**2 / (2 * (m - (u - t)))
        s_obs, s_c = s_obs * math.sqrt(f_o), s_c * math.sqrt(f_c)
    return s_obs, s_c


def test_vce_root_equals_the_long_foerstner_iteration():
    """The decade search + Brent finds the fixed point of Förstner's iteration (run 400
    times here) in a few factorisations."""
    rng = np.random.default_rng(11)
    w, h = 1000, 800
    uv = scattered(rng, 300, w, h)
    l = -smooth_field(uv, w, h, 0.2) + rng.normal(0, 0.3, (300, 2))
    ref_obs, ref_c = _foerstner(uv, l, w, h, 50, 1.0, 1.0, 400)
    g = fit_grid(uv, l, (w, h), 50, sigma_obs=1.0, sigma_constraint="vce", folds=0)
    assert g.sigma_constraint == pytest.approx(ref_c, rel=2e-3)
    assert g.sigma_obs[0] == pytest.approx(ref_obs, rel=2e-3)
    assert g.vce_iterations <= 14  # Förstner's own iteration needs 22 to 1e-3 here


def test_vce_without_a_root_is_a_named_error():
    """Noise without a field on a grid finer than its data: no ratio of the variances fits;
    the error says so (the plain iteration ran into a group without redundancy). (A weak
    smooth field of 0.2 px here has a root, at a stiff 0.008 px, since the constraints'
    redundancy counts the independent rows only.)"""
    from photogeom.errors import ConvergenceError

    rng = np.random.default_rng(11)
    w, h = 1000, 800
    uv = scattered(rng, 150, w, h)
    l = rng.normal(0, 0.3, (150, 2))
    with pytest.raises(ConvergenceError, match="no ratio of the variances fits"):
        fit_grid(uv, l, (w, h), 100, sigma_obs=1.0, sigma_constraint="vce", folds=0)


# ------------------------------------------------------------------ data snooping
def test_snooping_removes_gross_errors():
    rng = np.random.default_rng(2)
    w, h = 1000, 800
    uv = scattered(rng, 1500, w, h)
    l = -smooth_field(uv, w, h, 0.5) + rng.normal(0, 0.2, (1500, 2))
    bad = np.array([10, 500, 900])
    l[bad, 0] += 4.0
    l[bad[1], 1] -= 3.0
    # 3000 w-tests: alpha = 1e-4 expects 0.3 false alarms (the w are calibrated: with the
    # a-priori sigmas right, their spread is 1)
    grid = fit_grid(
        uv, l, (w, h), 100, sigma_obs=0.2, sigma_constraint=0.05, snooping=True, alpha=1e-4, folds=0
    )
    found = set(np.flatnonzero(grid.outliers))
    assert set(bad) <= found and len(found) <= len(bad) + 2
    plain = fit_grid(uv, l, (w, h), 100, sigma_obs=0.2, sigma_constraint=0.05, folds=0)
    assert not plain.outliers.any()
    # one round only: the fit of that round stands (one removal per cell per round)
    l[bad[0] + 1, 0] += 4.0  # a second blunder near the first is caught in round 2 at most
    one = fit_grid(
        uv,
        l,
        (w, h),
        100,
        sigma_obs=0.2,
        sigma_constraint=0.05,
        snooping=True,
        alpha=1e-4,
        max_snooping_rounds=1,
        folds=0,
    )
    assert 1 <= one.outliers.sum() <= len(bad) + 3
    assert one.sigma_obs.size == len(uv) - one.outliers.sum()


# ------------------------------------------------------------------ many images
def test_fit_grids_per_image():
    rng = np.random.default_rng(9)
    per = {
        f"IMG_{k}": (scattered(rng, 200, 600, 400), rng.normal(0, 1, (200, 2))) for k in range(3)
    }
    grids = fit_grids(per, (600, 400), 80, folds=0)
    assert list(grids) == list(per)
    one = fit_grid(*per["IMG_1"], (600, 400), 80, folds=0)
    np.testing.assert_array_equal(grids["IMG_1"].nodes, one.nodes)
    sizes = {k: (600, 400) for k in per}
    sizes["IMG_2"] = (500, 400)
    per["IMG_2"] = (scattered(rng, 200, 500, 400), rng.normal(0, 1, (200, 2)))
    assert fit_grids(per, sizes, 80, folds=0)["IMG_2"].layout.nx == 8
    per["IMG_9"] = (per["IMG_0"][0][:3], per["IMG_0"][1][:3])
    with pytest.raises(TooFewPointsError, match="image IMG_9"):
        fit_grids(per, (600, 400), 80, folds=0)


def test_fit_grids_takes_each_images_own_sigmas():
    # sigma_obs by image (one per residual): each grid as fit_grid with that image's sigmas
    rng = np.random.default_rng(10)
    per = {k: (scattered(rng, 150, 600, 400), rng.normal(0, 1, (150, 2))) for k in range(3)}
    sig = {k: rng.uniform(0.2, 2.0, 150) for k in per}
    grids = fit_grids(per, (600, 400), 80, folds=0, sigma_obs=sig)
    for k in per:
        one = fit_grid(*per[k], (600, 400), 80, folds=0, sigma_obs=sig[k])
        np.testing.assert_array_equal(grids[k].nodes, one.nodes)
        assert grids[k].sigma0 == one.sigma0
    del sig[2]
    with pytest.raises(InputError, match="image 2: sigma_obs gives no standard deviations"):
        fit_grids(per, (600, 400), 80, folds=0, sigma_obs=sig)


# ------------------------------------------------------------------ layout and bad input
def test_layout_covers_every_pixel():
    lay = GridLayout(7952, 5304, 100)
    assert lay.shape == (55, 81)
    assert (lay.nx - 1) * lay.spacing >= 7952 - 0.5 and (lay.nx - 2) * lay.spacing < 7951.5
    assert GridLayout(101, 50, 100).nx == 3  # the last pixel's outer edge at 100.5


def test_bad_input():
    rng = np.random.default_rng(1)
    uv = scattered(rng, 50, 400, 300)
    l = rng.normal(0, 1, (50, 2))
    for g in (0, -5, float("nan")):
        with pytest.raises(InputError, match="spacing"):
            fit_grid(uv, l, (400, 300), g)
    with pytest.raises(InputError, match="larger than the image"):
        fit_grid(uv, l, (400, 300), 500)
    with pytest.raises(TooFewPointsError, match="at least 4"):
        fit_grid(uv[:3], l[:3], (400, 300), 50)
    bad = l.copy()
    bad[7, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit_grid(uv, bad, (400, 300), 50)
    with pytest.raises(InputError, match="differ in shape"):
        fit_grid(uv, l[:-1], (400, 300), 50)
    with pytest.raises(InputError, match="outside"):
        fit_grid(uv + np.array([500.0, 0.0]), l, (400, 300), 50)
    with pytest.raises(InputError, match="border"):
        fit_grid(uv, l, (400, 300), 50, border="free")
    with pytest.raises(InputError, match="sigma_constraint"):
        fit_grid(uv, l, (400, 300), 50, sigma_constraint="estimate")
    with pytest.raises(InputError, match="min_support must be 0 or more"):
        fit_grid(uv, l, (400, 300), 50, min_support=-1)
    grid = fit_grid(uv, l, (400, 300), 50, folds=0)
    with pytest.raises(InputError, match="outside"):
        grid.evaluate([[400.0, 10.0]])
    with pytest.raises(InputError, match="NaN"):
        grid.evaluate([[np.nan, 10.0]])


@pytest.mark.parametrize("bad", [True, np.True_, "100", b"100", [100], None])
def test_a_spacing_that_is_not_a_number_is_refused_by_name(bad):
    """``True`` (an int) and ``"100"`` (converts) were taken as 1 px and 100 px."""
    rng = np.random.default_rng(1)
    uv = scattered(rng, 400, 600, 400)
    l = rng.normal(0, 0.1, (400, 2))
    want = f"grid spacing must be a number of pixels, not {bad!r}"
    with pytest.raises(InputError, match=f"^{re.escape(want)}$"):
        GridLayout(600, 400, bad)
    with pytest.raises(InputError, match=re.escape(want)):
        fit_grid(uv, l, (600, 400), bad, folds=0)
    with pytest.raises(InputError, match=re.escape(want)):
        fit_grids({"a": (uv, l)}, (600, 400), bad, folds=0)
    # numbers of any real type (and a 0-d array read from a file) are kept
    for g in (100, 100.0, np.float32(100), np.int64(100), np.array(100.0)):
        assert GridLayout(600, 400, g).spacing == 100.0


def test_the_block_functions_refuse_a_spacing_that_is_not_a_number():
    import photogeom as pg

    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)
    for bad in (True, "1000"):
        with pytest.raises(InputError, match="grid spacing must be a number of pixels"):
            pg.calibration.fit_residual_grids(sim.block, bad, folds=0)
    # the sweep checks every spacing before it fits the first (it takes minutes)
    fit = SimpleNamespace(block=sim.block)
    sweep = pg.calibration.sweep_spacings
    with pytest.raises(InputError, match=r"spacings\[1\] must be a number of pixels, not '500'"):
        sweep(fit, [300, "500"])
    with pytest.raises(InputError, match=r"spacings\[0\] must be a number of pixels, not True"):
        sweep(fit, [True, 500])
    with pytest.raises(InputError, match="spacings must be a list of numbers"):
        sweep(fit, "300,500")


def test_the_study_pipelines_check_their_spacings_before_any_work():
    """run_study and compare_in_adjustment met a bad spacing only when fitting its grids,
    after the simulation and the adjustments (minutes); the sweep's after the fine and
    coarse grids."""
    from photogeom.calibration.study import compare_in_adjustment, run_study

    with pytest.raises(InputError, match=r"^run_study: spacing must be a number of pixels"):
        run_study("no such preset", spacing=True)
    with pytest.raises(InputError, match=r"^run_study: coarse_spacing must be a number"):
        run_study("no such preset", coarse_spacing="2000")
    with pytest.raises(InputError, match=r"^run_study: sweep\[2\] must be a positive number"):
        run_study("no such preset", sweep=[100, 200, 0])
    with pytest.raises(InputError, match=r"^compare_in_adjustment: spacing must be a number"):
        compare_in_adjustment(None, "500")
    with pytest.raises(InputError, match=r"^compare_in_adjustment: combined_spacing must be"):
        compare_in_adjustment(None, 500, combined_spacing=True)
