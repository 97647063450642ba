"""The Schur-complement engine against the dense normal equations of the same problem."""

import tracemalloc

import numpy as np
import pytest

from photogeom.adjust.schur import (
    Linearization,
    SchurSystem,
    covariance_blocks,
    observation_cofactors,
    point_covariances,
)


def _problem(
    seed,
    L=5,
    b=4,
    n_groups=2,
    gl=3,
    n_points=12,
    fixed=True,
    coupling="auto",
    shared=False,
    own=0,
    own_groups="auto",
    hold=None,
):
    """A random problem and its dense normal equations; ``shared``: the groups share their
    first global column (the others their own); ``own``: the first ``own`` local blocks
    have a group of their own (``L`` groups if ``own == L``)."""
    rng = np.random.default_rng(seed)
    local_group = rng.integers(0, max(n_groups, 1), L)
    if own:
        # groups 0 .. own - 1 of the first local blocks alone, the others shared
        n_shared = 0 if own == L else n_groups
        # every shared group observed by two local blocks at least
        local_group = np.r_[np.arange(own), own + np.arange(L - own) % max(n_shared, 1)]
        n_groups = own + n_shared
    if shared:
        g = n_groups * (gl - 1) + 1
        own = 1 + local_group[:, None] * (gl - 1) + np.arange(gl - 1)[None, :]
        local_global = np.column_stack([np.zeros(L, dtype=int), own])
    else:
        g = n_groups * gl
        local_global = local_group[:, None] * gl + np.arange(gl)[None, :]
    loc, pt = [], []
    for j in range(n_points):
        ims = rng.choice(L, size=rng.integers(2, L + 1), replace=False)
        loc += list(ims)
        pt += [j] * ims.size
    loc, pt = np.array(loc), np.array(pt)
    n, d = loc.size, 2
    A = rng.standard_normal((n, d, b))
    G = rng.standard_normal((n, d, gl))
    P = rng.standard_normal((n, d, 3))
    r = rng.standard_normal((n, d))
    local_free = np.ones((L, b), bool)
    global_free = np.ones(g, bool)
    if fixed:
        local_free[0, :] = False
        local_free[2, 1] = False
        global_free[1] = False
    if hold is not None:  # position ``hold`` of every group's columns held
        global_free[np.unique(local_global[:, hold])] = False
    li = np.zeros((L, b, b))
    lg = np.zeros((L, b))
    Jl = rng.standard_normal((L, 3, b))
    rl = rng.standard_normal((L, 3))
    li += np.einsum("lki,lkj->lij", Jl, Jl)
    lg += np.einsum("lki,lk->li", Jl, rl)
    pi = np.zeros((n_points, 3, 3))
    pg_ = np.zeros((n_points, 3))
    pi[0] = np.eye(3) * 4
    pg_[0] = [0.3, -0.1, 0.2]
    gi = np.eye(g) * 0.5
    gg = rng.standard_normal(g) * 0.1
    lin = Linearization(r, A, G, P, li, lg, pi, pg_, gi, gg, 0.0)
    sysm = SchurSystem(
        L,
        b,
        g,
        n_points,
        loc,
        pt,
        local_global,
        local_free,
        global_free,
        backend="superlu",
        global_coupling=coupling,
        own_groups=own_groups,
    )
    # dense
    nc = L * b + g
    u = nc + 3 * n_points
    J = np.zeros((n * d, u))
    for k in range(n):
        rows = slice(k * d, k * d + d)
        J[rows, loc[k] * b : loc[k] * b + b] = A[k]
        J[rows, L * b + local_global[loc[k]]] = G[k]
        J[rows, nc + 3 * pt[k] : nc + 3 * pt[k] + 3] = P[k]
    N = J.T @ J
    grad = J.T @ r.ravel()
    for l_ in range(L):
        N[l_ * b : l_ * b + b, l_ * b : l_ * b + b] += li[l_]
        grad[l_ * b : l_ * b + b] += lg[l_]
    for j in range(n_points):
        N[nc + 3 * j : nc + 3 * j + 3, nc + 3 * j : nc + 3 * j + 3] += pi[j]
        grad[nc + 3 * j : nc + 3 * j + 3] += pg_[j]
    N[L * b : nc, L * b : nc] += gi
    grad[L * b : nc] += gg
    free = np.concatenate([local_free.ravel(), global_free, np.ones(3 * n_points, bool)])
    return sysm, lin, N, grad, free, J


@pytest.mark.parametrize(
    "seed,dense_inverse,coupling,n_groups,shared",
    [
        (0, True, "dense", 2, False),
        (1, False, "dense", 2, False),
        (2, True, "dense", 2, False),
        (3, False, "dense", 2, False),
        # the coupling of points with the global parameters per (point, group)
        (0, True, "sparse", 2, False),
        (1, False, "sparse", 2, False),
        (4, True, "sparse", 1, False),
        (5, False, "sparse", 5, False),
        (6, True, "sparse", 4, True),  # groups sharing a global column
        (7, False, "auto", 6, False),  # few groups: dense
    ],
)
def test_step_and_covariances_equal_the_dense_solution(
    seed, dense_inverse, coupling, n_groups, shared, monkeypatch
):
    import photogeom.adjust.sparse as sparse

    if not dense_inverse:  # the blocks by batched solves with unit vectors
        monkeypatch.setattr(sparse, "DENSE_INVERSE_MAX", 0)
    sysm, lin, N, grad, free, J = _problem(
        seed, L=7, n_groups=n_groups, coupling=coupling, shared=shared
    )
    assert sysm.sparse_global == (coupling == "sparse")
    ne = sysm.normal_equations(lin)
    dc, dp, F = ne.solve()
    Nf = N[np.ix_(free, free)]
    x = np.zeros(N.shape[0])
    x[free] = np.linalg.solve(Nf, -grad[free])
    nc = sysm.nc
    np.testing.assert_allclose(dc, x[:nc], rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(dp.ravel(), x[nc:], rtol=1e-9, atol=1e-11)
    Qf = np.linalg.inv(Nf)
    Q = np.zeros_like(N)
    Q[np.ix_(free, free)] = Qf
    cb = covariance_blocks(ne, F, pairs=True, batch_columns=7)
    b, L = sysm.b, sysm.n_local
    for l_ in range(L):
        np.testing.assert_allclose(
            cb.local[l_], Q[l_ * b : l_ * b + b, l_ * b : l_ * b + b], atol=1e-10
        )
        np.testing.assert_allclose(
            cb.local_global[l_], Q[l_ * b : l_ * b + b, L * b : nc], atol=1e-10
        )
    for k, (l1, l2) in enumerate(sysm.blocks):
        np.testing.assert_allclose(
            cb.pairs[k], Q[l1 * b : l1 * b + b, l2 * b : l2 * b + b], atol=1e-10
        )
    np.testing.assert_allclose(cb.global_, Q[L * b : nc, L * b : nc], atol=1e-10)
    _check_point_and_observation_cofactors(ne, cb, sysm, Q, J, nc)


@pytest.mark.parametrize("coupling", ["dense", "sparse"])
def test_damped_step_equals_dense_marquardt(coupling):
    sysm, lin, N, grad, free, _ = _problem(5, coupling=coupling)
    lam = 0.3
    ne = sysm.normal_equations(lin, damping=lam)
    dc, dp, _ = ne.solve()
    Nd = N.copy()
    Nd[np.diag_indices_from(Nd)] *= 1 + lam
    x = np.zeros(N.shape[0])
    Nf = Nd[np.ix_(free, free)]
    x[free] = np.linalg.solve(Nf, -grad[free])
    np.testing.assert_allclose(np.r_[dc, dp.ravel()], x, rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize(
    "seed,dense_inverse,coupling,own,n_groups,hold",
    [
        (10, True, "auto", 7, 0, None),  # a group per local block: no global parameter left
        (11, False, "auto", 7, 0, None),
        (12, True, "dense", 4, 1, None),  # mixed: own groups and one shared by three blocks
        (13, False, "sparse", 3, 2, None),
        (14, False, "dense", 5, 1, None),
        # a parameter held in every group: left out of the folded system
        (15, True, "auto", 7, 0, 2),
        (16, False, "sparse", 3, 2, 0),
    ],
)
def test_own_groups_held_locally_equal_the_dense_solution(
    seed, dense_inverse, coupling, own, n_groups, hold, monkeypatch
):
    """The groups of single local blocks held as their local unknowns: the step in the
    unfolded unknowns, the factor's solves, the blocks of the inverse (those of the
    global parameters by global_block / local_global_block), point covariances and
    observation cofactors equal those of the dense normal equations."""
    import photogeom.adjust.sparse as sparse

    if not dense_inverse:
        monkeypatch.setattr(sparse, "DENSE_INVERSE_MAX", 0)
    L = 7
    sysm, lin, N, grad, free, J = _problem(
        seed, L=L, n_groups=n_groups, own=own, own_groups="local", coupling=coupling, hold=hold
    )
    assert sysm.inner is not None
    assert sysm.inner.b == sysm.b + sysm.gl - (hold is not None)
    n_shared_cols = sysm.n_global - own * sysm.gl
    assert sysm.inner.n_global == (n_shared_cols + 1 if own < L else 0)
    ne = sysm.normal_equations(lin)
    dc, dp, F = ne.solve()
    Nf = N[np.ix_(free, free)]
    x = np.zeros(N.shape[0])
    x[free] = np.linalg.solve(Nf, -grad[free])
    nc, b = sysm.nc, sysm.b
    np.testing.assert_allclose(dc, x[:nc], rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(dp.ravel(), x[nc:], rtol=1e-9, atol=1e-11)
    Q = np.zeros_like(N)
    Q[np.ix_(free, free)] = np.linalg.inv(Nf)
    # the factor in the unfolded unknowns: its inverse is Q's camera-side block
    cf = free[:nc]
    E = np.eye(nc)[:, cf]
    np.testing.assert_allclose(F.solve(E)[cf], Q[:nc, :nc][np.ix_(cf, cf)], atol=1e-10)
    np.testing.assert_allclose(
        F.inverse_diagonal(np.flatnonzero(cf)), np.diag(Q)[:nc][cf], rtol=1e-9
    )
    np.testing.assert_allclose(
        F.inverse_gram(E), Q[:nc, :nc][np.ix_(cf, cf)], rtol=1e-9, atol=1e-10
    )
    cb = covariance_blocks(ne, F, pairs=True, batch_columns=7)
    for l_ in range(L):
        np.testing.assert_allclose(
            cb.local[l_], Q[l_ * b : l_ * b + b, l_ * b : l_ * b + b], atol=1e-10
        )
    for k, (l1, l2) in enumerate(sysm.blocks):
        np.testing.assert_allclose(
            cb.pairs[k], Q[l1 * b : l1 * b + b, l2 * b : l2 * b + b], atol=1e-10
        )
    g = np.arange(sysm.n_global)
    # every pair of local blocks shares a point here: all global blocks are at hand
    assert len(sysm.blocks) == L * (L - 1) // 2
    np.testing.assert_allclose(cb.global_block(g, g), Q[L * b : nc, L * b : nc], atol=1e-10)
    for l_ in range(L):
        np.testing.assert_allclose(
            cb.local_global_block(l_, g), Q[l_ * b : l_ * b + b, L * b : nc], atol=1e-10
        )
    _check_point_and_observation_cofactors(ne, cb, sysm, Q, J, nc)
    # damped: the Marquardt step of the dense system
    lam = 0.3
    ne = sysm.normal_equations(lin, damping=lam)
    dc, dp, _ = ne.solve()
    Nd = N.copy()
    Nd[np.diag_indices_from(Nd)] *= 1 + lam
    x = np.zeros(N.shape[0])
    x[free] = np.linalg.solve(Nd[np.ix_(free, free)], -grad[free])
    np.testing.assert_allclose(np.r_[dc, dp.ravel()], x, rtol=1e-9, atol=1e-11)
    pred = ne.predicted_decrease(dc, dp, lam)
    ref = -(grad[free] @ x[free]) + lam * np.sum(np.diag(N)[free] * x[free] ** 2)
    assert pred == pytest.approx(ref, rel=1e-9)


def test_own_groups_far_apart_take_a_solve():
    """Two local blocks with groups of their own that share no point: their calibration
    block is not among the covariance blocks, and global_block says so."""
    rng = np.random.default_rng(3)
    L, b, gl = 4, 2, 2
    # a chain: 0-1, 1-2, 2-3 share points, 0 and 3 none
    loc = np.array([0, 1, 1, 2, 2, 3, 0, 1, 1, 2, 0, 1, 2, 3])
    pt = np.array([0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6])
    n = loc.size
    lg = np.arange(L * gl).reshape(L, gl)
    sysm = SchurSystem(
        L,
        b,
        L * gl,
        7,
        loc,
        pt,
        lg,
        np.ones((L, b), bool),
        np.ones(L * gl, bool),
        own_groups="local",
    )
    lin = Linearization(
        rng.standard_normal((n, 2)),
        rng.standard_normal((n, 2, b)),
        rng.standard_normal((n, 2, gl)),
        rng.standard_normal((n, 2, 3)),
        np.tile(np.eye(b), (L, 1, 1)),
        np.zeros((L, b)),
        np.zeros((7, 3, 3)),
        np.zeros((7, 3)),
        np.eye(L * gl),
        np.zeros(L * gl),
        0.0,
    )
    ne = sysm.normal_equations(lin)
    F = ne.factor()
    cb = covariance_blocks(ne, F, pairs=True)
    assert not np.any((sysm.blocks[:, 0] == 0) & (sysm.blocks[:, 1] == 3))
    with pytest.raises(LookupError, match="solve with the factor"):
        cb.global_block(np.array([0]), np.array([3 * gl]))
    # blocks at hand agree with the solves
    cols = np.arange(2 * gl)  # groups of local blocks 0 and 1 (they share points)
    ref = F.solve(np.eye(sysm.nc)[:, L * b + cols])[L * b + cols]
    np.testing.assert_allclose(cb.global_block(cols, cols), ref, atol=1e-12)


def test_a_prior_coupling_an_own_group_with_others_is_refused():
    sysm, lin, *_ = _problem(3, L=7, n_groups=1, own=4, own_groups="local")
    gi = lin.global_info.copy()
    gi[0, -1] = gi[-1, 0] = 0.1  # an own group's column with a shared one
    lin.global_info = gi
    with pytest.raises(ValueError, match="own_groups='global'"):
        sysm.normal_equations(lin)


def _check_point_and_observation_cofactors(ne, cb, sysm, Q, J, nc):
    """The points' covariance blocks and the observations' cofactors from the covariance
    blocks ``cb`` equal those of the dense inverse ``Q`` (points after the ``nc`` camera
    unknowns) and the dense ``J Q J'``."""
    Qpp = point_covariances(ne, cb)
    for j in range(sysm.n_points):
        np.testing.assert_allclose(
            Qpp[j],
            Q[nc + 3 * j : nc + 3 * j + 3, nc + 3 * j : nc + 3 * j + 3],
            rtol=1e-9,
            atol=1e-10,
        )
    C = observation_cofactors(ne, cb, Qpp)
    JQJ = J @ Q @ J.T
    for k in range(sysm.n):
        np.testing.assert_allclose(
            C[k], JQJ[2 * k : 2 * k + 2, 2 * k : 2 * k + 2], rtol=1e-8, atol=1e-9
        )


def _many_rows(L=20, b=9, p=4000, per=5, seed=3, n_groups=0, gl=2, coupling="auto"):
    """A problem whose rows (p * per) far outnumber its local blocks (L of size b): each
    point in ``per`` distinct blocks; ``n_groups`` groups of ``gl`` global parameters (the
    local blocks in turn), none by default."""
    rng = np.random.default_rng(seed)
    loc = np.argsort(rng.random((p, L)), axis=1)[:, :per].ravel()
    pt = np.repeat(np.arange(p), per)
    n = loc.size
    gl = gl if n_groups else 0
    g = n_groups * gl
    lin = Linearization(
        rng.normal(size=(n, 2)),
        rng.normal(size=(n, 2, b)),
        rng.normal(size=(n, 2, gl)),
        rng.normal(size=(n, 2, 3)),
        np.tile(np.eye(b), (L, 1, 1)),
        np.zeros((L, b)),
        np.zeros((p, 3, 3)),
        np.zeros((p, 3)),
        np.eye(g),
        np.zeros(g),
        0.0,
    )
    lg = (np.arange(L) % max(n_groups, 1))[:, None] * gl + np.arange(gl)[None, :]
    sysm = SchurSystem(
        L,
        b,
        g,
        p,
        loc,
        pt,
        lg,
        np.ones((L, b), bool),
        np.ones(g, bool),
        global_coupling=coupling,
    )
    return sysm, lin


@pytest.mark.parametrize("groups", [0, 4])
def test_the_reduction_allocates_no_padded_copies_of_the_row_blocks(monkeypatch, groups):
    """``W_k`` and ``Y_k`` (n, b, 3) are the reduction's only arrays of the size of all rows
    beside the Jacobian blocks: the pair products, and with the coupling of the points with
    the global parameters per (point, group) the products of the rows with the groups,
    gather their rows from them in chunks (padded copies of them stood beside them, with a
    gathered copy of ``V^-1`` for every row). With a small ``CHUNK`` the temporaries that
    the call frees again stay below half of one such array (before: 2.1 of them without
    groups, 1.2 with the groups' padded copy of ``Y`` alone)."""
    import photogeom.adjust.schur as schur

    monkeypatch.setattr(schur, "CHUNK", 2 * schur.PAIR_GROUP)
    sysm, lin = _many_rows(n_groups=groups, coupling="sparse")
    assert sysm.sparse_global == bool(groups)
    n, b = sysm.n, sysm.b
    tracemalloc.start()
    try:
        normal = sysm.normal_equations(lin, damping=1e-3)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    row_array = n * b * 3 * 8
    assert normal.W.shape == normal.Y.shape == (n, b, 3)
    assert peak - kept < 0.5 * row_array, (peak - kept) / row_array


def test_the_observation_cofactors_gather_no_covariance_block_for_every_row(monkeypatch):
    """The cross cofactors of the rows' local blocks with their points took ``Q_ll`` of
    every row's local block at once (n x b x b, 131 MB on a 500-image BAL block with a
    camera per image); chunks of rows now. With a small ``CHUNK`` the temporaries freed
    again stay below half of that array (before: 1.3 of it), and the cofactors are those
    of the dense normal equations."""
    import photogeom.adjust.schur as schur

    monkeypatch.setattr(schur, "CHUNK", 2 * schur.PAIR_GROUP)
    sysm, lin = _many_rows()
    ne = sysm.normal_equations(lin)
    cb = covariance_blocks(ne, ne.factor(), pairs=True)
    Qpp = point_covariances(ne, cb)
    tracemalloc.start()
    try:
        observation_cofactors(ne, cb, Qpp)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n, b = sysm.n, sysm.b
    assert peak - kept < 0.5 * n * b * b * 8, (peak - kept) / (n * b * b * 8)
    # in chunks of rows, the cofactors of the dense normal equations
    sysm, lin, N, _, free, J = _problem(11, L=6, b=9, n_groups=1, gl=2, n_points=40)
    ne = sysm.normal_equations(lin)
    cb = covariance_blocks(ne, ne.factor(), pairs=True)
    got = observation_cofactors(ne, cb, point_covariances(ne, cb))
    Q = np.zeros_like(N)
    Q[np.ix_(free, free)] = np.linalg.inv(N[np.ix_(free, free)])
    ref = J @ Q @ J.T
    d = got.shape[1]
    blocks = np.stack([ref[d * k : d * k + d, d * k : d * k + d] for k in range(sysm.n)])
    np.testing.assert_allclose(got, blocks, rtol=1e-8, atol=1e-10 * np.abs(blocks).max())


def test_held_global_columns_without_rows_are_left_out_of_the_folded_system():
    """Every local block with a group of its own and two held global columns no row
    depends on (a camera group without images) beside one free such column with a prior:
    the held ones are not in the folded system (no dense coupling of the points with
    them), and the step, the factor's solves and the covariance blocks are those of the
    global form."""
    rng = np.random.default_rng(5)
    L, b, gl, p = 5, 3, 2, 12
    g = L * gl + 3
    loc = np.concatenate([rng.choice(L, 3, replace=False) for _ in range(p)])
    pt = np.repeat(np.arange(p), 3)
    n = loc.size
    lg = np.arange(L * gl).reshape(L, gl)
    gf = np.ones(g, bool)
    gf[L * gl : L * gl + 2] = False
    lin = Linearization(
        rng.standard_normal((n, 2)),
        rng.standard_normal((n, 2, b)),
        rng.standard_normal((n, 2, gl)),
        rng.standard_normal((n, 2, 3)),
        np.tile(np.eye(b), (L, 1, 1)),
        np.zeros((L, b)),
        np.zeros((p, 3, 3)),
        np.zeros((p, 3)),
        np.eye(g),
        rng.standard_normal(g),
        0.0,
    )
    out = {}
    for og in ("local", "global"):
        s = SchurSystem(L, b, g, p, loc, pt, lg, np.ones((L, b), bool), gf, own_groups=og)
        ne = s.normal_equations(lin)
        dc, dp, F = ne.solve()
        cb = covariance_blocks(ne, F, pairs=True)
        cols = np.r_[lg[1], L * gl + np.arange(3)]
        e = np.eye(s.nc)[:, -1]  # the free one (held ones: zero in and out, see MappedFactor)
        out[og] = (dc, dp, F.solve(e), cb.local_global_block(1, cols), s)
    assert out["local"][4].inner.n_global == 1  # the free column with its prior only
    for a, c in zip(out["local"][:4], out["global"][:4]):
        np.testing.assert_allclose(a, c, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    "seed,coupling,own,n_groups",
    [
        (20, "dense", 0, 2),
        (21, "sparse", 0, 3),
        (22, "auto", 7, 0),  # a group per local block, folded
        (23, "dense", 4, 1),  # own groups and a shared one
    ],
)
def test_a_second_right_hand_side_reuses_the_factor(seed, coupling, own, n_groups, monkeypatch):
    """``solve_gradient`` of ``gradient(lin, r)``: the damped step for other residual rows
    (no prior gradients) with the factor of the last solve, the reduction's blocks
    dropped, equals the dense Marquardt solution and that of a freshly formed system
    (1e-12); no second factorisation. ``damping_diagonal`` is the dense normal matrix's
    diagonal, the prior terms (``global_info`` too) included."""
    import photogeom.adjust.schur as schur

    L, lam = 7, 0.3
    sysm, lin, N, _, free, J = _problem(
        seed,
        L=L,
        n_groups=n_groups,
        own=own,
        own_groups="local" if own else "auto",
        coupling=coupling,
        shared=False,
    )
    assert (sysm.inner is not None) == bool(own)
    count = []
    real = schur.factorize
    monkeypatch.setattr(schur, "factorize", lambda *a, **k: count.append(1) or real(*a, **k))
    ne = sysm.normal_equations(lin, damping=lam)
    ne.solve()
    ne.drop_reduction()
    r2 = np.random.default_rng(seed + 100).standard_normal(lin.r.shape)
    gc, gp = sysm.gradient(lin, r2)
    np.testing.assert_allclose(np.r_[gc, gp.ravel()], J.T @ r2.ravel(), rtol=1e-12, atol=1e-12)
    dc, dp = ne.solve_gradient(gc, gp)
    assert len(count) == 1
    Nd = N.copy()
    Nd[np.diag_indices_from(Nd)] *= 1 + lam
    x = np.zeros(N.shape[0])
    x[free] = np.linalg.solve(Nd[np.ix_(free, free)], -(J.T @ r2.ravel())[free])
    np.testing.assert_allclose(np.r_[dc, dp.ravel()], x, rtol=1e-9, atol=1e-11)
    zero_l, zero_p = np.zeros_like(lin.local_grad), np.zeros_like(lin.point_grad)
    fresh = Linearization(
        r2, lin.A, lin.G, lin.P, lin.local_info, zero_l, lin.point_info, zero_p,
        lin.global_info, np.zeros_like(lin.global_grad), 0.0,
    )  # fmt: skip
    fc, fp, _ = sysm.normal_equations(fresh, damping=lam).solve()
    ref = np.r_[fc, fp.ravel()]
    got = np.r_[dc, dp.ravel()]
    assert np.linalg.norm(got - ref) <= 1e-12 * np.linalg.norm(ref)
    d = ne.damping_diagonal()
    np.testing.assert_allclose(d[free], np.diag(N)[free], rtol=1e-12)
    assert np.all(d[~free] == 0)
