"""Multi-view triangulation of a block's points with its cameras held fixed (vectorised).

For every requested point, all its image observations (optionally only those of some images)
are undistorted to normalised rays with the image's calibration, a linear start minimises
the sum of squared perpendicular distances to the rays (the "midpoint" of k rays), and a few
Gauss-Newton iterations minimise the weighted reprojection error in pixels through the full
Metashape model (:func:`~photogeom.camera.frame_kernel.project_rows`). Every point has its own
3x3 normal equations; all are formed with ``bincount`` over the observation rows and solved in
one batched call, so the cost is linear in the number of observations.

Points that cannot be triangulated keep NaN coordinates and a named status
(:data:`STATUS_TEXT`), never a silently wrong value.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera.frame_kernel import project_rows
from ..errors import InputError
from ..records import ReadOnlyRecord
from .block import Block, _ids, _lookup

__all__ = [
    "STATUS_BEHIND",
    "STATUS_NOT_CONVERGED",
    "STATUS_OK",
    "STATUS_POORLY_CONDITIONED",
    "STATUS_TEXT",
    "STATUS_TOO_FEW_RAYS",
    "STATUS_UNDISTORTION_FAILED",
    "Triangulation",
    "triangulate",
]

STATUS_OK = 0
STATUS_TOO_FEW_RAYS = 1
STATUS_BEHIND = 2
STATUS_POORLY_CONDITIONED = 3
STATUS_NOT_CONVERGED = 4
STATUS_UNDISTORTION_FAILED = 5
#: Meaning of each status code of :class:`Triangulation`.
STATUS_TEXT = {
    STATUS_OK: "triangulated",
    STATUS_TOO_FEW_RAYS: "too few rays (observed in fewer than min_rays of the images used)",
    STATUS_BEHIND: "behind a camera (the intersection lies behind one of the images seeing it)",
    STATUS_POORLY_CONDITIONED: "poorly conditioned (rays nearly parallel: spread below min_angle)",
    STATUS_NOT_CONVERGED: "not converged within the iterations",
    STATUS_UNDISTORTION_FAILED: "an observation could not be undistorted (outside the domain "
    "where the calibration's distortion is one-to-one)",
}


@dataclass(frozen=True, eq=False)
class Triangulation(ReadOnlyRecord):
    """Triangulated points (see :func:`triangulate`).

    Attributes
    ----------
    point_ids : (k,) ids of the points, in the order asked for.
    xyz : (k, 3) object coordinates; NaN where ``status != 0``.
    status : (k,) int codes, see :data:`STATUS_TEXT`.
    n_rays : (k,) number of observations used per point.
    angle : (k,) ray spread, radians: ``2 asin(sqrt(lambda_min / k))`` of the ray matrix
        ``sum(I - d d')``; for two rays exactly their intersection angle.
    rms : (k,) RMS of the reprojection residual vectors over the point's rays, pixels.
    covariance : (k, 3, 3) or None
        A-priori covariance ``(J' W J)^-1`` from the observations' sigmas (object units
        squared); NaN where ``status != 0``. Only when asked for.
    iterations : int
        Gauss-Newton iterations performed.
    """

    point_ids: np.ndarray
    xyz: np.ndarray
    status: np.ndarray
    n_rays: np.ndarray
    angle: np.ndarray
    rms: np.ndarray
    covariance: np.ndarray | None
    iterations: int

    @property
    def ok(self) -> np.ndarray:
        """(k,) bool: points with status 0."""
        return self.status == STATUS_OK

    @property
    def all_ok(self) -> bool:
        return bool(np.all(self.status == STATUS_OK))

    @property
    def std(self) -> np.ndarray | None:
        """(k, 3) a-priori standard deviations of X, Y, Z (None without covariance)."""
        if self.covariance is None:
            return None
        return np.sqrt(np.einsum("kii->ki", self.covariance))

    def describe_failures(self, limit: int = 5) -> str:
        """One line naming the points that failed and why.

        Parameters
        ----------
        limit : int
            Points named at most; the others are counted.

        Returns
        -------
        str
            The line; empty when every point was triangulated.
        """
        bad = np.flatnonzero(self.status != STATUS_OK)
        if bad.size == 0:
            return ""
        parts = [
            f"point {self.point_ids[i]}: {STATUS_TEXT[int(self.status[i])]}" for i in bad[:limit]
        ]
        more = f" (and {bad.size - limit} more)" if bad.size > limit else ""
        return f"{bad.size} point(s) not triangulated: " + "; ".join(parts) + more

    def apply(self, block: Block, *, on_failure: str = "raise") -> Block:
        """A new block with these points' coordinates replaced by the triangulated ones.

        The survey of control and check points is kept (:attr:`Block.surveyed`): the
        triangulated coordinates are estimates, and an adjustment of the new block still
        holds its control points to the survey and compares its check points with it.

        Parameters
        ----------
        block : Block
            A block holding all of :attr:`point_ids`.
        on_failure : {"raise", "keep"}
            Points that were not triangulated: raise :class:`InputError` naming them, or keep
            their coordinates in ``block``.

        Returns
        -------
        Block
            The new block.
        """
        if on_failure not in ("raise", "keep"):
            raise InputError(f"on_failure must be 'raise' or 'keep', got {on_failure!r}")
        if on_failure == "raise" and not self.all_ok:
            raise InputError(self.describe_failures() + " (pass on_failure='keep' to keep them)")
        rows = _lookup(block.point_ids, self.point_ids, "Triangulation.apply", "points")
        xyz = block.xyz.copy()
        xyz[rows[self.ok]] = self.xyz[self.ok]
        # the triangulated coordinates are estimates: the survey of control and check
        # points stays the survey (on a block without ``surveyed`` its xyz is the survey)
        return block.replace(xyz=xyz, surveyed=block.survey)

    def __len__(self) -> int:
        return int(self.point_ids.size)


def _sum_rows(index: np.ndarray, values: np.ndarray, k: int) -> np.ndarray:
    """Sum rows of ``values`` (n, ...) into ``k`` bins by ``index`` (n,)."""
    flat = values.reshape(values.shape[0], -1)
    out = np.empty((k, flat.shape[1]))
    for c in range(flat.shape[1]):  # over the few entries of a small matrix, not over rows
        out[:, c] = np.bincount(index, weights=flat[:, c], minlength=k)
    return out.reshape((k, *values.shape[1:]))


def _singular(N: np.ndarray) -> np.ndarray:
    """(k,) True where a 3x3 normal matrix is not finite or numerically singular."""
    fin = np.all(np.isfinite(N.reshape(N.shape[0], -1)), axis=1)
    out = ~fin
    if np.any(fin):
        lam = np.linalg.eigvalsh(N[fin])
        out[fin] = ~(lam[:, 0] > 1e-12 * np.maximum(lam[:, 2], 1e-300))
    return out


def normalized_rays(block: Block, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalised coordinates ``(X/Z, Y/Z)`` (Metashape axes) of observation rows.

    Affinity, shear and principal point are removed with each image's calibration (including
    image-variant offsets of f, cx, cy), the Brown distortion with its camera group's
    coefficients (one vectorised Newton inversion per group).

    Returns
    -------
    xy : (n, 2) normalised coordinates.
    ok : (n,) bool, False where the undistortion did not converge.
    """
    uv = block.observations.uv[rows]
    img = block.obs_image[rows]
    cal = block.calibration_matrix()[img]
    size = block.image_sizes()[img]
    f, cx, cy, b1, b2 = cal[:, 0], cal[:, 1], cal[:, 2], cal[:, 9], cal[:, 10]
    yd = (uv[:, 1] - (size[:, 1] * 0.5 - 0.5 + cy)) / f
    xd = (uv[:, 0] - (size[:, 0] * 0.5 - 0.5 + cx) - b2 * yd) / (f + b1)
    xy = np.column_stack([xd, yd])
    ok = np.ones(rows.size, dtype=bool)
    group = block.image_camera[img]
    for g in np.unique(group):  # camera groups, not points
        sel = np.flatnonzero(group == g)
        c = block.calibrations[g]
        res = c.distortion.undistort(xy[sel], tol=1e-10, scale=(c.f + c.b1, c.f))
        xy[sel] = res.points
        ok[sel] = res.converged
    return xy, ok


def triangulate(
    block: Block,
    point_ids: Sequence | None = None,
    *,
    images: Sequence | None = None,
    iterations: int = 20,
    tol: float = 1e-10,
    min_rays: int = 2,
    min_angle: float = 1e-3,
    covariance: bool = False,
) -> Triangulation:
    """Triangulate points from the block's image observations with its cameras fixed.

    Parameters
    ----------
    block : Block
        Cameras (calibrations, exterior orientations) are taken as exact; the observations'
        ``sigma`` weight the reprojection error.
    point_ids : sequence, optional
        Points to triangulate (default: all points of the block, whatever their role).
    images : sequence of image ids, optional
        Use only the observations in these images (e.g. one stereo pair).
    iterations : int
        Maximum Gauss-Newton iterations after the linear start.
    tol : float
        A point has converged when its last step is below ``tol`` times its distance to the
        cameras (relative, dimensionless).
    min_rays : int
        Minimum number of observations per point (>= 2).
    min_angle : float
        Minimum ray spread in radians (see :attr:`Triangulation.angle`); below it the point
        is reported as poorly conditioned.
    covariance : bool
        Also return the a-priori 3x3 covariance per point.

    Returns
    -------
    Triangulation
        Coordinates, per-point status, ray counts and spread, RMS residual, covariances.

    Raises
    ------
    InputError
        Unknown point or image ids, ``min_rays < 2``, ``iterations < 1``.
    """
    if min_rays < 2:
        raise InputError("min_rays must be >= 2 (one ray does not fix a point)")
    if iterations < 1:
        raise InputError("iterations must be >= 1")
    if point_ids is None:
        pts = np.arange(block.n_points)
        pid = block.point_ids
    else:
        pid = _ids(point_ids, "triangulate point_ids")
        pts = _lookup(block.point_ids, pid, "triangulate point_ids", "points")
    k = pts.size
    # observation rows of the requested points (and images)
    local = np.full(block.n_points, -1, dtype=np.int64)
    local[pts] = np.arange(k)
    use = local[block.obs_point] >= 0
    if images is not None:
        iid = _ids(images, "triangulate images")
        irow = _lookup(block.image_ids, iid, "triangulate images", "images")
        keep = np.zeros(block.n_images, dtype=bool)
        keep[irow] = True
        use &= keep[block.obs_image]
    rows = np.flatnonzero(use)
    lp = local[block.obs_point[rows]]
    status = np.zeros(k, dtype=np.int8)
    xy, und_ok = normalized_rays(block, rows)
    bad_und = np.bincount(lp[~und_ok], minlength=k) > 0
    rows, lp, xy = rows[und_ok], lp[und_ok], xy[und_ok]
    n_rays = np.bincount(lp, minlength=k)
    img = block.obs_image[rows]
    M = block.rotations()
    C_all = block.exterior[:, :3]
    centre = C_all.mean(axis=0) if block.n_images else np.zeros(3)
    C = C_all[img] - centre
    Mr = M[img]
    # object-space ray directions: photogrammetric image system (x, -y, -1), then M'
    dcam = np.column_stack([xy[:, 0], -xy[:, 1], -np.ones(rows.size)])
    d = np.einsum("nji,nj->ni", Mr, dcam)
    d /= np.linalg.norm(d, axis=1)[:, None]
    P = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    A = _sum_rows(lp, P, k)
    b = _sum_rows(lp, np.einsum("nij,nj->ni", P, C), k)
    few = n_rays < min_rays
    A[few] = np.eye(3)
    lam = np.linalg.eigvalsh(A)
    spread = 2.0 * np.arcsin(np.sqrt(np.clip(lam[:, 0] / np.maximum(n_rays, 1), 0.0, 1.0)))
    spread[few] = np.nan
    weak = ~few & ~(spread >= min_angle)
    A[weak] = np.eye(3)
    X = np.linalg.solve(A, b[:, :, None])[:, :, 0]
    # --- Gauss-Newton on the pixel reprojection error ---------------------------------------
    active = ~few & ~weak & ~bad_und
    cal = block.calibration_matrix()[img]
    size = block.image_sizes()[img]
    obs = block.observations.uv[rows]
    w = 1.0 / block.observations.sigma[rows] ** 2
    dist = np.sqrt(_sum_rows(lp, np.sum((X[lp] - C) ** 2, axis=1), k) / np.maximum(n_rays, 1))
    conv = np.zeros(k, dtype=bool)
    singular = np.zeros(k, dtype=bool)
    done = 0
    for _ in range(iterations):
        todo = active & ~conv
        sel = np.flatnonzero(todo[lp])  # rows of the points still moving
        if sel.size == 0:
            break
        ls = lp[sel]
        pr = project_rows(X[ls], Mr[sel], C[sel], cal[sel], size[sel])
        r = obs[sel] - pr.uv
        J = pr.d_point
        JW = J * w[sel, None, None]
        N = _sum_rows(ls, np.einsum("nai,naj->nij", JW, J), k)
        g = _sum_rows(ls, np.einsum("nai,na->ni", JW, r), k)
        N[~todo] = np.eye(3)
        g[~todo] = 0.0
        sing = _singular(N)
        if np.any(sing):  # e.g. a ray through the point at zero depth: stop that point
            singular |= sing
            active &= ~sing
            todo &= ~sing
            N[sing] = np.eye(3)
            g[sing] = 0.0
        dx = np.linalg.solve(N, g[:, :, None])[:, :, 0]
        X = X + dx
        done += 1
        conv |= todo & (np.linalg.norm(dx, axis=1) <= tol * np.maximum(dist, 1e-300))
    pr = project_rows(X[lp], Mr, C, cal, size, jacobian=covariance)
    r = pr.uv - obs
    rms = np.sqrt(_sum_rows(lp, np.sum(r * r, axis=1), k) / np.maximum(n_rays, 1))
    behind = np.bincount(lp[~(pr.depth > 0)], minlength=k) > 0
    status[~conv] = STATUS_NOT_CONVERGED
    status[behind] = STATUS_BEHIND
    status[weak | singular] = STATUS_POORLY_CONDITIONED
    status[bad_und] = STATUS_UNDISTORTION_FAILED
    status[few] = STATUS_TOO_FEW_RAYS
    good = status == STATUS_OK
    xyz = X + centre
    xyz[~good] = np.nan
    rms[~good & few] = np.nan
    cov = None
    if covariance:
        JW = pr.d_point * w[:, None, None]
        N = _sum_rows(lp, np.einsum("nai,naj->nij", JW, pr.d_point), k)
        N[~good] = np.eye(3)
        cov = np.linalg.inv(N)
        cov[~good] = np.nan
    return Triangulation(
        point_ids=pid,
        xyz=xyz,
        status=status,
        n_rays=n_rays,
        angle=spread,
        rms=rms,
        covariance=cov,
        iterations=done,
    )
