"""Residual grids estimated inside the bundle adjustment (Hastedt's approach).

The post-processing of the study fits a grid to the residuals of a finished adjustment. Here
the grid is an unknown of the adjustment itself: the computed image coordinate of a point is

    u_computed = project(X; exterior orientation, Brown calibration) - r(u_observed)

with ``r`` the bilinear interpolation of the node values of the image's grid (or of its
camera group's grid) at the observed position, the same finite-element model and the same
sign as :class:`~photogeom.calibration.ResidualGrid` (the modelled residual, computed minus
observed; a point's observation is corrected by ``u + r(u)``). The unknowns are adjusted
jointly: exterior orientations, free calibration parameters, points and grid nodes.

Pseudo-observations of the grids, all with observed value 0:

* smoothness (the study's intra-image constraint): every node equals the mean of its
  neighbours, standard deviation ``sigma_constraint`` (px);
* temporal (optional, ``per="image"``): the nodes of consecutive images of a camera group (in
  block order, i.e. the order of acquisition) are equal, standard deviation
  ``sigma_temporal`` (px);
* amplitude: every node's value is 0 with standard deviation ``sigma_amplitude`` (px), the
  expected size of the field (a signal variance, as in least-squares collocation). The
  observations cannot tell a per-image field of long wavelength from a deformation of the
  object and orientation (the tie points take most of it up): smoothness and temporal
  constraints penalise differences only, so those components would be left to the datum
  and the path of the iterations. The amplitude holds them near zero instead, where the
  observations say nothing. By default it is twice the RMS (per coordinate) of the field
  that grids of the same spacing and smoothness fit to the tie-point residuals of the block
  as given (:data:`AMPLITUDE_FACTOR`; the post-processing's fit, which averages the
  measurement noise out): the field is larger than what it leaves in the residuals of a
  first adjustment (on the simulated blocks the tie points take up 20-40 % of its RMS).
* the datum of the grid. A grid can take up part of the image model: a constant field is a
  shift of the image (principal point, or omega/phi), a field proportional to the image
  coordinates a scale or rotation (focal length, kappa, Z). Without a datum the split
  between grid and orientation would be decided by the smoothness weights alone and the
  system would be nearly singular. The datum conditions hold those components of every grid
  at zero: ``"similarity"`` (the default of per-image grids) the mean shift, scale and
  rotation of the node values, ``"affine"`` (the default of per-camera grids: the affinity
  b1, b2 of the Brown model too) the mean shift and the four linear terms. They are
  pseudo-observations with a standard deviation of 1e-4 px on the mean over the nodes
  (numerically hard constraints). MicMac's bilinear grid freezes two nodes on the middle
  line instead; the conditions here leave every node free and make the result independent of
  the node chosen.

The system is solved by Levenberg-Marquardt on the sparse normal equations of all unknowns
(CHOLMOD). With an amplitude the datum conditions stay out of the factorised matrix: they
are a low-rank term (4 or 6 columns per grid) added by the Woodbury identity, so the
normal equations hold no dense block per grid. It suits blocks of tens to a few hundred
images with grids of some hundred nodes (spacings of 300-1000 px on 20-40 Mpx images); finer
grids belong to the post-processing.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..adjust.levenberg import levenberg_marquardt_loop
from ..adjust.schur import invert_point_blocks
from ..adjust.sparse import HAVE_CHOLMOD, CGNotConvergedError, factorize
from ..bundle.adjustment import NCAL, Problem, _step_small
from ..bundle.block import Block
from ..bundle.determined import check_state_determined
from ..bundle.options import BundleOptions
from ..camera.frame_kernel import project_rows
from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..machine import physical_memory
from .grid import (
    BORDERS,
    GridLayout,
    ResidualGrid,
    _node_counts,
    _rms_len,
    check_min_support,
    check_spacing,
)

__all__ = ["GridAdjustment", "adjust_with_grids"]

PER = ("image", "camera")
DATUMS = ("similarity", "affine")
#: Standard deviation of the datum conditions (px, on the mean over the nodes).
DATUM_SIGMA = 1e-4
#: The rule of ``sigma_amplitude`` that takes it from the block's tie-point residuals.
AMPLITUDE_FROM_RESIDUALS = "residuals"
#: ``sigma_amplitude="residuals"``: this factor times the RMS per coordinate of the grids
#: fitted to the tie-point residuals.
AMPLITUDE_FACTOR = 2.0
#: Without CHOLMOD: camera-side unknowns (the points eliminated) up to which the reduced
#: system is factorised densely (LAPACK; 70 MB at 3000, 800 MB at 10000).
DENSE_REDUCED_MAX = 10000
#: Unknowns (without the points) up to which node standard deviations are computed by
#: default (a selected inversion of the system reduced by the points, see
#: :func:`_grid_cofactors`: 4.7 s CPU for 8700 unknowns, 21 images of 42 Mpx at 500 px,
#: where one triangular solve per node took 31.5 s; 17.7 s for 16 600 unknowns, twice
#: the adjustment, and 39-44 s for 33 000, about as long as the adjustment).
STD_MAX = 10000
#: Node standard deviations where the factor of the system reduced by the points is dense:
#: memory of one batch of unit vectors solved against it (bytes; see
#: :func:`_grid_cofactors`).
STD_BATCH_BYTES = 64 * 2**20
#: Marquardt damping at the start (relative to the diagonal of the normal matrix) when no
#: ``options`` are given. The grids' weak directions (the near null space between per-image
#: fields and the object) have eigenvalues far below 1e-4 of the diagonal, so a start at
#: 1e-4 damped them for 10 or more iterations; a failed step raises the damping as usual
#: when a block starts far from its solution. (The bundle adjustment's default is the same.)
INITIAL_DAMPING = 1e-8


@dataclass(frozen=True, eq=False)
class GridAdjustment:
    """A bundle adjustment with residual grids as unknowns.

    Attributes
    ----------
    grids : dict
        ``image id -> ResidualGrid``; with ``per="camera"`` the images of a camera group share
        one grid object. ``sigma0`` and ``redundancy`` of each grid are those of the joint
        adjustment; ``rms_before``/``rms_after`` the image's residuals at the joint solution
        without and with the grid (px).
    block : Block
        The joint estimate: exterior orientations, calibrations and points, with the
        observations as given (not corrected), and the record of this joint adjustment
        (``block.joint_adjustment``): :func:`~photogeom.calibration.readjust` of it with
        ``grids`` is ``fit`` again, sigma0 over the same effective redundancy.
    fit : BundleFit
        The observations corrected by the grids and adjusted with the exterior orientation and
        calibration held at the joint estimate: its points equal the joint solution's, its
        check points are triangulated from corrected observations, and its residuals,
        steps and check-point statistics are comparable with
        :func:`~photogeom.calibration.readjust` after the post-processing. Its sigma0 is
        over the effective redundancy of the chain of the joint adjustment and this
        re-adjustment (``fit.effective_redundancy``; its residuals are the joint
        adjustment's); its standard deviations are conditional on the fixed orientation
        (a note says so). Its block carries the record
        of this joint adjustment (``fit.block.joint_adjustment``, a
        :class:`JointAdjustmentRecord`), kept by copies and CSV block folders: readjust
        takes the joint adjustment as the first adjustment of its chain.
    per : {"image", "camera"}
    spacing : float
        Node spacing (px).
    datum : str
    sigma_constraint, sigma_temporal, sigma_amplitude : float
        Standard deviations of the pseudo-observations (px); ``sigma_temporal`` NaN without
        temporal constraints, ``sigma_amplitude`` NaN without the amplitude.
    sigma0 : float
        A-posteriori standard deviation of unit weight of the joint adjustment, with the
        weights ``P = sigma0_prior^2 / sigma^2`` of the options, as in
        :class:`~photogeom.bundle.BundleFit`: about ``sigma0_prior`` (1 by default) when the
        a-priori sigmas are right and the field is of the size its pseudo-observations
        state; below it where the field is smaller (none at all: the mean sigma0^2 is
        ``(n - tr(J N^-1 J')) / r``, 0.70-0.84 on a simulated block, see the docs). The
        standard deviations do not depend on ``sigma0_prior``.
    redundancy, n_unknowns : int
        Redundancy: scalar observations (image, GNSS, IMU, control) plus the rank of the
        grids' pseudo-observations, minus the free unknowns. The pseudo-observations are
        one prior on the nodes (as the signal of least-squares collocation), so they add
        the node values they determine, not their rows: with an amplitude every node,
        and the redundancy is the bundle adjustment's; without one, each grid (each run
        of grids joined by temporal constraints) less the fields its smoothness and datum
        leave free (none with ``border="mean"``). ``n_unknowns``: free unknowns.
    node_std : dict or None
        ``grid key -> (ny, nx, 2)`` standard deviations of the node values (px) from the joint
        covariance (keys are image ids, or camera ids with ``per="camera"``); None when not
        computed (see ``std`` of :func:`adjust_with_grids`).
    converged, iterations, message, cost_history
        Convergence diagnostics (cost: whitened squared norm of all terms).
    elapsed : float
        Seconds, the final conditional adjustment included.
    """

    grids: dict
    block: Block
    fit: object
    per: str
    spacing: float
    datum: str
    sigma_constraint: float
    sigma_temporal: float
    sigma0: float
    redundancy: int
    n_unknowns: int
    node_std: dict | None
    converged: bool
    iterations: int
    message: str
    cost_history: list = field(default_factory=list)
    elapsed: float = 0.0
    sigma_amplitude: float = float("nan")

    def to_dict(self) -> dict:
        """JSON-ready summary.

        Returns
        -------
        dict
            Settings (``per``, ``spacing`` px, ``datum``, sigmas px; None where not used),
            ``sigma0``, ``redundancy``, ``n_unknowns``, convergence, ``elapsed_s`` and the number
            of distinct grids.
        """
        return {
            "per": self.per,
            "spacing": self.spacing,
            "datum": self.datum,
            "sigma_constraint": self.sigma_constraint,
            "sigma_temporal": None if math.isnan(self.sigma_temporal) else self.sigma_temporal,
            "sigma_amplitude": None
            if math.isnan(self.sigma_amplitude)
            else self.sigma_amplitude,
            "sigma0": self.sigma0,
            "redundancy": self.redundancy,
            "n_unknowns": self.n_unknowns,
            "converged": self.converged,
            "iterations": self.iterations,
            "message": self.message,
            "elapsed_s": self.elapsed,
            "grids": len({id(g) for g in self.grids.values()}),
        }


# --------------------------------------------------------------------------- the problem
class _GridProblem:
    """The bundle problem with grid nodes appended to the unknowns."""

    def __init__(self, block, opts, spacing, per, datum, sc, st, sa, border):
        self.bp = bp = Problem(block, opts)
        self.block = block
        m, b, ng = bp.m, bp.b, bp.ng
        sizes = block.image_sizes().astype(int)
        cam_of_img = block.image_camera
        # grids: one per image or per camera group, each with the layout of its camera
        if per == "image":
            self.grid_keys = block.image_ids.tolist()
            grid_cam = cam_of_img.copy()
            self.grid_of_image = np.arange(m)
        else:
            self.grid_keys = block.camera_ids.tolist()
            grid_cam = np.arange(ng)
            self.grid_of_image = cam_of_img.copy()
        cam_size = {}
        for i in range(m):  # images, not points
            cam_size.setdefault(int(cam_of_img[i]), (int(sizes[i, 0]), int(sizes[i, 1])))
        layouts_cam = {}
        for c, (w, h) in cam_size.items():
            try:
                layouts_cam[c] = GridLayout(w, h, spacing)
            except InputError as exc:
                raise InputError(f"camera {block.camera_ids[c]}: {exc}") from None
        self.layouts = [layouts_cam.get(int(c)) for c in grid_cam]
        nn = np.array([0 if L is None else L.n_nodes for L in self.layouts], dtype=np.int64)
        #: the datum conditions as a low-rank term (with an amplitude), else dense blocks
        self.low_rank = sa is not None
        if not self.low_rank:
            _check_memory(nn, spacing)
        self.goff = np.r_[0, np.cumsum(2 * nn)]
        self.n_grid = int(self.goff[-1])
        self.nl, self.ncal = m * b, ng * NCAL
        self.off_g = self.nl + self.ncal
        self.off_p = self.off_g + self.n_grid
        self.ntot = self.off_p + 3 * bp.p
        # bilinear weights at the observations (constant over the iterations)
        gk = self.grid_of_image[bp.obs_i]
        self.obs_grid = gk
        nodes = np.zeros((bp.obs_i.size, 4), dtype=np.int64)
        wts = np.zeros((bp.obs_i.size, 4))
        for g in np.unique(gk).tolist():  # grids, not points
            sel = np.flatnonzero(gk == g)
            L = self.layouts[g]
            try:
                L.check_inside(bp.uv[sel], "observations")
            except InputError as exc:
                raise InputError(f"grid {self.grid_keys[g]}: {exc}") from None
            nodes[sel], wts[sel] = L.locate(bp.uv[sel])
        self.obs_nodes, self.obs_w = nodes, wts
        self.sc, self.st = sc, st
        self.R, self.U, self.n_pseudo = self._regularisation(datum, sc, st, sa, border, per)
        free = np.zeros(self.ntot, dtype=bool)
        free[: self.nl] = bp.local_free.ravel()
        free[self.nl : self.off_g] = bp.global_free
        free[self.off_g :] = True
        self.free = free
        self.free_idx = np.flatnonzero(free)
        # observations' rows and the columns of their non-grid Jacobian blocks
        n = bp.obs_i.size
        self.n = n
        self._cols_dense = bp.jacobian_columns(self.off_p)  # (n, b + 11 + 3)
        self._grid_cols = self.off_g + self.goff[gk][:, None] + 2 * nodes  # x; y is +1
        # the pattern of the Jacobian (rows 2k, 2k+1 of observation k) is the same in every
        # iteration: its indices are built once
        k = self._cols_dense.shape[1]
        rx = np.repeat(2 * np.arange(n), 4)
        self._J_rows = np.concatenate([np.repeat(np.arange(2 * n), k), rx, rx + 1])
        self._J_cols = np.concatenate(
            [
                np.repeat(self._cols_dense, 2, axis=0).ravel(),
                self._grid_cols.ravel(),
                self._grid_cols.ravel() + 1,
            ]
        )
        # the grids' pseudo-observations in the free unknowns (every grid unknown is free)
        g0 = int(np.sum(free[: self.off_g]))
        nf = self.free_idx.size
        self._R_free = sp.block_diag(
            [sp.csr_matrix((g0, g0)), self.R, sp.csr_matrix((nf - g0 - self.n_grid,) * 2)],
            format="csr",
        )
        # the preconditioner's blocks of backend="cg" in the camera-side free unknowns (the
        # points, last, excluded): each grid's nodes (which its datum term couples) with
        # the unknowns it competes with, the orientation of its image (per="image") or the
        # calibration of its camera group (per="camera"); the other images' orientations
        # and camera groups' calibrations one block each
        fc = self.free_idx[: nf - 3 * bp.p]
        grid = np.searchsorted(self.goff, fc - self.off_g, side="right") - 1
        own = self.grid_of_image if per == "image" else m + grid_cam  # image or calibration
        owner = np.where(
            fc < self.nl,
            fc // max(b, 1),
            np.where(fc < self.off_g, m + (fc - self.nl) // NCAL, own[np.maximum(grid, 0)]),
        )
        #: the preconditioner's block of every camera-side free unknown
        self.cg_blocks = owner
        # the datum columns in the camera-side free unknowns (the points, last, excluded)
        self.U_free = None
        if self.U is not None:
            nc = nf - 3 * bp.p
            k = self.U.shape[1]
            self.U_free = sp.vstack(
                [sp.csr_matrix((g0, k)), self.U, sp.csr_matrix((nc - g0 - self.n_grid, k))],
                format="csc",
            )

    # -------------------------------------------------------------- pseudo-observations
    def _regularisation(self, datum, sc, st, sa, border, per):
        """The grids' pseudo-observations as one precision matrix ``R + U U'``
        (n_grid x n_grid) and the number of observations they add to the redundancy: its
        rank.

        ``U`` (n_grid x conditions, sparse) holds the datum conditions divided by
        :data:`DATUM_SIGMA`, one column per condition and grid, when the grids have an
        amplitude (``sa``): ``R`` is then sparse and positive definite, and the solver adds
        ``U U'`` as a low-rank term. Without an amplitude ``R`` alone is singular, so the
        datum is added to it (a dense block of (2 nodes)^2 entries per grid) and ``U`` is
        None.

        All groups (smoothness, datum, amplitude, temporal) act on the same nodes, so they
        are one prior on the field, as the signal of least-squares collocation: however
        many rows they have, they inform the nodes once. A field drawn from that prior and
        noisy observations give an expected weighted square sum of the observations'
        number minus the unknowns the prior leaves free, not of the rows' number (the rows
        counted, sigma0 came out 0.83 on a block simulated from the model itself).
        """
        blocks, datum_diag, null, u_rows, u_cols, u_vals, k = [], [], [], [], [], [], 0
        for g, L in enumerate(self.layouts):  # grids, not points
            if L is None:
                blocks.append(sp.csr_matrix((0, 0)))
                null.append(0)
                continue
            C = L.constraint_matrix(border)
            CC = sp.kron(C.T @ C, sp.identity(2), format="csr") / sc**2
            D = _datum_rows(L, datum)
            if self.low_rank:
                blocks.append(CC)
                nz = np.nonzero(D)
                u_rows.append(self.goff[g] + nz[1])
                u_cols.append(k + nz[0])
                u_vals.append(D[nz] / DATUM_SIGMA)
                k += D.shape[0]
            else:
                blocks.append((CC + sp.csr_matrix(D.T @ D) / DATUM_SIGMA**2).tocsr())
                datum_diag.append(np.sum(D * D, axis=0) / DATUM_SIGMA**2)
            null.append(_free_field_dims(L, D, border))
        R = sp.block_diag(blocks, format="csr") if blocks else sp.csr_matrix((0, 0))
        if sa is not None and self.n_grid:
            R = (R + sp.identity(self.n_grid, format="csr") / sa**2).tocsr()
            null = [0] * len(null)  # the amplitude leaves no node value free
        U = None
        if self.low_rank:
            U = sp.csr_matrix(
                (
                    np.concatenate(u_vals) if u_vals else np.zeros(0),
                    (
                        np.concatenate(u_rows) if u_rows else np.zeros(0, np.int64),
                        np.concatenate(u_cols) if u_cols else np.zeros(0, np.int64),
                    ),
                ),
                shape=(self.n_grid, k),
            )
        # the datum conditions are (numerically) hard: no Marquardt damping scaled by them
        # (with the low-rank term they are not in the normal matrix that is damped)
        dd = np.zeros(self.ntot)
        if datum_diag:
            dd[self.off_g : self.off_p] = np.concatenate(datum_diag)
        self.datum_diag = dd
        if per == "image" and st is not None:
            # consecutive images of each camera group, in block order: the images of a
            # group need not be next to each other in the block (cameras of a rig
            # interleaved in the order of acquisition)
            cam = self.block.image_camera
            order = np.argsort(cam, kind="stable")
            same = cam[order[:-1]] == cam[order[1:]]
            pairs = list(zip(order[:-1][same].tolist(), order[1:][same].tolist()))
            if pairs:
                rows, cols, vals, start = [], [], [], 0
                for i, k in pairs:  # images, not points
                    size = int(self.goff[i + 1] - self.goff[i])
                    base = start + np.arange(size)
                    rows += [base, base]
                    cols += [self.goff[i] + np.arange(size), self.goff[k] + np.arange(size)]
                    vals += [np.ones(size), -np.ones(size)]
                    start += size
                T = sp.csr_matrix(
                    (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                    shape=(start, self.n_grid),
                )
                R = (R + (T.T @ T) / st**2).tocsr()
                # grids joined by temporal constraints share their free directions: one
                # set per run of consecutive images of a camera group
                for i, _k in pairs:  # images, not points
                    null[i] = 0
        return R, U, self.n_grid - int(sum(null))

    # -------------------------------------------------------------- model
    def grid_values(self, z: np.ndarray) -> np.ndarray:
        """The modelled residual (n, 2) px at every observation."""
        zx = z[self._grid_cols - self.off_g]
        zy = z[self._grid_cols - self.off_g + 1]
        return np.column_stack([np.sum(self.obs_w * zx, 1), np.sum(self.obs_w * zy, 1)])

    def residuals(self, s, z):
        X, M, C, cal = self.bp._rows(s)
        pr = project_rows(X, M, C, cal, self.bp.size, jacobian=False)
        return pr.uv - self.grid_values(z) - self.bp.uv, pr.depth

    def cost(self, s, z) -> tuple[float, np.ndarray]:
        c, _, depth = self.cost_rows(s, z)
        return c, depth

    def cost_rows(self, s, z) -> tuple[float, np.ndarray, np.ndarray]:
        """The cost of all terms, the squared whitened norms (n,) and the depths (n,) of
        the image rows."""
        v, depth = self.residuals(s, z)
        e2 = np.einsum("nd,nd->n", v, v) / self.bp.sigma_obs() ** 2
        return self.cost_of(s, z, e2), e2, depth

    def cost_of(self, s, z, e2: np.ndarray) -> float:
        """The cost of all terms from the squared whitened norms ``e2`` (n,) of the image
        rows: those, the priors (GNSS, IMU, control) and the grids' pseudo-observations."""
        c = float(np.sum(e2)) + self.bp.prior_terms(s)[4] + float(z @ (self.R @ z))
        if self.U is not None:
            uz = self.U.T @ z
            c += float(uz @ uz)
        return c

    def normal_equations(self, s, z):
        """``N`` (free unknowns, sparse) and the gradient ``J'r`` of all terms; with the
        low-rank datum (``U`` not None) ``N`` leaves ``U U'`` out, the gradient not."""
        bp = self.bp
        X, M, C, cal = bp._rows(s)
        pr = project_rows(X, M, C, cal, bp.size, jacobian=True)
        sw = 1.0 / bp.sigma_obs()
        r = (pr.uv - self.grid_values(z) - bp.uv) * sw[:, None]
        blocks = [pr.d_center, pr.d_rotation]
        if bp.b > 6:
            blocks.append(pr.d_calibration[:, :, :3])
        dense = np.concatenate([*blocks, pr.d_calibration, pr.d_point], axis=2)
        dense = dense * sw[:, None, None]
        gw = (-self.obs_w * sw[:, None]).ravel()  # (n, 4): the x row, then the y row
        J = sp.csr_matrix(
            (np.concatenate([dense.reshape(-1), gw, gw]), (self._J_rows, self._J_cols)),
            shape=(2 * self.n, self.ntot),
        )
        fi = self.free_idx
        J = J[:, fi]
        N = (J.T @ J).tocsr()
        g = J.T @ r.ravel()
        # priors of the bundle problem (GNSS, IMU, control) and the grids' pseudo-observations
        li, lg, pi, pgr, _, _ = bp.prior_terms(s)
        priors = sp.block_diag(
            [
                _block_diagonal(li),
                sp.csr_matrix((self.ncal + self.n_grid,) * 2),
                _block_diagonal(pi),
            ],
            format="csr",
        )
        N = (N + priors[fi][:, fi] + self._R_free).tocsr()
        Rz = self.R @ z if self.U is None else self.R @ z + self.U @ (self.U.T @ z)
        g_priors = np.concatenate([lg.ravel(), np.zeros(self.ncal), Rz, pgr.ravel()])
        return N, g + g_priors[fi]

    def grid_jacobian(self) -> sp.csr_matrix:
        """The whitened Jacobian (2n x n_grid) of the image rows (x then y per
        observation) in the node values: minus the bilinear weights over the sigmas."""
        sw = 1.0 / self.bp.sigma_obs()
        w = (-self.obs_w * sw[:, None]).ravel()
        cols = (self._grid_cols - self.off_g).ravel()
        rx = np.repeat(2 * np.arange(self.n), 4)
        return sp.csr_matrix(
            (
                np.concatenate([w, w]),
                (np.concatenate([rx, rx + 1]), np.concatenate([cols, cols + 1])),
            ),
            shape=(2 * self.n, self.n_grid),
        )

    def split(self, dx_free: np.ndarray):
        dx = np.zeros(self.ntot)
        dx[self.free_idx] = dx_free
        return dx[: self.off_g], dx[self.off_g : self.off_p], dx[self.off_p :].reshape(-1, 3)


def _block_diagonal(blocks: np.ndarray) -> sp.csr_matrix:
    """Sparse block-diagonal matrix of ``blocks`` (k, s, s)."""
    k, s, _ = blocks.shape
    if k == 0:
        return sp.csr_matrix((0, 0))
    base = np.arange(k)[:, None, None] * s
    r = np.broadcast_to(base + np.arange(s)[None, :, None], (k, s, s))
    c = np.broadcast_to(base + np.arange(s)[None, None, :], (k, s, s))
    return sp.csr_matrix((blocks.ravel(), (r.ravel(), c.ravel())), shape=(k * s, k * s))


def _free_field_dims(L: GridLayout, D: np.ndarray, border: str) -> int:
    """Directions of one grid's node values (x and y) that neither its smoothness rows nor
    its datum conditions ``D`` constrain: the fields ``C`` leaves free (constant with
    ``border="mean"``, bilinear with ``"linear"``, per component) minus those ``D`` holds."""
    u, v = L.node_coordinates()
    u, v = u.ravel() / L.spacing, v.ravel() / L.spacing
    funcs = [np.ones_like(u)] if border == "mean" else [np.ones_like(u), u, v, u * v]
    B = np.zeros((2 * u.size, 2 * len(funcs)))
    for k, f in enumerate(funcs):
        B[0::2, 2 * k], B[1::2, 2 * k + 1] = f, f
    B /= np.linalg.norm(B, axis=0)
    Dn = D / np.linalg.norm(D, axis=1, keepdims=True)
    return B.shape[1] - int(np.linalg.matrix_rank(Dn @ B, tol=1e-9))


#: Memory per entry of the grids' dense datum blocks (without an amplitude), bytes: each
#: grid's datum conditions couple all of its unknowns, so the normal equations and their
#: factor hold a dense block of (2 nodes)^2 entries per grid. Measured: 6 images of
#: 4000 x 3000 px with 100 px grids (6 blocks of 2542^2 entries) took 4.4 GB.
BYTES_PER_DATUM_ENTRY = 120


def _check_memory(nodes: np.ndarray, spacing: float) -> None:
    """Refuse grids without an amplitude whose dense datum blocks would need more memory
    than the machine has (before: numpy's "Unable to allocate 27.5 GiB" at 20 px, or
    minutes of swapping). With an amplitude the datum is a low-rank term: no dense block."""
    need = BYTES_PER_DATUM_ENTRY * float(np.sum((2.0 * nodes) ** 2))
    have = physical_memory()
    if have is None or need <= have:
        return
    raise InputError(
        f"grids in the adjustment at spacing {spacing:g} px: {int(nodes.max())} nodes per "
        f"grid over {int(np.count_nonzero(nodes))} grid(s); without sigma_amplitude each "
        f"grid's datum conditions couple all of its nodes, which needs about "
        f"{need / 2**30:.1f} GiB of memory, more than this machine's {have / 2**30:.1f} GiB: "
        "give sigma_amplitude (px, or 'residuals'; the datum then adds no dense block), "
        "use a larger spacing (grids inside the adjustment are meant to be coarse, 500 px "
        "in the documented runs), per='camera' (one grid per camera group), or fine grids "
        "after the adjustment (fit_residual_grids)"
    )


def _datum_rows(L: GridLayout, datum: str) -> np.ndarray:
    """Rows (conditions x 2 n_nodes) of the mean shift/scale/rotation (or affinity) of the
    node values; unknowns ordered node by node, (x, y)."""
    u, v = L.node_coordinates()
    u, v = u.ravel(), v.ravel()
    half = max(L.width, L.height) / 2.0
    uc, vc = (u - (L.width - 1) / 2.0) / half, (v - (L.height - 1) / 2.0) / half
    one, zero = np.ones_like(uc), np.zeros_like(uc)

    def row(fx, fy):
        out = np.empty(2 * uc.size)
        out[0::2], out[1::2] = fx, fy
        return out

    rows = [row(one, zero), row(zero, one)]
    if datum == "similarity":
        rows += [row(uc, vc), row(-vc, uc)]
    else:
        rows += [row(uc, zero), row(vc, zero), row(zero, uc), row(zero, vc)]
    return np.array(rows) / uc.size


# --------------------------------------------------------------------------- the solver
class _GridSteps:
    """The joint problem for :func:`~photogeom.adjust.levenberg.levenberg_marquardt_loop`:
    states are ``(bundle state, node values)``; the datum conditions are left out of the
    Marquardt damping."""

    def __init__(self, gp: _GridProblem, state, opts: BundleOptions) -> None:
        self.gp, self.opts = gp, opts
        self.N, self.g = gp.normal_equations(*state)
        self.scale_uv = float(max(L.width for L in gp.layouts if L is not None))

    def solve(self, damping: float):
        gp = self.gp
        d = np.maximum(self.N.diagonal() - gp.datum_diag[gp.free_idx], 1e-12)
        Nd = (self.N + sp.diags(damping * d)).tocsr()
        try:
            dx = _solve_by_points(
                Nd, self.g, 3 * gp.bp.p, self.opts.backend, gp.U_free, gp.cg_blocks
            )
        except CGNotConvergedError as exc:
            # not a singular system to be damped: a step that conjugate gradients cannot
            # deliver would end the adjustment away from its minimum
            raise ConvergenceError(
                f"adjust_with_grids: backend='cg' did not solve the normal equations with "
                f"residual grids ({exc.iterations} iterations, {Nd.shape[0] - 3 * gp.bp.p} "
                "unknowns without the points): use backend='cholmod' or 'auto' (a direct "
                "factorisation, which also names a singular system)"
            ) from exc
        pred = float(-(self.g @ dx) + damping * np.sum(d * dx * dx))
        return self.gp.split(dx), pred

    def evaluate(self, state, step):
        (s, z), (dcg, dz, dp) = state, step
        trial = (self.gp.bp.update(s, dcg, dp), z + dz)
        new_cost, self._e2, self._depth = self.gp.cost_rows(*trial)
        return trial, new_cost, bool(np.all(self._depth > 0))

    def refine(self, state, trial, cost: float):
        """The accepted ``trial`` with the tie points whose own step raised their cost (or
        put them behind a camera) moved by point-only steps, the cameras and the grids held
        at the trial (:meth:`~photogeom.bundle.adjustment.Problem.guard_point_steps` with
        the observations corrected by the trial's grids), and its cost."""
        gp = self.gp
        (s, _), (ts, tz) = state, trial
        target = gp.bp.uv + gp.grid_values(tz)
        ts, e2, _, changed = gp.bp.guard_point_steps(s, ts, self._e2, self._depth, target)
        if not changed:
            return trial, cost
        self._e2 = e2
        # summed anew: the trial's cost may exceed the refined one many times over
        return (ts, tz), gp.cost_of(ts, tz, e2)

    def small(self, state, step) -> bool:
        (s, _), (dcg, dz, dp) = state, step
        xtol = self.opts.xtol
        return bool(
            _step_small(self.gp.bp, s, dcg, dp, xtol)
            and np.abs(dz).max(initial=0) <= xtol * self.scale_uv
        )

    def accept(self, state) -> None:
        self.N, self.g = self.gp.normal_equations(*state)


def _levenberg_marquardt(gp: _GridProblem, opts: BundleOptions, progress):
    s = gp.bp.initial_state()
    z = np.zeros(gp.n_grid)
    cost, depth = gp.cost(s, z)
    if np.any(~(depth > 0)):
        raise DegenerateGeometryError(
            f"{int(np.sum(~(depth > 0)))} observation(s) have their point behind the camera at "
            "the start: check the initial exterior orientations and points"
        )
    steps = _GridSteps(gp, (s, z), opts)
    run = levenberg_marquardt_loop(
        steps, (s, z), cost, opts, exact_cost=1e-26 * max(2 * gp.n, 1), progress=progress
    )
    (s, z) = run.state
    return s, z, steps.N, run.cost, run.iterations, run.converged, run.message, run.history


def _point_blocks(Npp: sp.csr_matrix, k: int) -> np.ndarray:
    """The 3x3 diagonal blocks (k, 3, 3) of the point part of ``N`` (block diagonal)."""
    blocks = np.zeros((k, 3, 3))
    coo = Npp.tocoo()
    blocks[coo.row // 3, coo.row % 3, coo.col % 3] = coo.data
    return blocks


def _reduce_points(N: sp.csr_matrix, npt: int):
    """The camera-side system with the points (last ``npt`` unknowns, 3x3 blocks)
    eliminated: ``S = Ncc - Ncp Vinv Npc`` (dense when small, else sparse), ``Ncp``,
    ``Vinv`` (block diagonal, sparse)."""
    nc = N.shape[0] - npt
    Ncc = N[:nc][:, :nc]
    Ncp = N[:nc][:, nc:].tocsr()
    blocks = _point_blocks(N[nc:][:, nc:].tocsr(), npt // 3)
    Vinv = _block_diagonal(invert_point_blocks(blocks))
    S = Ncc - Ncp @ Vinv @ Ncp.T
    return S, Ncp, Vinv


def _solve_by_points(
    N: sp.csr_matrix,
    g: np.ndarray,
    npt: int,
    backend: str,
    U: sp.csc_matrix | None = None,
    blocks: np.ndarray | None = None,
) -> np.ndarray:
    """``(N + U U') dx = -g`` with the points eliminated first (3x3 blocks); the reduced
    system is factorised by :func:`~photogeom.adjust.sparse.factorize` (dense up to a few
    thousand unknowns, else CHOLMOD; densely up to :data:`DENSE_REDUCED_MAX` where CHOLMOD
    is missing, as SuperLU is slower there).

    ``U`` (camera-side unknowns x k, sparse; None: no such term) is the grids' datum, k
    conditions in all: it enters by the Sherman-Morrison-Woodbury identity,
    ``(S + U U')^-1 = S^-1 - S^-1 U (I + U' S^-1 U)^-1 U' S^-1``, so that only ``S``
    (without the dense (2 nodes)^2 block per grid) is factorised; k triangular solves
    form the k x k capacitance matrix (:meth:`~photogeom.adjust.sparse.SparseFactor.inverse_gram`).
    With ``backend="cg"`` (no factor to reuse for the k solves) ``U U'`` is added to ``S``,
    and the preconditioner inverts the diagonal blocks that ``blocks`` names (one label per
    camera-side unknown; :attr:`_GridProblem.cg_blocks`: each grid's nodes with its datum
    term and its image's orientation or camera group's calibration, each other
    orientation and calibration). Preconditioned by the
    diagonal alone, the datum's stiff rank-4 or rank-6 term per grid and a camera grid's
    coupling to every image of its group kept conjugate gradients from converging in
    ``10 n`` iterations at the Marquardt damping of a converging adjustment.
    """
    return _ReducedFactor(
        N, npt, U, "normal equations with residual grids", backend=backend, blocks=blocks
    ).solve(-g)


class _ReducedFactor:
    """``(N + U U')^-1`` for blocks of right-hand sides from one factorisation: the points
    (the last ``npt`` unknowns, 3x3 blocks) eliminated, the reduced system factorised by
    :func:`~photogeom.adjust.sparse.factorize` (``backend``: ``"auto"`` takes the dense
    factorisation up to :data:`DENSE_REDUCED_MAX` where CHOLMOD is missing), ``U``
    (camera-side unknowns x k, None: no such term) by the Woodbury identity with its
    capacitance matrix factorised once, or, with ``backend="cg"`` (no factor to reuse),
    added to the reduced system (see :func:`_solve_by_points`)."""

    def __init__(
        self,
        N: sp.csr_matrix,
        npt: int,
        U,
        what: str,
        *,
        backend: str = "auto",
        blocks: np.ndarray | None = None,
    ) -> None:
        self.nc = N.shape[0] - npt
        S, self.Ncp, self.Vinv = _reduce_points(N, npt)
        if backend == "auto" and not HAVE_CHOLMOD and self.nc <= DENSE_REDUCED_MAX:
            backend = "dense"
        self.U = U if U is not None and U.shape[1] else None
        if self.U is not None and backend == "cg":  # iterations on the operator: no factor
            S = S + self.U @ self.U.T
            self.U = None
        self.F = factorize(
            S.tocsc(), backend=backend, what=what, blocks=blocks if backend == "cg" else None
        )
        del S
        if self.U is not None:
            # I + W'W >= I: positive definite whenever the factor of S is
            self.C = sla.cho_factor(
                np.eye(self.U.shape[1]) + self.F.inverse_gram(self.U),
                lower=True,
                check_finite=False,
            )

    def solve(self, B: np.ndarray) -> np.ndarray:
        """``(N + U U')^-1 B`` for ``B`` (unknowns, k)."""
        nc = self.nc
        bc, bp = B[:nc], B[nc:]
        dc = self.F.solve(bc - self.Ncp @ (self.Vinv @ bp))
        if self.U is not None:
            w = sla.cho_solve(self.C, np.asarray(self.U.T @ dc), check_finite=False)
            dc = dc - self.F.solve(np.asarray(self.U @ w))
        dp = self.Vinv @ (bp - self.Ncp.T @ dc)
        return np.concatenate([dc, dp])


def _grid_cofactors(gp: _GridProblem, N: sp.csr_matrix, backend: str = "auto") -> np.ndarray:
    """``diag(N^-1)`` of the grid unknowns (``N`` with the low-rank datum ``U U'`` added
    when it is kept apart), never the whole inverse: the points (3x3 blocks, last) are
    eliminated, the reduced system is factorised (``backend``; ``"cg"`` has no factor,
    ``"auto"`` serves it) and the diagonal at the nodes comes from a supernodal selected
    inversion in the factor's fill-reducing order (triangular solves in batches of
    :data:`STD_BATCH_BYTES` where the factor is dense), the datum by the Woodbury identity
    (:func:`~photogeom.calibration.node_std.node_cofactors`)."""
    from .node_std import node_cofactors

    return node_cofactors(gp, N, backend, STD_BATCH_BYTES)


# --------------------------------------------------------------------------- the chain
#: The folder of a CSV block folder that holds the record of the joint adjustment of
#: :func:`adjust_with_grids` (its final fit's block, ``GridAdjustment.fit.block``): the
#: joint estimate as a CSV block (angles in radians) and ``settings.json``.
RECORD_FOLDER = "joint_adjustment"
#: Settings file of :data:`RECORD_FOLDER`.
RECORD_SETTINGS = "settings.json"


def _observations_digest(block: Block) -> str:
    """SHA-256 of a block's observed pixels (float64 bytes; a CSV round trip keeps them)."""
    import hashlib

    uv = np.ascontiguousarray(block.observations.uv, dtype="<f8")
    return hashlib.sha256(uv.tobytes()).hexdigest()


def grids_digest(block: Block, grids) -> str | None:
    """SHA-256 of the node values (float64) of the grids of ``block``'s images, in block
    order; None when an image has no grid in ``grids``."""
    import hashlib

    from .gridfile import match_grid_ids

    key_of, missing = match_grid_ids(block.image_ids.tolist(), grids)
    if missing:
        return None
    h = hashlib.sha256()
    for iid in block.image_ids.tolist():  # images, not points
        h.update(np.ascontiguousarray(grids[key_of[iid]].nodes, dtype="<f8").tobytes())
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class JointAdjustmentRecord:
    """The joint adjustment with grids that a block is the final fit of.

    :func:`adjust_with_grids` puts it on its final fit's block
    (``GridAdjustment.fit.block.joint_adjustment``); copies of the block keep it
    (:meth:`~photogeom.bundle.Block.replace` and every method deriving a block), a CSV block
    folder holds it (:data:`RECORD_FOLDER`), and a new adjustment's block has none.
    :func:`~photogeom.calibration.readjust` takes the joint adjustment as the first
    adjustment of its chain when the block is still that final fit (:meth:`mismatch`). The
    joint estimate ``GridAdjustment.block`` carries it too: ``readjust`` of that block with
    the joint adjustment's own grids is the final fit again, with its chain.

    Attributes
    ----------
    block : Block
        The joint estimate (orientations, calibration, points; the observations as given,
        not corrected).
    opts : BundleOptions
        The options of the joint adjustment.
    spacing : float
        Node spacing (px).
    per, datum, border : str
        As in :func:`adjust_with_grids`.
    sc, st, sa : float or None
        ``sigma_constraint``, ``sigma_temporal`` and ``sigma_amplitude`` (px; None: not used).
    observations_sha256 : str
        SHA-256 of the final fit's observed pixels (corrected by the grids), float64.
    estimate_sha256 : str
        SHA-256 of the joint estimate's observed pixels (as given), float64.
    grids_sha256 : str
        SHA-256 of the node values of the joint adjustment's grids (:func:`grids_digest`).
    """

    block: Block
    opts: BundleOptions
    spacing: float
    per: str
    datum: str
    sc: float
    st: float | None
    sa: float | None
    border: str
    observations_sha256: str
    estimate_sha256: str = ""
    grids_sha256: str = ""

    def mismatch(self, block: Block, *, estimate: bool = False) -> str | None:
        """Why ``block`` is not the final fit this record was made for (None: it is).

        Parameters
        ----------
        block : Block
            The block carrying the record.
        estimate : bool
            Compare with the joint estimate (its observations as given) instead.

        Returns
        -------
        str or None
            What differs: the observation rows, the observed pixels (bit for bit), the
            exterior orientation or the calibration (beyond 1e-10 relative, 1e-9 absolute:
            a CSV round trip in degrees changes the last digits).
        """
        est = self.block
        if not est.same_observation_rows(block):
            return "its observation rows"
        own = self.estimate_sha256 if estimate else self.observations_sha256
        if _observations_digest(block) != own:
            return "its observed pixels"
        if not np.allclose(block.exterior, est.exterior, rtol=1e-10, atol=1e-9):
            return "its exterior orientation"
        if not np.allclose(
            block.calibration_matrix(), est.calibration_matrix(), rtol=1e-10, atol=1e-9
        ) or not np.allclose(block.calibration_offset, est.calibration_offset, atol=1e-9):
            return "its calibration"
        return None

    def settings(self) -> dict:
        """JSON-ready settings (``settings.json`` of :data:`RECORD_FOLDER`).

        Returns
        -------
        dict
            ``spacing`` (px), ``per``, ``datum``, ``border``, ``sigma_constraint``,
            ``sigma_temporal``, ``sigma_amplitude`` (px, null where not used),
            ``observations_sha256``, ``estimate_sha256``, ``grids_sha256`` and ``options``
            (the fields of the BundleOptions).
        """
        import dataclasses

        opts = dataclasses.asdict(self.opts)
        if opts.get("free") is not None:
            opts["free"] = list(opts["free"])
        return {
            "written_by": "photogeom.calibration.adjust_with_grids",
            "spacing": self.spacing,
            "per": self.per,
            "datum": self.datum,
            "border": self.border,
            "sigma_constraint": self.sc,
            "sigma_temporal": self.st,
            "sigma_amplitude": self.sa,
            "observations_sha256": self.observations_sha256,
            "estimate_sha256": self.estimate_sha256,
            "grids_sha256": self.grids_sha256,
            "options": opts,
        }

    def texts(self) -> dict[str, str]:
        """The files of :data:`RECORD_FOLDER` by name: the joint estimate's CSV block
        (angles in radians, every digit kept) and ``settings.json``.

        Returns
        -------
        dict
            File name (inside :data:`RECORD_FOLDER`) -> text.
        """
        import json

        from ..bundle.io_csv import csv_block_texts

        out = csv_block_texts(self.block, angle_unit="rad")
        out[RECORD_SETTINGS] = json.dumps(self.settings(), indent=1) + "\n"
        return out

    @classmethod
    def read(cls, folder, block: Block) -> JointAdjustmentRecord:
        """The record in ``folder`` (:data:`RECORD_FOLDER` of a CSV block folder).

        Parameters
        ----------
        folder : path-like
            The record's folder.
        block : Block
            The block read from the enclosing folder (for the error messages).

        Returns
        -------
        JointAdjustmentRecord

        Raises
        ------
        FileFormatError
            A settings file that is not JSON or lacks a setting, or options that are not
            valid.
        """
        import json
        from pathlib import Path

        from ..bundle.io_csv import read_csv_block
        from ..errors import FileFormatError

        d = Path(folder)
        path = d / RECORD_SETTINGS
        try:
            s = json.loads(path.read_text(encoding="utf-8"))
            o = dict(s["options"])
            if o.get("free") is not None:
                o["free"] = tuple(o["free"])
            opts = BundleOptions(**o).validate()
            rec = cls(
                block=read_csv_block(d),
                opts=opts,
                spacing=float(s["spacing"]),
                per=str(s["per"]),
                datum=str(s["datum"]),
                sc=float(s["sigma_constraint"]),
                st=None if s["sigma_temporal"] is None else float(s["sigma_temporal"]),
                sa=None if s["sigma_amplitude"] is None else float(s["sigma_amplitude"]),
                border=str(s["border"]),
                observations_sha256=str(s["observations_sha256"]),
                estimate_sha256=str(s.get("estimate_sha256", "")),
                grids_sha256=str(s.get("grids_sha256", "")),
            )
        except (OSError, ValueError, KeyError, TypeError, InputError) as exc:
            raise FileFormatError(
                f"{path}: not the settings of a joint adjustment with grids ({exc}); "
                f"remove the folder {d} to read the block without them (readjust then "
                "takes the bundle adjustment of the block as the first adjustment of its "
                "chain)"
            ) from None
        return rec


def joint_first_adjustment(block: Block):
    """The first adjustment of the chain of ``block`` when it is the final fit's block of
    :func:`adjust_with_grids` (``GridAdjustment.fit.block``), else None.

    Returns
    -------
    tuple or None
        ``(J, rows, solve, sigma, nodes)``: the whitened Jacobian of the joint adjustment at
        its solution (rows: image observations x then y, GNSS, IMU, control coordinates;
        columns: its free unknowns, grid nodes included), the row ranges of the groups
        (as :func:`~photogeom.calibration.chain._first_jacobian`), ``solve(B)`` giving
        ``(J'J + P)^-1 B`` with ``P`` the precision of the grids' pseudo-observations (the
        datum by the Woodbury identity), the observations' standard deviations (px) and the
        columns of ``J`` that hold the grid nodes (a slice).
        The pseudo-observations are error-free here: the chain's redundancy is that of the
        observations' noise, as for a block without any local field.
    """
    rec = getattr(block, "joint_adjustment", None)
    if rec is None or rec.mismatch(block) is not None:
        return None
    from .chain import _first_jacobian

    gp = _GridProblem(
        rec.block, rec.opts, rec.spacing, rec.per, rec.datum, rec.sc, rec.st, rec.sa, rec.border
    )
    J0, rows = _first_jacobian(gp.bp)
    g0 = int(np.sum(gp.free[: gp.off_g]))
    Jg = gp.grid_jacobian()
    Jg = sp.vstack([Jg, sp.csr_matrix((J0.shape[0] - Jg.shape[0], gp.n_grid))], format="csr")
    J = sp.hstack([J0[:, :g0], Jg, J0[:, g0:]], format="csr")
    N = (J.T @ J + gp._R_free).tocsr()
    # the joint adjustment's backend: with "cg" nothing is factorised (each probe is solved
    # by conjugate gradients, as the adjustment's steps were)
    F = _ReducedFactor(
        N,
        3 * gp.bp.p,
        gp.U_free,
        "normal equations with residual grids at the solution",
        backend=rec.opts.backend,
        blocks=gp.cg_blocks,
    )
    return J, rows, F.solve, gp.bp.sigma_obs(), slice(g0, g0 + gp.n_grid)


#: The note of the final fit of :func:`adjust_with_grids` (``GridAdjustment.fit``).
IN_ADJUSTMENT_NOTE = (
    "the grids were estimated from these same observations in the joint adjustment: sigma0 "
    "is computed over the effective redundancy of the chain (the joint adjustment, then this "
    "re-adjustment; see effective_redundancy), but the standard deviations are conditional "
    "on the orientation and calibration held and too small"
)


# --------------------------------------------------------------------------- the call
def adjust_with_grids(
    block: Block,
    spacing: float,
    *,
    per: str = "image",
    sigma_constraint: float | str = "scaled",
    sigma_temporal: float | None = None,
    sigma_amplitude: float | str | None = AMPLITUDE_FROM_RESIDUALS,
    datum: str | None = None,
    border: str = "mean",
    min_support: int = 3,
    std: bool | None = None,
    options: BundleOptions | None = None,
    progress=None,
    **kwargs,
) -> GridAdjustment:
    """Bundle adjustment with finite-element residual grids as unknowns.

    Parameters
    ----------
    block : Block
        The block with initial values (as for :func:`photogeom.bundle_adjust`), e.g. the
        block of a first adjustment.
    spacing : float
        Node spacing in pixels (a few hundred: every grid node is an unknown of the
        adjustment).
    per : {"image", "camera"}
        One grid per image (image-variant fields) or one per camera group.
    sigma_constraint : float or "scaled"
        Standard deviation of the smoothness pseudo-observations (px); ``"scaled"``:
        ``0.1 px * (spacing / 100 px)^2`` (see :func:`fit_residual_grids`).
    sigma_temporal : float, optional
        Standard deviation (px) of the equality of the grids of consecutive images (block
        order) of one camera group, also where the images of other groups come between
        them; ``per="image"`` only. None: no temporal constraints.
    sigma_amplitude : float or "residuals" or None
        Standard deviation (px) of every node's value about zero: the expected size of the
        field (see the module). ``"residuals"`` (default): twice the RMS per coordinate of
        the grids of this spacing and smoothness fitted to the tie-point residuals of
        ``block`` at its given values - pass an adjusted block (as from a first
        adjustment), or a number where the block starts far from its solution. None: no
        amplitude (only smoothness, temporal constraints and datum; the datum conditions
        are then a dense block of (2 nodes)^2 entries per grid in the normal equations,
        refused where they cannot fit in memory).
    datum : {"similarity", "affine"}, optional
        Components of every grid held at zero (see the module); default ``"similarity"``
        per image, ``"affine"`` per camera.
    border : {"mean", "linear"}
        Smoothness rule of border nodes (:meth:`GridLayout.constraint_matrix`).
    min_support : int
        A node is supported when its adjacent cells hold at least this many observations.
    std : bool, optional
        Standard deviations of the nodes from the joint covariance (the diagonal of the
        inverse at the nodes, by a supernodal selected inversion of the system reduced by
        the points in the fill-reducing order of its sparse factor;
        ``backend="cg"`` factorises it with ``"auto"``).
        None: when at most 10 000 unknowns remain after the points (:data:`STD_MAX`).
    options : BundleOptions, optional
        Settings of the adjustment; keyword arguments override fields. The loss must be
        ``"squared"``; variance components, free networks and point covariances are not
        supported here, nor data snooping (``snooping=True`` or ``alpha`` as keywords are
        refused; ``options.snooping`` is not applied).
        Default: ``BundleOptions(initial_damping=1e-8)`` (:data:`INITIAL_DAMPING`; the
        grids' weak directions converge in a few Gauss-Newton steps, where a start at 1e-4
        needed 10 or more; the bundle adjustment's default too).
    progress : callable, optional
        ``progress(iteration, cost, damping)`` after each accepted step.
    **kwargs
        Fields of :class:`~photogeom.bundle.BundleOptions` overriding those of
        ``options`` (e.g. ``max_iter``).

    Returns
    -------
    GridAdjustment

    Raises
    ------
    InputError
        Bad spacing (0, negative, larger than the image), per, datum, sigmas or options;
        observations outside their image.
    DegenerateGeometryError
        As :func:`photogeom.bundle_adjust` (datum defect, points behind cameras), or a
        singular system.
    ConvergenceError
        ``backend="cg"``: conjugate gradients did not solve the normal equations in
        ``10 n`` iterations (the message names the direct backends).
    """
    t0 = time.perf_counter()
    if not isinstance(block, Block):
        raise InputError(
            f"adjust_with_grids needs a photogeom.bundle.Block, got {type(block).__name__}"
        )
    if per not in PER:
        raise InputError(f"per must be one of {', '.join(PER)}, not {per!r}")
    datum = datum or ("similarity" if per == "image" else "affine")
    if datum not in DATUMS:
        raise InputError(f"datum must be one of {', '.join(DATUMS)}, not {datum!r}")
    if border not in BORDERS:
        raise InputError(f"border must be one of {', '.join(BORDERS)}, not {border!r}")
    check_min_support(min_support)
    from .grid import scaled_constraint_sigma

    sc = check_spacing(scaled_constraint_sigma(sigma_constraint, spacing), "sigma_constraint")
    st = None if sigma_temporal is None else check_spacing(sigma_temporal, "sigma_temporal")
    if st is not None and per != "image":
        raise InputError("sigma_temporal needs per='image' (temporal constraints join images)")
    opts = options or BundleOptions(initial_damping=INITIAL_DAMPING)
    opts = opts.updated(**kwargs) if kwargs else opts.validate()
    if opts.loss != "squared":
        raise InputError(
            f"adjust_with_grids: loss={opts.loss!r} is not supported (squared loss only); "
            "remove blunders first (photogeom.bundle_adjust with snooping)"
        )
    if opts.variance_components:
        raise InputError("adjust_with_grids: variance_components=True is not supported")
    _refuse_unapplied(opts, kwargs)
    if opts.datum == "free":
        raise InputError(
            "adjust_with_grids needs a datum by control points or GNSS positions "
            "(datum='free' is not supported)"
        )
    block.validate()
    sa = _amplitude(block, sigma_amplitude, spacing, sc, border)
    gp = _GridProblem(block, opts, spacing, per, datum, sc, st, sa, border)
    s, z, N, cost, it, converged, message, history = _levenberg_marquardt(gp, opts, progress)
    # the block's own unknowns, which no grid determines (a part hinged on one or two points)
    check_state_determined(gp.bp, s)
    n_obs = 2 * gp.n + _prior_count(gp.bp) + gp.n_pseudo
    redundancy = int(n_obs - gp.free_idx.size)
    # the cost is whitened by the sigmas alone; with the weights P = sigma0_prior^2 / sigma^2
    # of the options (the bundle adjustment's convention) sigma0 is sigma0_prior times its
    # root, the cofactors are the sigmas' divided by sigma0_prior^2, and the standard
    # deviations do not depend on sigma0_prior
    var = cost / redundancy if redundancy > 0 else float("nan")
    s0p = float(opts.sigma0_prior)
    sigma0 = s0p * math.sqrt(var)
    est = gp.bp.to_block(s)
    # grids as ResidualGrid objects, with the image's residuals at the joint solution
    v, _ = gp.residuals(s, z)
    gv = gp.grid_values(z)
    bp = gp.bp
    want_std = std if std is not None else (gp.free_idx.size - 3 * bp.p) <= STD_MAX
    cof = _grid_cofactors(gp, N, opts.backend) if want_std else None
    objs, node_std = {}, ({} if want_std else None)
    for g, key in enumerate(gp.grid_keys):  # grids, not points
        L = gp.layouts[g]
        sel = np.flatnonzero(gp.obs_grid == g)
        if L is None:
            continue
        nodes = z[gp.goff[g] : gp.goff[g + 1]].reshape(L.shape[0], L.shape[1], 2)
        counts = _node_counts(L, bp.uv[sel]) if sel.size else np.zeros(L.shape, np.int64)
        std_g = []
        if cof is not None:
            c = cof[gp.goff[g] : gp.goff[g + 1]].reshape(L.shape[0], L.shape[1], 2)
            node_std[key] = np.sqrt(var * c)
            std_g = [c.mean(axis=2) / s0p**2]
        objs[key] = ResidualGrid(
            layout=L,
            nodes=nodes,
            sigma0=sigma0,
            redundancy=redundancy,
            sigma_obs=bp.sigma_obs()[sel],
            sigma_constraint=sc,
            support=counts >= min_support,
            counts=counts,
            rms_before=_rms_len(v[sel] + gv[sel]),
            rms_after=_rms_len(v[sel]),
            border=border,
            _std=std_g,
        )
    if per == "image":
        grids = {k: objs[k] for k in gp.grid_keys if k in objs}
    else:
        cam_ids = block.camera_ids.tolist()
        grids = {
            iid: objs[cam_ids[c]]
            for iid, c in zip(block.image_ids.tolist(), block.image_camera.tolist())
            if cam_ids[c] in objs
        }
    from ..bundle.adjustment import adjust_block
    from .blocks import correct_block_observations
    from .chain import chain_redundancy

    corrected = correct_block_observations(est, grids)
    record = JointAdjustmentRecord(
        est,
        opts,
        spacing,
        per,
        datum,
        sc,
        st,
        sa,
        border,
        _observations_digest(corrected),
        _observations_digest(est),
        grids_digest(est, grids) or "",
    )
    corrected = corrected.replace(joint_adjustment=record)
    # the re-adjustment's residuals are the joint adjustment's: sigma0 over the chain of the
    # two (its effective redundancy; over the re-adjustment's own count it was too small)
    chain = chain_redundancy(corrected, {}, uncorrected=corrected.image_ids.tolist())
    final = adjust_block(
        corrected,
        opts.updated(fix_exterior=True, free=(), snooping=False, point_covariance=False),
        effective_redundancy=chain,
    )
    final = replace(
        final,
        block=final.block.replace(joint_adjustment=record),
        notes=(*final.notes, IN_ADJUSTMENT_NOTE),
    )
    return GridAdjustment(
        grids=grids,
        block=est.replace(joint_adjustment=record),
        fit=final,
        per=per,
        spacing=float(gp.layouts[0].spacing if gp.layouts[0] is not None else spacing),
        datum=datum,
        sigma_constraint=sc,
        sigma_temporal=float("nan") if st is None else st,
        sigma_amplitude=float("nan") if sa is None else sa,
        sigma0=sigma0,
        redundancy=redundancy,
        n_unknowns=int(gp.free_idx.size),
        node_std=node_std,
        converged=converged,
        iterations=it,
        message=message,
        cost_history=history,
        elapsed=time.perf_counter() - t0,
    )


def _refuse_unapplied(opts: BundleOptions, asked: dict) -> None:
    """Refuse the settings of the bundle adjustment that the joint adjustment does not
    apply, when asked for: data snooping (``snooping=True`` or ``alpha`` given as keywords;
    the ``snooping`` of an ``options`` object, True by default there, is not applied) and
    point covariances (``point_covariance=True``). Both were accepted and silently left
    out: no w-test, no ``point_std``."""
    if asked.get("snooping") or "alpha" in asked:
        given = "snooping=True" if asked.get("snooping") else f"alpha={asked['alpha']!r}"
        raise InputError(
            f"adjust_with_grids: {given} is not supported (the joint adjustment with grids "
            "runs no data snooping); remove blunders first (photogeom.bundle_adjust with "
            "snooping=True), then adjust with grids without snooping or alpha"
        )
    if opts.point_covariance:
        raise InputError(
            "adjust_with_grids: point_covariance=True is not supported (the joint adjustment "
            "reports the node standard deviations, std=True; its final fit holds the "
            "orientation fixed): leave point_covariance out"
        )


def _prior_count(bp: Problem) -> int:
    return int(3 * (np.sum(bp.has_gnss) + np.sum(bp.has_imu) + bp.control.size))


def _amplitude(block: Block, value, spacing: float, sc: float, border: str) -> float | None:
    """``sigma_amplitude`` resolved to pixels (None: no amplitude)."""
    if value is None:
        return None
    if isinstance(value, str):
        if value != AMPLITUDE_FROM_RESIDUALS:
            raise InputError(
                f"sigma_amplitude must be a positive number of pixels, "
                f"{AMPLITUDE_FROM_RESIDUALS!r} or None, not {value!r}"
            )
        return AMPLITUDE_FACTOR * _smooth_residual_rms(block, spacing, sc, border)
    return check_spacing(value, "sigma_amplitude")


def _smooth_residual_rms(block: Block, spacing: float, sc: float, border: str) -> float:
    """RMS per coordinate (px), at the tie observations, of the grids of this spacing and
    smoothness fitted to the block's tie-point residuals (images with at least 4 of them,
    all finite)."""
    from .blocks import block_residuals, fit_residual_grids

    per = block_residuals(block)
    use = [k for k, (uv, v) in per.items() if np.all(np.isfinite(v)) and len(v) >= 4]
    if use:
        grids = fit_residual_grids(
            block, spacing, images=use, sigma_constraint=sc, border=border, folds=0
        )
        fitted = np.concatenate([grids[k].evaluate(per[k][0]) for k in use])  # images
        rms = float(np.sqrt(np.mean(fitted * fitted)))
    else:
        rms = 0.0
    if not (math.isfinite(rms) and rms > 0):
        raise InputError(
            "sigma_amplitude='residuals': the block has no tie-point residuals to take it "
            "from (fewer than 4 per image, or all zero); give sigma_amplitude in pixels or None"
        )
    return rms
