"""The redundancy of the chain adjustment - residual grids - re-adjustment.

When residual grids are fitted to the residuals of a block's own observations and the
corrected observations are adjusted again with the exterior orientation and calibration
held (:func:`~photogeom.calibration.readjust`), the final residuals are, linearised at the
solution and whitened by the observations' standard deviations,

    v = (I - H3) (I - G) (I - H1) e,

``e`` the observation errors, ``H1`` the hat matrix of the first adjustment (orientations,
calibration and points, with the GNSS, IMU and control-point observations), ``G`` the grids'
smoothers (each image's grid fitted to the residuals of the tie points it kept, evaluated at
every observation of the image) and ``H3`` the hat matrix of the re-adjustment (points only).
With ``e ~ N(0, sigma^2 I)``, ``E[v'v] = sigma^2 tr(M'M)`` for ``M`` the product above: the
chain's effective redundancy ``r = tr(M'M)``, the divisor that makes ``v'v / r`` unbiased.
It is below the re-adjustment's own count (observations minus point unknowns) by the first
adjustment's orientation and calibration unknowns (held afterwards at values that absorbed
part of the noise) and by what the grids took up.

When the block is the final fit's block of
:func:`~photogeom.calibration.adjust_with_grids` (its ``joint_adjustment`` record, which copies
and CSV block folders keep), ``H1`` is the hat matrix of that joint
adjustment (its calibration and grid nodes among the unknowns, the grids'
pseudo-observations a prior without errors of their own).

``tr(M'M) = E|M z|^2`` for random signs ``z`` (Hutchinson's estimator); every product ``M z``
is three linear solves: the first adjustment's normal equations, each grid's, and one 3 x 3
system per point. With ``K`` probes the relative standard error is about ``sqrt(2 / (K r))``;
a small problem is computed exactly (``M`` applied to every unit vector).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp

from ..adjust.sparse import factorize
from ..bundle._angles import opk_from_rotations
from ..bundle.adjustment import NCAL, Problem
from ..bundle.block import Block
from ..bundle.options import BundleOptions
from ..camera.frame_kernel import opk_from_increment_jacobian
from ..errors import DegenerateGeometryError, InputError
from .grid import FiniteElementSystem, fitted_solver
from .gridfile import match_grid_ids

__all__ = ["chain_redundancy"]

#: Probes of the estimate (random-sign vectors), at least: relative standard error about
#: ``sqrt(2 / (K r))``, 0.5 % for a redundancy of 10 000, 1.6 % for 1000, 4 % for 150.
PROBES = 8
#: More probes, a batch of :data:`PROBES` at a time, while the estimate's standard error is
#: above this share of it (1 %: 0.5 % on sigma0) ...
RELATIVE_ERROR = 0.01
#: ... up to this many probes.
MAX_PROBES = 64
#: Problems with at most this many observation components are computed exactly.
EXACT_ROWS = 256
#: Probes applied together (columns of one batch of solves).
BATCH = 64


def _first_jacobian(problem: Problem) -> tuple[sp.csr_matrix, dict]:
    """The whitened Jacobian (rows: image observations x then y per row, GNSS, IMU, control
    coordinates; columns: the free unknowns) of ``problem`` at its initial state, and the
    row ranges of the prior groups."""
    s = problem.initial_state()
    lin = problem.linearize(s, np.ones(problem.obs_i.size))
    m, b = problem.m, problem.b
    off_points = m * b + problem.ng * NCAL
    n_cols = off_points + 3 * problem.p
    free = np.concatenate(
        [problem.local_free.ravel(), problem.global_free, np.ones(3 * problem.p, bool)]
    )
    col_of = np.full(n_cols, -1)
    col_of[free] = np.arange(int(free.sum()))
    n = problem.obs_i.size
    cols = problem.jacobian_columns(off_points)  # (n, b + NCAL + 3)
    vals = np.concatenate([lin.A, lin.G, lin.P], axis=2)  # (n, 2, b + NCAL + 3)
    R = [np.broadcast_to(2 * np.arange(n)[:, None, None] + np.arange(2)[None, :, None], vals.shape)]
    Cc = [np.broadcast_to(cols[:, None, :], vals.shape)]
    V = [vals]
    rows = {"image": (0, 2 * n)}
    start = 2 * n
    gf = problem.group_factor
    block = problem.block

    def add(name, k_idx, local_cols, J):  # J (k, 3, c) on columns local_cols (k, c)
        nonlocal start
        k = k_idx.size
        r = start + 3 * np.arange(k)[:, None, None] + np.arange(3)[None, :, None]
        R.append(np.broadcast_to(r, J.shape))
        Cc.append(np.broadcast_to(local_cols[:, None, :], J.shape))
        V.append(J)
        rows[name] = (start, start + 3 * k)
        start += 3 * k

    if np.any(problem.has_gnss):
        k = np.flatnonzero(problem.has_gnss)
        sg = block.gnss_sigma[k] * math.sqrt(gf["gnss"])
        J = np.einsum("ka,ab->kab", 1.0 / sg, np.eye(3))
        add("gnss", k, k[:, None] * b + np.arange(3), J)
    if np.any(problem.has_imu):
        k = np.flatnonzero(problem.has_imu)
        sg = block.imu_sigma[k] * math.sqrt(gf["imu"])
        J = opk_from_increment_jacobian(opk_from_rotations(s.M[k])) / sg[:, :, None]
        add("imu", k, k[:, None] * b + 3 + np.arange(3), J)
    if problem.control.size:
        c = problem.control
        sg = np.broadcast_to(problem.control_sigma, (c.size, 3)) * math.sqrt(gf["control"])
        J = np.einsum("ka,ab->kab", 1.0 / sg, np.eye(3))
        add("control", c, off_points + 3 * c[:, None] + np.arange(3), J)
    R_ = np.concatenate([x.ravel() for x in R])
    C_ = col_of[np.concatenate([x.ravel() for x in Cc])]
    V_ = np.concatenate([x.ravel() for x in V])
    keep = (C_ >= 0) & (V_ != 0)
    J = sp.csr_matrix((V_[keep], (R_[keep], C_[keep])), shape=(start, int(free.sum())))
    return J, rows


def _first_problem(block: Block) -> Problem:
    """The first adjustment of ``block``: its free calibration (``block.free``), its datum
    from the control points and GNSS positions, a free network without them (the residuals,
    hence the hat matrix, do not depend on the datum)."""
    gnss = np.all(np.isfinite(block.gnss), axis=1)
    imu = np.all(np.isfinite(block.imu), axis=1)
    weighted = bool(np.any(block.role == "control") or gnss.any() or imu.any())
    try:
        return Problem(block, BundleOptions(datum="auto" if weighted else "free"))
    except DegenerateGeometryError as exc:
        raise DegenerateGeometryError(
            f"the effective redundancy of readjust's chain linearises the first adjustment "
            f"of the block the grids were fitted to, which its observations do not allow: "
            f"{exc}"
        ) from None


class _Chain:
    """The linearised chain of one block and its grids: :meth:`apply` gives ``M Z``."""

    def __init__(
        self, block: Block, grids: Mapping, uncorrected=(), joint_uncorrected=()
    ) -> None:
        from .in_adjustment import joint_first_adjustment

        # the re-adjustment: points only, the same observation rows (same block structure)
        p3 = Problem(block, BundleOptions(fix_exterior=True, free=()))
        joint = joint_first_adjustment(block)
        rec = block.joint_adjustment
        #: why the block's record of a joint adjustment does not apply (None: none, or used)
        self.lost = None if rec is None else rec.mismatch(block)
        if joint is None:
            p1 = _first_problem(block)
            self.J1, self.rows = _first_jacobian(p1)
            F1 = factorize(
                (self.J1.T @ self.J1).tocsc(), what="normal matrix of the first adjustment"
            )
            self.solve1 = F1.solve
            self.sigma = p1.sigma_obs()  # px, the whitening of the image rows
            self.joint = False
            if len(joint_uncorrected):
                raise InputError(
                    "joint_uncorrected names images left out of the correction by the grids "
                    "of a joint adjustment with grids, but the block is not the final fit of "
                    "adjust_with_grids (GridAdjustment.fit.block): leave joint_uncorrected out"
                )
            self.J1_model = self.J1
        else:  # the block of adjust_with_grids' final fit: the joint adjustment was first
            self.J1, self.rows, self.solve1, self.sigma, nodes = joint
            self.joint = True
            self.J1_model = self._without_grids(self.J1, nodes, p3, block, joint_uncorrected)
        self.n_rows = self.J1.shape[0]
        self.n_img = self.sigma.size
        lin3 = p3.linearize(p3.initial_state(), np.ones(p3.obs_i.size))
        self.P3 = lin3.P  # (n, 2, 3) whitened
        self.obs_j = p3.obs_j
        self.n_points = p3.p
        V = np.zeros((p3.p, 3, 3))
        np.add.at(V, p3.obs_j, np.einsum("nda,ndb->nab", lin3.P, lin3.P))
        self.control = p3.control
        if self.control.size:
            sg = np.broadcast_to(p3.control_sigma, (self.control.size, 3)) * math.sqrt(
                p3.group_factor["control"]
            )
            self.w_ctrl = 1.0 / sg  # (c, 3)
            V[self.control[:, None], np.arange(3), np.arange(3)] += self.w_ctrl**2
        self.Vinv = np.linalg.inv(V)
        self.images = self._grid_operators(block, grids, p3, uncorrected)

    @staticmethod
    def _without_grids(J1, nodes: slice, problem, block: Block, left) -> sp.csr_matrix:
        """``J1`` with the grid nodes' entries of the rows of the images ``left`` (ids)
        zeroed: the part of the joint adjustment's fit that reaches the observations of the
        re-adjustment. Those images' observations are not corrected by their grids, so
        their residuals at the held cameras keep the grids' share of the fit."""
        if not len(left):
            return J1
        ids = block.image_ids.tolist()
        unknown = [k for k in left if k not in set(ids)]
        if unknown:
            raise InputError(
                f"joint_uncorrected: unknown image id(s) {', '.join(map(str, unknown[:5]))}"
            )
        out = set(left)
        bad = np.array([iid in out for iid in ids], dtype=bool)[problem.obs_i]  # (n,)
        J = J1.tocoo()
        drop = (
            (J.row < 2 * bad.size)
            & bad[np.minimum(J.row // 2, bad.size - 1)]
            & (J.col >= nodes.start)
            & (J.col < nodes.stop)
        )
        return sp.csr_matrix((J.data[~drop], (J.row[~drop], J.col[~drop])), shape=J1.shape)

    @staticmethod
    def _grid_operators(block, grids, problem, uncorrected) -> list:
        """Per corrected image: its rows in the adjustment, the rows among them whose
        positions its grid kept (and their places in the fit), the grid's factorised normal
        equations and design matrix at every row of the image."""
        kept = set(uncorrected)
        ids = block.image_ids.tolist()
        key_of, _ = match_grid_ids(ids, grids)
        order = np.argsort(problem.obs_i, kind="stable")
        bounds = np.searchsorted(problem.obs_i[order], np.arange(block.n_images + 1))
        out = []
        for i, iid in enumerate(ids):  # images, not points
            rows = order[bounds[i] : bounds[i + 1]]
            if iid in kept or iid not in key_of or rows.size == 0:
                continue
            g = grids[key_of[iid]]
            if g.uv is None:
                raise InputError(
                    f"image {iid}: its grid was read without the pixel positions it was "
                    "fitted to; the chain's redundancy needs them (fit the grids again)"
                )
            used = ~g.outliers if g.outliers.size else np.ones(len(g.uv), bool)
            guv = np.asarray(g.uv)[used]
            uv = problem.uv[rows]
            key = uv[:, 0] + 1j * uv[:, 1]
            srt = np.argsort(key)
            pos = np.clip(np.searchsorted(key[srt], guv[:, 0] + 1j * guv[:, 1]), 0, key.size - 1)
            found = key[srt][pos] == guv[:, 0] + 1j * guv[:, 1]
            solve = fitted_solver(g)  # the fit's own factor, when the grid keeps it
            if solve is None:
                solve = FiniteElementSystem(
                    g.layout,
                    guv,
                    1.0 / np.asarray(g.sigma_obs) ** 2,
                    1.0 / g.sigma_constraint**2,
                    g.border,
                ).solve
            out.append(
                (
                    rows,
                    rows[srt[pos[found]]],  # rows whose residuals the grid was fitted to
                    np.flatnonzero(found),  # their places among the grid's points
                    guv.shape[0],
                    solve,
                    g.layout.design_matrix(uv),
                )
            )
        return out

    def apply(self, Z: np.ndarray) -> np.ndarray:
        """``M Z`` for ``Z`` (n_rows, k) whitened errors."""
        k = Z.shape[1]
        E = Z - self.J1_model @ self.solve1(np.asarray(self.J1.T @ Z))  # first adjustment
        n = self.n_img
        img = E[: 2 * n].reshape(n, 2, k)
        px = img * self.sigma[:, None, None]
        model = np.zeros_like(img)
        for rows, fit_rows, places, n_fit, solve, A_all in self.images:  # images
            L = np.zeros((n_fit, 2 * k))
            L[places] = px[fit_rows].reshape(-1, 2 * k)
            nodes = solve(L)
            model[rows] = np.asarray(A_all @ nodes).reshape(-1, 2, k)
        img = img - model / self.sigma[:, None, None]  # corrected, at the held cameras
        g = np.zeros((self.n_points, 3, k))
        np.add.at(g, self.obs_j, np.einsum("nda,ndk->nak", self.P3, img))
        if self.control.size:
            a, b = self.rows["control"]
            ctrl = E[a:b].reshape(-1, 3, k)
            g[self.control] += self.w_ctrl[:, :, None] * ctrl
        dp = -np.einsum("pab,pbk->pak", self.Vinv, g)
        out = E.copy()
        out[: 2 * n] = (img + np.einsum("nda,nak->ndk", self.P3, dp[self.obs_j])).reshape(2 * n, k)
        if self.control.size:
            out[a:b] = (ctrl + self.w_ctrl[:, :, None] * dp[self.control]).reshape(-1, k)
        return out


def chain_redundancy(
    block: Block,
    grids: Mapping,
    *,
    uncorrected=(),
    probes: int = PROBES,
    seed: int = 0,
    exact: bool | None = None,
    joint_uncorrected=(),
) -> dict:
    """Effective redundancy of the re-adjustment of ``block`` with grids fitted to its own
    residuals (see the module): ``tr(M'M)``, exact or estimated.

    Parameters
    ----------
    block : Block
        The adjusted block the grids were fitted to (``pg.bundle_adjust(...).block``); its
        free calibration parameters (``block.free``) and its GNSS, IMU and control
        observations define the first adjustment, linearised at the block's values with
        least-squares weights.
    grids : mapping
        ``image id -> ResidualGrid`` (with the pixel positions of the fit), linearised with
        their final weights (``sigma_obs``, ``sigma_constraint``: estimated ones included).
    uncorrected : sequence of image ids
        Images without a grid.
    probes : int
        Random-sign probes of the estimate (at least 2), and of each further batch while
        the estimate's standard error is above :data:`RELATIVE_ERROR` of it (up to
        :data:`MAX_PROBES` in all).
    seed : int
        Seed of the probes.
    exact : bool, optional
        Compute the trace exactly (``M`` applied to every unit vector: one batch of solves
        per 64 observation components); default: exact up to 256 observation components.
    joint_uncorrected : sequence of image ids
        When ``block`` is the final fit of :func:`~photogeom.calibration.adjust_with_grids`
        (its ``joint_adjustment`` record): the images whose observations the joint
        adjustment's grids were not applied to (``readjust(ga.block, ga.grids,
        uncorrected=...)``). Their residuals in the re-adjustment keep the grids' part of
        the joint fit: the chain's first step is ``I - J_c N^-1 J'``, ``J_c`` the joint
        Jacobian without the grid nodes in those images' rows. ``block`` is then the
        final fit with every image corrected (only its structure and values at the
        solution count). Refused for another block.

    Returns
    -------
    dict
        ``"value"`` (the effective redundancy, unitless), ``"method"`` (``"exact"`` or
        ``"estimated"``), ``"probes"`` (used) and ``"seed"`` (None when exact), ``"std"``
        (standard error of the estimate, 0 when exact), ``"observations"`` (the
        observation components of the chain), ``"first_adjustment"``
        (``"adjust_with_grids"`` when the block is the final fit of a joint adjustment with
        grids, by its :attr:`~photogeom.bundle.Block.joint_adjustment`, else
        ``"bundle_adjust"``) and ``"note"`` (None, or why the block's record of a joint
        adjustment was not used: the block is no longer that final fit).
    """
    if not (isinstance(probes, int | np.integer) and probes >= 2):
        raise InputError(f"probes must be an integer of at least 2, not {probes!r}")
    chain = _Chain(block, grids, uncorrected, joint_uncorrected)
    n = chain.n_rows
    if exact is None:
        exact = n <= EXACT_ROWS
    if exact:
        total = 0.0
        for lo in range(0, n, BATCH):  # batches of unit vectors
            hi = min(n, lo + BATCH)
            Z = np.zeros((n, hi - lo))
            Z[np.arange(lo, hi), np.arange(hi - lo)] = 1.0
            total += float(np.sum(chain.apply(Z) ** 2))
        return {
            "value": total,
            "method": "exact",
            "probes": None,
            "seed": None,
            "std": 0.0,
            "observations": int(n),
            **_first_words(chain),
        }
    rng = np.random.default_rng(seed)
    per = np.zeros(0)
    while True:  # batches of probes until the relative standard error is small enough
        k = int(probes) if per.size == 0 else min(int(probes), MAX_PROBES - per.size)
        Z = rng.choice(np.array([-1.0, 1.0]), size=(n, k))
        per = np.concatenate(
            [per]
            + [np.sum(chain.apply(Z[:, lo : lo + BATCH]) ** 2, axis=0) for lo in range(0, k, BATCH)]
        )
        std = float(per.std(ddof=1) / math.sqrt(per.size))
        if std <= RELATIVE_ERROR * per.mean() or per.size >= MAX_PROBES:
            break
    return {
        "value": float(per.mean()),
        "method": "estimated",
        "probes": int(per.size),
        "seed": int(seed),
        "std": std,
        "observations": int(n),
        **_first_words(chain),
    }


def _first_words(chain: _Chain) -> dict:
    """``"first_adjustment"`` and ``"note"`` of :func:`chain_redundancy`'s result."""
    if chain.lost is None:
        joint = chain.joint
        return {"first_adjustment": "adjust_with_grids" if joint else "bundle_adjust", "note": None}
    return {
        "first_adjustment": "bundle_adjust",
        "note": (
            "the block carries the record of a joint adjustment with grids "
            "(adjust_with_grids), but "
            f"{chain.lost} differ(s) from that adjustment's final fit, so the chain's first "
            "adjustment is the bundle adjustment of this block and its redundancy is too "
            "large if the grids were fitted to the final fit's residuals: pass the final "
            "fit's block (GridAdjustment.fit.block, a copy of it or a CSV block folder "
            "written from it) to fit_residual_grids and readjust"
        ),
    }
