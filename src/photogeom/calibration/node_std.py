"""Cofactors of the nodes of residual grids estimated inside the bundle adjustment.

``diag(N^-1)`` at the grid nodes of :func:`~photogeom.calibration.adjust_with_grids`, with
the points eliminated and the grids' datum by the Woodbury identity, never the whole
inverse. The system reduced by the points is factorised by
:func:`~photogeom.adjust.sparse.factorize`; with a sparse factor (CHOLMOD or SuperLU) its
fill-reducing order serves a supernodal selected inversion
(:class:`~photogeom.adjust.selected_inverse.GroupSelectedInverse`) over groups of the
unknowns: each image's orientation, each camera group's calibration, and tiles of
:data:`NODE_TILE` x :data:`NODE_TILE` nodes of each grid. Its work is that of one more
factorisation: on the 250-image study block at 1000 px (31 500 node values) the
inversion takes 14 s CPU, where one triangular solve over the whole factor per node took
131-170 s; with the factorisation and the Woodbury term's solves (one per datum
condition, 1000) the node standard deviations take 39-44 s.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..adjust.selected_inverse import GroupSelectedInverse
from ..adjust.sparse import factorize
from ..bundle.adjustment import NCAL
from ..errors import DegenerateGeometryError

#: Nodes per side of the tiles of a grid that the selected inversion groups (the x and y
#: values of 2 x 2 nodes: 8 unknowns). Smaller tiles follow the sparsity of the factor
#: more closely, larger ones give larger dense products; 2 was the fastest on the
#: 250-image study block at 1000 px (1 node: 22 s, 2: 14 s).
NODE_TILE = 2


def node_cofactors(gp, N: sp.csr_matrix, backend: str, batch_bytes: int) -> np.ndarray:
    """``diag(N^-1)`` of the grid unknowns of a joint adjustment with grids.

    Parameters
    ----------
    gp : photogeom.calibration.in_adjustment._GridProblem
        The problem: its free unknowns (camera side, then the points in 3 x 3 blocks),
        grids and datum columns ``U_free`` (None: none).
    N : scipy.sparse.csr_matrix
        Normal matrix of the free unknowns, without the low-rank datum ``U U'``.
    backend : str
        Factorisation of the reduced system (:func:`~photogeom.adjust.sparse.factorize`;
        ``"cg"`` has no factor: ``"auto"`` serves it).
    batch_bytes : int
        Memory of one batch of unit vectors where the factor is dense (LAPACK) and the
        diagonal comes from triangular solves (bytes).

    Returns
    -------
    numpy.ndarray, shape (n_grid,)
        Cofactors of the node values (px^2 over the unit weight), grid by grid.

    Raises
    ------
    DegenerateGeometryError
        The reduced system is singular at the solution.
    """
    from .in_adjustment import _reduce_points

    fi = gp.free_idx
    nc = fi.size - 3 * gp.bp.p
    S = _reduce_points(N, 3 * gp.bp.p)[0].tocsc()
    singular = (
        "the normal equations with residual grids are singular at the solution: a grid "
        "or orientation parameter is not determined (use a larger spacing or stronger "
        "constraints)"
    )
    try:
        F = factorize(
            S,
            backend="auto" if backend == "cg" else backend,
            what="the normal equations with residual grids at the solution",
        )
    except DegenerateGeometryError:
        raise DegenerateGeometryError(singular) from None
    rows = np.flatnonzero((fi[:nc] >= gp.off_g) & (fi[:nc] < gp.off_p))  # the nodes
    # the datum by the Woodbury identity: diag((S + U U')^-1) = diag(S^-1) - diag(Z C^-1 Z')
    # with Z = S^-1 U and C = I + U' Z
    U = gp.U_free
    corr = np.zeros(rows.size)
    if U is not None and U.shape[1]:
        Z = F.solve(U.toarray())
        C = np.eye(U.shape[1]) + np.asarray(U.T @ Z)
        C = sla.cho_factor(C, lower=True, check_finite=False)
        Zg = Z[rows]
        del Z
        corr = np.einsum("ij,ji->i", Zg, sla.cho_solve(C, Zg.T, check_finite=False))
        del Zg
    position = F.elimination_positions()
    if position is None:  # a dense factor: triangular solves
        d = F.inverse_diagonal(rows, batch_bytes=batch_bytes)
    else:
        del F
        labels = _groups(gp, fi[:nc])
        K = int(labels.max()) + 1
        last = np.full(K, -1, dtype=np.int64)
        np.maximum.at(last, labels, position)  # a group is eliminated with its last unknown
        rank = np.empty(K, dtype=np.int64)
        rank[np.argsort(last, kind="stable")] = np.arange(K)
        try:
            sel = GroupSelectedInverse(
                S, labels, rank, what="the normal equations with residual grids at the solution"
            )
        except DegenerateGeometryError:
            raise DegenerateGeometryError(singular) from None
        d = sel.diagonal()[rows]
    d = d - corr
    diag = np.full(gp.ntot, np.nan)
    diag[fi[rows]] = d
    return diag[gp.off_g : gp.off_p]


def _groups(gp, fc: np.ndarray) -> np.ndarray:
    """The group of every camera-side free unknown ``fc`` (indices into all unknowns):
    the orientation of an image, the calibration of a camera group, a tile of
    :data:`NODE_TILE` x :data:`NODE_TILE` nodes of a grid (x and y values); integers
    from 0."""
    m = gp.bp.m
    b = max(gp.bp.b, 1)
    grid = np.clip(np.searchsorted(gp.goff, fc - gp.off_g, side="right") - 1, 0, None)
    nx = np.array([1 if L is None else L.nx for L in gp.layouts] or [1], dtype=np.int64)
    node = np.maximum(fc - gp.off_g - gp.goff[grid], 0) // 2
    tiles_x = -(-nx // NODE_TILE)
    tile = (node // nx[grid]) // NODE_TILE * tiles_x[grid] + (node % nx[grid]) // NODE_TILE
    n_grids = len(gp.layouts)
    key = np.where(
        fc < gp.nl,
        fc // b,
        np.where(
            fc < gp.off_g,
            m + (fc - gp.nl) // NCAL,
            m + gp.ncal + grid + n_grids * tile,
        ),
    )
    return np.unique(key, return_inverse=True)[1].ravel()
