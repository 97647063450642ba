"""Observation-vectorised projection of the Metashape frame camera, with analytic derivatives.

One row per image observation: the object point, the image's exterior orientation and its
calibration are given per row (gathered from the block), so that a whole block projects in
one call. Conventions: ``p = M (X - X0)`` in the photogrammetric image system (x right,
y up, z backwards), Metashape's camera axes ``(p_x, -p_y, -p_z)``, the Brown model of
:mod:`photogeom.camera.metashape`, pixels with the centre of the first pixel at (0, 0).

Derivatives are with respect to

* the object point ``X`` (3),
* the projection centre ``X0`` (3),
* a rotation increment ``dtheta`` (3) applied on the left: ``M <- exp([dtheta]x) M``, so that
  ``dp/dtheta = -[p]x``. :func:`opk_from_increment_jacobian` converts to omega, phi, kappa.
* the calibration vector ``(f, cx, cy, k1, k2, k3, k4, p1, p2, b1, b2)`` (11).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

CALIBRATION_NAMES = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")


class Projection(NamedTuple):
    """Pixels and derivatives of :func:`project_rows` (row-wise, n rows)."""

    uv: np.ndarray  # (n, 2)
    depth: np.ndarray  # (n,) Metashape z (> 0 in front of the camera)
    d_point: np.ndarray | None  # (n, 2, 3)
    d_center: np.ndarray | None  # (n, 2, 3)
    d_rotation: np.ndarray | None  # (n, 2, 3)
    d_calibration: np.ndarray | None  # (n, 2, 11)


def project_rows(
    X: np.ndarray,
    M: np.ndarray,
    C: np.ndarray,
    cal: np.ndarray,
    size: np.ndarray,
    *,
    jacobian: bool = True,
) -> Projection:
    """Project object points row by row.

    Parameters
    ----------
    X : (n, 3) object points.
    M : (n, 3, 3) rotation matrices (object -> image system) of each row's image.
    C : (n, 3) projection centres.
    cal : (n, 11) calibration vectors (pixels; see :data:`CALIBRATION_NAMES`).
    size : (n, 2) image width and height, pixels.
    jacobian : bool
        Also return the derivatives.

    Returns
    -------
    Projection
    """
    d = X - C
    p = np.einsum("nij,nj->ni", M, d)
    Zc = -p[:, 2]
    iz = 1.0 / Zc
    x = p[:, 0] * iz
    y = -p[:, 1] * iz
    f, cx, cy = cal[:, 0], cal[:, 1], cal[:, 2]
    k1, k2, k3, k4 = cal[:, 3], cal[:, 4], cal[:, 5], cal[:, 6]
    p1, p2, b1, b2 = cal[:, 7], cal[:, 8], cal[:, 9], cal[:, 10]
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
    xy = x * y
    xd = x * rad + p1 * (r2 + 2.0 * x * x) + 2.0 * p2 * xy
    yd = y * rad + p2 * (r2 + 2.0 * y * y) + 2.0 * p1 * xy
    fx = f + b1
    uv = np.empty((X.shape[0], 2))
    uv[:, 0] = size[:, 0] * 0.5 - 0.5 + cx + xd * fx + yd * b2
    uv[:, 1] = size[:, 1] * 0.5 - 0.5 + cy + yd * f
    if not jacobian:
        return Projection(uv, Zc, None, None, None, None)

    n = X.shape[0]
    drad = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + r2 * 4.0 * k4))  # d rad / d r2
    # d(xd, yd) / d(x, y)
    a11 = rad + 2.0 * x * x * drad + 6.0 * p1 * x + 2.0 * p2 * y
    a12 = 2.0 * xy * drad + 2.0 * p1 * y + 2.0 * p2 * x
    a21 = 2.0 * xy * drad + 2.0 * p2 * x + 2.0 * p1 * y
    a22 = rad + 2.0 * y * y * drad + 6.0 * p2 * y + 2.0 * p1 * x
    # d(u, v) / d(x, y)
    g11 = fx * a11 + b2 * a21
    g12 = fx * a12 + b2 * a22
    g21 = f * a21
    g22 = f * a22
    # d(x, y) / dp: x = p0 / Zc, y = -p1 / Zc, Zc = -p2
    J = np.empty((n, 2, 3))
    J[:, 0, 0] = g11 * iz
    J[:, 0, 1] = -g12 * iz
    J[:, 0, 2] = (g11 * x + g12 * y) * iz
    J[:, 1, 0] = g21 * iz
    J[:, 1, 1] = -g22 * iz
    J[:, 1, 2] = (g21 * x + g22 * y) * iz
    d_point = np.einsum("nij,njk->nik", J, M)
    d_center = -d_point
    # dp/dtheta = -[p]x  ->  J @ (-[p]x)
    d_rot = np.empty((n, 2, 3))
    px, py, pz = p[:, 0], p[:, 1], p[:, 2]
    for r in range(2):
        j0, j1, j2 = J[:, r, 0], J[:, r, 1], J[:, r, 2]
        # (-[p]x) = [[0, pz, -py], [-pz, 0, px], [py, -px, 0]]
        d_rot[:, r, 0] = -j1 * pz + j2 * py
        d_rot[:, r, 1] = j0 * pz - j2 * px
        d_rot[:, r, 2] = -j0 * py + j1 * px
    d_cal = np.zeros((n, 2, 11))
    d_cal[:, 0, 0] = xd
    d_cal[:, 1, 0] = yd
    d_cal[:, 0, 1] = 1.0
    d_cal[:, 1, 2] = 1.0
    r2k = r2.copy()
    for c in range(3, 7):  # k1..k4: d(xd, yd)/dk = (x, y) r2^i
        d_cal[:, 0, c] = fx * x * r2k + b2 * y * r2k
        d_cal[:, 1, c] = f * y * r2k
        r2k = r2k * r2
    tx1, ty1 = r2 + 2.0 * x * x, 2.0 * xy  # d(xd, yd)/dp1
    tx2, ty2 = 2.0 * xy, r2 + 2.0 * y * y  # d(xd, yd)/dp2
    d_cal[:, 0, 7] = fx * tx1 + b2 * ty1
    d_cal[:, 1, 7] = f * ty1
    d_cal[:, 0, 8] = fx * tx2 + b2 * ty2
    d_cal[:, 1, 8] = f * ty2
    d_cal[:, 0, 9] = xd
    d_cal[:, 0, 10] = yd
    return Projection(uv, Zc, d_point, d_center, d_rot, d_cal)


def rotation_increment(theta: np.ndarray) -> np.ndarray:
    """``exp([theta]x)`` for rotation vectors (m, 3) -> (m, 3, 3) (Rodrigues' formula)."""
    t = np.asarray(theta, dtype=float).reshape(-1, 3)
    a = np.linalg.norm(t, axis=1)
    small = a < 1e-8
    a_safe = np.where(small, 1.0, a)
    s = np.where(small, 1.0 - a * a / 6.0, np.sin(a) / a_safe)
    c = np.where(small, 0.5 - a * a / 24.0, (1.0 - np.cos(a)) / (a_safe * a_safe))
    K = np.zeros((t.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -t[:, 2], t[:, 1]
    K[:, 1, 0], K[:, 1, 2] = t[:, 2], -t[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -t[:, 1], t[:, 0]
    return np.eye(3)[None] + s[:, None, None] * K + c[:, None, None] * (K @ K)


def increment_from_opk_jacobian(angles: np.ndarray) -> np.ndarray:
    """``T = dtheta / d(omega, phi, kappa)`` (m, 3, 3) at the given angles (m, 3).

    With ``M = M3(kappa) M2(phi) M1(omega)`` and a left increment ``M <- exp([dtheta]x) M``,
    ``dtheta = T d(omega, phi, kappa)`` with columns ``-M3 M2 e1``, ``-M3 e2``, ``-e3``.
    """
    a = np.asarray(angles, dtype=float).reshape(-1, 3)
    phi, kappa = a[:, 1], a[:, 2]
    cp, sp = np.cos(phi), np.sin(phi)
    ck, sk = np.cos(kappa), np.sin(kappa)
    T = np.zeros((a.shape[0], 3, 3))
    # M3 M2 e1 = M3 (cos p, 0, sin p) = (ck cp, -sk cp, sp)
    T[:, 0, 0], T[:, 1, 0], T[:, 2, 0] = -ck * cp, sk * cp, -sp
    # M3 e2 = (sk, ck, 0)
    T[:, 0, 1], T[:, 1, 1] = -sk, -ck
    T[:, 2, 2] = -1.0
    return T


def opk_from_increment_jacobian(angles: np.ndarray) -> np.ndarray:
    """``d(omega, phi, kappa) / dtheta`` (m, 3, 3): the inverse of
    :func:`increment_from_opk_jacobian` (singular at phi = +-90 degrees, gimbal lock)."""
    return np.linalg.inv(increment_from_opk_jacobian(angles))
