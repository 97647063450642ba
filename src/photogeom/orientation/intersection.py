"""Space intersection: object points from >= 2 oriented images (vectorised over points).

For every point the image observations of all images that see it are adjusted together:
a linear least-squares intersection of the rays (minimum sum of squared perpendicular
distances) gives start values, then Gauss-Newton iterations on the collinearity equations
(image residuals, computed minus observed) converge for all points at once: each point has
its own 3x3 normal equations, solved in one batched call. Statistics per point: redundancy
``2 k - 3`` for ``k`` rays, sigma0, cofactor and covariance matrices.

Lens distortion is removed from the observations first (iteratively, with a status); the
residuals therefore refer to distortion-free image coordinates. Their weights are those of
the measured coordinates carried through the undistortion: ``P = J.T J / sigma^2`` with
``J`` the 2x2 derivative of the measured (distorted) with respect to the distortion-free
image coordinates, so that the statistics do not depend on where in the image a point lies.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera.collinearity import FrameCamera
from ..camera.distortion import CHUNK
from ..camera.exterior import ExteriorOrientation
from ..camera.interior import InteriorOrientation
from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..records import ReadOnlyRecord
from ..validation import as_float64

__all__ = ["IntersectionResult", "space_intersection"]


@dataclass(frozen=True, eq=False)
class IntersectionResult(ReadOnlyRecord):
    """Intersected object points with per-point statistics.

    Attributes
    ----------
    points : (n, 3) object coordinates.
    cofactor : (n, 3, 3) ``Qxx = (A.T P A)^-1`` per point.
    sigma0 : (n,) a-posteriori standard deviation of unit weight (NaN when r = 0).
    sigma0_prior : float
    redundancy : (n,) int, ``2 k - 3``.
    n_rays : (n,) int, number of images observing each point.
    residuals : (n_images, n, 2) image residuals (computed minus observed; NaN where a point
        is not observed), distortion-free image coordinates in the unit of each image.
    converged : (n,) bool
    iterations : int
    """

    points: np.ndarray
    cofactor: np.ndarray
    sigma0: np.ndarray
    sigma0_prior: float
    redundancy: np.ndarray
    n_rays: np.ndarray
    residuals: np.ndarray
    converged: np.ndarray
    iterations: int

    @property
    def covariance(self) -> np.ndarray:
        """(n, 3, 3) a-posteriori covariance ``sigma0^2 Qxx`` (NaN when r = 0)."""
        return self.sigma0[:, None, None] ** 2 * self.cofactor

    @property
    def covariance_prior(self) -> np.ndarray:
        """(n, 3, 3) a-priori covariance ``sigma0_prior^2 Qxx``."""
        return self.sigma0_prior**2 * self.cofactor

    @property
    def std(self) -> np.ndarray:
        """(n, 3) a-posteriori standard deviations of X, Y, Z."""
        return np.sqrt(np.einsum("nii->ni", self.covariance))

    @property
    def std_prior(self) -> np.ndarray:
        """(n, 3) a-priori standard deviations of X, Y, Z."""
        return np.sqrt(np.einsum("nii->ni", self.covariance_prior))

    @property
    def rmse(self) -> np.ndarray:
        """(n,) per-point RMS of the image residual vectors over its rays."""
        v = np.nan_to_num(self.residuals)
        return np.sqrt(np.sum(v * v, axis=(0, 2)) / np.maximum(self.n_rays, 1))


def _cameras(cameras) -> list[tuple[InteriorOrientation, ExteriorOrientation]]:
    out = []
    for i, c in enumerate(cameras):
        if isinstance(c, FrameCamera):
            out.append((c.interior, c.exterior))
        elif isinstance(c, (tuple, list)) and len(c) == 2:
            io, eo = c
            if not isinstance(io, InteriorOrientation) or not isinstance(eo, ExteriorOrientation):
                raise InputError(f"camera {i}: expected (InteriorOrientation, ExteriorOrientation)")
            out.append((io, eo))
        else:
            raise InputError(f"camera {i}: expected a FrameCamera or an (io, eo) pair")
    return out


def _ideal_image(
    io: InteriorOrientation, xy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Remove distortion: ideal image coordinates, a validity mask and the derivative.

    Returns
    -------
    ideal : (n, 2) distortion-free image coordinates (NaN where unobserved).
    ok : (n,) bool, observed.
    J : (n, 2, 2) or None
        ``d(measured x, y) / d(ideal x, y)`` per point (identity where unobserved); None
        without distortion (identity everywhere).
    """
    ok = np.all(np.isfinite(xy), axis=1)
    out = np.full_like(xy, np.nan)
    if io.distortion is None or not np.any(ok):
        out[ok] = xy[ok]
        return out, ok, None
    res = io.undistort_image(xy[ok])
    if not res.all_converged:
        raise ConvergenceError(
            f"space intersection: undistortion failed: {res.describe_failures()}", result=res
        )
    xn = res.points
    out[ok] = np.stack(
        [io.x0 + io.fx * xn[:, 0] + io.b2 * xn[:, 1], io.y0 - io.f * xn[:, 1]], axis=1
    )
    # image offsets = S (normalised), S = [[fx, b2], [0, -f]]: J = S D S^-1
    S = np.array([[io.fx, io.b2], [0.0, -io.f]])
    J = np.broadcast_to(np.eye(2), (xy.shape[0], 2, 2)).copy()
    J[ok] = S @ io.distortion.jacobian(xn) @ np.linalg.inv(S)
    return out, ok, J


def space_intersection(
    image_points,
    cameras: Sequence,
    *,
    sigma=None,
    max_iter: int = 20,
    tol: float = 1e-10,
    min_rays: int = 2,
) -> IntersectionResult:
    """Object points from their image coordinates in >= 2 oriented images.

    Parameters
    ----------
    image_points : array_like, shape (n_images, n, 2)
        Image coordinates of n points in each image (unit of that image's interior
        orientation); NaN where a point is not observed.
    cameras : sequence of FrameCamera or (InteriorOrientation, ExteriorOrientation)
        One per image.
    sigma : float or array_like (n_images,), optional
        Standard deviation of the measured image coordinates, per image (unit of each
        image). With distortion, the weights of the distortion-free coordinates are
        ``J.T J / sigma^2`` (``J``: derivative of the measured with respect to the
        distortion-free coordinates); without, ``1/sigma^2``.
    max_iter, tol
        Gauss-Newton controls: a point has converged when its step changes its computed
        image coordinates by at most ``tol (1 + rms)`` (whitened).
    min_rays : int
        Minimum number of images per point (>= 2).

    Returns
    -------
    IntersectionResult

    Raises
    ------
    TooFewPointsError / InputError
        Points seen in fewer than ``min_rays`` images, shape mismatches, NaN orientations.
    DegenerateGeometryError
        Rays that are (nearly) parallel, so the point is not determined.
    """
    cams = _cameras(cameras)
    obs = as_float64(image_points, "image points")
    if obs.ndim == 2 and obs.shape[1] == 2 and len(cams) == obs.shape[0]:
        obs = obs[:, None, :]
    if obs.ndim != 3 or obs.shape[2] != 2:
        raise InputError(f"image_points: expected shape (n_images, n_points, 2), got {obs.shape}")
    m, n, _ = obs.shape
    if m != len(cams):
        raise InputError(f"image_points has {m} image(s) but {len(cams)} camera(s) were given")
    if min_rays < 2:
        raise InputError("min_rays must be >= 2 (one ray does not fix a point)")
    if np.any(np.isinf(obs)):
        raise InputError("image_points: infinite values (use NaN for unobserved points)")
    if sigma is None:
        sig = np.ones(m)
    else:
        sig = np.broadcast_to(np.asarray(sigma, dtype=float).reshape(-1), (m,)).copy()
        if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise InputError("sigma: standard deviations must be finite and > 0")
    ideal = np.empty_like(obs)
    valid = np.empty((m, n), dtype=bool)
    # whitening of the ideal residuals: (J / sigma) v has unit covariance (None: v / sigma)
    whiten: list[np.ndarray | None] = []
    for i, (io, _) in enumerate(cams):  # loop over images, vectorised over points
        ideal[i], valid[i], J = _ideal_image(io, obs[i])
        whiten.append(None if J is None else J / sig[i])
    n_rays = valid.sum(axis=0)
    few = n_rays < min_rays
    if np.any(few):
        idx = np.flatnonzero(few)
        raise InputError(
            f"space intersection: {idx.size} point(s) are observed in fewer than {min_rays} images "
            f"(point index {', '.join(str(int(i)) for i in idx[:10])}"
            f"{' ...' if idx.size > 10 else ''}); "
            "each point needs >= 2 rays"
        )
    # Reduce object coordinates to the mean projection centre (conditioning).
    centre = np.mean([eo.position for _, eo in cams], axis=0)
    Ms = np.stack([eo.matrix for _, eo in cams])
    Cs = np.stack([eo.position for _, eo in cams]) - centre
    # --- linear start: minimise perpendicular distances to the rays -------------------------
    Nl = np.zeros((n, 3, 3))
    bl = np.zeros((n, 3))
    rays = np.full((m, n, 3), np.nan)  # unit ray directions, NaN where not observed
    for i, (io, _) in enumerate(cams):
        xy = ideal[i]
        yd = (io.y0 - xy[:, 1]) / io.f
        xd = (xy[:, 0] - io.x0 - io.b2 * yd) / io.fx
        dcam = np.stack([xd, -yd, -np.ones(n)], axis=1)
        d = dcam @ Ms[i]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        Pm = np.eye(3) - d[:, :, None] * d[:, None, :]
        Pm[~valid[i]] = 0.0
        rays[i][valid[i]] = d[valid[i]]
        Nl += Pm
        bl += Pm @ Cs[i]
    X = _solve3(Nl, bl, "space intersection (ray start)")
    angles = _largest_ray_angles(rays)
    # --- Gauss-Newton on the image coordinates --------------------------------------------
    done = np.zeros(n, dtype=bool)
    it = 0
    while it < max_iter:
        it += 1
        N, b, step_fn, _ = _normals(X, cams, Ms, Cs, ideal, valid, sig, whiten, angles)
        dX = _solve3(N, b, "space intersection")
        step = step_fn(dX)
        rms = np.sqrt(_vtpv(X, cams, Ms, Cs, ideal, valid, sig, whiten) / (2 * n_rays))
        dX[done] = 0.0
        X = X + dX
        done |= step <= tol * (1.0 + rms)
        if np.all(done):
            break
    N, _, _, res = _normals(X, cams, Ms, Cs, ideal, valid, sig, whiten, angles)
    Q = np.linalg.inv(N)
    r = 2 * n_rays - 3
    vtpv = _vtpv(X, cams, Ms, Cs, ideal, valid, sig, whiten)
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = np.where(r > 0, np.sqrt(vtpv / np.maximum(r, 1)), np.nan)
    return IntersectionResult(X + centre, Q, s0, 1.0, r, n_rays, res, done, it)


def _project_all(X, io, M, C):
    """Ideal image coordinates (n, 2), d(x, y)/dX (n, 2, 3) and depth of points in one image."""
    d = X - C
    p = d @ M.T
    u, v, w = p[:, 0], p[:, 1], p[:, 2]
    # a point at the projection centre (w = 0) gives inf/NaN here without a numpy warning:
    # the caller refuses every point with w >= 0 (behind the camera) by name
    with np.errstate(divide="ignore", invalid="ignore"):
        iw = 1.0 / w
        x = io.x0 - io.fx * u * iw + io.b2 * v * iw
        y = io.y0 - io.f * v * iw
        # d(x, y)/dp
        G = np.zeros((X.shape[0], 2, 3))
        G[:, 0, 0] = -io.fx * iw
        G[:, 0, 1] = io.b2 * iw
        G[:, 0, 2] = (io.fx * u - io.b2 * v) * iw * iw
        G[:, 1, 1] = -io.f * iw
        G[:, 1, 2] = io.f * v * iw * iw
        J = G @ M
    return np.stack([x, y], axis=1), J, w


def _whitened(v: np.ndarray, A: np.ndarray, sig: float, L: np.ndarray | None):
    """Residuals (n, 2) and design (n, 2, 3) with unit weight: ``L v``, ``L A``."""
    if L is None:
        return v / sig, A / sig
    return np.einsum("nij,nj->ni", L, v), L @ A


#: Rays of a point that meet at most at this angle (degrees) are named nearly parallel when
#: the point falls behind a camera (its depth is then set by the noise of the rays).
PARALLEL_DEG = 1.0


def _largest_ray_angles(rays: np.ndarray) -> np.ndarray:
    """(n,) largest angle in degrees between any two rays of each point from unit ray
    directions ``rays`` (m, n, 3), NaN where a point is not observed in an image."""
    m = rays.shape[0]
    best = np.zeros(rays.shape[1])
    for i in range(m - 1):  # loop over image pairs, vectorised over points
        c = np.einsum("knj,nj->kn", rays[i + 1 :], rays[i])
        s = np.linalg.norm(np.cross(rays[i + 1 :], rays[i]), axis=2)
        ang = np.degrees(np.arctan2(s, c))  # accurate for small angles too
        best = np.fmax(best, np.nanmax(np.where(np.isnan(ang), -np.inf, ang), axis=0))
    return best


def _behind_message(i: int, idx: np.ndarray, angles: np.ndarray | None) -> str:
    """The error for points ``idx`` that fall behind image ``i``."""
    head = (
        f"space intersection: {idx.size} point(s) fall behind image {i} (point index "
        f"{', '.join(str(int(j)) for j in idx[:10])}); the rays do not meet in front of "
        "the cameras"
    )
    if angles is not None and np.all(angles[idx] <= PARALLEL_DEG):
        return (
            f"{head}: their rays are nearly parallel (they meet at {float(angles[idx].max()):.2g}"
            " deg at most), so the points' distances are set by the noise of the image "
            "coordinates; they need images taken from positions further apart (a base "
            "against the distance to the points), not the same or nearly the same position"
        )
    return f"{head}: check the orientations and the point correspondences"


def _normals(X, cams, Ms, Cs, ideal, valid, sig, whiten, angles=None):
    n = X.shape[0]
    N = np.zeros((n, 3, 3))
    b = np.zeros((n, 3))
    res = np.full((len(cams), n, 2), np.nan)
    As = []
    for i, (io, _) in enumerate(cams):  # loop over images, vectorised over points
        xy, A, w = _project_all(X, io, Ms[i], Cs[i])
        v = xy - ideal[i]
        ok = valid[i]
        behind = ok & ~(w < 0)
        if np.any(behind):
            idx = np.flatnonzero(behind)
            raise DegenerateGeometryError(_behind_message(i, idx, angles))
        vw, Aw = _whitened(np.where(ok[:, None], v, 0.0), A, sig[i], whiten[i])
        Aw = np.where(ok[:, None, None], Aw, 0.0)
        vw = np.where(ok[:, None], vw, 0.0)
        N += np.einsum("nki,nkj->nij", Aw, Aw)
        b -= np.einsum("nki,nk->ni", Aw, vw)
        res[i][ok] = v[ok]
        As.append(Aw)

    def step_fn(dX):
        s = np.zeros(n)
        for Aw in As:
            s = np.maximum(s, np.max(np.abs(np.einsum("nki,ni->nk", Aw, dX)), axis=1))
        return s

    return N, b, step_fn, res


def _vtpv(X, cams, Ms, Cs, ideal, valid, sig, whiten):
    """(n,) weighted sum of squared image residuals ``v.T P v`` per point."""
    tot = np.zeros(X.shape[0])
    for i, (io, _) in enumerate(cams):
        xy, A, _ = _project_all(X, io, Ms[i], Cs[i])
        v, _ = _whitened(np.where(valid[i][:, None], xy - ideal[i], 0.0), A, sig[i], whiten[i])
        tot += np.sum(v * v, axis=1)
    return tot


def _solve3(N: np.ndarray, b: np.ndarray, what: str) -> np.ndarray:
    """Solve batched 3x3 systems, refusing (nearly) singular ones (parallel rays)."""
    dg = np.sqrt(np.einsum("nii->ni", N))
    dg[dg == 0] = 1.0
    Ns = N / dg[:, :, None] / dg[:, None, :]
    out = np.empty_like(b)
    bad = np.zeros(N.shape[0], dtype=bool)
    for s in range(0, N.shape[0], CHUNK):  # blocks: the condition check is batched too
        e = min(s + CHUNK, N.shape[0])
        sv = np.linalg.svd(Ns[s:e], compute_uv=False)
        bad[s:e] = ~(sv[:, -1] > 1e-12 * sv[:, 0])
    if np.any(bad):
        idx = np.flatnonzero(bad)
        raise DegenerateGeometryError(
            f"{what}: {idx.size} point(s) are not determined: their rays are (nearly) parallel "
            f"(point index {', '.join(str(int(i)) for i in idx[:10])}); they need images taken "
            "from different positions"
        )
    out = np.linalg.solve(Ns, (b / dg)[..., None])[..., 0] / dg
    return out
