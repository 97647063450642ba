"""Sparse SPD factorisation: both backends against dense linear algebra."""

import numpy as np
import pytest
import scipy.sparse as sp

from photogeom.adjust.sparse import HAVE_CHOLMOD, factorize
from photogeom.errors import DegenerateGeometryError

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
