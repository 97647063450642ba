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


class GroupSelectedInverse:
    """The diagonal of ``N^-1`` of a sparse SPD matrix by a supernodal Cholesky factor over
    groups of unknowns and the block Takahashi recurrence on its filled pattern.

    The unknowns are partitioned into groups (``labels``: e.g. an image's orientation, a
    tile of a grid's nodes) that are eliminated in the order ``rank``, which should be
    fill-reducing (e.g. from the permutation of a sparse Cholesky factorisation). Chains of
    groups with the same pattern below them (fundamental supernodes) are factorised as one
    dense block column; the pattern of the rows is kept by groups. With ``L`` the factor,
    ``R`` the rows below a supernode ``k`` in its block column and
    ``Lhat = L[R, k] L[k, k]^-1``, the entries of ``Z = N^-1`` on the filled pattern follow
    from the last supernode to the first:

        Z[R, k] = -Z[R, R] Lhat
        Z[k, k] = (L[k, k] L[k, k]')^-1 - Lhat' Z[R, k]

    (``Z[R, R]`` lies on the filled pattern, as ``R`` is a clique of it). The work is that
    of the factorisation (dense products of blocks), not one triangular solve over the
    whole factor per wanted entry; the memory that of the factor and of ``Z`` on its
    pattern.

    Parameters
    ----------
    N : scipy.sparse matrix, shape (n, n)
        Symmetric positive definite (both triangles stored).
    labels : numpy.ndarray of int, shape (n,)
        The group of every unknown (integers from 0, every group used).
    rank : numpy.ndarray of int, shape (groups,)
        The place of every group in the elimination order (a permutation of the groups).
    what : str
        What the matrix is, for error messages.

    Raises
    ------
    DegenerateGeometryError
        ``N`` is not positive definite.
    """

    def __init__(self, N, labels: np.ndarray, rank: np.ndarray, *, what: str = "matrix"):
        N = sp.csc_matrix(N, dtype=float)
        n = N.shape[0]
        self.n, self.what = n, what
        self._diag = np.empty(n)
        if n == 0:
            return
        diag = N.diagonal()
        if np.any(~(diag > 0)):
            raise DegenerateGeometryError(f"{what} is singular (a zero on its diagonal)")
        coo = N.tocoo()
        low = coo.row >= coo.col
        rr, cc, xx = coo.row[low], coo.col[low], coo.data[low]
        rank = np.asarray(rank, dtype=np.int64)
        K = int(rank.size)
        grp = rank[np.asarray(labels, dtype=np.int64)]
        # supernodes: chains of the elimination tree of the groups, made consecutive
        struct = _symbolic(np.maximum(grp[rr], grp[cc]), np.minimum(grp[rr], grp[cc]), K)
        head = _supernode_heads(struct)
        order = np.lexsort((np.arange(K), head))  # groups by supernode, in order
        renum = np.empty(K, dtype=np.int64)
        renum[order] = np.arange(K)
        grp = renum[grp]
        struct = _symbolic(np.maximum(grp[rr], grp[cc]), np.minimum(grp[rr], grp[cc]), K)
        sn_of = np.unique(head[order], return_inverse=True)[1].ravel()  # group -> supernode
        # positions: unknowns grouped, groups in order
        perm = np.lexsort((np.arange(n), grp))
        where = np.empty(n, dtype=np.int64)
        where[perm] = np.arange(n)
        gstart = np.r_[0, np.cumsum(np.bincount(grp, minlength=K))]
        M = int(sn_of[-1]) + 1
        first = np.searchsorted(sn_of, np.arange(M + 1))  # groups of supernode J
        self._sn = (sn_of, gstart)
        # rows of every supernode's block column: its own unknowns, then those of the
        # groups below its last group
        rows = []
        for J in range(M):  # supernodes, not points
            below = struct[first[J + 1] - 1]
            rows.append(
                np.concatenate(
                    [np.arange(gstart[first[J]], gstart[first[J + 1]])]
                    + [np.arange(gstart[g], gstart[g + 1]) for g in below.tolist()]
                )
            )
        width = np.diff(gstart[first])
        scale = 1.0 / np.sqrt(diag)
        r, c = where[rr], where[cc]
        r, c = np.maximum(r, c), np.minimum(r, c)
        x = xx * scale[perm[r]] * scale[perm[c]]
        sn_c = sn_of[grp[perm[c]]]
        srt = np.argsort(sn_c, kind="stable")
        r, c, x, sn_c = r[srt], c[srt], x[srt], sn_c[srt]
        bounds = np.searchsorted(sn_c, np.arange(M + 1))
        cols = []
        for J in range(M):  # supernodes, not points
            a, b = bounds[J], bounds[J + 1]
            F = np.zeros((rows[J].size, width[J]))
            np.add.at(F, (np.searchsorted(rows[J], r[a:b]), c[a:b] - rows[J][0]), x[a:b])
            cols.append(F)
        with single_threaded_blas():
            self._factor(cols, rows, width)
            zd = self._takahashi(cols, rows, width)
        self._diag[perm] = zd * scale[perm] ** 2

    def _targets(self, rows_k: np.ndarray, w: int):
        """The supernodes that the rows ``rows_k`` below a block column of width ``w``
        fall in: ``(J, local start, local end)`` per supernode, the rows local to the part
        below the diagonal block."""
        sn_of, gstart = self._sn
        below = rows_k[w:]
        grp = np.searchsorted(gstart, below, side="right") - 1
        sn = sn_of[grp]
        cut = np.flatnonzero(np.diff(sn)) + 1
        starts = np.r_[0, cut]
        ends = np.r_[cut, sn.size]
        return [(int(sn[a]), int(a), int(e)) for a, e in zip(starts, ends)] if sn.size else []

    def _factor(self, cols, rows, width) -> None:
        """Right-looking supernodal Cholesky in place: every block column becomes
        ``[L_kk; L_Rk]``."""
        for k in range(len(cols)):  # supernodes, not points
            F, s = cols[k], width[k]
            try:
                Lkk = sla.cholesky(F[:s], lower=True, check_finite=False)
            except np.linalg.LinAlgError:
                raise DegenerateGeometryError(
                    f"{self.what} is not positive definite (a datum defect or an "
                    "undetermined unknown)"
                ) from None
            F[:s] = Lkk
            if F.shape[0] == s:
                continue
            F[s:] = sla.solve_triangular(Lkk, F[s:].T, lower=True, check_finite=False).T
            for J, a, e in self._targets(rows[k], s):  # supernodes below k
                tail = F[s + a :]
                upd = tail @ tail[: e - a].T
                pos = _compact(np.searchsorted(rows[J], rows[k][s + a :]))
                cpos = _compact(rows[k][s + a : s + e] - rows[J][0])
                if isinstance(cpos, slice):
                    cols[J][pos, cpos] -= upd
                else:
                    cols[J][np.ix_(pos, cpos)] -= upd

    def _takahashi(self, cols, rows, width) -> np.ndarray:
        """The block Takahashi recurrence (see the class): ``Z`` on the filled pattern, from
        the last supernode to the first; returns ``diag(Z)`` in the scaled, permuted order."""
        M = len(cols)
        out = np.empty(self.n)
        zcols = [None] * M
        for k in range(M - 1, -1, -1):  # supernodes, not points
            F, s = cols[k], width[k]
            Li = sla.solve_triangular(F[:s], np.eye(s), lower=True, check_finite=False)
            Zkk = Li.T @ Li
            if F.shape[0] > s:
                Lhat = F[s:] @ Li  # L_Rk L_kk^-1
                Y = np.zeros_like(Lhat)  # Z[R, R] Lhat
                for J, a, e in self._targets(rows[k], s):  # supernodes below k
                    pos = _compact(np.searchsorted(rows[J], rows[k][s + a :]))
                    cpos = _compact(rows[k][s + a : s + e] - rows[J][0])
                    # Z[R from J on, R in J]
                    Zj = (
                        zcols[J][pos, cpos]
                        if isinstance(cpos, slice)
                        else zcols[J][np.ix_(pos, cpos)]
                    )
                    Y[a:] += Zj @ Lhat[a:e]
                    Y[a:e] += Zj[e - a :].T @ Lhat[e:]
                Zkk += Lhat.T @ Y
                zcols[k] = np.vstack([Zkk, -Y])
            else:
                zcols[k] = Zkk
            cols[k] = None
            a0 = int(rows[k][0])
            out[a0 : a0 + s] = np.diag(Zkk)
        return out

    def diagonal(self) -> np.ndarray:
        """``diag(N^-1)`` in the original order, shape (n,)."""
        return self._diag.copy()


def _symbolic(gr: np.ndarray, gc: np.ndarray, K: int) -> list:
    """Symbolic block factorisation along the elimination tree: for every group ``k`` (in
    elimination order) the sorted groups below it in its block column of the factor, those
    coupled to it in the matrix (entries ``(gr, gc)``, ``gr >= gc``, by group) and those of
    the block columns of its children."""
    pattern = sp.csr_matrix((np.ones(gr.size, dtype=np.int8), (gc, gr)), shape=(K, K))
    pattern.sum_duplicates()  # row k: the groups coupled to k from below
    pending = [[] for _ in range(K)]
    struct = []
    for k in range(K):  # groups, not points
        own = pattern.indices[pattern.indptr[k] : pattern.indptr[k + 1]]
        s = np.unique(np.concatenate([own, *pending[k]]))
        s = s[s > k]
        struct.append(s)
        pending[k] = None
        if s.size:
            pending[int(s[0])].append(s[1:])
    return struct


def _supernode_heads(struct: list) -> np.ndarray:
    """The supernode of every group, named by its last group: chains of the elimination
    tree where a group is its parent's only child and its pattern below the parent is the
    parent's (fundamental supernodes; merging them adds no fill)."""
    K = len(struct)
    parent = np.array([int(s[0]) if s.size else -1 for s in struct], dtype=np.int64)
    children = np.bincount(parent[parent >= 0], minlength=K)
    head = np.arange(K)
    for k in range(K - 1, -1, -1):  # groups, not points
        p = int(parent[k])
        if p >= 0 and children[p] == 1 and struct[k].size == struct[p].size + 1:
            head[k] = head[p]
    return head


def _compact(idx: np.ndarray):
    """``idx`` (sorted, distinct) as a slice where it is a run of consecutive integers
    (indexing by a slice reads and writes in place of a gather and a scatter)."""
    if idx.size and int(idx[-1]) - int(idx[0]) == idx.size - 1:
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx
