"""Camera groups of one image held in that image's unknowns: the *folding* of a
:class:`~photogeom.adjust.schur.SchurSystem`.

A group of global parameters that only one local block's rows depend on (a camera group
observed by one image, as every image of a BAL file has) need not be global: held as further
unknowns of that local block it is eliminated and inverted blockwise with it, and a block
with a camera group per image has no global parameter at all (memory and work linear in the
local blocks and their co-visible neighbours instead of the square of the groups).

This module holds the decision (:func:`own_group_locals`, :func:`folded_locals`), the map
between the unknowns of the two forms (:class:`Folding`: the *unfolded* system, whose
unknowns are local blocks of ``b`` and the global parameters, and the *folded* one, whose
local blocks have ``b`` plus the own groups' free parameters), and the views of the folded
system in the unfolded one's unknowns: the normal equations (:class:`FoldedNormal`), the
factor (:class:`MappedFactor`) and the covariance blocks
(:class:`FoldedCovarianceBlocks`). The results are those of the global form to rounding.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    from .schur import CovarianceBlocks, Linearization, SchurSystem
    from .sparse import SparseFactor

#: Local blocks with a group of global parameters of their own (no other local block's rows
#: depend on its columns: a camera group observed by one image only) from which those
#: parameters are folded into their local blocks (see :func:`folded_locals`), or this
#: fraction of the local blocks. Folded, a block with a camera group per image (BAL, free
#: network, statistics included) adjusts in 0.21 s of CPU time instead of 0.49 s with 8
#: images, 0.36 s instead of 1.11 s with 16, 0.82 s instead of 2.73 s with 40; every local
#: block then has the groups' free unknowns, held where it has no group of its own, which a
#: few own groups among many shared do not repay: 500 FC6310 images, those without a group
#: of their own sharing one (3 iterations with statistics, CPU), folded / global 21.6 s /
#: 8.0 s with 32 own groups, 22.2 / 11.7 s with 100, 24.1 / 19.6 s with 175, 21.6 / 26.4 s
#: with 250 (the global form's dense calibration blocks grow with the square of the own
#: groups, the folded form's held unknowns with the images).
OWN_GROUPS_LOCAL = 200
OWN_GROUPS_FRACTION = 0.5
#: Entries of the dense block of the local blocks by the own groups' parameters (local
#: blocks x own parameters) from which those are folded however few they are: the global
#: form's blocks of them would need 0.8 GB and more at 6 unknowns a local block, several
#: times that with their accumulation and covariances.
OWN_GROUPS_DENSE_ENTRIES = 2**24


def own_group_locals(local_global: np.ndarray, n_global: int) -> np.ndarray:
    """Which local blocks' global columns belong to them alone: no other local block's
    rows depend on any of them and each occurs once in the block's row of
    ``local_global`` (a camera group observed by one image only).

    Parameters
    ----------
    local_global : numpy.ndarray of int, shape (n_local, gl)
        The global columns each local block's rows depend on.
    n_global : int
        Global parameters.

    Returns
    -------
    numpy.ndarray of bool, shape (n_local,)
    """
    lg = np.asarray(local_global, dtype=np.int64)
    if lg.ndim != 2 or lg.shape[1] == 0 or n_global == 0:
        return np.zeros(lg.shape[0] if lg.ndim else 0, dtype=bool)
    count = np.bincount(lg.ravel(), minlength=n_global)
    return np.all(count[lg] == 1, axis=1)


def folded_locals(local_global: np.ndarray, n_global: int, own_groups: str = "auto") -> np.ndarray:
    """The local blocks whose own global parameters (:func:`own_group_locals`) a
    :class:`~photogeom.adjust.schur.SchurSystem` with ``own_groups`` holds in their local block.

    ``"local"``: every such block; ``"global"``: none; ``"auto"``: every such block from
    :data:`OWN_GROUPS_LOCAL` of them on, or from :data:`OWN_GROUPS_FRACTION` of the local
    blocks, or where the local blocks times the own parameters reach
    :data:`OWN_GROUPS_DENSE_ENTRIES` (a block with a camera per image, as BAL files give:
    its calibrations, which would be global parameters growing with the square of the
    images, become the images' own unknowns, eliminated like their orientations).

    Returns
    -------
    numpy.ndarray of bool, shape (n_local,)
    """
    if own_groups not in ("auto", "local", "global"):
        raise ValueError(f"own_groups must be 'auto', 'local' or 'global', not {own_groups!r}")
    own = own_group_locals(local_global, n_global)
    k = int(own.sum())
    lg = np.asarray(local_global)
    dense = own.size * k * (lg.shape[1] if lg.ndim == 2 else 0)  # Python ints
    few = (
        k < OWN_GROUPS_LOCAL
        and k < OWN_GROUPS_FRACTION * own.size
        and dense < OWN_GROUPS_DENSE_ENTRIES
    )
    if own_groups == "global" or (own_groups == "auto" and few):
        own[:] = False
    return own


class Folding:
    """The map between the unknowns of a system with own groups held as global parameters
    (the *unfolded* one: ``n_local`` local blocks of ``b``, ``n_global`` globals) and the
    system with them in their local blocks (the *folded* one).

    The positions in the rows of ``local_global`` held in every own group (a camera
    group's fixed parameters) are left out of the folded system (their steps and
    covariances are zero); the others are unknowns ``b, b + 1, ...`` of every local block,
    held where the block has no group of its own or holds that parameter. The blocks
    without an own group keep the shared columns as globals; the folded ones depend on a
    held dummy global column (zero derivatives), so that every row has ``gl`` of them.
    Held global columns that no local block depends on (a camera group without images)
    are left out of the folded system too: as globals of a folded system with no shared
    group they would be coupled densely with every point (points x 3 x those columns, 2.3
    GB more for 10 such groups beside a 500-image block with a camera per image).

    Parameters
    ----------
    local_global : numpy.ndarray of int, shape (n_local, gl)
        The unfolded system's global columns of each local block.
    n_global : int
        The unfolded system's global parameters.
    local_free : numpy.ndarray of bool, shape (n_local, b)
    global_free : numpy.ndarray of bool, shape (n_global,)
        The unfolded system's estimated parameters.
    local : numpy.ndarray of int, shape (n,)
        The local block of each observation row group.
    own : numpy.ndarray of bool, shape (n_local,)
        The local blocks whose own groups are folded (:func:`folded_locals`).

    Attributes
    ----------
    b : int
        Size of the folded local blocks (``b`` plus the kept positions ``keep``).
    local_global, local_free, global_free : numpy.ndarray
        The folded system's structure (``local_global`` (n_local, gl) or (n_local, 0)
        where every local block is folded).
    col_local, col_pos : numpy.ndarray of int, shape (n_global,)
        The local block holding each unfolded global column (-1: shared) and its position
        among the kept ones (-1: left out of the folded system).
    sh_idx : numpy.ndarray of int, shape (n_global,)
        The folded global column of each shared column (-1: own, or held and no local
        block depends on it: left out).
    index : numpy.ndarray of int, shape (n_local * b + n_global,)
        The index in the folded system of every unfolded unknown (local blocks, then
        globals); ``n_folded`` (a zero beyond its end) for the ones left out.
    """

    def __init__(
        self,
        local_global: np.ndarray,
        n_global: int,
        local_free: np.ndarray,
        global_free: np.ndarray,
        local: np.ndarray,
        own: np.ndarray,
    ) -> None:
        L, b = local_free.shape
        g, gl = n_global, local_global.shape[1]
        self.n_local, self.b_unfolded = L, b
        self.own = own
        self.own_row = own[local]
        self._global_free = global_free
        own_l = np.flatnonzero(own)
        own_cols = local_global[own_l]  # (n_own, gl)
        keep = np.flatnonzero(global_free[own_cols].any(axis=0))  # positions in a row
        b2 = b + keep.size
        slot = np.full(gl, -1, dtype=np.int64)
        slot[keep] = np.arange(keep.size)
        col_local = np.full(g, -1, dtype=np.int64)
        col_pos = np.full(g, -1, dtype=np.int64)  # -1: held in every own group, left out
        col_local[own_cols] = own_l[:, None]
        col_pos[own_cols] = slot[None, :]
        used = np.zeros(g, dtype=bool)
        used[local_global.ravel()] = True
        shared = np.flatnonzero((col_local < 0) & (used | global_free))
        sh_idx = np.full(g, -1, dtype=np.int64)
        sh_idx[shared] = np.arange(shared.size)
        others = ~own
        if np.any(others):
            dummy = shared.size
            lg2 = np.full((L, gl), dummy, dtype=np.int64)
            lg2[others] = sh_idx[local_global[others]]
            gf2 = np.r_[global_free[shared], False]
        else:
            lg2 = np.zeros((L, 0), dtype=np.int64)
            gf2 = global_free[shared]
        lf2 = np.zeros((L, b2), dtype=bool)
        lf2[:, :b] = local_free
        lf2[own_l, b:] = global_free[own_cols[:, keep]]
        self.keep, self.b = keep, b2
        self.local_global, self.local_free, self.global_free = lg2, lf2, gf2
        self.col_local, self.col_pos = col_local, col_pos
        self.shared, self.sh_idx = shared, sh_idx
        self.n_folded = L * b2 + gf2.size
        loc_idx = (np.arange(L)[:, None] * b2 + np.arange(b)[None, :]).ravel()
        glob_idx = np.where(
            col_local >= 0,
            np.where(col_pos >= 0, col_local * b2 + b + col_pos, self.n_folded),
            np.where(sh_idx >= 0, L * b2 + sh_idx, self.n_folded),
        )
        self.index = np.r_[loc_idx, glob_idx]

    def to_inner(self, x: np.ndarray) -> np.ndarray:
        """A vector (nc,) or columns (nc, k) of the unfolded system's unknowns in the folded
        system's order (its held extra unknowns zero)."""
        x = np.asarray(x, dtype=float)
        out = np.zeros((self.n_folded + 1, *x.shape[1:]))
        out[self.index] = x
        return out[:-1]

    def from_inner(self, x: np.ndarray) -> np.ndarray:
        """A vector (n_folded,) or columns (n_folded, k) of the folded system in the
        unfolded system's unknowns (those left out of it zero)."""
        x = np.asarray(x, dtype=float)
        return np.concatenate([x, np.zeros((1, *x.shape[1:]))])[self.index]

    def linearization(self, lin: Linearization) -> Linearization:
        """The linearisation in the folded system's unknowns: the own groups' derivatives
        and prior terms in their local blocks, the shared ones global."""
        L, b = self.n_local, self.b_unfolded
        keep = self.keep
        b2 = self.b
        n_global2 = self.global_free.size
        own_row = self.own_row
        n, d = lin.r.shape
        A = np.empty((n, d, b2))
        A[:, :, :b] = lin.A
        A[:, :, b:] = lin.G[:, :, keep] * own_row[:, None, None]
        if self.local_global.shape[1]:
            G = lin.G * ~own_row[:, None, None]
        else:
            G = np.zeros((n, d, 0))
        li = np.zeros((L, b2, b2))
        li[:, :b, :b] = lin.local_info
        lgr = np.zeros((L, b2))
        lgr[:, :b] = lin.local_grad
        cl, cp, sh = self.col_local, self.col_pos, self.sh_idx
        own_c = cl >= 0
        kept = cp >= 0  # the own columns in the folded system (the others held everywhere)
        sh_c = sh >= 0  # the shared columns in it (held ones without rows left out)
        gg = np.asarray(lin.global_grad, dtype=float)
        np.add.at(lgr, (cl[kept], b + cp[kept]), gg[kept])
        gg2 = np.zeros(n_global2)
        gg2[sh[sh_c]] = gg[sh_c]
        gi = sp.coo_matrix(lin.global_info)
        i, j, v = gi.row, gi.col, gi.data
        both_own = own_c[i] & own_c[j] & (cl[i] == cl[j])
        both_sh = ~own_c[i] & ~own_c[j]
        gf = self._global_free
        cross = ~(both_own | both_sh) & (v != 0) & gf[i] & gf[j]
        if np.any(cross):
            raise ValueError(
                "global_info couples the global parameters of a group that one local block "
                "alone depends on with other global parameters: pass own_groups='global'"
            )
        both_own &= kept[i] & kept[j]
        both_sh &= sh_c[i] & sh_c[j]
        np.add.at(li, (cl[i[both_own]], b + cp[i[both_own]], b + cp[j[both_own]]), v[both_own])
        gi2 = np.zeros((n_global2, n_global2))
        np.add.at(gi2, (sh[i[both_sh]], sh[j[both_sh]]), v[both_sh])
        return dataclasses.replace(
            lin, A=A, G=G, local_info=li, local_grad=lgr, global_info=gi2, global_grad=gg2
        )


class FoldedNormal:
    """Normal equations of a :class:`SchurSystem` whose own groups are held in their local
    blocks: those of the folded system (``inner``), with steps, right-hand sides and the
    factor in the unfolded system's unknowns."""

    def __init__(self, sys: SchurSystem, lin: Linearization, damping: float) -> None:
        self.sys, self.lin = sys, lin
        self.inner = sys.inner.normal_equations(sys.folding.linearization(lin), damping=damping)
        self.S = self.inner.S

    def factor(self) -> MappedFactor:
        return MappedFactor(self.inner.factor(), self.sys)

    def reduced_rhs(self) -> np.ndarray:
        return self.sys.folding.from_inner(self.inner.reduced_rhs())

    def back_substitute(self, dc: np.ndarray) -> np.ndarray:
        return self.inner.back_substitute(self.sys.folding.to_inner(dc))

    def solve(self) -> tuple[np.ndarray, np.ndarray, MappedFactor]:
        dc, dp, F = self.inner.solve()
        return self.sys.folding.from_inner(dc), dp, MappedFactor(F, self.sys)

    def solve_gradient(self, gc: np.ndarray, gp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The step of the same damped system for the gradient ``gc`` (nc,), in the unfolded
        system's unknowns, and ``gp`` (n_points, 3) with the factor of the last
        :meth:`solve` (no second reduction or factorisation): camera side (nc,), points
        (n_points, 3)."""
        dc, dp = self.inner.solve_gradient(self.sys.folding.to_inner(gc), gp)
        return self.sys.folding.from_inner(dc), dp

    def drop_reduction(self) -> None:
        """Free what :meth:`solve_gradient` does not need: the folded system's reduced
        matrix, its blocks and its linearisation (the factor is kept)."""
        self.inner.drop_reduction()
        self.S = None

    def damping_diagonal(self) -> np.ndarray:
        """The diagonal the damping is scaled by, camera side in the unfolded system's
        unknowns (zero for those left out of the folded one), then points (nc + 3
        n_points,)."""
        d = self.inner.damping_diagonal()
        nc = self.sys.inner.nc
        return np.concatenate([self.sys.folding.from_inner(d[:nc]), d[nc:]])

    def predicted_decrease(self, dc: np.ndarray, dp: np.ndarray, damping: float) -> float:
        return self.inner.predicted_decrease(self.sys.folding.to_inner(dc), dp, damping)


class MappedFactor:
    """The factor of a folded reduced system (:attr:`SchurSystem.inner`) seen in the
    unknowns of the unfolded one (``sys``): the folded system's extra unknowns are held (a
    unit diagonal, no coupling) and the unfolded one's left out of it are held too, so that
    solving with them zero is solving the unfolded system."""

    def __init__(self, factor: SparseFactor, sys: SchurSystem) -> None:
        self.inner, self.sys = factor, sys
        self.n = sys.nc
        self.backend, self.what = factor.backend, factor.what

    def _in(self, b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        if b.shape[0] != self.n:
            raise ValueError(f"{self.what}: the right side has {b.shape[0]} rows, not {self.n}")
        return self.sys.folding.to_inner(b)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``N^-1 b`` for ``b`` of shape (n,) or (n, k)."""
        return self.sys.folding.from_inner(self.inner.solve(self._in(b)))

    def inverse_gram(self, B, batch_bytes: int = 64 * 2**20) -> np.ndarray:
        """``B' N^-1 B`` (k, k) for ``B`` of shape (n, k), dense or sparse."""
        B = sp.csr_matrix(B, dtype=float)
        if B.shape[0] != self.n:
            raise ValueError(f"{self.what}: B has {B.shape[0]} rows, the matrix {self.n}")
        idx = self.sys.folding.index
        inside = idx < self.inner.n
        E = sp.csr_matrix(
            (np.ones(int(inside.sum())), (idx[inside], np.flatnonzero(inside))),
            shape=(self.inner.n, self.n),
        )
        return self.inner.inverse_gram(E @ B, batch_bytes=batch_bytes)

    def inverse_diagonal(self, idx=None, batch_bytes: int = 64 * 2**20) -> np.ndarray:
        """Entries ``idx`` (default: all) of the diagonal of ``N^-1``."""
        idx = np.arange(self.n) if idx is None else np.asarray(idx, dtype=np.int64).ravel()
        at = self.sys.folding.index[idx]
        out = np.zeros(idx.size)
        inside = at < self.inner.n
        out[inside] = self.inner.inverse_diagonal(at[inside], batch_bytes=batch_bytes)
        return out

    def dense_inverse(self) -> np.ndarray:
        """The whole inverse ``N^-1`` (n, n)."""
        Q = self.inner.dense_inverse()
        Q = np.pad(Q, ((0, 1), (0, 1)))
        idx = self.sys.folding.index
        return Q[np.ix_(idx, idx)]


class FoldedCovarianceBlocks:
    """Blocks of ``Q_cc`` of a :class:`SchurSystem` whose own groups are held in their
    local blocks, in its unknowns: ``local`` (n_local, b, b) and ``pairs`` (n_blocks, b, b)
    as in :class:`CovarianceBlocks`; the blocks of global parameters by
    :meth:`global_block` and :meth:`local_global_block` (no dense array of all global
    parameters); ``inner`` the :class:`CovarianceBlocks` of the folded system."""

    def __init__(self, inner: CovarianceBlocks, sys: SchurSystem) -> None:
        self.inner, self.sys = inner, sys
        b = sys.b
        self.local = inner.local[:, :b, :b]
        self.pairs = None if inner.pairs is None else inner.pairs[:, :b, :b]
        L = sys.n_local
        bl = sys.blocks
        self._pair_key = bl[:, 0] * L + bl[:, 1]  # sorted (np.unique in SchurSystem._pairs)

    def _pair(self, la: np.ndarray, lb: np.ndarray) -> np.ndarray:
        """Index of the block of local blocks ``min(la, lb)``, ``max(la, lb)``."""
        L = self.sys.n_local
        key = np.minimum(la, lb) * L + np.maximum(la, lb)
        t = np.searchsorted(self._pair_key, key)
        t = np.minimum(t, max(self._pair_key.size - 1, 0))
        if self.inner.pairs is None or self._pair_key.size == 0 or np.any(self._pair_key[t] != key):
            raise LookupError(
                "the covariance of two local blocks that share no point is not among the "
                "blocks computed: solve with the factor"
            )
        return t

    def _entries(self, ra, pa, rb, pb) -> np.ndarray:
        """``Q`` of folded unknowns (local ``ra`` or -1 for global, position ``pa`` in it
        or in the shared globals) by (``rb``, ``pb``), elementwise (broadcast)."""
        Qi = self.inner
        ra, pa, rb, pb = np.broadcast_arrays(ra, pa, rb, pb)
        out = np.zeros(ra.shape)  # -2: held in every own group, left out: zero
        ga, gb = ra == -1, rb == -1
        la, lb = ra >= 0, rb >= 0
        ga, gb = ga & (lb | gb), gb & (la | ga)  # pairs with a left-out one stay zero
        la, lb = la & (lb | gb), lb & (la | ga)
        m = ga & gb
        out[m] = Qi.global_[pa[m], pb[m]]
        m = la & gb
        out[m] = Qi.local_global[ra[m], pa[m], pb[m]]
        m = ga & lb
        out[m] = Qi.local_global[rb[m], pb[m], pa[m]]
        m = la & lb & (ra == rb)
        out[m] = Qi.local[ra[m], pa[m], pb[m]]
        m = la & lb & (ra != rb)
        if np.any(m):
            t = self._pair(ra[m], rb[m])
            lo = ra[m] < rb[m]  # Q[lo, hi] stored; Q[hi, lo] its transpose
            out[m] = np.where(lo, Qi.pairs[t, pa[m], pb[m]], Qi.pairs[t, pb[m], pa[m]])
        return out

    def _global(self, cols: np.ndarray):
        s, f = self.sys, self.sys.folding
        cols = np.asarray(cols, dtype=np.int64)
        loc = f.col_local[cols]
        cp = f.col_pos[cols]
        sh = f.sh_idx[cols]
        pos = np.where(loc >= 0, s.b + cp, sh)
        left_out = np.where(loc >= 0, cp < 0, sh < 0)  # not in the folded system
        return np.where(left_out, -2, loc), pos

    def global_block(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``Q`` of global parameters ``rows`` (k1,) by ``cols`` (k2,): (k1, k2).

        Raises
        ------
        LookupError
            Two of them belong to local blocks that share no point (their block is not
            computed).
        """
        ra, pa = self._global(rows)
        rb, pb = self._global(cols)
        return self._entries(ra[:, None], pa[:, None], rb[None, :], pb[None, :])

    def local_global_block(self, local: int, cols: np.ndarray) -> np.ndarray:
        """``Q`` of local block ``local`` by global parameters ``cols`` (k,): (b, k)."""
        rb, pb = self._global(cols)
        ra = np.full((self.sys.b, 1), int(local))
        pa = np.arange(self.sys.b)[:, None]
        return self._entries(ra, pa, rb[None, :], pb[None, :])
