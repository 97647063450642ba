"""Sparse SPD factorisation: both backends against dense linear algebra."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from photogeom.adjust.sparse import HAVE_CHOLMOD, factorize
from photogeom.errors import DegenerateGeometryError

sys.path.insert(0, str(Path(__file__).parent))
from sparse_systems import banded_dense_blocks

BACKENDS = ["superlu", "dense", "cg"] + (["cholmod"] if HAVE_CHOLMOD else [])


def _spd(n=60, seed=0):
    A = sp.random(4 * n, n, density=0.05, random_state=seed) + sp.eye(4 * n, n)
    return sp.csc_matrix(A.T @ A)


@pytest.mark.parametrize("backend", BACKENDS)
def test_solve_and_inverse_blocks_match_dense(backend):
    N = _spd()
    Nd = N.toarray()
    f = factorize(N, backend=backend)
    assert f.backend == backend
    rng = np.random.default_rng(1)
    b = rng.standard_normal((60, 3))
    tol = 1e-8 if backend == "cg" else 1e-10  # conjugate gradients: iterative accuracy
    np.testing.assert_allclose(f.solve(b), np.linalg.solve(Nd, b), rtol=tol, atol=1e-12)
    np.testing.assert_allclose(f.solve(b[:, 0]), np.linalg.solve(Nd, b[:, 0]), rtol=tol)
    Q = np.linalg.inv(Nd)
    blocks = f.inverse_blocks(np.array([0, 6, 54]), 6)
    for k, s in enumerate([0, 6, 54]):
        np.testing.assert_allclose(blocks[k], Q[s : s + 6, s : s + 6], rtol=tol * 10, atol=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
def test_indefinite_and_empty_columns_are_named_errors(backend):
    Nd = _spd().toarray()
    Nd[5, 5] = -1.0
    with pytest.raises(DegenerateGeometryError, match="reduced camera system"):
        factorize(sp.csc_matrix(Nd), backend=backend, what="reduced camera system")
    if backend == "cg":
        return  # conjugate gradients cannot certify definiteness (documented)
    rng = np.random.default_rng(2)
    u = rng.standard_normal((30, 28))
    with pytest.raises(DegenerateGeometryError, match="positive definite"):
        factorize(sp.csc_matrix(u @ u.T - 1e-3 * np.eye(30)), backend=backend)


@pytest.mark.skipif(not HAVE_CHOLMOD, reason="CHOLMOD (sksparse-minimal) not installed")
def test_cholmod_with_big_supernodes_matches_lapack():
    N = banded_dense_blocks()
    b = np.random.default_rng(3).standard_normal(N.shape[0])
    x = factorize(N, backend="cholmod").solve(b)
    np.testing.assert_allclose(x, np.linalg.solve(N.toarray(), b), rtol=1e-10, atol=1e-14)
    Nd = N.toarray()
    # indefinite with a positive diagonal (a 2 x 2 minor below zero), inside a supernode
    Nd[700, 701] = Nd[701, 700] = 2.0 * np.sqrt(Nd[700, 700] * Nd[701, 701])
    with pytest.raises(DegenerateGeometryError, match="not positive definite"):
        factorize(sp.csc_matrix(Nd), backend="cholmod")


@pytest.mark.skipif(not HAVE_CHOLMOD, reason="CHOLMOD (sksparse-minimal) not installed")
def test_the_bound_blas_gives_the_reference_blas_solution(tmp_path):
    """CHOLMOD bound to the optimised BLAS (the default) and to the wheel's reference BLAS
    (PHOTOGEOM_CHOLMOD_BLAS=reference, a fresh process) solve alike."""
    import os
    import subprocess
    import sys

    from photogeom.adjust import sparse

    N = banded_dense_blocks()
    b = np.random.default_rng(4).standard_normal(N.shape[0])
    sp.save_npz(tmp_path / "N.npz", N)
    np.save(tmp_path / "b.npy", b)
    code = (
        "import sys, numpy as np, scipy.sparse as sp\n"
        "from photogeom.adjust import sparse\n"
        "N = sp.load_npz(sys.argv[1]); b = np.load(sys.argv[2])\n"
        "np.save(sys.argv[3], sparse.factorize(N, backend='cholmod').solve(b))\n"
        "print(sparse.CHOLMOD_BLAS)\n"
    )
    env = {**os.environ, sparse.BLAS_VARIABLE: "reference"}
    out = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "N.npz"), str(tmp_path / "b.npy"),
         str(tmp_path / "x.npy")],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert out.stdout.startswith("reference")
    x_ref = np.load(tmp_path / "x.npy")
    x = factorize(N, backend="cholmod").solve(b)
    np.testing.assert_allclose(x, x_ref, rtol=1e-11, atol=1e-15)


def test_blas_binding_can_be_switched_off_and_needs_no_opencv(monkeypatch):
    import importlib.util

    from photogeom.adjust import sparse

    monkeypatch.setenv(sparse.BLAS_VARIABLE, "reference")
    assert sparse._bind_optimised_blas().startswith("reference")
    monkeypatch.delenv(sparse.BLAS_VARIABLE)
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    assert sparse._optimised_blas() is None
    assert sparse._bind_optimised_blas().startswith("reference")


@pytest.mark.parametrize("backend", BACKENDS)
def test_inverse_gram_matches_dense(backend):
    """``B' N^-1 B`` by half solves (Cholesky backends) or solves, in batches of a few
    columns, with a sparse ``B`` whose columns touch few rows."""
    N = _spd()
    B = sp.random(60, 7, density=0.1, random_state=3, format="csc") + sp.eye(60, 7)
    f = factorize(N, backend=backend)
    ref = B.toarray().T @ np.linalg.solve(N.toarray(), B.toarray())
    tol = 1e-8 if backend == "cg" else 1e-12
    for batch in (8 * 60 * 3, 2**26):  # 3 columns per batch, all at once
        np.testing.assert_allclose(f.inverse_gram(B, batch), ref, rtol=tol, atol=tol)
    np.testing.assert_allclose(f.solve(np.ones(60)), np.linalg.solve(N.toarray(), np.ones(60)))


@pytest.mark.skipif(not HAVE_CHOLMOD, reason="CHOLMOD's factor is outside Python's memory")
def test_the_scaling_of_a_factorised_matrix_copies_it_once():
    """Every factorisation scales the matrix symmetrically by its diagonal: two sparse
    matrix products and a conversion before (transient memory 1.0 times the matrix's,
    0.16-0.25 s against CHOLMOD's 0.8-0.9 s on a 2000-image reduced camera system); each
    entry multiplied by its row's and column's scales now (0.34 times, 0.05 s), the same
    values and pattern (stored zeros dropped as before)."""
    import tracemalloc

    N = banded_dense_blocks(nb=6, b=60)
    for r, c in ((5, 0), (0, 5)):  # a stored zero, both triangles
        N.data[N.indptr[c] + np.flatnonzero(N.indices[N.indptr[c] : N.indptr[c + 1]] == r)] = 0
    assert N.nnz > 0 and np.any(N.data == 0.0)
    s = 1.0 / np.sqrt(N.diagonal())
    ref = sp.csc_matrix(sp.diags(s) @ N @ sp.diags(s))  # the independent route
    ref.sort_indices()
    factorize(N, backend="cholmod")  # imports first
    tracemalloc.start()
    try:
        f = factorize(N, backend="cholmod")
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    got = f._Ns
    np.testing.assert_array_equal(got.indptr, ref.indptr)
    np.testing.assert_array_equal(got.indices, ref.indices)
    np.testing.assert_array_equal(got.data, ref.data)
    assert not np.any(got.data == 0.0)
    assert peak - kept <= 0.6 * 12 * N.nnz  # bytes of the matrix (values and row indices)


@pytest.mark.parametrize("backend", ["dense", "superlu"])
def test_the_dense_inverse_holds_one_matrix_of_its_size(backend):
    """The whole inverse (the covariance blocks of a reduced camera system up to
    DENSE_INVERSE_MAX unknowns) equals the inverse by numpy while at most
    1.2 times an n x n array is held at once (before: a C-order copy beside LAPACK's
    Fortran-order one, and the two triangles and their sum beside the inverse, about 3 of
    them above the result: 932 -> 637 MB resident adjusting a 500-image BAL block)."""
    import tracemalloc

    n = 1100
    N = _spd(n, seed=4)
    f = factorize(N, backend=backend)
    tracemalloc.start()
    try:
        Q = f.dense_inverse()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak <= 1.2 * 8 * n * n, peak / (8 * n * n)
    ref = np.linalg.inv(N.toarray())
    np.testing.assert_allclose(Q, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_elimination_order_puts_an_arrow_matrix_dense_unknown_last(backend):
    # An "arrow" matrix: unknown 0 coupled to all others, which are coupled to nothing else.
    # Eliminating it first fills the whole factor; any fill-reducing order takes it last.
    n = 300
    N = sp.lil_matrix((n, n))
    N.setdiag(10.0 + np.arange(n))
    N[0, :] = 1.0
    N[:, 0] = 1.0
    N[0, 0] = 1000.0
    positions = factorize(sp.csc_matrix(N), backend=backend).elimination_positions()
    if backend in ("dense", "cg"):
        assert positions is None
    else:
        np.testing.assert_array_equal(np.sort(positions), np.arange(n))
        assert positions[0] == n - 1
