"""Statistics of the 3D similarity from the linearised Gauss-Markov model, in closed form.

The observation equations ``X_i + v_i = t + s R(omega, phi, kappa) x_i`` (per-point isotropic
weights ``w_i``) linearised at a solution give, with ``x'_i`` the source coordinates reduced to
their weighted centroid ``xg`` and the shift re-parametrised about it
(``t = Xg + t' - s R xg``), a *block-diagonal* normal matrix:

* shift ``t'``: ``W I`` with ``W = sum w_i``;
* scale: ``a = sum w_i |x'_i|^2`` (no coupling: ``sum w_i x'_i = 0``; ``x.T R.T dR x = 0``);
* rotation, as a right perturbation ``R (I + [delta]x)``: ``s^2 (a I - S)`` with the
  weighted scatter ``S = sum w_i x'_i x'_i.T``.

So the 7x7 cofactor matrix needs only ``W``, ``S`` and the solution: no (3n x 7) design
matrix. The rotation block is mapped to omega, phi, kappa (``delta = G d(angles)``) and the
shift back to ``t`` with the Jacobian of ``t = Xg + t' - s R xg``. Redundancy numbers and
Baarda's normalised residuals follow per point from the same blocks (O(n)).

Angles follow the *transposed* convention ``R = M(omega, phi, kappa).T`` (radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def opk_transposed(R: np.ndarray) -> tuple[float, float, float, bool]:
    """``(omega, phi, kappa, gimbal)`` of ``R = M(omega, phi, kappa).T`` in radians.

    The same formulas as :func:`photogeom.rotation.opk_from_matrix` (applied to ``R.T``),
    in scalar arithmetic for speed; at gimbal lock (``cos phi < 1e-9``) omega is set to 0
    and ``gimbal`` is True. Works on a non-orthogonal ``R`` (reads the same elements).
    """
    r = R.tolist()
    m31, m32, m33, m21, m11 = r[0][2], r[1][2], r[2][2], r[0][1], r[0][0]
    cos_phi = math.hypot(m32, m33)
    phi = math.atan2(m31, cos_phi)
    if cos_phi < 1e-9:
        return 0.0, phi, math.atan2(r[1][0], r[1][1]), True
    return math.atan2(-m32, m33), phi, math.atan2(-m21, m11), False


def rotation_derivatives(omega: float, phi: float, kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """``R = M(omega, phi, kappa).T`` and ``dR / d(omega, phi, kappa)`` (3, 3, 3), radians.

    ``M = M3(kappa) M2(phi) M1(omega)`` (see :func:`photogeom.rotation.opk_matrix`); the
    derivatives replace one factor by its derivative. Scalar arithmetic (called once per
    iteration or solve).
    """
    cw, sw = math.cos(omega), math.sin(omega)
    cp, sp = math.cos(phi), math.sin(phi)
    ck, sk = math.cos(kappa), math.sin(kappa)
    M1 = np.array([[1.0, 0.0, 0.0], [0.0, cw, sw], [0.0, -sw, cw]])
    M2 = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
    M3 = np.array([[ck, sk, 0.0], [-sk, ck, 0.0], [0.0, 0.0, 1.0]])
    D1 = np.array([[0.0, 0.0, 0.0], [0.0, -sw, cw], [0.0, -cw, -sw]])
    D2 = np.array([[-sp, 0.0, -cp], [0.0, 0.0, 0.0], [cp, 0.0, -sp]])
    D3 = np.array([[-sk, ck, 0.0], [-ck, -sk, 0.0], [0.0, 0.0, 0.0]])
    M32 = M3 @ M2
    M21 = M2 @ M1
    R = (M32 @ M1).T
    dR = np.stack([(M32 @ D1).T, (M3 @ D2 @ M1).T, (D3 @ M21).T])
    return R, dR


def angle_to_perturbation(R: np.ndarray, dR: np.ndarray) -> np.ndarray:
    """``G`` (3, 3) with ``delta = G d(angles)`` for ``R(angles + d) = R (I + [delta]x)``:
    column a is ``vee(R.T dR_a)``."""
    K = R.T @ dR  # (3, 3, 3): R.T dR_a, skew-symmetric
    return np.array(
        [[K[0, 2, 1], K[1, 2, 1], K[2, 2, 1]],
         [K[0, 0, 2], K[1, 0, 2], K[2, 0, 2]],
         [K[0, 1, 0], K[1, 1, 0], K[2, 1, 0]]]
    )


@dataclass(frozen=True)
class LinearisedStatistics:
    """Statistics of the linearised model at a solution.

    Attributes
    ----------
    cofactor : numpy.ndarray, shape (u, u)
        ``Qxx`` of ``(tx, ty, tz[, scale], omega, phi, kappa)`` (u = 7, or 6 without scale);
        NaN rows/columns for angles at gimbal lock.
    vtpv : float
    redundancy_numbers, normalized_residuals : numpy.ndarray, shape (n, 3)
        Per component; the normalised residual is NaN where the redundancy number is ~0.
    point_blocks : numpy.ndarray, shape (n, 3, 3)
        ``A Qxx A.T`` blocks per point (for Gauss-Helmert corrections of the source).
    """

    cofactor: np.ndarray
    vtpv: float
    redundancy_numbers: np.ndarray
    normalized_residuals: np.ndarray
    point_blocks: np.ndarray


def linearised_statistics(
    xr: np.ndarray,
    v: np.ndarray,
    *,
    scale: float,
    angles: tuple[float, float, float],
    source_centroid: np.ndarray,
    weights: np.ndarray | None = None,
    sigma0_prior: float = 1.0,
    with_scale: bool = True,
    blocks: bool = False,
) -> LinearisedStatistics:
    """Closed-form Gauss-Markov statistics of ``X_i + v_i = t + s R x_i`` at a solution.

    Parameters
    ----------
    xr : numpy.ndarray, shape (n, 3)
        Source points reduced to their (weighted) centroid.
    v : numpy.ndarray, shape (n, 3)
        Residuals (computed minus observed) at the solution, target units.
    scale : float
    angles : (omega, phi, kappa)
        Radians, transposed convention: the linearisation uses ``R(angles)`` (orthogonal).
    source_centroid : numpy.ndarray, shape (3,)
        ``xg`` (to map the reduced shift back to ``t``).
    weights : numpy.ndarray, shape (n,), optional
        Point weights (``P_i = w_i I``); 1 when omitted.
    sigma0_prior : float
    with_scale : bool
        False: rigid model (6 parameters).
    blocks : bool
        Also return the per-point 3x3 blocks of ``A Qxx A.T`` (else ``point_blocks`` is None).
    """
    n = xr.shape[0]
    if weights is None:
        w = None
        Wsum = float(n)
        S = xr.T @ xr
        vtpv = float(v.reshape(-1) @ v.reshape(-1))
    else:
        w = weights
        Wsum = float(np.add.reduce(w))
        S = (xr * w[:, None]).T @ xr
        vtpv = float(np.add.reduce(np.add.reduce(v * v, axis=1) * w))
    a = float(S[0, 0] + S[1, 1] + S[2, 2])
    s = scale
    R, dR = rotation_derivatives(*angles)
    G = angle_to_perturbation(R, dR)
    Qd = np.linalg.inv(s * s * (a * _EYE3 - S))
    u = 7 if with_scale else 6
    # cofactor of the reduced unknowns (t', [s,] delta): block diagonal
    Qr = np.zeros((u, u))
    Qr[0, 0] = Qr[1, 1] = Qr[2, 2] = 1.0 / Wsum
    if with_scale:
        Qr[3, 3] = 1.0 / a
    Qr[u - 3 :, u - 3 :] = Qd
    # back from the reduced shift t' to t = Xg + t' - s R xg: dt/ds = -R xg,
    # dt/d(delta) = s R [xg]x
    J = np.eye(u)
    xg = np.asarray(source_centroid, dtype=float)
    if with_scale:
        J[:3, 3] = -(R @ xg)
    J[:3, u - 3 :] = s * (R @ _skew_rows(xg[None])[0])
    Q1 = J @ Qr @ J.T
    # rotation perturbation -> omega, phi, kappa (undefined at gimbal lock: NaN rows)
    K = np.eye(u)
    if abs(np.linalg.det(G)) > 1e-9:
        K[u - 3 :, u - 3 :] = np.linalg.inv(G)
        Q = K @ Q1 @ K.T
    else:
        Q = Q1.copy()
        Q[u - 3 :, :] = np.nan
        Q[:, u - 3 :] = np.nan
    # per point, the rotation rows of A (as delta) are -s (R_j x x'_i) = -s [R_j]x x'_i, so
    # (A Qxx A.T)_jk = x'.T (s^2 [R_j]x.T Qd [R_k]x) x' + ... (parametrisation-invariant)
    K = _skew_rows(R)  # [R_j]x
    T = (s * s) * (np.swapaxes(K, 1, 2) @ Qd @ K)  # (3, 3, 3), j a b
    hd = np.einsum("na,jab,nb->nj", xr, T, xr)
    hd += 1.0 / Wsum
    if with_scale:
        Rx = xr @ R.T
        hd += Rx * Rx / a
    h = hd if w is None else hd * w[:, None]
    red = 1.0 - h
    num = v if w is None else v * np.sqrt(w)[:, None]
    den = np.sqrt(np.abs(red)) * sigma0_prior
    wn = np.full(v.shape, np.nan)
    np.divide(num, den, out=wn, where=red > 1e-12)
    C = None
    if blocks:
        T4 = (s * s) * np.einsum("iba,bc,jcd->ijad", K, Qd, K)
        C = np.einsum("na,ijab,nb->nij", xr, T4, xr)
        C += _EYE3[None] / Wsum
        if with_scale:
            C += Rx[:, :, None] * Rx[:, None, :] / a
    return LinearisedStatistics(Q, vtpv, red, wn, C)


_EYE3 = np.eye(3)


def _skew_rows(v: np.ndarray) -> np.ndarray:
    """``[v_i]x`` for rows v (k, 3) -> (k, 3, 3), ``[v]x u = v x u``."""
    Z = np.zeros((v.shape[0], 3, 3))
    Z[:, 0, 1], Z[:, 0, 2] = -v[:, 2], v[:, 1]
    Z[:, 1, 0], Z[:, 1, 2] = v[:, 2], -v[:, 0]
    Z[:, 2, 0], Z[:, 2, 1] = -v[:, 1], v[:, 0]
    return Z
