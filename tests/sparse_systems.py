"""Sparse test systems shared by the solver tests."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def banded_dense_blocks(nb: int = 8, b: int = 150, seed: int = 2) -> sp.csc_matrix:
    """SPD with dense b x b blocks coupled to their neighbours: big supernodes, so a sparse
    Cholesky runs the dense BLAS/LAPACK kernels (dgemm, dsyrk, dtrsm, dpotrf)."""
    rng = np.random.default_rng(seed)
    n = nb * b
    A = np.zeros((n, n))
    for i in range(nb):
        for j in (i, i + 1):
            if j < nb:
                A[i * b : (i + 1) * b, j * b : (j + 1) * b] = rng.standard_normal((b, b))
    return sp.csc_matrix(A @ A.T + n * np.eye(n))
