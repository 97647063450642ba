"""Normal equations of block-structured least squares, solved with the Schur complement.

The problems of this module have three kinds of unknowns:

* *local* blocks of size ``b`` (e.g. one image's exterior orientation), many of them;
* *global* parameters (e.g. the calibration of the camera groups), each local block's rows
  depending on a few of them (a *group*, one row of ``local_global``);
* *point* blocks of size 3, very many (object points), each seen by a few local blocks.

Each row group ``k`` (an observation of dimension ``d``, e.g. the two pixel coordinates of an
image point) depends on one local block ``local[k]``, the global columns
``local_global[local[k]]`` of that block and one point ``point[k]``. Given the whitened
residuals and Jacobian blocks, :class:`SchurSystem` forms the normal equations, eliminates
the points (3x3 blocks, inverted in one vectorised call), solves the sparse reduced system
(:mod:`photogeom.adjust.sparse`) and back-substitutes. Memory and work are linear in the
number of observations and in the number of pairs of observations of one point; no dense
matrix of the size of all unknowns is ever formed. With many groups (a camera group per
image) the coupling of the points with the global parameters is held per pair (point,
group observing it) and the global rows of the reduced system follow the groups that share
points; only the (local, global) and (global, global) blocks and their covariances are held
densely (memory local blocks x globals and globals squared). The global parameters of a
group that one local block alone depends on (a camera group of one image, as every image of
a BAL file has) are held as further unknowns of that local block instead (see
``own_groups`` of :class:`SchurSystem` and :mod:`photogeom.adjust.folding`, which holds that
folding and whose names this module re-exports): a block with a camera per image then has
no global parameter at all.

The covariance part gives blocks of the inverse: local and global blocks of the reduced
system (by solves with unit vectors, never a dense inverse of the whole system), the
marginal 3x3 covariance of every point ``Q_pp = V^-1 + V^-1 W' Q_cc W V^-1`` and the
cofactor of every observation's residual (redundancy numbers and data snooping).

Conventions: residuals ``r`` are whitened (divided by their standard deviation), the cost is
``r' r`` and the Gauss-Newton step solves ``(J'J + damping) dx = -J' r``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import DegenerateGeometryError
from .folding import (
    OWN_GROUPS_FRACTION,
    OWN_GROUPS_LOCAL,
    FoldedCovarianceBlocks,
    FoldedNormal,
    Folding,
    MappedFactor,
    folded_locals,
    own_group_locals,
)
from .sparse import SparseFactor, factorize

__all__ = [
    "CHUNK",
    "DENSE_GLOBAL_BYTES",
    "OWN_GROUPS_FRACTION",
    "OWN_GROUPS_LOCAL",
    "PAIR_GROUP",
    "SPARSE_GLOBAL_GROUPS",
    "CovarianceBlocks",
    "FoldedCovarianceBlocks",
    "Linearization",
    "MappedFactor",
    "SchurSystem",
    "covariance_blocks",
    "dense_coupling_bytes",
    "folded_locals",
    "invert_point_blocks",
    "observation_cofactors",
    "own_group_locals",
    "point_covariances",
    "weak_point_blocks",
]

#: Observation rows processed at once (bounds temporary memory).
CHUNK = 32768
#: Pairs of observations of one point summed by one matrix product into an off-diagonal
#: block of the reduced system (a block's pairs in groups of this many, the last padded
#: with zeros). One product per pair (a 6x3 by 3x6 product each) cost twice the time.
PAIR_GROUP = 16
#: Distinct global column sets (camera groups) from which the coupling of points with global
#: parameters is held per (point, group) instead of densely (points x 3 x globals). Below
#: it the dense form is faster (a 48-image block with 31 932 observations adjusted in
#: 1.4 s dense, 2.1 s sparse with 8 groups; 2.3 s, 2.9 s with 16; 3.6 s, 3.7 s with 32;
#: 4.0 s both with 48).
SPARSE_GLOBAL_GROUPS = 32
#: Bytes of the dense coupling (see :func:`dense_coupling_bytes`) above which it is held
#: sparse with fewer groups too.
DENSE_GLOBAL_BYTES = 512e6


def dense_coupling_bytes(n_global: int, n_rows: int, n_points: int, b: int) -> float:
    """Bytes of the largest dense arrays coupling the points with the global parameters:
    the reduction's (rows + points) x 3 x ``n_global`` or the statistics' rows x (b + 3) x
    ``n_global`` and points x 12 x ``n_global`` (8-byte floats).

    Parameters
    ----------
    n_global, n_rows, n_points, b : int
        Global parameters, observation row groups, points, size of a local block.

    Returns
    -------
    float
        Bytes.
    """
    return 8.0 * n_global * max(3 * n_rows + 9 * n_points, (b + 3) * n_rows + 12 * n_points)


def _segments(keys: np.ndarray, n_keys: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stable order by key, the start of each non-empty segment and its key."""
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    if sk.size == 0:
        return order, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    return order, starts, sk[starts]


def _chunks(starts: np.ndarray, total: int, size: int = CHUNK):
    """Ranges ``(s0, s1, seg0, seg1)`` of whole segments holding about ``size`` rows."""
    nseg = starts.size
    seg = 0
    while seg < nseg:
        lo = starts[seg]
        # last segment whose start is < lo + size (at least one segment)
        seg1 = int(np.searchsorted(starts, lo + size, side="left"))
        seg1 = max(seg1, seg + 1)
        hi = starts[seg1] if seg1 < nseg else total
        yield int(lo), int(hi), seg, seg1
        seg = seg1


def _padded_groups(
    order: np.ndarray, starts: np.ndarray, total: int, t: int = PAIR_GROUP
) -> tuple[np.ndarray, np.ndarray]:
    """Entries in segment order in groups of ``t`` that do not cross segments (each
    segment's last group padded with entry ``total``): the entry of each slot
    (n_groups * t,) and the segment of each group (n_groups,)."""
    count = np.diff(np.r_[starts, total])
    groups = -(-count // t)
    first_group = np.cumsum(groups) - groups
    seg = np.repeat(np.arange(starts.size), count)
    pos = np.arange(total) - starts[seg]
    dest = (first_group[seg] + pos // t) * t + pos % t
    slots = np.full(int(groups.sum()) * t, total, dtype=np.int64)
    slots[dest] = order
    return slots, np.repeat(np.arange(starts.size), groups)


def _grouped_products(
    left: np.ndarray,
    right: np.ndarray,
    slots_l: np.ndarray,
    slots_r: np.ndarray,
    group_seg: np.ndarray,
    n_seg: int,
    t: int = PAIR_GROUP,
) -> np.ndarray:
    """``out[s] = sum over the entries of segment s of left[i]' right[j]`` (left (k + 1, 3,
    m), right (k' + 1, 3, m'), each with a zero block last, the slot index ``k`` / ``k'`` of
    the padding: no padded copies of them), one (m, 3t) x (3t, m') product per group of
    ``t`` entries."""
    m, m2 = left.shape[2], right.shape[2]
    out = np.zeros((n_seg, m, m2))
    n_groups = group_seg.size
    per = max(1, CHUNK // t)
    for g0 in range(0, n_groups, per):  # chunks of groups: bounded temporaries
        g1 = min(n_groups, g0 + per)
        a = left[slots_l[g0 * t : g1 * t]].reshape(g1 - g0, 3 * t, m)
        c = right[slots_r[g0 * t : g1 * t]].reshape(g1 - g0, 3 * t, m2)
        prod = a.transpose(0, 2, 1) @ c
        key = group_seg[g0:g1]
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        out[key[first]] += np.add.reduceat(prod, first, axis=0)
    return out


def _segment_sum(values_fn, order, starts, keys, total, out) -> None:
    """``out[keys[s]] += sum of values over segment s``; ``values_fn(rows)`` gives the
    per-row values for observation rows ``rows`` (in segment order)."""
    for lo, hi, s0, s1 in _chunks(starts, total):
        rows = order[lo:hi]
        vals = values_fn(rows)
        red = np.add.reduceat(vals, starts[s0:s1] - lo, axis=0)
        out[keys[s0:s1]] += red


@dataclass
class Linearization:
    """Whitened residuals and Jacobian blocks of one linearisation.

    Attributes
    ----------
    r : (n, d) residual rows; A : (n, d, b) local; G : (n, d, gl) global (columns
    ``local_global[local[k]]``); P : (n, d, 3) point.
    local_info, local_grad : (n_local, b, b), (n_local, b) extra terms (priors) ``J'J``, ``J'r``
    point_info, point_grad : (n_points, 3, 3), (n_points, 3)
    global_info, global_grad : (g, g) (an array or a scipy sparse matrix), (g,)
    cost : float, ``r'r`` of all terms
    """

    r: np.ndarray
    A: np.ndarray
    G: np.ndarray
    P: np.ndarray
    local_info: np.ndarray
    local_grad: np.ndarray
    point_info: np.ndarray
    point_grad: np.ndarray
    global_info: np.ndarray
    global_grad: np.ndarray
    cost: float


class SchurSystem:
    """The structure of a block-structured problem (fixed over the iterations).

    Parameters
    ----------
    n_local, b : number and size of the local blocks.
    n_global : number of global parameters.
    n_points : number of points (blocks of 3).
    local, point : (n,) int, the local block and the point of each observation row group.
    local_global : (n_local, gl) int, the global columns each local block's rows depend on.
    local_free : (n_local, b) bool; global_free : (n_global,) bool
        Parameters that are estimated; the others keep their values (their columns are
        dropped from the normal equations).
    backend : sparse solver backend (see :mod:`photogeom.adjust.sparse`).
    global_coupling : {"auto", "dense", "sparse"}
        How the coupling of points with the global parameters is held: ``"dense"`` as
        (points, 3, n_global) arrays (memory points x globals), ``"sparse"`` per pair of a
        point and a distinct row of ``local_global`` (a camera group) of the local blocks
        observing it (memory linear in the observations times the track length),
        ``"auto"`` sparse from :data:`SPARSE_GLOBAL_GROUPS` distinct rows on or where the
        dense arrays would exceed :data:`DENSE_GLOBAL_BYTES`. The results agree to
        rounding.
    own_groups : {"auto", "local", "global"}
        Where the global parameters of a group that only one local block depends on (a
        camera group observed by one image) are held (:func:`folded_locals`): ``"local"``
        as further unknowns of that local block (all local blocks then have ``b`` plus
        one per position of a row of ``local_global`` free in any such group, held where a
        block has no group of its own or holds that parameter), eliminated
        and inverted blockwise like the others, with memory and work linear in the local
        blocks and their co-visible neighbours; ``"global"`` as global parameters (dense
        blocks of local blocks x globals and globals squared); ``"auto"`` local from
        :data:`OWN_GROUPS_LOCAL` such blocks on. The interface (the step's layout, the
        factor's :meth:`~SparseFactor.solve`, the covariance blocks) is that of the global
        form either way and the results agree to rounding.
    """

    def __init__(
        self,
        n_local: int,
        b: int,
        n_global: int,
        n_points: int,
        local: np.ndarray,
        point: np.ndarray,
        local_global: np.ndarray,
        local_free: np.ndarray,
        global_free: np.ndarray,
        *,
        backend: str = "auto",
        global_coupling: str = "auto",
        own_groups: str = "auto",
    ) -> None:
        self.n_local, self.b, self.n_global, self.n_points = n_local, b, n_global, n_points
        self.local = np.asarray(local, dtype=np.int64)
        self.point = np.asarray(point, dtype=np.int64)
        self.local_global = np.asarray(local_global, dtype=np.int64).reshape(n_local, -1)
        self.gl = self.local_global.shape[1]
        self.local_free = np.asarray(local_free, dtype=bool).reshape(n_local, b)
        self.global_free = np.asarray(global_free, dtype=bool).reshape(n_global)
        self.backend = backend
        self.n = self.local.size
        self.nc = n_local * b + n_global
        #: the system with the own groups' parameters in their local blocks and the map
        #: between the two (None: not folded; see :mod:`photogeom.adjust.folding`)
        self.inner: SchurSystem | None = None
        self.folding: Folding | None = None
        fold = folded_locals(self.local_global, n_global, own_groups)
        if np.any(fold):
            self._fold(fold, global_coupling)
            return
        self.order_pt, self.pt_starts, self.pt_keys = _segments(self.point, n_points)
        self.order_loc, self.loc_starts, self.loc_keys = _segments(self.local, n_local)
        self._pairs()
        if global_coupling not in ("auto", "dense", "sparse"):
            raise ValueError(
                f"global_coupling must be 'auto', 'dense' or 'sparse', not {global_coupling!r}"
            )
        self.sparse_global = False
        if n_global and self.gl:
            self.group_cols, grp = np.unique(self.local_global, axis=0, return_inverse=True)
            self.local_group = np.asarray(grp, dtype=np.int64).reshape(-1)
            n_grp = self.group_cols.shape[0]
            big = (
                n_grp >= SPARSE_GLOBAL_GROUPS
                or dense_coupling_bytes(n_global, self.n, n_points, b) > DENSE_GLOBAL_BYTES
            )
            self.sparse_global = global_coupling == "sparse" or (global_coupling == "auto" and big)
        self._pattern()
        self._dense_h_index = None
        if self.sparse_global:
            self._point_groups()

    # --- own groups held locally ------------------------------------------------------------

    def _fold(self, own: np.ndarray, global_coupling: str) -> None:
        """The system with the free global columns of the local blocks ``own`` (L,) as
        their local unknowns (``self.inner``) and the map between the two
        (``self.folding``, a :class:`~photogeom.adjust.folding.Folding`)."""
        f = Folding(
            self.local_global, self.n_global, self.local_free, self.global_free, self.local, own
        )
        self.folding = f
        self.inner = SchurSystem(
            self.n_local,
            f.b,
            f.global_free.size,
            self.n_points,
            self.local,
            self.point,
            f.local_global,
            f.local_free,
            f.global_free,
            backend=self.backend,
            global_coupling=global_coupling,
            own_groups="global",
        )
        inner = self.inner
        self.blocks, self.n_pairs = inner.blocks, inner.n_pairs
        self.pair_k1, self.pair_k2, self.pair_block = inner.pair_k1, inner.pair_k2, inner.pair_block
        self.sparse_global = inner.sparse_global

    # --- structure ---------------------------------------------------------------------------

    def _pairs(self) -> None:
        """Pairs of observation rows of one point in two different local blocks."""
        o = self.order_pt
        counts = np.diff(np.r_[self.pt_starts, self.n])
        seg_of = np.repeat(np.arange(counts.size), counts)
        pos = np.arange(self.n) - self.pt_starts[seg_of]
        partners = counts[seg_of] - 1 - pos
        total = int(partners.sum())
        k1s = np.repeat(np.arange(self.n), partners)
        # offsets 1..partners within each repeat group
        first = np.repeat(np.cumsum(partners) - partners, partners)
        d = np.arange(total) - first + 1
        k1 = o[k1s]
        k2 = o[k1s + d]
        l1, l2 = self.local[k1], self.local[k2]
        same = l1 == l2
        if np.any(same):
            raise DegenerateGeometryError(
                "a point is observed twice in the same local block (image): remove the "
                "duplicate observation"
            )
        swap = l1 > l2
        k1, k2 = np.where(swap, k2, k1), np.where(swap, k1, k2)
        l1, l2 = self.local[k1], self.local[k2]
        key = l1 * self.n_local + l2
        uniq, inv = np.unique(key, return_inverse=True)
        self.pair_k1, self.pair_k2 = k1, k2
        self.blocks = np.column_stack([uniq // self.n_local, uniq % self.n_local])
        self.pair_block = inv.astype(np.int64)  # index into self.blocks of each pair
        self.pair_order, self.pair_starts, self.pair_keys = _segments(inv, uniq.size)
        self.n_pairs = k1.size
        self._pair_groups()

    def _pair_groups(self) -> None:
        """The pairs of each off-diagonal block in groups of :data:`PAIR_GROUP` (the last
        padded with row ``n``, a zero row): ``_group_k1``, ``_group_k2`` (n_groups *
        PAIR_GROUP,) observation rows, ``_group_block`` (n_groups,) the block of each."""
        t = PAIR_GROUP
        nb = self.blocks.shape[0]
        po = self.pair_order
        blk = self.pair_block[po]  # block of each pair, in block order
        count = np.bincount(blk, minlength=nb)
        groups = -(-count // t)
        first_group = np.cumsum(groups) - groups
        first_pair = np.cumsum(count) - count
        pos = np.arange(self.n_pairs) - first_pair[blk]
        dest = (first_group[blk] + pos // t) * t + pos % t
        self.n_groups = int(groups.sum())
        dtype = np.int32 if self.n < np.iinfo(np.int32).max else np.int64
        self._group_k1 = np.full(self.n_groups * t, self.n, dtype=dtype)
        self._group_k2 = np.full(self.n_groups * t, self.n, dtype=dtype)
        self._group_k1[dest] = self.pair_k1[po]
        self._group_k2[dest] = self.pair_k2[po]
        self._group_block = np.repeat(np.arange(nb), groups)

    def _point_groups(self) -> None:
        """Pairs (point, camera group) of the sparse coupling of points with the global
        parameters and the index lists that combine them (all sorted by point):

        * ``pg_point``, ``pg_group`` (n_pg,): the pairs, each distinct group of a point's rows;
          ``row_pg`` (n,) the pair of each observation row;
        * ``rp_row``, ``rp_pg``: every (observation row, pair) of the same point;
        * ``pp_a``, ``pp_b``: every (pair, pair) of the same point (both orders, and each
          pair with itself).
        """
        n_grp = self.group_cols.shape[0]
        grp_row = self.local_group[self.local]
        key = self.point * n_grp + grp_row
        uniq, inv = np.unique(key, return_inverse=True)
        self.pg_point = uniq // n_grp
        self.pg_group = uniq % n_grp
        self.row_pg = np.asarray(inv, dtype=np.int64).reshape(-1)
        n_pg = uniq.size
        self.n_pg = n_pg
        self.pg_cols = self.group_cols[self.pg_group]  # (n_pg, gl)
        self.pg_order, self.pg_row_starts, self.pg_row_keys = _segments(self.row_pg, n_pg)
        npg = np.bincount(self.pg_point, minlength=self.n_points)
        first = np.cumsum(npg) - npg  # first pair of each point
        self.pg_pt_starts = first[npg > 0]
        self.pg_pt_keys = np.flatnonzero(npg > 0)

        def expand(owner_point, owners):
            cnt = npg[owner_point]
            rep = np.repeat(owners, cnt)
            start = np.repeat(np.cumsum(cnt) - cnt, cnt)
            other = first[np.repeat(owner_point, cnt)] + np.arange(rep.size) - start
            return rep, other, cnt

        # rows in point order: the (row, pair) entries of one point and of one row contiguous
        rows = self.order_pt
        self.rp_row, self.rp_pg, cnt = expand(self.point[rows], rows)
        n_rp = self.rp_row.size
        self.rp_row_starts = (np.cumsum(cnt) - cnt)[cnt > 0]
        self.rp_row_keys = rows[cnt > 0]
        pt_rp = self.point[self.rp_row]
        self.rp_pt_starts = (
            np.flatnonzero(np.r_[True, pt_rp[1:] != pt_rp[:-1]])
            if n_rp
            else (np.zeros(0, dtype=np.int64))
        )
        self.rp_pt_keys = pt_rp[self.rp_pt_starts]
        # by (local block of the row, group of the pair): the local-global blocks
        lg_key = self.local[self.rp_row] * n_grp + self.pg_group[self.rp_pg]
        self.rp_lg_order, self.rp_lg_starts, keys = _segments(lg_key, self.n_local * n_grp)
        self.rp_lg_local, self.rp_lg_group = keys // n_grp, keys % n_grp
        slots, self._lg_seg = _padded_groups(self.rp_lg_order, self.rp_lg_starts, n_rp)
        self._lg_row = np.r_[self.rp_row, self.n][slots]
        self._lg_pg = np.r_[self.rp_pg, n_pg][slots]
        # by pair: the cross cofactors of the groups with the points
        self.rp_pg_order, self.rp_pg_starts, self.rp_pg_keys = _segments(self.rp_pg, n_pg)
        # (pair, pair) of one point, contiguous by the first pair (hence by point)
        self.pp_a, self.pp_b, cnt = expand(self.pg_point, np.arange(n_pg))
        self.pp_a_starts = (np.cumsum(cnt) - cnt)[cnt > 0]
        self.pp_a_keys = np.flatnonzero(cnt > 0)
        pt_pp = self.pg_point[self.pp_a]
        self.pp_pt_starts = np.flatnonzero(np.r_[True, pt_pp[1:] != pt_pp[:-1]])
        self.pp_pt_keys = pt_pp[self.pp_pt_starts]
        gg_key = self.pg_group[self.pp_a] * n_grp + self.pg_group[self.pp_b]
        self.pp_gg_order, self.pp_gg_starts, keys = _segments(gg_key, n_grp * n_grp)
        self.pp_gg_a, self.pp_gg_b = keys // n_grp, keys % n_grp
        slots, self._gg_seg = _padded_groups(self.pp_gg_order, self.pp_gg_starts, self.pp_a.size)
        self._gg_a = np.r_[self.pp_a, n_pg][slots]
        self._gg_b = np.r_[self.pp_b, n_pg][slots]
        # entries of the reduced system in the global rows and columns: a local block with
        # the groups that observe its points (its own too), a group with the groups that
        # share a point with it (and the whole diagonal)
        b, L, g = self.b, self.n_local, self.n_global
        lk = np.r_[self.rp_lg_local, np.arange(L)]
        gk = np.r_[self.rp_lg_group, self.local_group]
        cols = self.group_cols[gk]
        pos = (lk[:, None, None] * b + np.arange(b)[None, :, None]) * g + cols[:, None, :]
        self.lg_pos = np.unique(pos.ravel())  # flat indices into (L b, g)
        ga = np.r_[self.pp_gg_a, np.arange(n_grp)]
        gb = np.r_[self.pp_gg_b, np.arange(n_grp)]
        ca, cb = self.group_cols[ga], self.group_cols[gb]
        self.gg_mask = np.zeros(g * g, dtype=bool)
        self.gg_mask[(ca[:, :, None] * g + cb[:, None, :]).ravel()] = True
        self.gg_mask[np.arange(g) * (g + 1)] = True

    def _pattern(self) -> None:
        """Index arrays of the reduced matrix in CSC order (assembled from block data); with
        the sparse coupling of the global parameters only of the local-local blocks (the
        global rows and columns follow the points, see :meth:`_point_groups`)."""
        b, L = self.b, self.n_local
        g = 0 if self.sparse_global else self.n_global
        rr, cc = np.meshgrid(np.arange(b), np.arange(b), indexing="ij")
        rows, cols = [], []
        base = np.arange(L) * b
        rows.append((base[:, None, None] + rr[None]).ravel())
        cols.append((base[:, None, None] + cc[None]).ravel())
        b1 = self.blocks[:, 0] * b
        b2 = self.blocks[:, 1] * b
        rows.append((b1[:, None, None] + rr[None]).ravel())
        cols.append((b2[:, None, None] + cc[None]).ravel())
        rows.append((b2[:, None, None] + cc[None]).ravel())  # transposed blocks
        cols.append((b1[:, None, None] + rr[None]).ravel())
        if g:
            gr, gc = np.meshgrid(np.arange(b), np.arange(g), indexing="ij")
            rows.append((base[:, None, None] + gr[None]).ravel())
            cols.append((L * b + gc[None] + 0 * base[:, None, None]).ravel())
            rows.append((L * b + gc[None] + 0 * base[:, None, None]).ravel())
            cols.append((base[:, None, None] + gr[None]).ravel())
            ggr, ggc = np.meshgrid(np.arange(g), np.arange(g), indexing="ij")
            rows.append((L * b + ggr).ravel())
            cols.append((L * b + ggc).ravel())
        rows = np.concatenate(rows)
        cols = np.concatenate(cols)
        perm = np.lexsort((rows, cols))
        self._csc_perm = perm
        self._csc_indices = rows[perm].astype(np.int32)
        self._csc_indptr = np.r_[0, np.cumsum(np.bincount(cols, minlength=self.nc))].astype(
            np.int64
        )

    def dense_h_index(self) -> np.ndarray:
        """Flat index into ``H`` (n_points, 3, n_global) of every entry of the rows' ``G_k' P_k``
        (n, gl, 3) with the dense coupling of the points with the global parameters: formed
        once (structure only), not at every iteration (a fresh array of 24 gl n bytes).

        Returns
        -------
        numpy.ndarray of int64, shape (n * gl * 3,)
        """
        if self._dense_h_index is None:
            g = self.n_global
            cols = self.local_global[self.local]  # (n, gl)
            pt3 = self.point[:, None, None] * 3 + np.arange(3)[None, None, :]
            self._dense_h_index = (pt3 * g + cols[:, :, None]).ravel().astype(np.intp, copy=False)
        return self._dense_h_index

    # --- normal equations ----------------------------------------------------------------

    def gradient(self, lin: Linearization, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``J' r`` of residual rows ``r`` (n, d) with the Jacobian blocks of ``lin``
        (those of this system's unknowns, not of its folded form), without prior terms.

        Parameters
        ----------
        lin : Linearization
            Its ``A``, ``G`` and ``P`` are used.
        r : numpy.ndarray, shape (n, d)
            Whitened residual rows (any unit; the gradient has the same).

        Returns
        -------
        tuple of numpy.ndarray
            Camera side (nc,): local blocks, then global; points (n_points, 3).
        """
        b, L, g, gl = self.b, self.n_local, self.n_global, self.gl
        gloc = np.bincount(
            (self.local[:, None] * b + np.arange(b)).ravel(),
            weights=np.einsum("ndc,nd->nc", lin.A, r).ravel(),
            minlength=L * b,
        )
        gglob = np.zeros(g)
        if g and gl:
            gglob = np.bincount(
                self.local_global[self.local].ravel(),
                weights=np.einsum("ndc,nd->nc", lin.G, r).ravel(),
                minlength=g,
            )
        gpt = np.bincount(
            (self.point[:, None] * 3 + np.arange(3)).ravel(),
            weights=np.einsum("ndc,nd->nc", lin.P, r).ravel(),
            minlength=self.n_points * 3,
        )
        return np.concatenate([gloc, gglob]), gpt.reshape(self.n_points, 3)

    def _masked(self, lin: Linearization) -> Linearization:
        """Drop the columns of fixed parameters (zero Jacobian entries)."""
        if np.all(self.local_free) and np.all(self.global_free):
            return lin
        # copies of the Jacobian blocks only where a column is fixed (a fresh array per
        # iteration); the rows' masks gathered from the local blocks' (bool, not indices)
        A = lin.A
        if not np.all(self.local_free):
            A = lin.A * self.local_free[self.local][:, None, :]
        G = lin.G
        if self.gl and not np.all(self.global_free):
            G = lin.G * self.global_free[self.local_global][self.local][:, None, :]
        lf = self.local_free
        li = lin.local_info * (lf[:, :, None] & lf[:, None, :])
        lg = lin.local_grad * lf
        gf = self.global_free
        gi = lin.global_info * np.outer(gf, gf)
        gg = lin.global_grad * gf
        return Linearization(
            lin.r, A, G, lin.P, li, lg, lin.point_info, lin.point_grad, gi, gg, lin.cost
        )

    def normal_equations(self, lin: Linearization, damping: float = 0.0) -> _Normal:
        """Form the damped normal equations and the reduced (camera) system."""
        if self.inner is not None:
            return FoldedNormal(self, lin, damping)
        if sp.issparse(lin.global_info):
            lin = Linearization(
                lin.r,
                lin.A,
                lin.G,
                lin.P,
                lin.local_info,
                lin.local_grad,
                lin.point_info,
                lin.point_grad,
                lin.global_info.toarray(),
                lin.global_grad,
                lin.cost,
            )
        lin = self._masked(lin)
        b, L, g, gl = self.b, self.n_local, self.n_global, self.gl
        A, G, P, r = lin.A, lin.G, lin.P, lin.r
        # per-local sums: U_ll, U_lg (local global columns), gradients
        U = lin.local_info.copy()
        Ulg = np.zeros((L, b, gl))
        Ugl_loc = np.zeros((L, gl, gl))
        gloc = lin.local_grad.copy()
        ggl_loc = np.zeros((L, gl))

        # one small GEMM per local block over its rows: [A G r]'[A G r], each block's rows
        # gathered by themselves (no reordered copy of all rows: a fresh array per iteration)
        ends = np.r_[self.loc_starts[1:], self.n]
        for lo, hi, key in zip(self.loc_starts.tolist(), ends.tolist(), self.loc_keys.tolist()):
            rows = self.order_loc[lo:hi]
            Bi = np.concatenate([A[rows], G[rows], r[rows][:, :, None]], axis=2)
            Bi = Bi.reshape(-1, b + gl + 1)
            Mi = Bi.T @ Bi
            U[key] += Mi[:b, :b]
            gloc[key] += Mi[:b, -1]
            if gl:
                Ulg[key] = Mi[:b, b : b + gl]
                Ugl_loc[key] = Mi[b : b + gl, b : b + gl]
                ggl_loc[key] = Mi[b : b + gl, -1]
        # global sums (scatter local global columns)
        Ugg = lin.global_info.copy()
        gglob = lin.global_grad.copy()
        if gl:
            cols = self.local_global
            idx = (cols[:, :, None] * g + cols[:, None, :]).ravel()
            Ugg += np.bincount(idx, weights=Ugl_loc.ravel(), minlength=g * g).reshape(g, g)
            gglob += np.bincount(cols.ravel(), weights=ggl_loc.ravel(), minlength=g)
        # per-point sums
        V = lin.point_info.copy()
        gpt = lin.point_grad.copy()

        PT = P.transpose(0, 2, 1)

        def per_point(rows):
            pt_ = PT[rows]
            return np.concatenate(
                [(pt_ @ P[rows]).reshape(rows.size, 9), (pt_ @ r[rows][:, :, None])[:, :, 0]],
                axis=1,
            )

        accp = np.zeros((self.n_points, 12))
        _segment_sum(per_point, self.order_pt, self.pt_starts, self.pt_keys, self.n, accp)
        V += accp[:, :9].reshape(-1, 3, 3)
        gpt += accp[:, 9:]
        # damping (Marquardt: scaled by the diagonal), fixed parameters get a unit diagonal
        dl = np.einsum("lii->li", U)
        dg = np.diag(Ugg).copy()
        dp = np.einsum("pii->pi", V)
        diag_l, diag_g, diag_p = dl.copy(), dg.copy(), dp.copy()
        if damping > 0:
            U[:, np.arange(b), np.arange(b)] += damping * np.maximum(dl, 1e-12)
            Ugg[np.arange(g), np.arange(g)] += damping * np.maximum(dg, 1e-12)
            V[:, np.arange(3), np.arange(3)] += damping * np.maximum(dp, 1e-12)
        fixed_l = ~self.local_free
        U[:, np.arange(b), np.arange(b)] += fixed_l
        Ugg[np.arange(g), np.arange(g)] += ~self.global_free
        return _Normal(self, lin, U, Ulg, Ugg, V, gloc, gglob, gpt, diag_l, diag_g, diag_p)


def weak_point_blocks(V: np.ndarray) -> np.ndarray:
    """Which 3x3 point blocks ``V`` (p, 3, 3) of normal equations are (nearly) singular:
    a determinant at most 1e-14 times the cube of the trace (the point is not determined by
    its rays: all nearly parallel, or fewer than two).

    Returns
    -------
    numpy.ndarray of bool, shape (p,)
    """
    det = np.linalg.det(V)
    scale = np.einsum("pii->p", V) ** 3
    return ~(np.abs(det) > 1e-14 * np.maximum(scale, 1e-300))


def invert_point_blocks(V: np.ndarray) -> np.ndarray:
    """Inverses of the 3x3 point blocks ``V`` (p, 3, 3) of normal equations.

    Raises
    ------
    DegenerateGeometryError
        A block is (nearly) singular (:func:`weak_point_blocks`): its point is not
        determined by its rays.
    """
    weak = weak_point_blocks(V)
    if np.any(weak):
        raise DegenerateGeometryError(
            f"{int(weak.sum())} point(s) are not determined by their rays (all rays "
            "nearly parallel or fewer than two); first point row "
            f"{int(np.flatnonzero(weak)[0])}",
        )
    return np.linalg.inv(V)


class _Normal:
    """Damped normal equations of one linearisation, reduced by the Schur complement."""

    def __init__(self, sys, lin, U, Ulg, Ugg, V, gloc, gglob, gpt, diag_l, diag_g, diag_p):
        self.sys, self.lin = sys, lin
        self.U, self.Ulg, self.Ugg, self.V = U, Ulg, Ugg, V
        self.gloc, self.gglob, self.gpt = gloc, gglob, gpt
        self.diag = (diag_l, diag_g, diag_p)
        self._factor: SparseFactor | None = None  # of the last solve (see solve_residuals)
        self.Vinv = invert_point_blocks(V)
        self._reduce()

    def _reduce(self) -> None:
        s = self.sys
        b, L, g, gl = s.b, s.n_local, s.n_global, s.gl
        A, G, P = self.lin.A, self.lin.G, self.lin.P
        Vinv = self.Vinv
        pt = s.point
        # W_k = A_k' P_k (b, 3); Y_k = W_k Vinv_j, each with a zero row n beyond the end
        # (the padding of the pair groups below: no padded copies of them), Y in chunks of
        # rows (no gathered copy of Vinv for all rows)
        n = s.n
        Wz = np.empty((n + 1, b, 3))
        Yz = np.empty((n + 1, b, 3))
        Wz[n] = Yz[n] = 0.0
        W, Y = Wz[:n], Yz[:n]
        np.matmul(A.transpose(0, 2, 1), P, out=W)
        for lo in range(0, n, CHUNK):
            hi = min(n, lo + CHUNK)
            np.matmul(W[lo:hi], Vinv[pt[lo:hi]], out=Y[lo:hi])
        self.W, self.Y = W, Y
        # H_j (3, g): sum over the point's rows of P_k' G_k in global columns; sparse: one
        # (3, gl) block Hp per pair (point, group), VHp = Vinv_j Hp
        sparse = s.sparse_global
        if sparse:
            H = VH = None
            # with a zero block n_pg beyond the end (the padding of the grouped products)
            Hpz = np.zeros((s.n_pg + 1, 3, gl))
            _segment_sum(
                lambda rows: (P[rows].transpose(0, 2, 1) @ G[rows]).reshape(rows.size, -1),
                s.pg_order,
                s.pg_row_starts,
                s.pg_row_keys,
                s.n,
                Hpz.reshape(s.n_pg + 1, 3 * gl),
            )
            Hp = Hpz[: s.n_pg]
            VHpz = np.zeros((s.n_pg + 1, 3, gl))
            VHp = VHpz[: s.n_pg]
            for lo in range(0, s.n_pg, CHUNK):  # no gathered copy of Vinv for every pair
                hi = min(s.n_pg, lo + CHUNK)
                np.matmul(Vinv[s.pg_point[lo:hi]], Hp[lo:hi], out=VHp[lo:hi])
        elif g:
            Wg = G.transpose(0, 2, 1) @ P  # (n, gl, 3)
            H = np.bincount(s.dense_h_index(), weights=Wg.ravel(), minlength=s.n_points * 3 * g)
            del Wg
            H = H.reshape(s.n_points, 3, g)
        else:
            H = np.zeros((s.n_points, 3, 0))
        if not sparse:
            Hp = VHp = None
            VH = Vinv @ H  # (p, 3, g)
        self.H, self.VH, self.Hp, self.VHp = H, VH, Hp, VHp
        # diagonal blocks U_ll - sum_k Y_k W_k' and local-global blocks - sum_k Y_k H_j,
        # one GEMM per local block over its rows (rows (k, 3) x b), each block's rows
        # gathered by themselves (no reordered copies of all rows)
        D = self.U.copy()
        LG = np.zeros((L, b, g))
        ol = s.order_loc
        dense_lg = g and not sparse
        ends = np.r_[s.loc_starts[1:], s.n]
        for lo, hi, key in zip(s.loc_starts.tolist(), ends.tolist(), s.loc_keys.tolist()):
            rows = ol[lo:hi]
            Yi = Y[rows].transpose(0, 2, 1).reshape(-1, b)
            D[key] -= Yi.T @ W[rows].transpose(0, 2, 1).reshape(-1, b)
            if dense_lg:
                LG[key] -= Yi.T @ H[pt[rows]].reshape(-1, g)
        if sparse:
            # - sum over (row k, pair e) of one point of Y_k Hp_e, by (local, group of e)
            blk = _grouped_products(
                Yz.transpose(0, 2, 1), Hpz, s._lg_row, s._lg_pg, s._lg_seg, s.rp_lg_starts.size
            )
            cols = s.group_cols[s.rp_lg_group]  # (blocks, gl)
            flat = (
                (s.rp_lg_local[:, None, None] * b + np.arange(b)[None, :, None]) * g
                + cols[:, None, :]
            ).ravel()
            LG -= np.bincount(flat, weights=blk.ravel(), minlength=L * b * g).reshape(L, b, g)
            del blk, flat
        # off-diagonal blocks: - sum over pairs Y_k1 W_k2', one (b, 3t) x (3t, b) product per
        # group of t pairs of a block (rows: the columns of Y_k, W_k; row n zero)
        nb = s.blocks.shape[0]
        off = np.zeros((nb, b * b))
        if s.n_pairs:
            t = PAIR_GROUP
            per = max(1, CHUNK // t)
            for g0 in range(0, s.n_groups, per):  # chunks of groups: bounded temporaries
                g1 = min(s.n_groups, g0 + per)
                y = Yz[s._group_k1[g0 * t : g1 * t]].transpose(0, 2, 1).reshape(g1 - g0, 3 * t, b)
                w = Wz[s._group_k2[g0 * t : g1 * t]].transpose(0, 2, 1).reshape(g1 - g0, 3 * t, b)
                prod = (y.transpose(0, 2, 1) @ w).reshape(g1 - g0, b * b)
                key = s._group_block[g0:g1]
                first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
                off[key[first]] += np.add.reduceat(prod, first, axis=0)
        off = -off
        # local-global: U_lg (scattered into the global columns)
        if g:
            cols = s.local_global
            for c in range(gl):  # gl columns, not points
                LG[np.arange(L), :, cols[:, c]] += self.Ulg[:, :, c]
            # fixed parameters: no coupling
            LG *= s.local_free[:, :, None]
            LG *= s.global_free[None, None, :]
            # global-global: U_gg - sum_j H_j' Vinv_j H_j
            if sparse:
                # over the (pair, pair) of one point, by (group, group)
                blk = _grouped_products(Hpz, VHpz, s._gg_a, s._gg_b, s._gg_seg, s.pp_gg_starts.size)
                ca, cb = s.group_cols[s.pp_gg_a], s.group_cols[s.pp_gg_b]
                flat = (ca[:, :, None] * g + cb[:, None, :]).ravel()
                hvh = np.bincount(flat, weights=blk.ravel(), minlength=g * g).reshape(g, g)
                GG = self.Ugg - hvh
                del blk, flat, hvh
            else:
                GG = self.Ugg - H.reshape(-1, g).T @ VH.reshape(-1, g)
            gf = s.global_free
            GG = np.where(np.outer(gf, gf), GG, np.diag((~gf).astype(float)))
        else:
            GG = np.zeros((0, 0))
        self.D, self.off, self.LG, self.GG = D, off, LG, GG
        # the pattern lists symmetric counterparts in the same element order (see _pattern)
        parts = [D.ravel(), off.ravel(), off.ravel()]
        if not sparse:
            parts += [LG.ravel(), LG.ravel(), GG.ravel()]
        data = np.concatenate(parts)
        self.S = sp.csc_matrix(
            (data[s._csc_perm], s._csc_indices, s._csc_indptr), shape=(s.nc, s.nc)
        )
        if sparse:  # the global rows and columns: the pattern's entries and any other non-zero
            lgv = LG.reshape(-1)[s.lg_pos]
            r_ = s.lg_pos // g
            c_ = L * b + s.lg_pos % g
            ggv = GG.reshape(-1)
            at = np.flatnonzero(s.gg_mask | (ggv != 0))
            rows = np.concatenate([r_, c_, L * b + at // g])
            cols = np.concatenate([c_, r_, L * b + at % g])
            vals = np.concatenate([lgv, lgv, ggv[at]])
            self.S = self.S + sp.csc_matrix((vals, (rows, cols)), shape=(s.nc, s.nc))

    # --- solving -------------------------------------------------------------------------

    def factor(self) -> SparseFactor:
        return factorize(
            self.S, backend=self.sys.backend, what="reduced camera system", block_size=self.sys.b
        )

    def reduced_rhs(self, grads: tuple | None = None) -> np.ndarray:
        """``-(g_c - W V^-1 g_p)`` stacked (local blocks, then global), of the
        linearisation's gradients or of ``grads``: local (n_local, b), global (n_global,),
        points (n_points, 3)."""
        s = self.sys
        L, b = s.n_local, s.b
        gloc, gglob, gpt = (self.gloc, self.gglob, self.gpt) if grads is None else grads
        Vg = (self.Vinv @ gpt[:, :, None])[:, :, 0]  # V^-1 g_p
        acc = np.zeros((L, b))
        _segment_sum(
            lambda rows: (self.W[rows] @ Vg[s.point[rows]][:, :, None])[:, :, 0],
            s.order_loc,
            s.loc_starts,
            s.loc_keys,
            s.n,
            acc,
        )
        rl = -(gloc - acc) * s.local_free
        if s.sparse_global:
            hv = (self.Hp.transpose(0, 2, 1) @ Vg[s.pg_point][:, :, None])[:, :, 0]
            hg = np.bincount(s.pg_cols.ravel(), weights=hv.ravel(), minlength=s.n_global)
        elif s.n_global:
            hg = self.H.reshape(-1, s.n_global).T @ Vg.ravel()
        else:
            hg = np.zeros(0)
        rg = -(gglob - hg) * s.global_free
        return np.concatenate([rl.ravel(), rg])

    def back_substitute(self, dc: np.ndarray, gpt: np.ndarray | None = None) -> np.ndarray:
        """Point steps ``-V^-1 (g_p + W' dc)`` (n_points, 3) for camera-side steps ``dc``
        (``g_p`` the linearisation's point gradients or ``gpt`` (n_points, 3))."""
        s = self.sys
        L, b = s.n_local, s.b
        dl = dc[: L * b].reshape(L, b)
        dg = dc[L * b :]
        acc = np.zeros((s.n_points, 3))
        _segment_sum(
            lambda rows: (dl[s.local[rows]][:, None, :] @ self.W[rows])[:, 0, :],
            s.order_pt,
            s.pt_starts,
            s.pt_keys,
            s.n,
            acc,
        )
        t = (self.gpt if gpt is None else gpt) + acc
        if s.sparse_global:
            hd = (self.Hp @ dg[s.pg_cols][:, :, None])[:, :, 0]  # (n_pg, 3)
            t[s.pg_pt_keys] += np.add.reduceat(hd, s.pg_pt_starts, axis=0)
        elif s.n_global:
            t += self.H @ dg
        return -(self.Vinv @ t[:, :, None])[:, :, 0]

    def solve(self) -> tuple[np.ndarray, np.ndarray, SparseFactor]:
        """Camera-side step (nc,), point step (n_points, 3) and the factor used (kept for
        :meth:`solve_residuals`)."""
        F = self.factor()
        self._factor = F
        dc = F.solve(self.reduced_rhs())
        return dc, self.back_substitute(dc), F

    def solve_gradient(self, gc: np.ndarray, gp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The step of the same damped system for the gradient ``gc`` (nc,), ``gp``
        (n_points, 3) in place of the linearisation's (e.g. :meth:`SchurSystem.gradient` of
        other residuals): camera side (nc,), points (n_points, 3).

        The factor of the last :meth:`solve` is used (factorised here if there was none):
        the matrix does not depend on the gradient, so a second right-hand side (a geodesic
        acceleration's) costs a solve with the factor and no reduction.
        """
        F = self._factor
        if F is None:
            F = self._factor = self.factor()
        s = self.sys
        gc = np.asarray(gc, dtype=float)
        gp = np.asarray(gp, dtype=float).reshape(s.n_points, 3)
        grads = (gc[: s.n_local * s.b].reshape(s.n_local, s.b), gc[s.n_local * s.b :], gp)
        dc = F.solve(self.reduced_rhs(grads))
        return dc, self.back_substitute(dc, gp)

    def drop_reduction(self) -> None:
        """Free what :meth:`solve_gradient` with the kept factor does not need: the reduced
        matrix and its blocks, ``Y``, the linearisation (its masked Jacobian blocks);
        :meth:`predicted_decrease` and :meth:`damping_diagonal` still work."""
        if self._factor is None:
            self._factor = self.factor()
        self.S = self.D = self.off = self.LG = self.GG = None
        self.U = self.Ulg = self.Ugg = self.V = None
        self.Y = self.VH = self.VHp = self.lin = None

    def damping_diagonal(self) -> np.ndarray:
        """The diagonal the damping is scaled by (that of ``J'J`` with the prior terms,
        at least 1e-12; zero for fixed parameters), camera side then points (nc + 3
        n_points,): the metric of steps that :meth:`predicted_decrease` uses."""
        s = self.sys
        diag = np.concatenate([np.maximum(d, 1e-12).ravel() for d in self.diag])
        free = np.concatenate(
            [s.local_free.ravel(), s.global_free, np.ones(self.diag[2].size, dtype=bool)]
        )
        return diag * free

    def predicted_decrease(self, dc: np.ndarray, dp: np.ndarray, damping: float) -> float:
        """``-2 g'dx - dx' N dx`` of the undamped model, from the damped solution."""
        g = np.concatenate([self.gloc.ravel(), self.gglob, self.gpt.ravel()])
        dx = np.concatenate([dc, dp.ravel()])
        return float(-(g @ dx) + damping * np.sum(self.damping_diagonal() * dx * dx))


@dataclass
class CovarianceBlocks:
    """Blocks of ``Q_cc`` (the inverse of the reduced system) needed for statistics.

    ``local`` (n_local, b, b): diagonal blocks; ``pairs`` (n_blocks, b, b): blocks of the
    pairs of local blocks that share a point (``Q[l1, l2]`` with ``l1 < l2`` as in
    ``SchurSystem.blocks``); ``local_global`` (n_local, b, g); ``global_`` (g, g).
    Entries of fixed parameters are zero.
    """

    local: np.ndarray
    pairs: np.ndarray | None
    local_global: np.ndarray
    global_: np.ndarray

    def global_block(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``Q`` of global parameters ``rows`` (k1,) by ``cols`` (k2,): (k1, k2)."""
        return self.global_[np.ix_(rows, cols)]

    def local_global_block(self, local: int, cols: np.ndarray) -> np.ndarray:
        """``Q`` of local block ``local`` by global parameters ``cols`` (k,): (b, k)."""
        return self.local_global[local][:, cols]


def covariance_blocks(
    normal: _Normal, factor: SparseFactor, *, pairs: bool, batch_columns: int = 512
) -> CovarianceBlocks | FoldedCovarianceBlocks:
    """Blocks of the inverse of the reduced system by solves with unit vectors in batches
    (memory ``nc * batch_columns``)."""
    if isinstance(normal, FoldedNormal):
        inner = covariance_blocks(
            normal.inner, factor.inner, pairs=pairs, batch_columns=batch_columns
        )
        return FoldedCovarianceBlocks(inner, normal.sys)
    s = normal.sys
    b, L, g = s.b, s.n_local, s.n_global
    Ql = np.zeros((L, b, b))
    Qlg = np.zeros((L, b, g))
    Qp = np.zeros((s.blocks.shape[0], b, b)) if pairs else None
    per = max(1, batch_columns // b)
    from .sparse import DENSE_INVERSE_MAX

    if s.nc <= DENSE_INVERSE_MAX and factor.backend != "cg":
        Qd = factor.dense_inverse()
        per = L  # one "batch": all columns at once from the dense inverse
    else:
        Qd = None
    for l0 in range(0, L, per):
        l1 = min(L, l0 + per)
        ncol = (l1 - l0) * b
        if Qd is not None:
            X = Qd[:, l0 * b : l1 * b]
        else:
            E = np.zeros((s.nc, ncol))
            E[np.arange(l0 * b, l1 * b), np.arange(ncol)] = 1.0
            X = factor.solve(E)  # columns: Q[:, local l0..l1]
        Xr = X[: L * b].reshape(L, b, l1 - l0, b)
        idx = np.arange(l1 - l0)
        Ql[l0:l1] = Xr[l0 + idx, :, idx, :]
        if g:
            Qlg[l0:l1] = X[L * b :].reshape(g, l1 - l0, b).transpose(1, 2, 0)
        if pairs and s.blocks.shape[0]:
            sel = np.flatnonzero((s.blocks[:, 0] >= l0) & (s.blocks[:, 0] < l1))
            if sel.size:
                lo_, hi_ = s.blocks[sel, 0], s.blocks[sel, 1]
                # Q[hi, lo] rows hi, columns lo -> Q[lo, hi] = its transpose
                blk = Xr[hi_, :, lo_ - l0, :]  # (k, b(rows of hi), b(cols of lo))
                Qp[sel] = blk.transpose(0, 2, 1)
    if g:
        if Qd is not None:
            Qgg = Qd[L * b :, L * b :].copy()
        else:
            E = np.zeros((s.nc, g))
            E[L * b + np.arange(g), np.arange(g)] = 1.0
            Qgg = factor.solve(E)[L * b :]
        Qgg = 0.5 * (Qgg + Qgg.T)
    else:
        Qgg = np.zeros((0, 0))
    lf = s.local_free
    Ql *= lf[:, :, None] & lf[:, None, :]
    Qlg *= lf[:, :, None]
    if g:
        gf = s.global_free
        Qlg *= gf[None, None, :]
        Qgg *= np.outer(gf, gf)
    if Qp is not None:
        Qp *= lf[s.blocks[:, 0]][:, :, None] & lf[s.blocks[:, 1]][:, None, :]
    return CovarianceBlocks(Ql, Qp, Qlg, Qgg)


def _local_global_cols(Qlg: np.ndarray, local: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``Qlg[local[i]][:, cols[i]]`` (k, b, gl) of the local-global blocks (L, b, g)."""
    b = Qlg.shape[1]
    return Qlg[local[:, None, None], np.arange(b)[None, :, None], cols[:, None, :]]


def point_covariances(normal: _Normal, Q: CovarianceBlocks) -> np.ndarray:
    """Marginal cofactor of every point (n_points, 3, 3):
    ``V^-1 + V^-1 W' Q_cc W V^-1`` (needs ``Q.pairs``)."""
    if isinstance(normal, FoldedNormal):
        return point_covariances(normal.inner, Q.inner)
    s = normal.sys
    Y, Vinv, VH = normal.Y, normal.Vinv, normal.VH
    out = Vinv.copy()
    acc = np.zeros((s.n_points, 9))
    loc = s.local

    def self_terms(rows):
        y = Y[rows]
        yt = y.transpose(0, 2, 1)
        t = yt @ Q.local[loc[rows]] @ y
        if s.n_global and not s.sparse_global:
            c = yt @ Q.local_global[loc[rows]] @ VH[s.point[rows]].transpose(0, 2, 1)
            t += c + c.transpose(0, 2, 1)
        return t.reshape(rows.size, 9)

    _segment_sum(self_terms, s.order_pt, s.pt_starts, s.pt_keys, s.n, acc)
    if s.sparse_global:
        VHp = normal.VHp

        def global_terms(rows):  # rows: (observation row, pair) of one point
            k, e = s.rp_row[rows], s.rp_pg[rows]
            c = (
                Y[k].transpose(0, 2, 1)
                @ _local_global_cols(Q.local_global, loc[k], s.pg_cols[e])
                @ VHp[e].transpose(0, 2, 1)
            )
            return (c + c.transpose(0, 2, 1)).reshape(rows.size, 9)

        n_rp = s.rp_row.size
        _segment_sum(global_terms, np.arange(n_rp), s.rp_pt_starts, s.rp_pt_keys, n_rp, acc)

        def global_global(rows):  # rows: (pair, pair) of one point
            a, b_ = s.pp_a[rows], s.pp_b[rows]
            qgg = Q.global_[s.pg_cols[a][:, :, None], s.pg_cols[b_][:, None, :]]
            return (VHp[a] @ qgg @ VHp[b_].transpose(0, 2, 1)).reshape(rows.size, 9)

        n_pp = s.pp_a.size
        _segment_sum(global_global, np.arange(n_pp), s.pp_pt_starts, s.pp_pt_keys, n_pp, acc)
    if s.n_pairs:
        k1, k2 = s.pair_k1, s.pair_k2
        blk_of_pair = s.pair_block
        pp = s.point[k1]
        order, starts, keys = _segments(pp, s.n_points)

        def pair_terms(rows):
            a = Y[k1[rows]].transpose(0, 2, 1) @ Q.pairs[blk_of_pair[rows]] @ Y[k2[rows]]
            return (a + a.transpose(0, 2, 1)).reshape(rows.size, 9)

        _segment_sum(pair_terms, order, starts, keys, s.n_pairs, acc)
    out += acc.reshape(-1, 3, 3)
    if s.n_global and not s.sparse_global:
        out += VH @ Q.global_ @ VH.transpose(0, 2, 1)
    return 0.5 * (out + out.transpose(0, 2, 1))


def observation_cofactors(normal: _Normal, Q: CovarianceBlocks, Qpp: np.ndarray) -> np.ndarray:
    """Cofactor ``J Q J'`` of the adjusted value of every observation row group (n, d, d)
    (whitened; the residual cofactor is ``I - J Q J'``)."""
    if isinstance(normal, FoldedNormal):
        return observation_cofactors(normal.inner, Q.inner, Qpp)
    s = normal.sys
    A, G, P = normal.lin.A, normal.lin.G, normal.lin.P
    Y, VH = normal.Y, normal.VH
    loc, pt = s.local, s.point
    n = s.n
    # cross cofactor camera-side (local b + global g) x point for each row: Q_{c,p_j}
    # Q_{l,p_j} = -(sum_k' Q_{l,l(k')} Y_k' + Q_{l,g} VH_j)
    Qlp = np.empty(Y.shape)  # own term k' = k, in chunks of rows (no Q.local for every row)
    for lo in range(0, n, CHUNK):
        hi = min(n, lo + CHUNK)
        np.negative(Q.local[loc[lo:hi]] @ Y[lo:hi], out=Qlp[lo:hi])
    if s.sparse_global:
        VHp = normal.VHp
        n_rp = s.rp_row.size

        def local_global(rows):  # rows: (observation row, pair) of one row
            k, e = s.rp_row[rows], s.rp_pg[rows]
            q = _local_global_cols(Q.local_global, loc[k], s.pg_cols[e])
            return (q @ VHp[e].transpose(0, 2, 1)).reshape(rows.size, -1)

        acc = np.zeros((n, Qlp.shape[1] * 3))
        _segment_sum(local_global, np.arange(n_rp), s.rp_row_starts, s.rp_row_keys, n_rp, acc)
        Qlp -= acc.reshape(Qlp.shape)
        del acc
    elif s.n_global:
        Qlp -= Q.local_global[loc] @ VH[pt].transpose(0, 2, 1)
    if s.n_pairs:
        k1, k2 = s.pair_k1, s.pair_k2
        blk_of_pair = s.pair_block
        # row k1 needs Q[l1, l2] Y_k2; row k2 needs Q[l2, l1] Y_k1 = Q[l1, l2]' Y_k1
        for lo in range(0, s.n_pairs, CHUNK):
            hi = min(s.n_pairs, lo + CHUNK)
            q = Q.pairs[blk_of_pair[lo:hi]]
            a = q @ Y[k2[lo:hi]]
            c = q.transpose(0, 2, 1) @ Y[k1[lo:hi]]
            np.subtract.at(Qlp, k1[lo:hi], a)
            np.subtract.at(Qlp, k2[lo:hi], c)
    if s.sparse_global:
        # Q_{g,p_j} in the columns of each pair (point j, group):
        # -(sum_k' Q_{g,l(k')} Y_k' + sum over the point's pairs e' of Q_{g,g(e')} VHp_e')
        gl = s.gl
        Qgp = np.zeros((s.n_pg, gl * 3))

        def rows_term(rows):  # rows: (observation row, pair), by pair
            k, e = s.rp_row[rows], s.rp_pg[rows]
            q = _local_global_cols(Q.local_global, loc[k], s.pg_cols[e])
            return (q.transpose(0, 2, 1) @ Y[k]).reshape(rows.size, -1)

        _segment_sum(rows_term, s.rp_pg_order, s.rp_pg_starts, s.rp_pg_keys, s.rp_row.size, Qgp)

        def pairs_term(rows):  # rows: (pair, pair), by the first
            a, b_ = s.pp_a[rows], s.pp_b[rows]
            qgg = Q.global_[s.pg_cols[a][:, :, None], s.pg_cols[b_][:, None, :]]
            return (qgg @ VHp[b_].transpose(0, 2, 1)).reshape(rows.size, -1)

        n_pp = s.pp_a.size
        _segment_sum(pairs_term, np.arange(n_pp), s.pp_a_starts, s.pp_a_keys, n_pp, Qgp)
        Qgp = -Qgp.reshape(s.n_pg, gl, 3)
    elif s.n_global:
        # Q_{g,p_j} = -(sum_k' Q_{g,l(k')} Y_k' + Q_gg VH_j) per point
        Qgp = -(Q.global_ @ VH.transpose(0, 2, 1))
        accg = np.zeros((s.n_points, s.n_global * 3))
        _segment_sum(
            lambda rows: (Q.local_global[loc[rows]].transpose(0, 2, 1) @ Y[rows]).reshape(
                rows.size, -1
            ),
            s.order_pt,
            s.pt_starts,
            s.pt_keys,
            n,
            accg,
        )
        Qgp -= accg.reshape(s.n_points, s.n_global, 3)
    d = A.shape[1]
    out = np.empty((n, d, d))
    for lo in range(0, n, CHUNK):  # chunks of rows: bounded temporaries
        r = slice(lo, min(n, lo + CHUNK))
        a, p_, lr, pr = A[r], P[r], loc[r], pt[r]
        at, pt_ = a.transpose(0, 2, 1), p_.transpose(0, 2, 1)
        o = a @ Q.local[lr] @ at
        o += p_ @ Qpp[pr] @ pt_
        c = a @ Qlp[r] @ pt_
        o += c + c.transpose(0, 2, 1)
        if s.n_global:
            g_ = G[r]
            gt = g_.transpose(0, 2, 1)
            cols = s.local_global[lr]  # (k, gl)
            o += g_ @ Q.global_[cols[:, :, None], cols[:, None, :]] @ gt
            c = a @ _local_global_cols(Q.local_global, lr, cols) @ gt
            o += c + c.transpose(0, 2, 1)
            if s.sparse_global:
                c = g_ @ Qgp[s.row_pg[r]] @ pt_
            else:
                c = g_ @ np.take_along_axis(Qgp[pr], cols[:, :, None], axis=1) @ pt_
            o += c + c.transpose(0, 2, 1)
        out[r] = o
    return out
