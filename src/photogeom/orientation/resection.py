"""Space resection: exterior orientation of one image from control points.

1. Initial values: closed-form perspective-3-point solutions (Grunert's elimination: the
   three distances from the projection centre satisfy three law-of-cosines equations,
   reduced here to a quartic by the resultant of two quadratics) on several well-spread
   triples, the linear DLT (>= 6 non-coplanar points) and the plane homography (>= 4 nearly
   coplanar points), scored by the reprojection of all points; several are refined when the
   best does not give a plausible adjustment. With exactly three points the geometry has up
   to four solutions: pass ``initial``.
2. A Gauss-Markov adjustment of the collinearity equations with an analytic Jacobian,
   optionally self-calibrating interior parameters (f, x0, y0, b1, b2, k1..k4, p1, p2).

The result is a :class:`ResectionFit` (a :class:`~photogeom.adjust.Fit`) with sigma0,
standard deviations, residuals (computed minus observed image coordinates) and check points.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.polynomial import polynomial as npoly

from ..adjust import Fit, gauss_markov
from ..camera._checks import with_check_points
from ..camera.collinearity import IO_PARAMETERS, FrameCamera, _projection_derivatives, project
from ..camera.distortion import COEFFICIENTS, BrownDistortion
from ..camera.exterior import NAMES as EO_NAMES
from ..camera.exterior import ExteriorOrientation
from ..camera.interior import InteriorOrientation
from ..errors import DegenerateGeometryError, InputError, PhotogeomError, SuspectResultWarning
from ..records import ReadOnlyRecord
from ..rotation import gimbal_lock_note
from ..validation import (
    as_float64,
    as_points,
    check_count,
    check_finite_magnitude,
    check_same_length,
)

__all__ = [
    "BatchResection",
    "ResectionFit",
    "p3p",
    "space_resection",
    "space_resection_batch",
    "start_candidates",
]


@dataclass(frozen=True, eq=False, repr=False)
class ResectionFit(Fit):
    """Result of :func:`space_resection`; ``model`` is the oriented :class:`FrameCamera`.

    ``suspect_reason`` is empty for a plausible adjustment; otherwise it says why the result
    should not be trusted as it is (``suspect`` is then True, the reason is among ``notes``
    and a :class:`~photogeom.errors.SuspectResultWarning` was issued).

    Attributes
    ----------
    suspect_reason : str, default ""
        Why the result should not be trusted as it is; empty for a plausible adjustment.
        The other fields are those of :class:`~photogeom.adjust.Fit`.
    """

    crs_role = "ground"

    suspect_reason: str = ""

    @property
    def suspect(self) -> bool:
        """True when sigma0 is implausible for the a-priori sigma (see ``suspect_reason``)."""
        return bool(self.suspect_reason)

    @property
    def camera(self) -> FrameCamera:
        """The oriented camera (interior possibly self-calibrated)."""
        return self.model

    @property
    def exterior(self) -> ExteriorOrientation:
        """Estimated exterior orientation (angles in radians)."""
        return self.model.exterior

    @property
    def interior(self) -> InteriorOrientation:
        """Interior orientation used (or self-calibrated)."""
        return self.model.interior

    @property
    def position(self) -> np.ndarray:
        """Projection centre (3,)."""
        return self.model.exterior.position

    @property
    def rotation(self) -> np.ndarray:
        """Rotation matrix ``M = M3(kappa) M2(phi) M1(omega)``."""
        return self.model.exterior.matrix


# --- perspective-3-point -----------------------------------------------------------------------


def _bearings(image: np.ndarray, io: InteriorOrientation) -> np.ndarray:
    """Unit direction vectors in the camera frame (camera looks along -z)."""
    xn = io.normalized_from_image(image)
    v = np.stack([xn[:, 0], -xn[:, 1], -np.ones(len(xn))], axis=1)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _rigid_from_pairs(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t with ``dst ~ R src + t`` (least squares, det R = +1)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs


def p3p(ground, image, io: InteriorOrientation) -> list[ExteriorOrientation]:
    """All exterior orientations consistent with three control points (closed form).

    Parameters
    ----------
    ground : array_like, shape (3, 3)
        Object coordinates of three points (not collinear).
    image : array_like, shape (3, 2)
        Their image coordinates in the unit of ``io``.
    io : InteriorOrientation
        Known interior orientation (distortion is removed first).

    Returns
    -------
    list of ExteriorOrientation
        Up to four solutions with all three points in front of the camera (may be empty
        for inconsistent data).
    """
    G = as_points(ground, 3, "ground points")
    im = as_points(image, 2, "image points")
    if G.shape[0] != 3 or im.shape[0] != 3:
        raise InputError("p3p needs exactly three ground and three image points")
    e = np.linalg.norm(np.cross(G[1] - G[0], G[2] - G[0]))
    if e <= 1e-12 * max(np.linalg.norm(G[1] - G[0]), np.linalg.norm(G[2] - G[0])) ** 2:
        raise DegenerateGeometryError("p3p: the three control points are collinear")
    j = _bearings(im, io)
    sols: list[ExteriorOrientation] = []
    seen: list[np.ndarray] = []
    for pc in _p3p_points(G, j, 0.0):
        R, t = _rigid_from_pairs(pc, G)
        key = np.concatenate([t, R.ravel()])
        tol = 1e-9 * (1 + float(np.abs(t).max()))
        if any(float(np.max(np.abs(key - k) - 1e-9 * np.abs(k))) <= tol for k in seen):
            continue
        seen.append(key)
        try:
            sols.append(ExteriorOrientation.from_matrix(t, R.T, on_gimbal_lock="omega-zero"))
        except PhotogeomError:  # pragma: no cover - defensive
            continue
    return sols


def _poly_sub(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` for coefficient arrays in increasing powers (of different lengths)."""
    out = np.zeros(max(a.size, b.size))
    out[: a.size] += a
    out[: b.size] -= b
    return out


def _horner(coefficients: list, v: float) -> float:
    """Value at ``v`` of the polynomial with ``coefficients`` in increasing powers."""
    out = 0.0
    for c in reversed(coefficients):
        out = out * v + c
    return out


# --- start values ----------------------------------------------------------------------------

#: Largest imaginary part (relative to ``1 + |real part|``) of a root of the P3P quartic still
#: taken as a start candidate: noise turns the double root of an ill-conditioned triple into a
#: complex pair whose real part is close to the true solution.
COMPLEX_ROOT_TOLERANCE = 0.1

#: P3P triples tried for start values (the best-spread one first, then well-spread others).
N_TRIPLES = 6

#: At most this many distinct start candidates are refined when the first does not give a
#: plausible adjustment (it did not converge, or its sigma0 fails the plausibility checks).
MAX_STARTS = 6


def _spread_triple(im: np.ndarray) -> tuple[int, int, int]:
    c = im.mean(axis=0)
    i0 = int(np.argmax(np.sum((im - c) ** 2, axis=1)))
    i1 = int(np.argmax(np.sum((im - im[i0]) ** 2, axis=1)))
    d = im[i1] - im[i0]
    area = np.abs(d[0] * (im[:, 1] - im[i0, 1]) - d[1] * (im[:, 0] - im[i0, 0]))
    area[[i0, i1]] = -1
    return i0, i1, int(np.argmax(area))


def _triples(im: np.ndarray, count: int) -> list[tuple[int, int, int]]:
    """``count`` distinct point triples with large image triangles (deterministic)."""
    n = im.shape[0]
    if n == 3:
        return [(0, 1, 2)]
    first = tuple(sorted(_spread_triple(im)))
    rng = np.random.default_rng(0)
    draws = np.sort(np.argsort(rng.random((12 * count, n)), axis=1)[:, :3], axis=1)
    draws = np.unique(draws, axis=0)
    a, b, c = im[draws[:, 0]], im[draws[:, 1]], im[draws[:, 2]]
    u, v = b - a, c - a
    area = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    order = np.argsort(-area)
    out = [first]
    for k in order:
        t = tuple(int(i) for i in draws[k])
        if t not in out:
            out.append(t)
        if len(out) >= count:
            break
    return out


def _p3p_points(G: np.ndarray, j: np.ndarray, imaginary_tolerance: float) -> list[np.ndarray]:
    """The three points in the camera frame (3, 3) for each solution of the P3P problem
    (Grunert's distances along the unit rays ``j``); roots of the quartic with an imaginary
    part up to ``imaginary_tolerance (1 + |real part|)`` are taken by their real part."""
    a2 = float(np.sum((G[1] - G[2]) ** 2))
    b2 = float(np.sum((G[0] - G[2]) ** 2))
    c2 = float(np.sum((G[0] - G[1]) ** 2))
    ca, cb, cg = float(j[1] @ j[2]), float(j[0] @ j[2]), float(j[0] @ j[1])
    A, C = a2 / b2, c2 / b2
    # With s2 = u s1, s3 = v s1 (Grunert):
    #   p(u) = u^2 - 2 v cos(alpha) u + v^2 - A (1 + v^2 - 2 v cos(beta)) = 0
    #   q(u) = u^2 - 2 cos(gamma) u + 1 - C (1 + v^2 - 2 v cos(beta)) = 0
    # coefficient arrays in increasing powers of v.
    p1 = np.array([0.0, -2.0 * ca])
    p0 = np.array([-A, 2.0 * A * cb, 1.0 - A])
    q1 = np.array([-2.0 * cg])
    q0 = np.array([1.0 - C, 2.0 * C * cb, -C])
    d0 = np.array([1.0 - C + A, 2.0 * cb * (C - A), A - C - 1.0])  # q0 - p0
    d1 = np.array([-2.0 * cg, 2.0 * ca])  # q1 - p1
    cross = _poly_sub(np.convolve(p1, q0), np.convolve(p0, q1))
    res = _poly_sub(np.convolve(d0, d0), np.convolve(d1, cross))
    res = np.trim_zeros(res, "b")
    roots = npoly.polyroots(res) if res.size > 1 else np.array([])
    out: list[np.ndarray] = []
    dres = npoly.polyder(res) if res.size > 1 else res
    # scalar polynomial values by Horner's rule (coefficients in increasing powers)
    c_res, c_dres, c_d0, c_d1 = (list(map(float, c)) for c in (res, dres, d0, d1))
    c_q0, c_q1 = list(map(float, q0)), list(map(float, q1))
    for r in roots:
        if r.real <= 0:
            continue
        is_real = abs(r.imag) <= 1e-6 * (1.0 + abs(r.real))
        if not is_real and abs(r.imag) > imaginary_tolerance * (1.0 + abs(r.real)):
            continue
        v = float(r.real)
        if is_real:
            for _ in range(3):  # polish the companion-matrix root by Newton steps
                dv = _horner(c_dres, v)
                if dv == 0:
                    break
                v -= _horner(c_res, v) / dv
        den = _horner(c_d1, v)
        us = []
        if abs(den) > 1e-10:
            us.append(-_horner(c_d0, v) / den)  # (p - q)(u) = -d1 u - d0 = 0
        else:  # p and q share both roots: solve q(u) = 0
            qq = [_horner(c_q0, v), _horner(c_q1, v), 1.0]
            us.extend(x.real for x in npoly.polyroots(qq) if abs(x.imag) < 1e-9)
        for u in us:
            if u <= 0:
                continue
            den1 = 1.0 + v * v - 2.0 * v * cb
            if den1 <= 0:
                continue
            s1 = np.sqrt(b2 / den1)
            out.append(np.array([s1, u * s1, v * s1])[:, None] * j)
    return out


def _rigid_batch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations R (K, 3, 3) and translations t (K, 3) with ``dst ~ R src + t`` per problem
    (least squares, det R = +1); ``src``, ``dst`` of shape (K, m, 3)."""
    cs, cd = src.mean(axis=1), dst.mean(axis=1)
    H = np.einsum("kmi,kmj->kij", src - cs[:, None], dst - cd[:, None])
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, 1, 2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    d[d == 0] = 1.0
    V[:, :, 2] *= d[:, None]
    R = V @ np.swapaxes(U, 1, 2)
    return R, cd - np.einsum("kij,kj->ki", R, cs)


def _homogeneous_rays(xn: np.ndarray) -> np.ndarray:
    """``(-x, y, 1)`` per point: proportional to ``M (X - X0)`` (camera looks along -z)."""
    return np.column_stack([-xn[:, 0], xn[:, 1], np.ones(len(xn))])


def _camera_from_linear(A: np.ndarray, b: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rotations M and centres X0 from ``P = [A | b] ~ lambda M [I | -X0]`` (both signs)."""
    out = []
    for s in (1.0, -1.0):
        As = s * A
        if not np.linalg.det(As) > 0:
            continue
        U, _, Vt = np.linalg.svd(As)
        M = U @ Vt
        try:
            X0 = -np.linalg.solve(As, s * b)
        except np.linalg.LinAlgError:
            continue
        if np.all(np.isfinite(X0)):
            out.append((M, X0))
    return out


def _linear_starts(g: np.ndarray, xn: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Start candidates ``(M, X0)`` from the linear DLT (>= 6 points, not coplanar) and from
    the plane homography (>= 4 points, coplanar or nearly so), in normalised coordinates."""
    n = g.shape[0]
    c = g.mean(axis=0)
    gc = g - c
    _, sv, Vt = np.linalg.svd(gc, full_matrices=False)
    scale = float(sv[0] / np.sqrt(n)) or 1.0
    gs = gc / scale
    h = _homogeneous_rays(xn)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    thin = sv[2] <= 0.05 * sv[0]
    if n >= 6 and not sv[2] <= 1e-6 * sv[0]:
        X = np.column_stack([gs, np.ones(n)])
        Z = np.zeros_like(X)
        rows = np.concatenate(
            [
                np.hstack([X, Z, -h[:, :1] * X]),
                np.hstack([Z, X, -h[:, 1:2] * X]),
            ]
        )
        _, s, V = np.linalg.svd(rows, full_matrices=False)
        if s[-2] > 1e-9 * s[0]:
            P = V[-1].reshape(3, 4)
            for M, X0 in _camera_from_linear(P[:, :3], P[:, 3]):
                out.append((M, c + scale * X0))
    if n >= 4 and thin:
        E = Vt[:2].T  # plane axes (3, 2)
        ab = gs @ E
        X = np.column_stack([ab, np.ones(n)])
        Z = np.zeros_like(X)
        rows = np.concatenate(
            [
                np.hstack([X, Z, -h[:, :1] * X]),
                np.hstack([Z, X, -h[:, 1:2] * X]),
            ]
        )
        _, s, V = np.linalg.svd(rows, full_matrices=False)
        if s[-2] > 1e-9 * s[0]:
            H = V[-1].reshape(3, 3)  # [M e1, M e2, -M X0] up to a factor
            for sgn in (1.0, -1.0):
                Hs = sgn * H / np.sqrt(np.linalg.norm(H[:, 0]) * np.linalg.norm(H[:, 1]))
                r1, r2 = Hs[:, 0], Hs[:, 1]
                r3 = np.cross(r1, r2)
                ME = np.column_stack([r1, r2, r3 / (np.linalg.norm(r3) or 1.0)])
                U, _, Wt = np.linalg.svd(ME)
                ME = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Wt)) or 1.0]) @ Wt
                # ME = M [E, e3]: M = ME [E, e3]^T
                B = np.column_stack([E, np.cross(E[:, 0], E[:, 1])])
                M = ME @ B.T
                X0 = -M.T @ Hs[:, 2]
                out.append((M, c + scale * X0))
    return out


def _score(g: np.ndarray, xn: np.ndarray, f: float, Ms: np.ndarray, X0s: np.ndarray) -> np.ndarray:
    """RMS reprojection error (unit of ``f``) of K candidates over all points; inf when a
    point is behind the camera. ``Ms`` (K, 3, 3), ``X0s`` (K, 3)."""
    p = np.einsum("kij,knj->kni", Ms, g[None, :, :] - X0s[:, None, :])
    w = p[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        pred = np.stack([-p[..., 0] / w, p[..., 1] / w], axis=-1)
        e = np.sqrt(np.mean(np.sum((pred - xn) ** 2, axis=-1), axis=-1)) * f
    e[~np.all(w < 0, axis=1) | ~np.isfinite(e)] = np.inf
    return e


#: A start with cos(phi) below this (radians) begins this far from phi = +-90 degrees, where
#: omega and kappa are not separable and the adjustment's design is singular.
LOCK_START_OFFSET = 1e-4


def _gimbal_lock_error(exc: DegenerateGeometryError, model, jac, x0) -> DegenerateGeometryError:
    """``exc`` itself, or when only omega and kappa are named as undetermined, the same
    error saying that the adjustment reached phi = +-90 degrees (gimbal lock)."""
    text = str(exc)
    if "(omega, kappa are undetermined" not in text:
        return exc
    return DegenerateGeometryError(
        "space resection: the adjustment reached phi = +-90 degrees, where omega and kappa "
        "(rotations about the same axis there) are not separable in the omega-phi-kappa "
        "angles: the orientation is determined, its angles are not (error-free image "
        "coordinates of a camera at exactly phi = +-90 degrees). Express the ground "
        "coordinates in a system turned about its y axis, so that the camera's phi is away "
        f"from +-90 degrees, and turn the result back ({text})"
    )


def _distinct_points(g: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """Indices of the first of each group of coinciding points (sorted by position).

    Parameters
    ----------
    g : ndarray, shape (n, 3)
        Object coordinates (m or any length unit).
    rel_tol : float
        Points whose coordinates agree to ``rel_tol`` times the extent of all points (on a
        grid of that spacing) count as one position.

    Returns
    -------
    ndarray of int
        One index per distinct position.
    """
    lo = g.min(axis=0)
    extent = float(np.max(g.max(axis=0) - lo))
    if not extent > 0.0:
        return np.zeros(1, dtype=np.intp)
    cells = np.round((g - lo) / (rel_tol * extent))
    # np.unique(cells, axis=0, return_index=True)[1], the same indices in the same order,
    # without its structured-array detour (which cost a tenth of a 20-point resection):
    # a stable lexicographic sort of the rows, then the first row of each run of equal ones
    order = np.lexsort(cells.T[::-1])
    s = cells[order]
    first = np.empty(order.size, dtype=bool)
    first[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=first[1:])
    return order[first]


def start_candidates(
    ground, image, io: InteriorOrientation, *, triples: int = N_TRIPLES, limit: int = 16
) -> list[tuple[float, ExteriorOrientation]]:
    """Start values for a resection, best first, as ``(rms reprojection error, orientation)``.

    Candidates come from P3P on ``triples`` well-spread point triples (roots of the quartic
    with small imaginary parts included, as noise turns a double root into a complex pair),
    from the linear DLT (>= 6 points, not coplanar) and from the plane homography (>= 4
    points, nearly coplanar). Each is scored by its RMS reprojection error over all points
    (unit of ``io``, distortion removed from the observations); candidates putting a point
    behind the camera are dropped, and so are duplicates. At most ``limit`` are returned.
    """
    g = as_points(ground, 3, "ground points")
    im = as_points(image, 2, "image points")
    n = g.shape[0]
    xn = io.normalized_from_image(im, on_failure="keep")
    if not np.all(np.isfinite(xn)):
        return []
    j = np.stack([xn[:, 0], -xn[:, 1], -np.ones(n)], axis=1)
    j /= np.linalg.norm(j, axis=1, keepdims=True)
    tol = 0.0 if n == 3 else COMPLEX_ROOT_TOLERANCE
    cam: list[np.ndarray] = []
    obj: list[np.ndarray] = []
    for t in _triples(xn, triples):
        G = g[list(t)]
        e = np.linalg.norm(np.cross(G[1] - G[0], G[2] - G[0]))
        if e <= 1e-12 * max(np.linalg.norm(G[1] - G[0]), np.linalg.norm(G[2] - G[0])) ** 2:
            continue
        pcs = _p3p_points(G, j[list(t)], tol)
        cam += pcs
        obj += [G] * len(pcs)
    Ms: list[np.ndarray] = []
    X0s: list[np.ndarray] = []
    if cam:
        R, tr = _rigid_batch(np.array(cam), np.array(obj))
        Ms.append(np.swapaxes(R, 1, 2))
        X0s.append(tr)
    if n >= 4:
        lin = _linear_starts(g, xn)
        if lin:
            Ms.append(np.array([m for m, _ in lin]))
            X0s.append(np.array([x for _, x in lin]))
    if not Ms:
        return []
    M_arr, X_arr = np.concatenate(Ms), np.concatenate(X0s)
    scores = _score(g, xn, float(io.f), M_arr, X_arr)
    order = np.argsort(scores, kind="stable")
    order = order[np.isfinite(scores[order])]
    size = float(np.sqrt(np.mean(np.sum((g - g.mean(axis=0)) ** 2, axis=1)))) or 1.0
    keys = np.concatenate([X_arr / size, M_arr.reshape(-1, 9)], axis=1)
    out: list[tuple[float, ExteriorOrientation]] = []
    kept: list[int] = []
    for k in order:
        if kept and np.min(np.max(np.abs(keys[kept] - keys[k]), axis=1)) < 1e-6:
            continue
        try:
            eo = ExteriorOrientation.from_matrix(X_arr[k], M_arr[k], on_gimbal_lock="omega-zero")
        except PhotogeomError:  # pragma: no cover - defensive
            continue
        kept.append(int(k))
        out.append((float(scores[k]), eo))
        if len(out) >= limit:
            break
    return out


# --- resection ---------------------------------------------------------------------------------


#: Significance level of the global test (chi-square test of v'Pv against the redundancy)
#: that flags a resection as suspect when the a-priori sigma of the image coordinates is given.
GLOBAL_TEST_ALPHA = 1e-3

#: Without an a-priori sigma, a resection is flagged as suspect when the RMS image residual
#: exceeds this fraction of the RMS spread of the control points in the image.
RELATIVE_RESIDUAL_LIMIT = 0.01


def _image_spread(im: np.ndarray) -> float:
    """RMS distance of the image points from their centroid."""
    return float(np.sqrt(np.mean(np.sum((im - im.mean(axis=0)) ** 2, axis=1))))


def implausibility(adj, sigma_given: bool, spread: float, unit: str) -> str:
    """Why the adjustment ``adj`` of a resection is implausible, or ``""``.

    With the a-priori sigma given, the global test: ``v'Pv / sigma0_prior^2`` against the
    chi-square quantile ``1 - GLOBAL_TEST_ALPHA`` for the redundancy. Always: the RMS image
    residual against ``RELATIVE_RESIDUAL_LIMIT`` times the spread of the control points in the
    image (a scale-free bound on what a correct orientation leaves). Nothing is tested at
    redundancy 0.
    """
    from scipy.special import chdtri  # chi-square quantile (lighter than scipy.stats)

    r = adj.redundancy
    if r <= 0 or not np.isfinite(adj.vtpv):
        return ""
    reasons = []
    if sigma_given:
        T = adj.vtpv / adj.sigma0_prior**2
        limit = float(chdtri(r, GLOBAL_TEST_ALPHA))
        if T > limit:
            reasons.append(
                f"sigma0 {adj.sigma0:.4g} fails the global test for the given sigma "
                f"(v'Pv / sigma0_prior^2 = {T:.4g} > {limit:.4g}, the chi-square quantile at "
                f"alpha = {GLOBAL_TEST_ALPHA:g} for redundancy {r})"
            )
    v = adj.residuals.reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum(v * v, axis=1))))
    if rms > RELATIVE_RESIDUAL_LIMIT * spread:
        reasons.append(
            f"RMS image residual {rms:.4g} {unit} is {100 * rms / spread:.2g}% of the spread of "
            f"the control points in the image (limit {100 * RELATIVE_RESIDUAL_LIMIT:g}%)"
        )
    if not reasons:
        return ""
    return (
        "; ".join(reasons)
        + ". Either the observations hold blunders (see fit.snooping()), the given sigma is "
        "too small, or the adjustment ended in a false minimum (try initial= from another "
        "source)"
    )


def _image_weights(sigma, n: int) -> np.ndarray | None:
    from ..camera.dlt_estimation import image_weights

    return image_weights(sigma, n)


def space_resection(
    ground,
    image,
    io: InteriorOrientation,
    *,
    initial: ExteriorOrientation | None = None,
    calibrate: Sequence[str] = (),
    sigma=None,
    ids=None,
    check_ground=None,
    check_image=None,
    check_ids=None,
    system: str = "image",
    pixel_origin: str = "center",
    max_iter: int = 50,
    tol: float = 1e-10,
) -> ResectionFit:
    """Exterior orientation of one image from >= 3 control points (collinearity adjustment).

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Object coordinates of the control points.
    image : array_like, shape (n, 2)
        Image coordinates in the unit of ``io`` (or pixels with ``system="pixel"``).
    io : InteriorOrientation
        Interior orientation (the start values of calibrated parameters).
    initial : ExteriorOrientation, optional
        Start values; required with exactly three points when they admit several solutions.
    calibrate : sequence of str
        Interior parameters to estimate as well, from ``f, x0, y0, b1, b2, k1..k4, p1, p2``
        (needs ``2 n >= 6 + len(calibrate)`` and geometry that separates them).
    sigma : float or array_like (n,) or (n, 2), optional
        Standard deviations of the image coordinates (unit of ``io``); weights ``1/sigma^2``.
    ids : sequence, optional
        Point ids of the control points.
    check_ground, check_image, check_ids : optional
        Check points: not in the adjustment; residuals reported.
    system : {"image", "pixel"}
        Coordinates of ``image`` / ``check_image``; residuals are always image coordinates
        in the unit of ``io``.
    pixel_origin : {"center", "corner"}
        Pixel convention for ``system="pixel"``.
    max_iter, tol
        Gauss-Newton controls (see :func:`~photogeom.adjust.gauss_markov`).

    Returns
    -------
    ResectionFit
        Parameters ``X0, Y0, Z0, omega, phi, kappa`` (radians) plus calibrated ones.
        ``suspect`` is True (with ``suspect_reason``, a note and a
        :class:`~photogeom.errors.SuspectResultWarning`) when sigma0 fails the global test
        for the given ``sigma`` (alpha = :data:`GLOBAL_TEST_ALPHA`) or the RMS image residual
        exceeds :data:`RELATIVE_RESIDUAL_LIMIT` of the image spread of the control points.

    Notes
    -----
    Without ``initial`` the start values are the candidates of :func:`start_candidates`
    (P3P on several triples, the linear DLT, the plane homography), best reprojection first;
    when the adjustment from the best does not converge, ends with a point behind the camera
    or is implausible, up to :data:`MAX_STARTS` candidates are refined and the smallest
    ``v'Pv`` is kept.
    """
    t0 = time.perf_counter()
    g = as_points(ground, 3, "ground points")
    check_finite_magnitude(g, "ground points", "space resection")
    im = as_points(image, 2, "image points")
    check_same_length(g, im, "ground points", "image points")
    if system == "pixel":
        im = io.pixel_to_image(im, pixel_origin)
    elif system != "image":
        raise InputError(f"system must be 'image' or 'pixel', not {system!r}")
    n = g.shape[0]
    calib = tuple(calibrate)
    bad = [c for c in calib if c not in IO_PARAMETERS]
    if bad or len(set(calib)) != len(calib):
        raise InputError(
            f"calibrate: unknown or repeated parameter(s) {', '.join(bad) or calib}; "
            f"choose from {', '.join(IO_PARAMETERS)}"
        )
    check_count(n, 3, "space resection", "6 exterior parameters, 2 observations per point")
    u = 6 + len(calib)
    need = (u + 1) // 2
    check_count(
        n,
        need,
        "self-calibrating space resection",
        f"{u} unknowns ({', '.join(calib)} besides the exterior orientation) need {u} observations",
    )
    w = _image_weights(sigma, n)
    first = _distinct_points(g)
    n_distinct = first.size
    repeated = (
        f" (the {n} control points are only {n_distinct} distinct ground positions: "
        "points are repeated)"
        if n_distinct < n
        else ""
    )
    if n_distinct < 3:
        raise DegenerateGeometryError(
            f"space resection: the {n} control points are only {n_distinct} distinct ground "
            "position(s) (points are repeated), which cannot determine an orientation; give "
            "at least 3 distinct control points (4 or more for a unique solution)"
        )
    sv = np.linalg.svd(g - g.mean(axis=0), compute_uv=False)
    if not sv[1] > 1e-9 * sv[0]:
        raise DegenerateGeometryError(
            f"space resection: the {n} control points lie on one line (relative spread "
            f"across it {sv[1] / sv[0]:.1e}), so the rotation about that line is undetermined; "
            "give at least 3 control points not on a line (4 or more for a unique solution)"
        )
    # --- start values ---
    if initial is None:
        if n_distinct == 3:
            # A repeated point adds no geometry: three positions admit up to four solutions.
            cands = start_candidates(g[first], im[first], io, limit=16)
        else:
            cands = start_candidates(g, im, io, limit=MAX_STARTS)
        if not cands:
            raise DegenerateGeometryError(
                "space resection: no start values found (the closed-form solutions put points "
                "behind the camera or the control is degenerate); pass initial="
            )
        if n_distinct == 3 and len(cands) > 1:
            listing = "; ".join(f"X0=({e.X0:.6g}, {e.Y0:.6g}, {e.Z0:.6g})" for _, e in cands)
            raise InputError(
                f"space resection: three control points{repeated} admit {len(cands)} exterior "
                f"orientations ({listing}); pass initial= an approximate orientation or add a "
                "fourth point (photogeom.orientation.p3p lists them)"
            )
        starts = [e for _, e in cands[:MAX_STARTS]]
    elif not isinstance(initial, ExteriorOrientation):
        raise InputError("initial must be an ExteriorOrientation")
    else:
        starts = [initial]
    # --- adjustment on centred ground coordinates ---
    centre = g.mean(axis=0)
    gc = g - centre
    io0 = io
    if any(c in COEFFICIENTS for c in calib) and io0.distortion is None:
        io0 = replace(io0, distortion=BrownDistortion())

    def unpack_io(x: np.ndarray) -> InteriorOrientation:
        if not calib:
            return io0
        vals = dict(zip(calib, x[6:]))
        base = {k: vals[k] for k in ("f", "x0", "y0", "b1", "b2") if k in vals}
        dist = io0.distortion
        dk = {k: vals[k] for k in COEFFICIENTS if k in vals}
        if dk:
            dist = replace(dist or BrownDistortion(), **dk)
        return replace(io0, distortion=dist, **base) if (base or dk) else io0

    cache: dict[bytes, object] = {}

    def derivs(x: np.ndarray):
        # the engine asks for the model and the Jacobian at the same x: one evaluation
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            try:
                cache[key] = _projection_derivatives(gc, unpack_io(x), x[:3], x[3:6], calib)
            except PhotogeomError:
                cache[key] = None
        return cache[key]

    def model(x):
        d = derivs(x)
        return np.full(2 * n, np.nan) if d is None else d.xy.reshape(-1)

    def jac(x):
        d = derivs(x)
        return np.concatenate([d.d_eo, d.d_io], axis=2).reshape(2 * n, -1)

    names = (*EO_NAMES, *calib)
    spread = _image_spread(im)

    def adjust_from(start: ExteriorOrientation):
        angles = start.angles
        if np.cos(angles[1]) < LOCK_START_OFFSET:
            # at phi = +-90 deg the omega and kappa columns of the Jacobian coincide: start
            # just off the lock (the adjustment moves phi anyway)
            angles = angles.copy()
            angles[1] = np.copysign(0.5 * np.pi - LOCK_START_OFFSET, angles[1])
        x0 = np.concatenate(
            [
                [start.X0 - centre[0], start.Y0 - centre[1], start.Z0 - centre[2]],
                angles,
                [_io_value(io0, c) for c in calib],
            ]
        )
        try:
            adj = gauss_markov(
                model,
                x0,
                im.reshape(-1),
                jacobian=jac,
                weights=w,
                names=names,
                max_iter=max_iter,
                tol=tol,
                what="space resection",
            )
        except DegenerateGeometryError as exc:
            raise _gimbal_lock_error(exc, model, jac, x0) from exc
        x = adj.x.copy()
        x[:3] += centre
        eo = ExteriorOrientation(*x[:6])
        behind = int(np.sum(eo.to_camera(g)[:, 2] >= 0))
        if behind:
            raise DegenerateGeometryError(
                f"space resection converged to an orientation with {behind} control "
                "point(s) behind the camera; the start values were on the wrong branch. Pass "
                "initial= closer to the true orientation"
            )
        return adj, x, eo

    # Refine the best start; when that fails or its sigma0 is implausible, the next distinct
    # starts, keeping the adjustment with the smallest v'Pv.
    best = None
    first_error: PhotogeomError | None = None
    for start in starts:
        try:
            adj, x, eo_hat = adjust_from(start)
        except PhotogeomError as exc:
            first_error = first_error or exc
            continue
        reason = implausibility(adj, sigma is not None, spread, io.unit)
        if best is None or adj.vtpv < best[0].vtpv:
            best = (adj, x, eo_hat, reason)
        if not reason:
            break
    if best is None:
        assert first_error is not None
        if len(starts) > 1:
            first_error.args = (
                f"{first_error} (each of {len(starts)} start values from the closed-form "
                "solutions failed)",
            )
        raise first_error
    adj, x, eo_hat, reason = best
    io_hat = unpack_io(adj.x)
    notes = (f"self-calibrated: {', '.join(calib)}",) if calib else ()
    if reason:
        notes = (*notes, f"suspect result: {reason}")
        warnings.warn(f"space resection: {reason}", SuspectResultWarning, stacklevel=2)
    units = {"X0": "m", "Y0": "m", "Z0": "m", "omega": "rad", "phi": "rad", "kappa": "rad"}
    units.update({c: ("1" if c in COEFFICIENTS else io.unit) for c in calib})
    camera = FrameCamera(io_hat, eo_hat)
    fit = ResectionFit.from_adjustment(
        adj,
        camera,
        "space resection (collinearity, Gauss-Markov)",
        point_dim=2,
        parameters=x,
        parameter_names=names,
        ids=None if ids is None else tuple(ids),
        residual_labels=("x", "y"),
        residual_unit=io.unit,
        parameter_units=units,
        elapsed=time.perf_counter() - t0,
        notes=notes,
        suspect_reason=reason,
    )
    lock = gimbal_lock_note(fit.parameter_names, fit.parameters, fit.covariance)
    if lock:
        fit = replace(fit, notes=(*fit.notes, lock))
    return with_check_points(
        fit,
        lambda g: project(g, io_hat, eo_hat, behind="nan"),
        check_ground,
        check_image,
        check_ids,
        observed_to_image=(
            (lambda ci: io.pixel_to_image(ci, pixel_origin)) if system == "pixel" else None
        ),
    )


def _io_value(io: InteriorOrientation, name: str) -> float:
    if name in COEFFICIENTS:
        return 0.0 if io.distortion is None else float(getattr(io.distortion, name))
    return float(getattr(io, name))


# --- many resections at once -------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BatchResection(ReadOnlyRecord):
    """Results of :func:`space_resection_batch` for B problems.

    Attributes
    ----------
    parameters : (B, 6) ``X0, Y0, Z0, omega, phi, kappa`` (radians).
    cofactor : (B, 6, 6) ``Qxx`` of the parameters.
    sigma0 : (B,) a-posteriori standard deviation of unit weight (NaN when r = 0).
    sigma0_prior : float
    redundancy : int
    residuals : (B, n, 2) image residuals, computed minus observed.
    converged : (B,) bool, iteration criterion met with all points in front of the camera.
    iterations : int, Gauss-Newton iterations of the slowest problem.
    """

    parameters: np.ndarray
    cofactor: np.ndarray
    sigma0: np.ndarray
    sigma0_prior: float
    redundancy: int
    residuals: np.ndarray
    converged: np.ndarray
    iterations: int

    @property
    def std(self) -> np.ndarray:
        """(B, 6) a-posteriori standard deviations ``sigma0 sqrt(diag Qxx)``."""
        return self.sigma0[:, None] * np.sqrt(np.einsum("bii->bi", self.cofactor))

    @property
    def std_prior(self) -> np.ndarray:
        """(B, 6) a-priori standard deviations ``sigma0_prior sqrt(diag Qxx)``."""
        return self.sigma0_prior * np.sqrt(np.einsum("bii->bi", self.cofactor))

    def exterior(self, i: int) -> ExteriorOrientation:
        """Exterior orientation of problem ``i``.

        Parameters
        ----------
        i : int
            Index of the problem.

        Returns
        -------
        ExteriorOrientation
            Object units, angles in rad.
        """
        return ExteriorOrientation(*self.parameters[i])


#: Smallest ratio of the extreme eigenvalues of a batched resection's column-scaled normal
#: equations; below it they are singular to double precision.
_BATCH_NORMAL_LIMIT = 1e-15


def _problems(idx: np.ndarray) -> str:
    shown = ", ".join(str(int(i)) for i in idx[:10])
    return f"problem(s) {shown}{', ...' if idx.size > 10 else ''} ({idx.size} in all)"


def _check_batch_spread(gc: np.ndarray) -> None:
    """Refuse problems whose centred control points (B, n, 3) coincide or lie on a line."""
    sv = np.linalg.svd(gc, compute_uv=False)  # (B, 3), descending
    bad = np.flatnonzero(~(sv[:, 1] > 1e-9 * sv[:, 0]))
    if bad.size:
        raise DegenerateGeometryError(
            f"space resection (batch): the control points of {_problems(bad)} coincide or lie "
            "on one line, which does not determine an orientation; give each problem at "
            "least 3 control points not on a line (4 or more for a unique solution)"
        )


def _check_batch_normal(Ns: np.ndarray, iteration: int) -> None:
    """Refuse singular column-scaled normal equations (B, 6, 6), naming the problems."""
    ev = np.linalg.eigvalsh(Ns)
    bad = np.flatnonzero(~(ev[:, 0] > _BATCH_NORMAL_LIMIT * ev[:, -1]))
    if bad.size:
        raise DegenerateGeometryError(
            f"space resection (batch): at iteration {iteration} the observations of "
            f"{_problems(bad)} do not determine the six parameters (singular normal "
            "equations: weak control, or phi at +-90 degrees, where omega and kappa are not "
            "separable); check those problems' control points and start values (initial)"
        )


def _batched_projection(gc: np.ndarray, x: np.ndarray, io: InteriorOrientation):
    """Image coordinates (B, n, 2), Jacobian (B, n, 2, 6) and depth (B, n) for B cameras."""
    from ..rotation import opk_matrix

    w_, p_, k_ = x[:, 3], x[:, 4], x[:, 5]
    M = opk_matrix(w_, p_, k_)  # (B, 3, 3)
    cw, sw, cp, sp, ck, sk = np.cos(w_), np.sin(w_), np.cos(p_), np.sin(p_), np.cos(k_), np.sin(k_)
    z = np.zeros_like(cw)
    o = np.ones_like(cw)

    def mat(rows):
        return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)

    M1 = mat([[o, z, z], [z, cw, sw], [z, -sw, cw]])
    M2 = mat([[cp, z, -sp], [z, o, z], [sp, z, cp]])
    M3 = mat([[ck, sk, z], [-sk, ck, z], [z, z, o]])
    dM1 = mat([[z, z, z], [z, -sw, cw], [z, -cw, -sw]])
    dM2 = mat([[-sp, z, -cp], [z, z, z], [cp, z, -sp]])
    dM3 = mat([[-sk, ck, z], [-ck, -sk, z], [z, z, z]])
    dMs = (M3 @ M2 @ dM1, M3 @ dM2 @ M1, dM3 @ M2 @ M1)
    d = gc - x[:, None, :3]  # (B, n, 3)
    p = np.einsum("bij,bnj->bni", M, d)
    u, v, w = p[..., 0], p[..., 1], p[..., 2]
    iw = 1.0 / w
    B, n = u.shape
    Np = np.zeros((B, n, 2, 3))
    Np[..., 0, 0] = -iw
    Np[..., 0, 2] = u * iw * iw
    Np[..., 1, 1] = iw
    Np[..., 1, 2] = -v * iw * iw
    xn = np.stack([-u * iw, v * iw], axis=-1).reshape(-1, 2)
    C = np.array([[io.fx, io.b2], [0.0, -io.f]])
    if io.distortion is not None:
        G = np.einsum("ij,njk->nik", C, io.distortion.jacobian(xn)).reshape(B, n, 2, 2)
    else:
        G = np.broadcast_to(C, (B, n, 2, 2))
    xy = io.image_from_normalized(xn).reshape(B, n, 2)
    Gp = np.einsum("bnij,bnjk->bnik", G, Np)
    J = np.empty((B, n, 2, 6))
    J[..., :3] = -np.einsum("bnij,bjk->bnik", Gp, M)
    for j, dM in enumerate(dMs):
        J[..., 3 + j] = np.einsum("bnij,bjk,bnk->bni", Gp, dM, d)
    return xy, J, w


def _batch_start(initial, B: int) -> np.ndarray:
    """Start values (B, 6) from one ExteriorOrientation, a sequence of B of them, or numbers
    of shape (6,) or (B, 6); :class:`InputError` naming ``initial`` otherwise."""
    want = (
        f"initial: expected an ExteriorOrientation, a sequence of {B} of them, or start values "
        f"X0, Y0, Z0, omega, phi, kappa of shape (6,) or ({B}, 6)"
    )
    if isinstance(initial, ExteriorOrientation):
        return np.broadcast_to(initial.parameters, (B, 6))
    if isinstance(initial, Sequence) and any(isinstance(e, ExteriorOrientation) for e in initial):
        if not all(isinstance(e, ExteriorOrientation) for e in initial):
            raise InputError(f"{want}; got a sequence mixing them with other values")
        x0 = np.array([e.parameters for e in initial], dtype=float)
    else:
        try:
            x0 = np.asarray(initial, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{want}; got {type(initial).__name__}") from None
    if x0.shape not in ((6,), (B, 6)):
        raise InputError(f"{want}; got shape {x0.shape}")
    return np.broadcast_to(x0, (B, 6))


def space_resection_batch(
    ground,
    image,
    io: InteriorOrientation,
    initial,
    *,
    sigma=None,
    max_iter: int = 30,
    tol: float = 1e-10,
) -> BatchResection:
    """Many space resections at once (batched Gauss-Newton on 6x6 normal equations).

    For B images with their own control observations, e.g. Monte-Carlo trials or a set of
    independent photos, with the interior orientation known and shared. Start values are
    required (use :func:`space_resection` or :func:`p3p` for one image without them).

    Parameters
    ----------
    ground : array_like, shape (n, 3) or (B, n, 3)
        Control points (shared by all problems or per problem).
    image : array_like, shape (B, n, 2)
        Image coordinates in the unit of ``io``.
    io : InteriorOrientation
    initial : ExteriorOrientation, sequence of B ExteriorOrientation, or array_like (B, 6) or (6,)
        Start values ``X0, Y0, Z0, omega, phi, kappa`` (radians).
    sigma : float, optional
        Standard deviation of every image coordinate, in the unit of ``io`` (weights
        ``1/sigma^2``).
    max_iter, tol
        Iteration limit; a problem has converged when its step changes the whitened computed
        observations by at most ``tol (1 + rms(v_w))``.

    Returns
    -------
    BatchResection
    """
    im = as_float64(image, "image")
    if im.ndim != 3 or im.shape[2] != 2:
        raise InputError(f"image: expected shape (B, n, 2), got {im.shape}")
    B, n, _ = im.shape
    g = as_float64(ground, "ground")
    if g.ndim == 2:
        g = np.broadcast_to(g, (B, *g.shape))
    if g.shape != (B, n, 3):
        raise InputError(f"ground: expected shape (n, 3) or ({B}, {n}, 3), got {g.shape}")
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(im))):
        raise InputError("ground/image: NaN or infinite values")
    check_count(n, 3, "space resection", "6 exterior parameters, 2 observations per point")
    x = np.array(_batch_start(initial, B), dtype=float)
    s = 1.0 if sigma is None else float(sigma)
    if not s > 0:
        raise InputError("sigma must be > 0")
    centre = g.mean(axis=1)
    gc = g - centre[:, None, :]
    _check_batch_spread(gc)
    x[:, :3] -= centre
    # starts at phi = +-90 deg (singular design) begin just off it, as in space_resection
    lock = np.cos(x[:, 4]) < LOCK_START_OFFSET
    x[lock, 4] = np.copysign(0.5 * np.pi - LOCK_START_OFFSET, x[lock, 4])
    done = np.zeros(B, dtype=bool)
    it = 0
    while it < max_iter:
        it += 1
        xy, J, _ = _batched_projection(gc, x, io)
        v = (xy - im).reshape(B, -1) / s
        A = J.reshape(B, 2 * n, 6) / s
        N = np.einsum("bki,bkj->bij", A, A)
        b = -np.einsum("bki,bk->bi", A, v)
        dg = np.sqrt(np.einsum("bii->bi", N))
        dg[dg == 0] = 1.0
        Ns = N / dg[:, :, None] / dg[:, None, :]
        _check_batch_normal(Ns, it)
        dx = np.linalg.solve(Ns, (b / dg)[..., None])[..., 0] / dg
        step = np.max(np.abs(np.einsum("bki,bi->bk", A, dx)), axis=1)
        rms = np.sqrt(np.mean(v * v, axis=1))
        dx[done] = 0.0
        x += dx
        done |= step <= tol * (1.0 + rms)
        if np.all(done):
            break
    xy, J, w = _batched_projection(gc, x, io)
    res = xy - im
    A = J.reshape(B, 2 * n, 6) / s
    N = np.einsum("bki,bkj->bij", A, A)
    dg = np.sqrt(np.einsum("bii->bi", N))
    dg[dg == 0] = 1.0
    Ns = N / dg[:, :, None] / dg[:, None, :]
    _check_batch_normal(Ns, it)
    Q = np.linalg.inv(Ns) / dg[:, :, None] / dg[:, None, :]
    r = 2 * n - 6
    vtpv = np.sum((res / s) ** 2, axis=(1, 2))
    sigma0 = np.sqrt(vtpv / r) if r > 0 else np.full(B, np.nan)
    x[:, :3] += centre
    converged = done & np.all(w < 0, axis=1)
    return BatchResection(x, Q, sigma0, s, r, res, converged, it)
