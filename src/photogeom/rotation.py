"""Rotation matrices and their angles, with the photogrammetric conventions pinned.

Conventions (see the README table and ``docs/conventions.md``):

* Elementary rotations of the coordinate *axes* (passive), positive counter-clockwise
  seen from the positive end of the axis: ``M1(w)``, ``M2(p)``, ``M3(k)``;
  ``Mi(t) = Ri(-t)`` where ``Ri`` is the usual active rotation.
* Orientation matrix ``M(omega, phi, kappa) = M3(kappa) @ M2(phi) @ M1(omega)``,
  used directly by the collinearity equations ``(x - x0, y - y0, -f) = lam M (X - X0)``.
* A 3D similarity ``X = s R x + t`` stores ``R``; its angles follow one of two conventions:
  ``"transposed"`` (default; Wolf, Mikhail, Kraus): ``R = M(omega, phi, kappa).T``,
  ``"direct"`` (closed-form absolute orientation paper): ``R = M(omega, phi, kappa)``.

All functions take radians and broadcast over leading batch axes.
Quaternions, axis-angle, Rodrigues (Gibbs) vectors and general Euler sequences are
delegated to :class:`scipy.spatial.transform.Rotation`, whose matrices act on
coordinates (``R @ x``), exactly as our ``R``.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from .errors import GimbalLockError, InputError
from .units import from_radians, to_radians

Convention = Literal["transposed", "direct"]
CONVENTIONS: tuple[str, ...] = ("transposed", "direct")
DEFAULT_CONVENTION: Convention = "transposed"

#: Below this value of cos(phi) the angles omega and kappa are not separable.
GIMBAL_TOLERANCE = 1e-9

#: Below this value of cos(phi) :func:`opk_from_matrix` takes kappa from entries of order one
#: (the textbook atan2(-m21, m11) divides the rounding errors of the matrix by cos(phi)).
NEAR_GIMBAL_LOCK = 1e-2


def _Rotation():
    """scipy's Rotation class, imported on first use (scipy.spatial is slow to import)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _stack(rows) -> np.ndarray:
    """Build (..., 3, 3) from nested lists of broadcastable arrays."""
    arrs = np.broadcast_arrays(*[np.asarray(v, dtype=float) for row in rows for v in row])
    return np.stack(arrs, axis=-1).reshape((*arrs[0].shape, 3, 3))


def m1(omega) -> np.ndarray:
    """Elementary axis rotation about x: ``[[1,0,0],[0,c,s],[0,-s,c]]`` (radians)."""
    c, s = np.cos(omega), np.sin(omega)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[o, z, z], [z, c, s], [z, -s, c]])


def m2(phi) -> np.ndarray:
    """Elementary axis rotation about y: ``[[c,0,-s],[0,1,0],[s,0,c]]`` (radians)."""
    c, s = np.cos(phi), np.sin(phi)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[c, z, -s], [z, o, z], [s, z, c]])


def m3(kappa) -> np.ndarray:
    """Elementary axis rotation about z: ``[[c,s,0],[-s,c,0],[0,0,1]]`` (radians)."""
    c, s = np.cos(kappa), np.sin(kappa)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[c, s, z], [-s, c, z], [z, z, o]])


def opk_matrix(omega, phi, kappa) -> np.ndarray:
    """Photogrammetric orientation matrix ``M = M3(kappa) M2(phi) M1(omega)``.

    Parameters
    ----------
    omega, phi, kappa : float or array_like
        Angles in radians (broadcast together).

    Returns
    -------
    numpy.ndarray
        Shape ``(..., 3, 3)``.
    """
    sw, cw = np.sin(omega), np.cos(omega)
    sp, cp = np.sin(phi), np.cos(phi)
    sk, ck = np.sin(kappa), np.cos(kappa)
    return _stack(
        [
            [ck * cp, ck * sp * sw + sk * cw, -ck * sp * cw + sk * sw],
            [-sk * cp, -sk * sp * sw + ck * cw, sk * sp * cw + ck * sw],
            [sp, -cp * sw, cp * cw],
        ]
    )


def opk_matrix_and_derivatives(
    omega: float, phi: float, kappa: float
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``M = M3(kappa) M2(phi) M1(omega)`` and ``dM/domega, dM/dphi, dM/dkappa`` (radians).

    Scalar arithmetic for one attitude: each derivative replaces one elementary factor by
    its derivative. Cheaper than the broadcasting builders where it is called once per
    iteration (resection, absolute orientation).
    """
    cw, sw = math.cos(omega), math.sin(omega)
    cp, sp = math.cos(phi), math.sin(phi)
    ck, sk = math.cos(kappa), math.sin(kappa)
    M1 = np.array([[1.0, 0.0, 0.0], [0.0, cw, sw], [0.0, -sw, cw]])
    M2 = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
    M3 = np.array([[ck, sk, 0.0], [-sk, ck, 0.0], [0.0, 0.0, 1.0]])
    dM1 = np.array([[0.0, 0.0, 0.0], [0.0, -sw, cw], [0.0, -cw, -sw]])
    dM2 = np.array([[-sp, 0.0, -cp], [0.0, 0.0, 0.0], [cp, 0.0, -sp]])
    dM3 = np.array([[-sk, ck, 0.0], [-ck, -sk, 0.0], [0.0, 0.0, 0.0]])
    M32 = M3 @ M2
    return M32 @ M1, (M32 @ dM1, M3 @ dM2 @ M1, dM3 @ (M2 @ M1))


def opk_from_matrix(
    M,
    *,
    on_gimbal_lock: Literal["raise", "omega-zero"] = "raise",
    tolerance: float = GIMBAL_TOLERANCE,
) -> tuple:
    """Angles (omega, phi, kappa) in radians of ``M = M3(kappa) M2(phi) M1(omega)``.

    ``phi = atan2(m31, hypot(m32, m33))`` in [-pi/2, pi/2], ``omega = atan2(-m32, m33)``,
    ``kappa = atan2(-m21, m11)``; near gimbal lock (``cos(phi) <`` :data:`NEAR_GIMBAL_LOCK`)
    kappa is read from the first row of ``M (M2(phi) M1(omega))^T = M3(kappa)`` instead, whose
    entries are of order one, so that the angles give ``M`` back to rounding (the textbook
    formula loses digits as ``1 / cos(phi)``: 7e-8 at phi = 90 - 1e-7 degrees). For a
    rotation ``phi`` equals the textbook ``asin(m31)``
    (to rounding, and more accurately near +-90 degrees, where ``asin`` loses half the
    digits); for a matrix that is not orthogonal (the raw closed-form absolute orientation)
    the two differ: :meth:`AbsoluteOrientationFit.angles` reads that matrix with
    ``asin(m31)`` as its paper publishes, this function does not.

    Parameters
    ----------
    M : array_like, shape (..., 3, 3)
        Rotation matrix (or batch).
    on_gimbal_lock : {"raise", "omega-zero"}
        At phi = +-90 deg only omega +- kappa is defined. ``"raise"`` raises
        :class:`GimbalLockError`; ``"omega-zero"`` sets omega = 0 and puts the whole
        rotation about the vertical into kappa.
    tolerance : float
        Gimbal lock is declared when ``cos(phi) < tolerance``.

    Returns
    -------
    omega, phi, kappa : float or numpy.ndarray
    """
    M = np.asarray(M, dtype=float)
    if M.shape[-2:] != (3, 3):
        raise InputError(f"rotation matrix: expected shape (..., 3, 3), got {M.shape}")
    m11, m21 = M[..., 0, 0], M[..., 1, 0]
    m31, m32, m33 = M[..., 2, 0], M[..., 2, 1], M[..., 2, 2]
    cos_phi = np.hypot(m32, m33)
    phi = np.arctan2(m31, cos_phi)
    omega = np.arctan2(-m32, m33)
    kappa = np.arctan2(-m21, m11)
    near = cos_phi < NEAR_GIMBAL_LOCK
    if np.any(near):
        # m11, m21 (like m32, m33) are cos(phi) times O(1): their rounding errors, relative
        # to cos(phi), separate kappa from omega. Kappa from the first row of
        # M (M2(phi) M1(omega))^T = M3(kappa) instead, whose entries are O(1), keeps
        # M(omega, phi, kappa) = M to rounding (the rotation about the vertical taken up by
        # kappa whatever the error of omega).
        cw, sw = np.cos(omega), np.sin(omega)
        cp, sp = cos_phi, m31
        m12, m13 = M[..., 0, 1], M[..., 0, 2]
        k_near = np.arctan2(m12 * cw + m13 * sw, m11 * cp + (m12 * sw - m13 * cw) * sp)
        kappa = np.where(near, k_near, kappa)
    locked = cos_phi < tolerance
    if np.any(locked):
        if on_gimbal_lock == "raise":
            raise GimbalLockError(
                "gimbal lock: phi is +-90 degrees, so omega and kappa are not separable "
                "(only their sum or difference is defined); use on_gimbal_lock='omega-zero', "
                "another Euler sequence (euler_from_matrix) or a quaternion"
            )
        if on_gimbal_lock != "omega-zero":
            raise InputError(
                f"on_gimbal_lock must be 'raise' or 'omega-zero', not {on_gimbal_lock!r}"
            )
        # With omega = 0: M = M3(k) M2(p); row 2 gives (-sin k, cos k) in (m12, m22).
        k_locked = np.arctan2(M[..., 0, 1], M[..., 1, 1])
        omega = np.where(locked, 0.0, omega)
        kappa = np.where(locked, k_locked, kappa)
    if np.ndim(omega) == 0:
        return float(omega), float(phi), float(kappa)
    return omega, phi, kappa


def _check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise InputError(
            f"unknown rotation convention {convention!r}; use 'transposed' "
            "(R = M(omega, phi, kappa).T, Wolf/Kraus) or 'direct' (R = M(omega, phi, kappa))"
        )


def rotation_from_angles(
    omega, phi, kappa, convention: Convention = DEFAULT_CONVENTION, unit: str = "rad"
) -> np.ndarray:
    """Rotation ``R`` of a similarity ``X = s R x + t`` from its angles.

    ``convention="transposed"``: ``R = M(omega, phi, kappa).T = R1(omega) R2(phi) R3(kappa)``;
    ``convention="direct"``: ``R = M(omega, phi, kappa)``.
    """
    _check_convention(convention)
    w, p, k = (to_radians(a, unit) for a in (omega, phi, kappa))
    M = opk_matrix(w, p, k)
    return np.swapaxes(M, -1, -2) if convention == "transposed" else M


def angles_from_rotation(
    R,
    convention: Convention = DEFAULT_CONVENTION,
    unit: str = "rad",
    *,
    on_gimbal_lock: Literal["raise", "omega-zero"] = "raise",
) -> tuple:
    """Angles (omega, phi, kappa) of a similarity rotation ``R`` in ``unit``.

    Inverse of :func:`rotation_from_angles` (phi in [-90, 90] degrees).
    """
    _check_convention(convention)
    R = np.asarray(R, dtype=float)
    M = np.swapaxes(R, -1, -2) if convention == "transposed" else R
    angles = opk_from_matrix(M, on_gimbal_lock=on_gimbal_lock)
    out = tuple(from_radians(a, unit) for a in angles)
    return tuple(float(a) for a in out) if np.ndim(out[0]) == 0 else out


# --- other parametrisations (delegated to scipy) -------------------------------------------


def _as_rotation(R):
    R = np.asarray(R, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise InputError(f"rotation matrix: expected shape (..., 3, 3), got {R.shape}")
    return _Rotation().from_matrix(R)


def quaternion_from_matrix(R, *, scalar_first: bool = True) -> np.ndarray:
    """Unit quaternion of rotation matrix ``R`` (which acts as ``R @ x``).

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or a stack of them).
    scalar_first : bool
        ``True``: ``(w, x, y, z)`` (Hamilton, Horn); ``False``: ``(x, y, z, w)`` (scipy, ROS).
        The sign is chosen with ``w >= 0``.

    Returns
    -------
    numpy.ndarray, shape (4,) or (..., 4)
        Unit quaternion(s), unitless.
    """
    q = _as_rotation(R).as_quat(canonical=True)  # scalar last
    return np.roll(q, 1, axis=-1) if scalar_first else q


def matrix_from_quaternion(q, *, scalar_first: bool = True) -> np.ndarray:
    """Rotation matrix of a quaternion (normalised first); see :func:`quaternion_from_matrix`."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 4:
        raise InputError(f"quaternion: expected shape (..., 4), got {q.shape}")
    norm = np.linalg.norm(q, axis=-1)
    if np.any(norm < 1e-12):
        raise InputError("quaternion: zero quaternion does not represent a rotation")
    if scalar_first:
        q = np.roll(q, -1, axis=-1)
    return _Rotation().from_quat(q).as_matrix()


def axis_angle_from_matrix(R) -> tuple[np.ndarray, np.ndarray]:
    """Unit rotation axis and angle (radians, in [0, pi]) of ``R``: ``R @ x`` rotates ``x``
    counter-clockwise by the angle about the axis (right-hand rule)."""
    rv = _as_rotation(R).as_rotvec()
    angle = np.linalg.norm(rv, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(angle[..., None] > 0, rv / angle[..., None], [0.0, 0.0, 1.0])
    return axis, angle


def matrix_from_axis_angle(axis, angle) -> np.ndarray:
    """Rotation matrix from an axis (normalised here) and an angle in radians."""
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm < 1e-15):
        raise InputError("axis-angle: the rotation axis has zero length")
    return (
        _Rotation().from_rotvec(axis / norm * np.asarray(angle, dtype=float)[..., None]).as_matrix()
    )


def rodrigues_from_matrix(R) -> np.ndarray:
    """Rodrigues (Gibbs) vector ``g = tan(angle / 2) * axis``; infinite at 180 degrees."""
    axis, angle = axis_angle_from_matrix(R)
    if np.any(np.isclose(angle, np.pi, atol=1e-12)):
        raise InputError("Rodrigues/Gibbs vector is infinite for a rotation of 180 degrees")
    return np.tan(angle / 2.0)[..., None] * axis


def matrix_from_rodrigues(g) -> np.ndarray:
    """Rotation matrix from a Rodrigues (Gibbs) vector ``g = tan(angle / 2) * axis``:
    ``R = I + 2 / (1 + g.g) * ([g]x + [g]x^2)``."""
    g = np.asarray(g, dtype=float)
    gx = skew(g)
    eye = np.broadcast_to(np.eye(3), gx.shape)
    return eye + (2.0 / (1.0 + np.sum(g * g, axis=-1)))[..., None, None] * (gx + gx @ gx)


def euler_from_matrix(R, seq: str, unit: str = "rad") -> np.ndarray:
    """Euler angles of ``R`` for any scipy sequence (``"xyz"`` extrinsic, ``"XYZ"`` intrinsic).

    These are angles of *active* rotations composing ``R``; see scipy's documentation.
    """
    return from_radians(_as_rotation(R).as_euler(seq), unit)


def matrix_from_euler(seq: str, angles, unit: str = "rad") -> np.ndarray:
    """Rotation matrix from Euler angles of an scipy sequence (active rotations)."""
    return _Rotation().from_euler(seq, to_radians(angles, unit)).as_matrix()


# --- helpers ---------------------------------------------------------------------------------


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]x`` with ``[v]x @ u = v x u``; shape (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros_like(v[..., 0])
    return _stack(
        [[z, -v[..., 2], v[..., 1]], [v[..., 2], z, -v[..., 0]], [-v[..., 1], v[..., 0], z]]
    )


def orthogonality_defect(R) -> np.ndarray | float:
    """Frobenius norm ``|R.T R - I|`` (0 for an exact rotation)."""
    R = np.asarray(R, dtype=float)
    d = np.linalg.norm(np.swapaxes(R, -1, -2) @ R - np.eye(3), axis=(-2, -1))
    return float(d) if np.ndim(d) == 0 else d


def nearest_rotation(A) -> np.ndarray:
    """Closest proper rotation to ``A`` in the Frobenius norm (polar decomposition, det = +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(A, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones((*np.shape(d), 3))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt


def is_rotation(R, tol: float = 1e-9) -> bool:
    """``True`` when every matrix of ``R`` is orthonormal with determinant +1 (within ``tol``)."""
    R = np.asarray(R, dtype=float)
    return bool(
        np.all(np.asarray(orthogonality_defect(R)) < tol)
        and np.all(np.abs(np.linalg.det(R) - 1.0) < tol)
    )
