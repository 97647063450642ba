"""Iterative 3D-similarity adjustments through :mod:`photogeom.adjust`.

* :func:`similarity_gauss_markov` - method E: only the target coordinates are observations,
  ``X_i + v_i = t + s R(omega, phi, kappa) x_i``, full Jacobian, Gauss-Newton;
* :func:`similarity_gauss_helmert` - method F (iterative): errors in both systems,
  ``t + s R (x_i + v_x,i) - (X_i + v_X,i) = 0``, weights or covariances per system, per point
  or full; the condition Jacobian of the observations is block-sparse.

Both work in coordinates reduced to the centroids (numerically safe for UTM-sized values next
to model coordinates of order 1) and with the rotation relative to the start rotation
``R0``: the unknowns are ``t' (3), s, a1, a2, a3`` of ``X - Xg = t' + s R (x - xg)`` with
``R = R0 M(a1, a2, a3).T`` and ``a = 0`` at the start, so the iteration never meets the
singularity of Euler angles (phi = +-90 deg) unless it turns by 90 degrees from its start.
:func:`to_original` maps the solution and its cofactor to ``t = Xg + t' - s R xg`` and the
omega, phi, kappa of R (radians, transposed convention ``R = M(omega, phi, kappa).T``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from ..adjust import Adjustment, gauss_helmert, gauss_markov
from .absolute_stats import angle_to_perturbation, opk_transposed, rotation_derivatives

NAMES7 = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")
NAMES6 = ("tx", "ty", "tz", "omega", "phi", "kappa")


def names(with_scale: bool) -> tuple[str, ...]:
    """Parameter names of the similarity (7) or rigid (6) model."""
    return NAMES7 if with_scale else NAMES6


def unpack(p: np.ndarray, with_scale: bool) -> tuple[np.ndarray, float, np.ndarray]:
    """``(t, s, angles)`` from a parameter vector in the order of :func:`names`."""
    if with_scale:
        return p[:3], float(p[3]), p[4:7]
    return p[:3], 1.0, p[3:6]


def pack(t, s: float, angles, with_scale: bool) -> np.ndarray:
    """Inverse of :func:`unpack`."""
    t = [float(v) for v in t]
    angles = [float(v) for v in angles]
    return np.array([*t, float(s), *angles] if with_scale else [*t, *angles])


def _rotation(p: np.ndarray, with_scale: bool, R0: np.ndarray):
    """``R = R0 M(a).T`` and ``dR/da`` (3, 3, 3) for the relative angles a of p."""
    _, _, a = unpack(p, with_scale)
    Rl, dRl = rotation_derivatives(*a)
    return R0 @ Rl, np.matmul(R0, dRl)


def to_original(
    p_red: np.ndarray,
    source_ref: np.ndarray,
    target_ref: np.ndarray,
    with_scale: bool,
    R0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Original parameters ``(t, [s,] omega, phi, kappa)``, the Jacobian
    d(original)/d(reduced), the rotation ``R = M(omega, phi, kappa).T`` and a gimbal-lock flag.

    At gimbal lock (phi = +-90 deg) omega is set to 0 and the rows of the angles in the
    Jacobian are NaN: their standard deviations are undefined.
    """
    tr, s, _ = unpack(p_red, with_scale)
    R, dR = _rotation(p_red, with_scale, R0)
    omega, phi, kappa, gimbal = opk_transposed(R)
    Rg, dRg = rotation_derivatives(omega, phi, kappa)
    t = target_ref + tr - s * (R @ source_ref)
    u = p_red.size
    J = np.eye(u)
    if with_scale:
        J[:3, 3] = -(R @ source_ref)
    J[:3, u - 3 :] = -s * (dR @ source_ref).T
    G_glob = angle_to_perturbation(Rg, dRg)
    if abs(np.linalg.det(G_glob)) > 1e-9:
        J[u - 3 :, u - 3 :] = np.linalg.solve(G_glob, angle_to_perturbation(R, dR))
    else:
        J[u - 3 :, :] = np.nan
    return pack(t, s, (omega, phi, kappa), with_scale), J, Rg, gimbal


def to_reduced(
    t: np.ndarray, s: float, R0: np.ndarray, source_ref: np.ndarray, target_ref: np.ndarray,
    with_scale: bool,
) -> np.ndarray:
    """Reduced parameters of an original ``(t, s, R0)``: ``t' = t + s R0 xg - Xg``, a = 0."""
    tr = np.asarray(t, dtype=float) + s * (R0 @ source_ref) - target_ref
    return pack(tr, s, (0.0, 0.0, 0.0), with_scale)


def _model_jacobian(xr: np.ndarray, p: np.ndarray, with_scale: bool, R0: np.ndarray):
    """Computed reduced target points (n, 3) and the Jacobian (3n, u) of the similarity."""
    tr, s, _ = unpack(p, with_scale)
    R, dR = _rotation(p, with_scale, R0)
    Rx = xr @ R.T
    f = tr + s * Rx
    n = xr.shape[0]
    u = p.size
    A = np.empty((n, 3, u))
    A[:, :, :3] = np.eye(3)
    k = 3
    if with_scale:
        A[:, :, 3] = Rx
        k = 4
    A[:, :, k:] = s * np.einsum("aij,nj->nia", dR, xr)
    return f, A.reshape(3 * n, u)


@dataclass(frozen=True)
class ReducedProblem:
    """Source and target reduced to reference points (their centroids)."""

    source: np.ndarray
    target: np.ndarray
    source_ref: np.ndarray
    target_ref: np.ndarray


def reduce(source: np.ndarray, target: np.ndarray, w: np.ndarray | None = None) -> ReducedProblem:
    """Reduce both point sets to their (point-weighted) centroids."""
    if w is None:
        xg, Xg = source.mean(axis=0), target.mean(axis=0)
    else:
        xg, Xg = (w @ source) / w.sum(), (w @ target) / w.sum()
    return ReducedProblem(source - xg, target - Xg, xg, Xg)


def similarity_gauss_markov(
    prob: ReducedProblem,
    p0_reduced: np.ndarray,
    *,
    with_scale: bool,
    R0: np.ndarray,
    weights: np.ndarray | None = None,
    covariance: np.ndarray | None = None,
    sigma0_prior: float = 1.0,
    max_iter: int = 50,
    tol: float = 1e-10,
) -> Adjustment:
    """Gauss-Markov adjustment (never raises on non-convergence; the caller decides).

    ``weights``: diagonal of P for the 3n target coordinates (point-major order);
    ``covariance``: (3n, 3n) or (n, 3, 3).
    """
    xr = prob.source
    cache: dict = {}

    def evaluate(p):
        key = p.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = _model_jacobian(xr, p, with_scale, R0)
        return cache[key]

    return gauss_markov(
        lambda p: evaluate(p)[0].reshape(-1),
        p0_reduced,
        prob.target.reshape(-1),
        jacobian=lambda p: evaluate(p)[1],
        weights=weights,
        covariance=covariance,
        sigma0_prior=sigma0_prior,
        names=names(with_scale),
        max_iter=max_iter,
        tol=tol,
        raise_on_failure=False,
        what="absolute orientation (Gauss-Markov)",
    )


def _b_matrix(s: float, R: np.ndarray, n: int) -> scipy.sparse.bsr_matrix:
    """``dg/dl`` (3n, 6n) for observations ordered ``[x_1, X_1, x_2, X_2, ...]``."""
    block = np.hstack([s * R, -np.eye(3)])
    data = np.broadcast_to(block, (n, 3, 6)).copy()
    return scipy.sparse.bsr_matrix(
        (data, np.arange(n), np.arange(n + 1)), shape=(3 * n, 6 * n)
    )


def similarity_gauss_helmert(
    prob: ReducedProblem,
    p0_reduced: np.ndarray,
    *,
    with_scale: bool,
    R0: np.ndarray,
    weights: np.ndarray | None = None,
    covariance: np.ndarray | None = None,
    sigma0_prior: float = 1.0,
    max_iter: int = 50,
    tol: float = 1e-10,
) -> Adjustment:
    """Gauss-Helmert adjustment with observations ``l = [x_1, X_1, x_2, X_2, ...]`` (6n).

    ``weights`` (6n,) or ``covariance`` (6n, 6n) or (n, 6, 6) in that order.
    """
    n = prob.source.shape[0]
    L = np.hstack([prob.source, prob.target]).reshape(-1)

    def split(lv):
        pts = lv.reshape(n, 6)
        return pts[:, :3], pts[:, 3:]

    def conditions(p, lv):
        xs, Xs = split(lv)
        tr, sc, _ = unpack(p, with_scale)
        R, _ = _rotation(p, with_scale, R0)
        return (tr + sc * (xs @ R.T) - Xs).reshape(-1)

    def jac_x(p, lv):
        xs, _ = split(lv)
        return _model_jacobian(xs, p, with_scale, R0)[1]

    def jac_l(p, lv):
        _, sc, _ = unpack(p, with_scale)
        R, _ = _rotation(p, with_scale, R0)
        return _b_matrix(sc, R, n)

    return gauss_helmert(
        conditions,
        p0_reduced,
        L,
        jacobian_x=jac_x,
        jacobian_l=jac_l,
        weights=weights,
        covariance=covariance,
        sigma0_prior=sigma0_prior,
        names=names(with_scale),
        max_iter=max_iter,
        tol=tol,
        raise_on_failure=False,
        what="absolute orientation (Gauss-Helmert)",
    )

