"""Vectorised 3x3 linear algebra for batches of many small problems.

LAPACK through ``numpy.linalg`` costs a few microseconds *per matrix* even for a stacked
(B, 3, 3) array; the functions here work on all B matrices at once with elementwise numpy
operations on (B,) arrays (structure of arrays), in chunks that stay in the CPU cache.

* :func:`svd3` - singular value decomposition by one-sided Jacobi rotations (Hestenes):
  accurate to a few units of round-off, any rank.
"""

from __future__ import annotations

import numpy as np

#: Problems per chunk (arrays of this many doubles stay in the CPU cache).
CHUNK = 4096
#: One-sided Jacobi stops when every column pair has ``|a_p . a_q| <= tol |a_p| |a_q|``.
JACOBI_TOL = 4e-16
#: Upper bound on Jacobi sweeps (3x3 matrices need 4-6).
JACOBI_SWEEPS = 20

_PAIRS = ((0, 1), (0, 2), (1, 2))


def _svd3_chunk(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # zeta = (beta - alpha) / (2 gamma) overflows to inf for tiny gamma: the rotation is
    # then t = 0, as it should be
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        return _svd3_chunk_impl(H)


def _svd3_chunk_impl(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = [[np.ascontiguousarray(H[:, i, j]) for j in range(3)] for i in range(3)]
    B = H.shape[0]
    one, zero = np.ones(B), np.zeros(B)
    v = [[one.copy() if i == j else zero.copy() for j in range(3)] for i in range(3)]
    for _ in range(JACOBI_SWEEPS):
        rotated = False
        for p, q in _PAIRS:
            ap0, ap1, ap2 = a[0][p], a[1][p], a[2][p]
            aq0, aq1, aq2 = a[0][q], a[1][q], a[2][q]
            alpha = ap0 * ap0 + ap1 * ap1 + ap2 * ap2
            beta = aq0 * aq0 + aq1 * aq1 + aq2 * aq2
            gamma = ap0 * aq0 + ap1 * aq1 + ap2 * aq2
            need = np.abs(gamma) > JACOBI_TOL * np.sqrt(alpha * beta)
            if not need.any():
                continue
            rotated = True
            zeta = (beta - alpha) / (2.0 * np.where(need, gamma, 1.0))
            t = np.copysign(1.0, zeta) / (np.abs(zeta) + np.hypot(1.0, zeta))
            t = np.where(need, t, 0.0)
            c = 1.0 / np.sqrt(1.0 + t * t)
            s = c * t
            for M in (a, v):
                for i in range(3):
                    mp, mq = M[i][p], M[i][q]
                    M[i][p] = c * mp - s * mq
                    M[i][q] = s * mp + c * mq
        if not rotated:
            break
    S = np.stack([np.sqrt(a[0][j] ** 2 + a[1][j] ** 2 + a[2][j] ** 2) for j in range(3)], axis=1)
    A = np.stack([np.stack(row, axis=1) for row in a], axis=1)  # (B, 3, 3)
    V = np.stack([np.stack(row, axis=1) for row in v], axis=1)
    order = np.argsort(-S, axis=1)
    S = np.take_along_axis(S, order, axis=1)
    A = np.take_along_axis(A, order[:, None, :], axis=2)
    V = np.take_along_axis(V, order[:, None, :], axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        U = np.where(S[:, None, :] > 0, A / S[:, None, :], 0.0)
    # the third left singular vector from the cross product of the first two: exact
    # orthogonality even when sigma3 is at round-off level (its column of A is then noise);
    # its sign follows A's third column (either sign gives the same R = V diag(1,1,d) U.T)
    u3 = np.cross(U[:, :, 0], U[:, :, 1])
    sgn = np.where(np.einsum("bi,bi->b", u3, A[:, :, 2]) < 0, -1.0, 1.0)
    U[:, :, 2] = u3 * sgn[:, None]
    return U, S, np.swapaxes(V, 1, 2)


def svd3(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched SVD ``H = U diag(S) Vt`` of (B, 3, 3), S descending (as ``numpy.linalg.svd``).

    ``Vt`` is a product of plane rotations (det +1). The third left singular vector is the
    cross product of the first two (signed like H's third direction), so U is orthogonal even
    for rank-deficient H (for rank <= 1 the extra columns of U are zero: such problems are
    degenerate for every use here).
    """
    H = np.asarray(H, dtype=float)
    if H.shape[0] <= CHUNK:
        return _svd3_chunk(H)
    parts = [_svd3_chunk(H[i : i + CHUNK]) for i in range(0, H.shape[0], CHUNK)]
    return tuple(np.concatenate(p, axis=0) for p in zip(*parts))
