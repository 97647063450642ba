"""Selected entries of the inverse of a sparse SPD matrix with a narrow block band.

The standard deviations of unknowns, the redundancy numbers of observations (data
snooping) and the redundancy contributions of groups (variance components) need entries
of ``N^-1`` only where ``N`` itself has non-zeros; a dense inverse is never needed.
For a matrix that is block tridiagonal in blocks of size ``s`` (after an optional
permutation), the block version of Takahashi's recurrence gives the diagonal blocks
``Z_II`` and the blocks ``Z_I,I+1`` of ``Z = N^-1`` from the Schur complements

    S_0 = D_0,   S_I = D_I - E_{I-1}' S_{I-1}^-1 E_{I-1},   G_I = S_I^-1 E_I
    Z_{K-1,K-1} = S_{K-1}^-1
    Z_{I,I+1} = -G_I Z_{I+1,I+1},   Z_{I,I} = S_I^-1 - Z_{I,I+1} G_I'

in ``O(K s^3)`` operations (``D_I`` diagonal blocks, ``E_I`` the blocks right of them).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import DegenerateGeometryError


class BlockSelectedInverse:
    """Entries of ``N^-1`` within one block of the block diagonal of a permuted ``N``.

    Parameters
    ----------
    N : scipy.sparse matrix, shape (n, n)
        Symmetric positive definite.
    block : int
        Block size ``s``; after the permutation, ``N[p, q]`` must vanish for
        ``|p // s - q // s| > 1``.
    perm : numpy.ndarray of int, shape (n,), optional
        ``N`` is processed as ``N[perm][:, perm]``; entries are still addressed by the
        original indices.
    what : str
        What the matrix is, for error messages.

    Raises
    ------
    DegenerateGeometryError
        ``N`` is not positive definite.
    ValueError
        ``N`` has entries outside the block band.
    """

    def __init__(self, N, block: int, perm: np.ndarray | None = None, *, what: str = "matrix"):
        N = sp.csr_matrix(N, dtype=float)
        n = N.shape[0]
        s = int(block)
        if s < 1:
            raise ValueError("block must be positive")
        if perm is None:
            perm = np.arange(n)
        perm = np.asarray(perm, dtype=np.int64)
        where = np.empty(n, dtype=np.int64)  # original index -> position after permutation
        where[perm] = np.arange(n)
        self.n, self.s, self._where = n, s, where
        coo = N.tocoo()
        r, c, x = where[coo.row], where[coo.col], coo.data
        diag = N.diagonal()
        if np.any(~(diag > 0)):
            raise DegenerateGeometryError(f"{what} is singular (a zero on its diagonal)")
        scale = 1.0 / np.sqrt(diag[perm])  # by permuted position
        x = x * scale[r] * scale[c]
        K = max(1, -(-n // s))
        bi, bj = r // s, c // s
        if np.any(np.abs(bi - bj) > 1):
            raise ValueError("the matrix has entries outside the block band")
        D = np.zeros((K, s, s))
        E = np.zeros((max(K - 1, 0), s, s))
        m = bi == bj
        np.add.at(D, (bi[m], r[m] % s, c[m] % s), x[m])
        m = bj == bi + 1
        np.add.at(E, (bi[m], r[m] % s, c[m] % s), x[m])
        pad = np.arange(n, K * s)  # padding: decoupled unit diagonal
        D[pad // s, pad % s, pad % s] = 1.0
        with single_threaded_blas():
            self._Zd, self._Zo = _recurrence(D, E, K, s, what)
        self._scale = scale

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``N^-1[rows, cols]`` element-wise (broadcast), for index pairs within reach.

        Raises
        ------
        ValueError
            A pair whose blocks are more than one apart (not computed).
        """
        rows, cols = np.broadcast_arrays(np.asarray(rows), np.asarray(cols))
        p, q = self._where[rows], self._where[cols]
        s = self.s
        bp, bq = p // s, q // s
        if np.any(np.abs(bp - bq) > 1):
            raise ValueError("entries requested outside the computed block band")
        out = np.empty(p.shape)
        same = bp == bq
        out[same] = self._Zd[bp[same], p[same] % s, q[same] % s]
        up = bq == bp + 1
        out[up] = self._Zo[bp[up], p[up] % s, q[up] % s]
        lo = bp == bq + 1
        out[lo] = self._Zo[bq[lo], q[lo] % s, p[lo] % s]
        return out * self._scale[p] * self._scale[q]

    def diagonal(self) -> np.ndarray:
        """``diag(N^-1)`` in the original order, shape (n,)."""
        i = np.arange(self.n)
        return self.entries(i, i)


def single_threaded_blas():
    """A context for the small block products of this module.

    It does not change the BLAS thread limit: that limit is process-wide, and changing it
    here would change other threads' BLAS (and their last bits) while they run. Users who
    want single-threaded BLAS on a loaded machine set ``OPENBLAS_NUM_THREADS=1`` (or
    threadpoolctl) for the whole process.
    """
    import contextlib

    return contextlib.nullcontext()


def _recurrence(D, E, K, s, what):
    """Block Takahashi recurrence: diagonal and upper off-diagonal blocks of the inverse."""
    Sinv = np.empty((K, s, s))
    G = np.empty((max(K - 1, 0), s, s))
    S = D[0]
    eye = np.eye(s)
    for i in range(K):
        try:
            cf = sla.cho_factor(S, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            raise DegenerateGeometryError(
                f"{what} is not positive definite (a datum defect or an undetermined unknown)"
            ) from None
        Sinv[i] = sla.cho_solve(cf, eye, check_finite=False)
        if i < K - 1:
            G[i] = Sinv[i] @ E[i]
            S = D[i + 1] - E[i].T @ G[i]
    Zd = np.empty((K, s, s))
    Zo = np.empty((max(K - 1, 0), s, s))
    Zd[K - 1] = Sinv[K - 1]
    for i in range(K - 2, -1, -1):
        Zo[i] = -G[i] @ Zd[i + 1]
        Zd[i] = Sinv[i] - Zo[i] @ G[i].T
    return Zd, Zo
