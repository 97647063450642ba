"""Space resection: exterior orientation of one image from control points.

1. Initial values: a closed-form perspective-3-point solution (Grunert's elimination: the
   three distances from the projection centre satisfy three law-of-cosines equations,
   reduced here to a quartic by the resultant of two quadratics), disambiguated by the
   remaining points; with >= 6 non-coplanar points a DLT decomposition is tried as well.
   With exactly three points the geometry has up to four solutions: pass ``initial``.
2. A Gauss-Markov adjustment of the collinearity equations with an analytic Jacobian,
   optionally self-calibrating interior parameters (f, x0, y0, b1, b2, k1..k4, p1, p2).

The result is a :class:`ResectionFit` (a :class:`~photogeom.adjust.Fit`) with sigma0,
standard deviations, residuals (computed minus observed image coordinates) and check points.
"""

from __future__ import annotations

import time
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
from ..errors import DegenerateGeometryError, InputError, PhotogeomError
from ..validation import as_points, check_count, check_same_length

__all__ = ["BatchResection", "ResectionFit", "p3p", "space_resection", "space_resection_batch"]


@dataclass(frozen=True, eq=False)
class ResectionFit(Fit):
    """Result of :func:`space_resection`; ``model`` is the oriented :class:`FrameCamera`."""

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
    d0 = npoly.polysub(q0, p0)
    d1 = npoly.polysub(q1, p1)
    res = npoly.polysub(
        npoly.polymul(d0, d0),
        npoly.polymul(d1, npoly.polysub(npoly.polymul(p1, q0), npoly.polymul(p0, q1))),
    )
    res = np.trim_zeros(res, "b")
    roots = npoly.polyroots(res) if res.size > 1 else np.array([])
    sols: list[ExteriorOrientation] = []
    seen: list[np.ndarray] = []
    dres = npoly.polyder(res) if res.size > 1 else res
    # scalar polynomial values by Horner's rule (coefficients in increasing powers)
    c_res, c_dres, c_d0, c_d1 = (list(map(float, c)) for c in (res, dres, d0, d1))
    c_q0, c_q1 = list(map(float, q0)), list(map(float, q1))
    for r in roots:
        if abs(r.imag) > 1e-6 * (1.0 + abs(r.real)) or r.real <= 0:
            continue
        v = float(r.real)
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
            pc = np.array([s1, u * s1, v * s1])[:, None] * j
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


def _horner(coefficients: list, v: float) -> float:
    """Value at ``v`` of the polynomial with ``coefficients`` in increasing powers."""
    out = 0.0
    for c in reversed(coefficients):
        out = out * v + c
    return out


# --- start values ----------------------------------------------------------------------------


def _spread_triple(im: np.ndarray) -> tuple[int, int, int]:
    c = im.mean(axis=0)
    i0 = int(np.argmax(np.sum((im - c) ** 2, axis=1)))
    i1 = int(np.argmax(np.sum((im - im[i0]) ** 2, axis=1)))
    d = im[i1] - im[i0]
    area = np.abs(d[0] * (im[:, 1] - im[i0, 1]) - d[1] * (im[:, 0] - im[i0, 0]))
    area[[i0, i1]] = -1
    return i0, i1, int(np.argmax(area))


def _reprojection_rms(g, im, io, eo) -> float:
    try:
        xy = project(g, io, eo, behind="nan")
    except PhotogeomError:
        return np.inf
    if not np.all(np.isfinite(xy)):
        return np.inf
    return float(np.sqrt(np.mean(np.sum((xy - im) ** 2, axis=1))))


def initial_exterior(
    ground, image, io: InteriorOrientation
) -> list[tuple[float, ExteriorOrientation]]:
    """Candidate start values, best first, as ``(rms reprojection error, orientation)``.

    P3P on a well-spread triple (further triples, then - with >= 6 non-coplanar points - the
    DLT decomposition, only when it gives no candidate with every point in front), each
    scored by its reprojection RMS over all points (points behind the camera disqualify).
    """
    g = as_points(ground, 3, "ground points")
    im = as_points(image, 2, "image points")
    n = g.shape[0]
    triples = [(0, 1, 2)] if n == 3 else [_spread_triple(im)]
    if n >= 5:  # further triples, used only when the first gives no valid candidate
        rng = np.random.default_rng(0)
        triples += [tuple(rng.choice(n, 3, replace=False)) for _ in range(3)]
    scored: list[tuple[float, ExteriorOrientation]] = []
    for t in triples:
        try:
            cands = p3p(g[list(t)], im[list(t)], io)
        except PhotogeomError:
            continue
        scored += [(_reprojection_rms(g, im, io, e), e) for e in cands]
        if any(np.isfinite(s[0]) for s in scored):
            break
    if n >= 6 and not any(np.isfinite(s[0]) for s in scored):
        from ..camera.dlt_estimation import estimate_dlt

        try:
            fit = estimate_dlt(
                g, io.normalized_from_image(im) * np.array([1.0, -1.0]), unit=io.unit,
                refine=False,
            )
            scored.append((_reprojection_rms(g, im, io, fit.exterior), fit.exterior))
        except PhotogeomError:
            pass
    scored.sort(key=lambda p: p[0])
    return [s for s in scored if np.isfinite(s[0])]


# --- resection ---------------------------------------------------------------------------------


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
    """
    t0 = time.perf_counter()
    g = as_points(ground, 3, "ground points")
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
    # --- start values ---
    if initial is None:
        cands = initial_exterior(g, im, io)
        if not cands:
            raise DegenerateGeometryError(
                "space resection: no start values found (the closed-form solutions put points "
                "behind the camera or the control is degenerate); pass initial="
            )
        if n == 3 and len(cands) > 1:
            listing = "; ".join(f"X0=({e.X0:.6g}, {e.Y0:.6g}, {e.Z0:.6g})" for _, e in cands)
            raise InputError(
                f"space resection: three control points admit {len(cands)} exterior "
                f"orientations ({listing}); pass initial= an approximate orientation or add a "
                "fourth point (photogeom.orientation.p3p lists them)"
            )
        initial = cands[0][1]
    elif not isinstance(initial, ExteriorOrientation):
        raise InputError("initial must be an ExteriorOrientation")
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

    x0 = np.concatenate(
        [
            [initial.X0 - centre[0], initial.Y0 - centre[1], initial.Z0 - centre[2]],
            initial.angles,
            [_io_value(io0, c) for c in calib],
        ]
    )
    names = (*EO_NAMES, *calib)
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
    x = adj.x.copy()
    x[:3] += centre
    io_hat = unpack_io(adj.x)
    eo_hat = ExteriorOrientation(*x[:6])
    wdepth = eo_hat.to_camera(g)[:, 2]
    if np.any(wdepth >= 0):
        raise DegenerateGeometryError(
            f"space resection converged to an orientation with {int(np.sum(wdepth >= 0))} control "
            "point(s) behind the camera; the start values were on the wrong branch. Pass "
            "initial= closer to the true orientation"
        )
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
        notes=(f"self-calibrated: {', '.join(calib)}",) if calib else (),
    )
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


@dataclass(frozen=True)
class BatchResection:
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
        """Exterior orientation of problem ``i``."""
        return ExteriorOrientation(*self.parameters[i])


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
    initial : ExteriorOrientation or array_like (B, 6) or (6,)
        Start values ``X0, Y0, Z0, omega, phi, kappa`` (radians).
    sigma : float, optional
        Standard deviation of every image coordinate (weights ``1/sigma^2``).
    max_iter, tol
        Iteration limit; a problem has converged when its step changes the whitened computed
        observations by at most ``tol (1 + rms(v_w))``.

    Returns
    -------
    BatchResection
    """
    im = np.asarray(image, dtype=float)
    if im.ndim != 3 or im.shape[2] != 2:
        raise InputError(f"image: expected shape (B, n, 2), got {im.shape}")
    B, n, _ = im.shape
    g = np.asarray(ground, dtype=float)
    if g.ndim == 2:
        g = np.broadcast_to(g, (B, *g.shape))
    if g.shape != (B, n, 3):
        raise InputError(f"ground: expected shape (n, 3) or ({B}, {n}, 3), got {g.shape}")
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(im))):
        raise InputError("ground/image: NaN or infinite values")
    check_count(n, 3, "space resection", "6 exterior parameters, 2 observations per point")
    x0 = (
        initial.parameters
        if isinstance(initial, ExteriorOrientation)
        else np.asarray(initial, float)
    )
    x = np.array(np.broadcast_to(x0, (B, 6)), dtype=float)
    s = 1.0 if sigma is None else float(sigma)
    if not s > 0:
        raise InputError("sigma must be > 0")
    centre = g.mean(axis=1)
    gc = g - centre[:, None, :]
    x[:, :3] -= centre
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
    Q = np.linalg.inv(N)
    r = 2 * n - 6
    vtpv = np.sum((res / s) ** 2, axis=(1, 2))
    sigma0 = np.sqrt(vtpv / r) if r > 0 else np.full(B, np.nan)
    x[:, :3] += centre
    converged = done & np.all(w < 0, axis=1)
    return BatchResection(x, Q, sigma0, s, r, res, converged, it)
