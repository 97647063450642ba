"""Estimation of the DLT from control points: linear, rigorous and constrained.

* Linear (Abdel-Aziz & Karara): ``x = L1 X + L2 Y + L3 Z + L4 - x (L9 X + L10 Y + L11 Z)``
  (and y), solved in normalised coordinates (centroid reduction and isotropic scaling of
  object and image points); >= 6 non-coplanar points.
* Rigorous (default): the linear solution refined by a Gauss-Markov adjustment of the
  rational DLT equations, so that residuals are image residuals (computed minus observed).
* Constrained: the rigorous adjustment with the two orthogonality conditions of ``M``
  (equal scale in x and y, no shear); >= 5 non-coplanar points. With exactly five points the
  start comes from the two-dimensional null space of the linear system and the quartic
  zero-shear condition.

Coplanar control makes the DLT singular (the plane fixes only a homography); the error
says so and points to space resection with a known interior orientation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..adjust import Fit, gauss_markov, normalize_points, solve_linear
from ..errors import DegenerateGeometryError, InputError, TooFewPointsError
from ..rotation import LOCK_COS_PHI, gimbal_lock_note
from ..validation import (
    as_float64,
    as_points,
    check_count,
    check_finite_magnitude,
    check_same_length,
)
from ._checks import with_check_points
from .dlt import DLT, NAMES, dlt_from_orientation, orientation_from_dlt
from .exterior import ExteriorOrientation
from .interior import InteriorOrientation


@dataclass(frozen=True, eq=False, repr=False)
class DLTFit(Fit):
    """A :class:`~photogeom.adjust.Fit` of a DLT with named access to the camera."""

    crs_role = "ground"

    @property
    def dlt(self) -> DLT:
        """The estimated :class:`~photogeom.camera.dlt.DLT`."""
        return self.model

    @property
    def camera_matrix(self) -> np.ndarray:
        """3x4 camera matrix (``P[2, 3] = 1``)."""
        return self.model.matrix

    @property
    def interior(self) -> InteriorOrientation:
        """Interior orientation decomposed from the DLT (``cx = f + b1``, ``cy = f``)."""
        return self.extras["interior"]

    @property
    def exterior(self) -> ExteriorOrientation:
        """Exterior orientation decomposed from the DLT."""
        return self.extras["exterior"]

    def orientation_covariance(self, *, prior: bool = False) -> np.ndarray:
        """Covariance of the decomposed orientation.

        Order of :data:`ORIENTATION_NAMES`: ``cx, cy, x0, y0, b2`` (image unit), ``X0, Y0, Z0``
        (object units), ``omega, phi, kappa`` (rad).

        Propagated from the covariance of ``L1 .. L11`` (a posteriori, or with ``prior``
        a priori: the one defined at redundancy 0) by the Jacobian of the decomposition
        (:func:`~photogeom.camera.orientation_from_dlt`), taken by central differences
        with steps of a thousandth of each parameter's standard deviation.

        Parameters
        ----------
        prior : bool, default False
            Use the a priori covariance ``sigma0_prior^2 Qxx`` instead of the a posteriori one.

        Returns
        -------
        numpy.ndarray, shape (11, 11)
            All NaN when a standard deviation of ``L1 .. L11`` is not finite.
        """
        C = self.covariance_prior if prior else self.covariance
        C = np.asarray(C, dtype=float)
        std = np.sqrt(np.clip(np.diag(C), 0.0, None))
        if not np.all(np.isfinite(std)):
            return np.full((11, 11), np.nan)
        L0 = np.asarray(self.parameters, dtype=float)
        h = np.where(std > 0, 1e-3 * std, 1e-9 * np.maximum(np.abs(L0), 1e-12))
        J = np.empty((11, 11))
        for i in range(11):  # the eleven parameters, not points
            d = np.zeros(11)
            d[i] = h[i]
            up, down = _orientation_vector(L0 + d), _orientation_vector(L0 - d)
            diff = up - down
            diff[8:] = (diff[8:] + np.pi) % (2.0 * np.pi) - np.pi  # angles across the cut
            J[:, i] = diff / (2.0 * h[i])
        return J @ C @ J.T

    def orientation_std(self, angle_unit: str = "deg", *, prior: bool = False) -> dict:
        """Standard deviations of the decomposed orientation by name.

        Names of :data:`ORIENTATION_NAMES`; see :meth:`orientation_covariance`.

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the angle standard deviations (``"deg"``, ``"gon"``, ``"rad"``, ...).
        prior : bool, default False
            From the a priori covariance instead of the a posteriori one.

        Returns
        -------
        dict of str to float
            ``cx, cy, x0, y0, b2`` in the image unit, ``X0, Y0, Z0`` in object units,
            ``omega, phi, kappa`` in ``angle_unit``.
        """
        from ..units import from_radians

        s = np.sqrt(np.clip(np.diag(self.orientation_covariance(prior=prior)), 0.0, None))
        s[8:] = np.asarray(from_radians(s[8:], angle_unit))
        return {n: float(v) for n, v in zip(ORIENTATION_NAMES, s)}


#: Names of the decomposed orientation (:meth:`DLTFit.orientation_covariance`).
ORIENTATION_NAMES = ("cx", "cy", "x0", "y0", "b2", "X0", "Y0", "Z0", "omega", "phi", "kappa")


def _orientation_vector(L: np.ndarray) -> np.ndarray:
    """cx, cy, x0, y0, b2, X0, Y0, Z0, omega, phi, kappa of the DLT ``L`` (radians)."""
    io, eo = orientation_from_dlt(L)
    return np.array(
        [io.fx, io.fy, io.x0, io.y0, io.b2, eo.X0, eo.Y0, eo.Z0, eo.omega, eo.phi, eo.kappa]
    )


def image_weights(sigma, n: int) -> np.ndarray | None:
    if sigma is None:
        return None
    s = as_float64(sigma, "sigma", coordinates=False)
    if s.ndim == 0:
        s = np.full((n, 2), float(s))
    elif s.shape == (n,):
        s = np.repeat(s[:, None], 2, axis=1)
    elif s.shape != (n, 2):
        raise InputError(
            f"sigma: expected a scalar, ({n},) or ({n}, 2) values, got shape {s.shape}"
        )
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError("sigma: image standard deviations must be finite and > 0")
    return (1.0 / s**2).reshape(-1)


def check_not_coplanar(ground: np.ndarray, what: str, need: int, hint: str) -> None:
    """Raise :class:`DegenerateGeometryError` when the points are (nearly) coplanar."""
    c = ground - ground.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    if s[0] == 0 or s[-1] <= 1e-7 * s[0]:
        raise DegenerateGeometryError(
            f"{what}: the control points are coplanar (or collinear): relative thickness "
            f"{(s[-1] / s[0]) if s[0] > 0 else 0.0:.1e}, so the system is singular. At least "
            f"{need} non-coplanar points are needed; {hint}"
        )


#: Significance level of the test that the control's distances from a plane show in the
#: image coordinates (the DLT against the planar projective transformation of the plane's
#: coordinates): below it the DLT's camera is set by the noise of the image coordinates.
RELIEF_ALPHA = 0.001


def check_relief_shows(
    ground: np.ndarray, image: np.ndarray, weights: np.ndarray | None, adj, what: str,
    hint: str,
) -> None:
    """Raise :class:`DegenerateGeometryError` when nearly coplanar control is coplanar as far
    as the image coordinates can tell.

    The DLT's fit is compared with that of a planar projective transformation (8 parameters)
    from the coordinates of the points in their best-fitting plane to the image: when the
    DLT's three further parameters do not reduce the weighted squared residuals significantly
    (F-test at :data:`RELIEF_ALPHA`), the points' distances from the plane do not show in
    the image beyond its noise and the DLT's projection centre is undetermined.

    Parameters
    ----------
    ground : numpy.ndarray, shape (n, 3)
        Control points, object units.
    image : numpy.ndarray, shape (n, 2)
        Their image coordinates, mm or px.
    weights : numpy.ndarray, shape (2 n,), optional
        Weights of the image coordinates (1 / sigma^2, per coordinate, point by point).
    adj : Adjustment
        The DLT's adjustment (its ``vtpv`` and ``redundancy``, image units squared).
    what, hint : str
        Name of the estimate and the advice of the message.
    """
    from scipy.special import fdtri  # F quantile (scipy.stats is slow to import)

    from ..estimation import estimate_transform

    c = ground - ground.mean(axis=0)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    n = ground.shape[0]
    try:
        planar = estimate_transform(
            "projective2d", c @ vt[:2].T, image,
            weights=None if weights is None else weights.reshape(n, 2),
        )  # fmt: skip
    except (DegenerateGeometryError, InputError):
        return  # no planar transformation to compare with: the plane test does not apply
    r_dlt, r_plane = int(adj.redundancy), int(planar.redundancy)
    ss_dlt = float(adj.vtpv)
    ss_plane = float(planar.sigma0**2 * r_plane)
    if r_dlt <= 0 or r_plane <= r_dlt or not np.isfinite(ss_plane):
        return
    if ss_dlt <= 0.0:
        return  # error-free image coordinates: any relief shows
    F = ((ss_plane - ss_dlt) / (r_plane - r_dlt)) / (ss_dlt / r_dlt)
    limit = float(fdtri(r_plane - r_dlt, r_dlt, 1.0 - RELIEF_ALPHA))
    if F <= limit:
        rms = float(s[-1] / np.sqrt(n))
        raise DegenerateGeometryError(
            f"{what}: the control points are coplanar as far as the image coordinates can "
            f"tell: their RMS distance from the best-fitting plane, {rms:.3g} (relative "
            f"thickness {s[-1] / s[0]:.1e}), does not show in the image beyond its noise (a "
            f"planar projective transformation fits the image coordinates as well: F = "
            f"{F:.3g}, at most {limit:.3g} at alpha = {RELIEF_ALPHA:g}), so the projection "
            f"centre is undetermined. Give control points with larger height differences; "
            f"{hint}"
        )


_COPLANAR_HINT = (
    "for planar control use a space resection with known interior orientation "
    "(photogeom.orientation.space_resection, >= 3 points); the constrained DLT (>= 5 points) "
    "also needs points off the plane"
)


def _linear_rows(gn: np.ndarray, xn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = gn.shape[0]
    A = np.zeros((2 * n, 11))
    A[0::2, 0:3] = gn
    A[0::2, 3] = 1.0
    A[0::2, 8:11] = -xn[:, 0:1] * gn
    A[1::2, 4:7] = gn
    A[1::2, 7] = 1.0
    A[1::2, 8:11] = -xn[:, 1:2] * gn
    return A, xn.reshape(-1)


def _rational_model(gn: np.ndarray):
    h = np.hstack([gn, np.ones((gn.shape[0], 1))])

    def model(L):
        D = h[:, :3] @ L[8:11] + 1.0
        return np.stack([(h @ L[0:4]) / D, (h @ L[4:8]) / D], axis=1).reshape(-1)

    def jac(L):
        D = h[:, :3] @ L[8:11] + 1.0
        x = (h @ L[0:4]) / D
        y = (h @ L[4:8]) / D
        J = np.zeros((gn.shape[0], 2, 11))
        J[:, 0, 0:4] = h / D[:, None]
        J[:, 1, 4:8] = h / D[:, None]
        J[:, 0, 8:11] = -(x / D)[:, None] * gn
        J[:, 1, 8:11] = -(y / D)[:, None] * gn
        return J.reshape(-1, 11)

    return model, jac


def orthogonality_conditions(L) -> np.ndarray:
    """The two orthogonality conditions of the DLT (zero for ``cx = cy`` and no shear).

    ``h1 = |a|^2 - |b|^2 + ((b.c)^2 - (a.c)^2) / |c|^2``, ``h2 = a.b - (a.c)(b.c) / |c|^2``
    with ``a = (L1, L2, L3)``, ``b = (L5, L6, L7)``, ``c = (L9, L10, L11)``.

    Parameters
    ----------
    L : array_like, shape (11,)
        DLT parameters ``L1 .. L11``.

    Returns
    -------
    numpy.ndarray, shape (2,)
        ``(h1, h2)``.
    """
    L = np.asarray(L, dtype=float)
    a, b, c = L[0:3], L[4:7], L[8:11]
    q, u, w = c @ c, a @ c, b @ c
    return np.array([a @ a - b @ b + (w * w - u * u) / q, a @ b - u * w / q])


def _orthogonality_gradient(L) -> np.ndarray:
    L = np.asarray(L, dtype=float)
    a, b, c = L[0:3], L[4:7], L[8:11]
    q, u, w = c @ c, a @ c, b @ c
    H = np.zeros((2, 11))
    H[0, 0:3] = 2 * a - 2 * u * c / q
    H[0, 4:7] = -2 * b + 2 * w * c / q
    H[0, 8:11] = (2 * w * b - 2 * u * a) / q - (w * w - u * u) * 2 * c / q**2
    H[1, 0:3] = b - w * c / q
    H[1, 4:7] = a - u * c / q
    H[1, 8:11] = -(w * a + u * b) / q + u * w * 2 * c / q**2
    return H


def _shear_and_aspect(P: np.ndarray) -> tuple[float, float]:
    a1, a2, a3 = P[0, :3], P[1, :3], P[2, :3]
    c1, c2 = np.cross(a1, a3), np.cross(a2, a3)
    n1, n2 = np.linalg.norm(c1), np.linalg.norm(c2)
    return float(c1 @ c2 / (n1 * n2)), float(abs(n1 - n2) / (n1 + n2))


def _distinct_count(g: np.ndarray, rel_tol: float = 1e-9) -> int:
    """Number of distinct ground points (m): coordinates equal to ``rel_tol`` times the
    extent of all points (on a grid of that spacing) count as one position."""
    lo = g.min(axis=0)
    extent = float(np.max(g.max(axis=0) - lo))
    if not extent > 0.0:
        return 1
    return int(np.unique(np.round((g - lo) / (rel_tol * extent)), axis=0).shape[0])


def _five_point_start(gn: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """Camera matrix through five points with zero shear and equal scales (normalised)."""
    n = gn.shape[0]
    h = np.hstack([gn, np.ones((n, 1))])
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = h
    A[0::2, 8:12] = -xn[:, 0:1] * h
    A[1::2, 4:8] = h
    A[1::2, 8:12] = -xn[:, 1:2] * h
    Vt = np.linalg.svd(A)[2]
    N1, N2 = Vt[-2].reshape(3, 4), Vt[-1].reshape(3, 4)

    def skew(P):
        a1, a2, a3 = P[0, :3], P[1, :3], P[2, :3]
        return np.cross(a1, a3) @ np.cross(a2, a3)

    ts = np.arange(-2.0, 3.0)
    coef = np.polyfit(ts, [skew(N1 + t * N2) for t in ts], 4)
    cands = [N1 + float(t.real) * N2 for t in np.roots(coef) if abs(t.imag) < 1e-8 * (1 + abs(t))]
    cands.append(N2)
    best, best_err = None, np.inf
    for P in cands:
        if abs(P[2, 3]) < 1e-12 or abs(np.linalg.det(P[:, :3])) < 1e-14:
            continue
        sh, asp = _shear_and_aspect(P)
        if abs(sh) > 1e-6:
            continue
        try:
            orientation_from_dlt(P, "px", points=gn)  # raises when points are behind
        except (DegenerateGeometryError, InputError):
            continue
        if asp < best_err:
            best, best_err = P, asp
    if best is None:
        raise DegenerateGeometryError(
            "constrained DLT: five points admit no camera with orthogonal image axes and equal "
            "scales that sees all of them; check the point correspondences or add points"
        )
    return best / best[2, 3]


def _feasible(Ln: np.ndarray) -> np.ndarray:
    """Nearest-in-spirit DLT that satisfies the orthogonality conditions (cx = cy, no shear)."""
    io, eo = orientation_from_dlt(Ln, "px")
    f = 0.5 * (io.fx + io.fy)
    io2 = InteriorOrientation(f=f, x0=io.x0, y0=io.y0, unit="px")
    return dlt_from_orientation(io2, eo)


def estimate_dlt(
    ground,
    image,
    *,
    constrained: bool = False,
    refine: bool = True,
    unit: str = "mm",
    sigma=None,
    ids=None,
    check_ground=None,
    check_image=None,
    check_ids=None,
    max_iter: int = 50,
) -> DLTFit:
    """Estimate the eleven DLT parameters from control points.

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Object coordinates of the control points.
    image : array_like, shape (n, 2)
        Their image coordinates (right-handed image system, y up, in ``unit``).
    constrained : bool
        Impose the two orthogonality conditions (>= 5 points); otherwise >= 6 points.
    refine : bool
        Refine the linear solution by the rigorous (rational) adjustment so that the
        residuals are image residuals. ``False`` returns the linear solution, whose
        residuals are those of the linear equations (``D_i`` times the image residual,
        ``D_i`` the DLT denominator in normalised coordinates). Ignored when constrained.
    unit : {"mm", "px"}
        Unit of the image coordinates.
    sigma : float or array_like (n,) or (n, 2), optional
        Standard deviation of the image coordinates, in ``unit`` (weights ``1 / sigma^2``).
    ids : sequence, optional
        Point ids of the control points.
    check_ground, check_image, check_ids : optional
        Check points (not in the estimate); their residuals are reported.
    max_iter : int
        Iteration limit of the nonlinear adjustment.

    Returns
    -------
    DLTFit
        ``model`` is a :class:`DLT`; ``parameters`` are ``L1 .. L11``; residuals (n, 2) are
        computed minus observed image coordinates.
    """
    t0 = time.perf_counter()
    g = as_points(ground, 3, "ground points")
    check_finite_magnitude(g, "ground points", "DLT estimation")
    im = as_points(image, 2, "image points")
    check_same_length(g, im, "ground points", "image points")
    n = g.shape[0]
    what = "constrained DLT" if constrained else "DLT"
    need = 5 if constrained else 6
    hint = (
        "the constrained DLT has 11 parameters and 2 conditions"
        if constrained
        else "11 parameters; the constrained DLT needs 5, a resection with known interior "
        "orientation 3"
    )
    check_count(n, need, what, hint)
    distinct = _distinct_count(g)
    if distinct < need:
        raise TooFewPointsError(
            what, distinct, need,
            f"the {n} control points are only {distinct} distinct ground positions: points "
            f"are repeated; {hint}",
        )  # fmt: skip
    check_not_coplanar(g, what, need, _COPLANAR_HINT)
    w = image_weights(sigma, n)
    Ng, Ni = normalize_points(g), normalize_points(im)
    gn, xn = Ng.apply(g), Ni.apply(im)
    s_img = Ni.scale
    # weights of the normalised observations: P_n = P s^2 keeps v.T P v (and sigma0) unchanged
    wn = (np.ones(2 * n) if w is None else w) * s_img**2
    method = "linear DLT (normalised)"
    adj = None
    if distinct >= 6:
        A, obs = _linear_rows(gn, xn)
        adj = solve_linear(A, obs, weights=wn, names=NAMES, what=f"{what} (linear)")
        Ln = adj.x
        # A linear equation is the image residual times the DLT denominator D of its point:
        # weighted by P / D^2 (D from the first solution) its statistics are those of the
        # image coordinates (unweighted by D, sigma0 and the standard deviations of close-range
        # control, D varying with depth, were off by 20-30 %)
        den = gn @ Ln[8:11] + 1.0
        if np.all(np.isfinite(den)) and np.all(den != 0):
            wd = wn / np.repeat(den * den, 2)
            adj = solve_linear(A, obs, weights=wd, names=NAMES, what=f"{what} (linear)")
            Ln = adj.x
        check_relief_shows(g, im, w, adj, what, _COPLANAR_HINT)
    else:
        Ln = _five_point_start(gn, xn).reshape(-1)[:11]
    if constrained or refine:
        model, jac = _rational_model(gn)
        cons = None
        if constrained:
            Ln = _feasible(Ln)
            cons = (orthogonality_conditions, _orthogonality_gradient)
            method = "constrained DLT (Gauss-Markov with orthogonality conditions)"
        else:
            method = "DLT (linear start, Gauss-Markov on the rational equations)"
        adj = gauss_markov(
            model,
            Ln,
            xn.reshape(-1),
            jacobian=jac,
            weights=wn,
            names=NAMES,
            constraints=cons,
            max_iter=max_iter,
            what=what,
        )
        Ln = adj.x
    # Back to original coordinates: P = T2^-1 Pn T3, normalised so that P[2, 3] = 1.
    T2inv = np.linalg.inv(Ni.matrix)
    T3 = Ng.matrix
    Pfull = T2inv @ np.append(Ln, 1.0).reshape(3, 4) @ T3
    D = np.kron(T2inv, T3.T)
    L = Pfull.reshape(-1)[:11] / Pfull[2, 3]
    J = (D[:11, :11] - np.outer(L, D[11, :11])) / Pfull[2, 3]
    dlt = DLT(L, unit)
    try:
        io, eo = orientation_from_dlt(dlt, unit, points=g)
    except DegenerateGeometryError:
        raise
    gu = "m"
    units = {n_: f"{unit}/{gu}" for n_ in ("L1", "L2", "L3", "L5", "L6", "L7")}
    units.update({"L4": unit, "L8": unit, "L9": f"1/{gu}", "L10": f"1/{gu}", "L11": f"1/{gu}"})
    fit = DLTFit.from_adjustment(
        adj,
        dlt,
        method,
        point_dim=2,
        parameters=L,
        parameter_names=NAMES,
        jacobian=J,
        ids=None if ids is None else tuple(ids),
        residual_labels=("x", "y"),
        residual_unit=unit,
        parameter_units=units,
        extras={"interior": io, "exterior": eo},
        notes=(
            ()
            if (refine or constrained)
            else (
                "linear solution: residuals are those of the linear DLT equations (image residual "
                "times the DLT denominator in normalised coordinates)",
            )
        ),
    )
    fit = replace(fit, residuals=fit.residuals * s_img, elapsed=time.perf_counter() - t0)
    if np.cos(eo.phi) < LOCK_COS_PHI:
        lock = gimbal_lock_note(
            ORIENTATION_NAMES, _orientation_vector(L), fit.orientation_covariance()
        )
        if lock:
            fit = replace(fit, notes=(*fit.notes, f"decomposed orientation {lock}"))
    return with_check_points(fit, dlt.project, check_ground, check_image, check_ids)
