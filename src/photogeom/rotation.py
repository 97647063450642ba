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

#: Below this value of cos(phi) (|phi| above 84.3 degrees) the standard deviations of omega and
#: kappa exceed the precision of the rotation itself by 1 / cos(phi), more than 10 times, and
#: are correlated to nearly +-1: the estimators say so in a note.
LOCK_COS_PHI = 0.1


def gimbal_lock_note(names, values, covariance) -> str | None:
    """The note of an estimate whose phi is near +-90 degrees (the gimbal lock of omega, phi,
    kappa), or None.

    Parameters
    ----------
    names : sequence of str
        Parameter names; those called ``omega``, ``phi`` and ``kappa`` are read.
    values : array_like, shape (u,)
        Parameter values (angles in radians).
    covariance : array_like, shape (u, u)
        Their covariance (angles in radians squared).

    Returns
    -------
    str or None
        When ``cos(phi) <`` :data:`LOCK_COS_PHI` and omega and kappa have finite standard
        deviations: a note that these are inflated by ``1 / cos(phi)`` and correlated
        (giving both), so that they describe the rotation only together.
    """
    names = list(names)
    if not all(k in names for k in ("omega", "phi", "kappa")):
        return None
    i, j, k = (names.index(n) for n in ("omega", "phi", "kappa"))
    phi = float(np.asarray(values, dtype=float)[j])
    c = np.asarray(covariance, dtype=float)
    if not math.cos(phi) < LOCK_COS_PHI or not np.all(np.isfinite(c[np.ix_([i, k], [i, k])])):
        return None
    so, sk = math.sqrt(max(c[i, i], 0.0)), math.sqrt(max(c[k, k], 0.0))
    if so == 0.0 or sk == 0.0:
        return None
    rho = c[i, k] / (so * sk)
    return (
        f"near the gimbal lock of omega, phi, kappa (phi {math.degrees(phi):.6g} deg, "
        f"{90.0 - abs(math.degrees(phi)):.3g} deg from +-90): omega and kappa turn about "
        f"nearly the same axis, so their standard deviations ({math.degrees(so):.3g} and "
        f"{math.degrees(sk):.3g} deg) are inflated by up to 1/cos(phi) = "
        f"{1.0 / max(math.cos(phi), 1e-300):.3g} and correlated {rho:+.4f}; the rotation is "
        "not less precise than elsewhere: use the angles' covariance together, not their "
        "separate standard deviations"
    )


def _Rotation():
    """scipy's Rotation class, imported on first use (scipy.spatial is slow to import)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _stack(rows) -> np.ndarray:
    """Build (..., 3, 3) from nested lists of broadcastable arrays."""
    arrs = np.broadcast_arrays(*[np.asarray(v, dtype=float) for row in rows for v in row])
    return np.stack(arrs, axis=-1).reshape((*arrs[0].shape, 3, 3))


def m1(omega) -> np.ndarray:
    """Elementary axis rotation about x: ``[[1,0,0],[0,c,s],[0,-s,c]]``.

    Parameters
    ----------
    omega : float or array_like
        Angle(s) in rad.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        One matrix per angle (shape ``(3, 3)`` for a scalar).
    """
    c, s = np.cos(omega), np.sin(omega)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[o, z, z], [z, c, s], [z, -s, c]])


def m2(phi) -> np.ndarray:
    """Elementary axis rotation about y: ``[[c,0,-s],[0,1,0],[s,0,c]]``.

    Parameters
    ----------
    phi : float or array_like
        Angle(s) in rad.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        One matrix per angle (shape ``(3, 3)`` for a scalar).
    """
    c, s = np.cos(phi), np.sin(phi)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[c, z, -s], [z, o, z], [s, z, c]])


def m3(kappa) -> np.ndarray:
    """Elementary axis rotation about z: ``[[c,s,0],[-s,c,0],[0,0,1]]``.

    Parameters
    ----------
    kappa : float or array_like
        Angle(s) in rad.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        One matrix per angle (shape ``(3, 3)`` for a scalar).
    """
    c, s = np.cos(kappa), np.sin(kappa)
    z, o = np.zeros_like(c), np.ones_like(c)
    return _stack([[c, s, z], [-s, c, z], [z, z, o]])


def opk_matrix(omega, phi, kappa) -> np.ndarray:
    """Photogrammetric orientation matrix ``M = M3(kappa) M2(phi) M1(omega)``.

    Parameters
    ----------
    omega, phi, kappa : float or array_like
        Angles in rad (broadcast together).

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        ``M``, one matrix per broadcast angle triple (shape ``(3, 3)`` for scalars).
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
    """``M = M3(kappa) M2(phi) M1(omega)`` and ``dM/domega, dM/dphi, dM/dkappa``.

    Scalar arithmetic for one attitude: each derivative replaces one elementary factor by
    its derivative. Cheaper than the broadcasting builders where it is called once per
    iteration (resection, absolute orientation).

    Parameters
    ----------
    omega, phi, kappa : float
        Angles in rad (scalars only).

    Returns
    -------
    M : numpy.ndarray, shape (3, 3)
        The orientation matrix.
    derivatives : tuple of three numpy.ndarray, shape (3, 3)
        ``(dM/domega, dM/dphi, dM/dkappa)``, per rad.
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
    on_gimbal_lock : {"raise", "omega-zero"}, default "raise"
        At phi = +-90 deg only omega +- kappa is defined. ``"raise"`` raises
        :class:`GimbalLockError`; ``"omega-zero"`` sets omega = 0 and puts the whole
        rotation about the vertical into kappa.
    tolerance : float, default GIMBAL_TOLERANCE (1e-9)
        Gimbal lock is declared when ``cos(phi) < tolerance`` (unitless).

    Returns
    -------
    omega, phi, kappa : float or numpy.ndarray
        Angles in rad: floats for one matrix, arrays of shape ``(...)`` for a batch.

    Raises
    ------
    InputError
        When ``M`` is not of shape ``(..., 3, 3)``, or (at gimbal lock) ``on_gimbal_lock`` is
        neither value.
    GimbalLockError
        At gimbal lock with ``on_gimbal_lock="raise"``.
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

    Parameters
    ----------
    omega, phi, kappa : float or array_like
        Angles in ``unit`` (broadcast together).
    convention : {"transposed", "direct"}, default "transposed"
        ``"transposed"``: ``R = M(omega, phi, kappa).T = R1(omega) R2(phi) R3(kappa)``
        (Wolf, Mikhail, Kraus); ``"direct"``: ``R = M(omega, phi, kappa)``.
    unit : str, default "rad"
        Angle unit: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"``.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
        ``R`` (shape ``(3, 3)`` for scalar angles).

    Raises
    ------
    InputError
        For an unknown ``convention`` or ``unit``.
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

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrix (or batch) of ``X = s R x + t``.
    convention : {"transposed", "direct"}, default "transposed"
        As in :func:`rotation_from_angles`.
    unit : str, default "rad"
        Unit of the returned angles: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"``.
    on_gimbal_lock : {"raise", "omega-zero"}, default "raise"
        As in :func:`opk_from_matrix`.

    Returns
    -------
    omega, phi, kappa : float or numpy.ndarray
        Angles in ``unit``: floats for one matrix, arrays of shape ``(...)`` for a batch.

    Raises
    ------
    InputError
        For an unknown ``convention`` or ``unit``, or ``R`` not of shape ``(..., 3, 3)``.
    GimbalLockError
        At phi = +-90 deg with ``on_gimbal_lock="raise"``.
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
    scalar_first : bool, default True
        ``True``: ``(w, x, y, z)`` (Hamilton, Horn); ``False``: ``(x, y, z, w)`` (scipy, ROS).
        The sign is chosen with ``w >= 0``.

    Returns
    -------
    numpy.ndarray, shape (4,) or (..., 4)
        Unit quaternion(s), unitless.

    Raises
    ------
    InputError
        When ``R`` is not of shape ``(..., 3, 3)``.
    """
    q = _as_rotation(R).as_quat(canonical=True)  # scalar last
    return np.roll(q, 1, axis=-1) if scalar_first else q


def matrix_from_quaternion(q, *, scalar_first: bool = True) -> np.ndarray:
    """Rotation matrix of a quaternion (normalised first); see :func:`quaternion_from_matrix`.

    Parameters
    ----------
    q : array_like, shape (4,) or (..., 4)
        Quaternion(s), any non-zero length (unitless).
    scalar_first : bool, default True
        ``True``: ``q`` is ``(w, x, y, z)``; ``False``: ``(x, y, z, w)``.

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack), acting as ``R @ x``.

    Raises
    ------
    InputError
        When the last axis of ``q`` is not 4 long, or a quaternion is zero.
    """
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
    """Unit rotation axis and angle of ``R``.

    ``R @ x`` rotates ``x`` counter-clockwise by the angle about the axis (right-hand rule).

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack).

    Returns
    -------
    axis : numpy.ndarray, shape (3,) or (..., 3)
        Unit axis; ``(0, 0, 1)`` for the identity (angle 0).
    angle : numpy.float64 or numpy.ndarray, shape (...)
        Angle in rad, in [0, pi].

    Raises
    ------
    InputError
        When ``R`` is not of shape ``(..., 3, 3)``.
    """
    rv = _as_rotation(R).as_rotvec()
    angle = np.linalg.norm(rv, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(angle[..., None] > 0, rv / angle[..., None], [0.0, 0.0, 1.0])
    return axis, angle


def matrix_from_axis_angle(axis, angle) -> np.ndarray:
    """Rotation matrix from an axis (normalised here) and an angle.

    Parameters
    ----------
    axis : array_like, shape (3,) or (..., 3)
        Rotation axis, any non-zero length (unitless).
    angle : float or array_like, shape (...)
        Angle(s) in rad, counter-clockwise about ``axis`` (right-hand rule).

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack), acting as ``R @ x``.

    Raises
    ------
    InputError
        When an axis has zero length.
    """
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm < 1e-15):
        raise InputError("axis-angle: the rotation axis has zero length")
    return (
        _Rotation().from_rotvec(axis / norm * np.asarray(angle, dtype=float)[..., None]).as_matrix()
    )


def rodrigues_from_matrix(R) -> np.ndarray:
    """Rodrigues (Gibbs) vector ``g = tan(angle / 2) * axis`` of ``R``.

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack).

    Returns
    -------
    numpy.ndarray, shape (3,) or (..., 3)
        Gibbs vector(s), unitless.

    Raises
    ------
    InputError
        When ``R`` is not of shape ``(..., 3, 3)``, or a rotation is of 180 degrees (where
        the vector is infinite).
    """
    axis, angle = axis_angle_from_matrix(R)
    if np.any(np.isclose(angle, np.pi, atol=1e-12)):
        raise InputError("Rodrigues/Gibbs vector is infinite for a rotation of 180 degrees")
    return np.tan(angle / 2.0)[..., None] * axis


def matrix_from_rodrigues(g) -> np.ndarray:
    """Rotation matrix from a Rodrigues (Gibbs) vector ``g = tan(angle / 2) * axis``.

    ``R = I + 2 / (1 + g.g) * ([g]x + [g]x^2)``.

    Parameters
    ----------
    g : array_like, shape (3,) or (..., 3)
        Gibbs vector(s), unitless.

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack), acting as ``R @ x``.

    Raises
    ------
    InputError
        When ``g`` is not of shape ``(..., 3)``.
    """
    g = np.asarray(g, dtype=float)
    if g.ndim == 0 or g.shape[-1] != 3:
        raise InputError(f"Rodrigues vector: expected shape (3,) or (..., 3), got {g.shape}")
    gx = skew(g)
    eye = np.broadcast_to(np.eye(3), gx.shape)
    return eye + (2.0 / (1.0 + np.sum(g * g, axis=-1)))[..., None, None] * (gx + gx @ gx)


#: Below this value of the sine (proper Euler sequences) or cosine (Tait-Bryan) of the
#: middle angle :func:`euler_from_matrix` declares gimbal lock: the rotation's entries that
#: separate the outer angles are then at the level of rounding.
EULER_LOCK_TOLERANCE = 1e-15

_AXIS = {"x": 0, "y": 1, "z": 2}


def _elementary(axis: int, angle: np.ndarray) -> np.ndarray:
    """Active rotation(s) (..., 3, 3) by ``angle`` (rad) about coordinate axis 0, 1 or 2."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R = np.zeros((*np.shape(angle), 3, 3))
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., j, i] = s
    R[..., i, j] = -s
    return R


def _euler_angles(R: np.ndarray, seq: str) -> np.ndarray:
    """Closed-form Euler angles (..., 3) in rad of rotation matrices (..., 3, 3).

    The matrix is written as a product ``Rp(alpha) Rq(beta) Rr(gamma)`` (extrinsic ``"abc"``:
    ``Rc Rb Ra``; intrinsic ``"ABC"``: ``RA RB RC``) and its axes permuted onto ``z y x``
    (Tait-Bryan) or ``x y x`` (proper), angles changing sign for an odd permutation. The middle
    angle comes from ``atan2`` of entries of order one; the angle scipy sets to zero at gimbal
    lock (the third of ``seq``) from the textbook ``atan2``; the remaining one from the matrix
    with the other two rotations taken off, whose entries are of order one, so that the angles
    give ``R`` back to rounding however close to the lock.
    """
    extrinsic = seq.islower()
    axes = [_AXIS[a] for a in seq.lower()]
    p, q, r = axes[::-1] if extrinsic else axes
    proper = p == r
    k = 3 - p - q if proper else r
    P = np.zeros((3, 3))
    if proper:  # p -> x, q -> y, the other -> +-z: a rotation, the angles unchanged
        P[0, p] = P[1, q] = 1.0
        P[2, k] = 1.0 if (q - p) % 3 == 1 else -1.0
        sign = 1.0
    else:  # p -> z, q -> y, r -> x: an odd permutation changes the angles' signs
        P[2, p] = P[1, q] = P[0, r] = 1.0
        sign = 1.0 if (q - p) % 3 == 2 else -1.0
    S = P @ R @ P.T  # = Rp'(sign alpha) Rq'(sign beta) Rr'(sign gamma) in the standard axes
    if proper:  # S = Rx(a) Ry(b) Rx(g)
        sb = np.hypot(S[..., 0, 1], S[..., 0, 2])
        beta = np.arctan2(sb, S[..., 0, 0])
        locked = sb < EULER_LOCK_TOLERANCE
        left_axis, right_axis = 0, 0
        left = np.arctan2(S[..., 1, 0], -S[..., 2, 0])
        right = np.arctan2(S[..., 0, 1], S[..., 0, 2])
    else:  # S = Rz(a) Ry(b) Rx(g)
        cb = np.hypot(S[..., 2, 1], S[..., 2, 2])
        beta = np.arctan2(-S[..., 2, 0], cb)
        locked = cb < EULER_LOCK_TOLERANCE
        left_axis, right_axis = 2, 0
        left = np.arctan2(S[..., 1, 0], S[..., 0, 0])
        right = np.arctan2(S[..., 2, 1], S[..., 2, 2])
    Rb = _elementary(1, beta)
    if extrinsic:  # scipy zeroes the third angle of seq: alpha, the left one
        left = np.where(locked, 0.0, left)
        X = np.swapaxes(Rb, -1, -2) @ np.swapaxes(_elementary(left_axis, left), -1, -2) @ S
        right = np.arctan2(X[..., 2, 1], X[..., 1, 1])  # X = Rx(gamma)
    else:  # the third of seq is gamma, the right one
        right = np.where(locked, 0.0, right)
        Y = S @ np.swapaxes(_elementary(right_axis, right), -1, -2) @ np.swapaxes(Rb, -1, -2)
        i, j = (left_axis + 1) % 3, (left_axis + 2) % 3  # Y = R_left(alpha)
        left = np.arctan2(Y[..., j, i], Y[..., i, i])
    out = sign * np.stack([left, beta, right], axis=-1)
    return out[..., ::-1] if extrinsic else out


def euler_from_matrix(R, seq: str, unit: str = "rad") -> np.ndarray:
    """Euler angles of ``R`` for any scipy sequence (``"xyz"`` extrinsic, ``"XYZ"`` intrinsic).

    These are angles of *active* rotations composing ``R``, in scipy's conventions and
    ranges (the first and third angle in [-pi, pi], the middle one in [-pi/2, pi/2] for
    Tait-Bryan sequences such as ``"xyz"``, in [0, pi] for proper ones such as ``"zxz"``);
    at gimbal lock (the middle angle's cosine, or sine, below
    :data:`EULER_LOCK_TOLERANCE`) the third angle is 0, as scipy sets it. Computed in closed
    form here (scipy's ``as_euler`` declares the lock within 1e-7 rad of it, so that its
    angles gave ``R`` back only to 2e-7 there): the angles give ``R`` back to rounding
    (1e-15) at any distance from the lock, for every sequence. A matrix that is not
    orthogonal is first replaced by the nearest rotation (as scipy's ``from_matrix`` does).

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack).
    seq : str
        Three axis letters, all lower case (extrinsic) or all upper case (intrinsic).
    unit : str, default "rad"
        Unit of the returned angles: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"``.

    Returns
    -------
    numpy.ndarray, shape (3,) or (..., 3)
        The three angles in ``unit``, in the order of ``seq``.

    Raises
    ------
    InputError
        When ``R`` is not of shape ``(..., 3, 3)``, ``seq`` is not three axis letters of one
        case, or ``unit`` is unknown.
    """
    _check_sequence(seq)
    R = np.asarray(R, dtype=float)
    M = _as_rotation(R).as_matrix().reshape(R.shape)
    return from_radians(_euler_angles(M, seq), unit)


def matrix_from_euler(seq: str, angles, unit: str = "rad") -> np.ndarray:
    """Rotation matrix from Euler angles of a scipy sequence (active rotations).

    Parameters
    ----------
    seq : str
        Three axis letters, all lower case (extrinsic) or all upper case (intrinsic).
    angles : array_like, shape (3,) or (..., 3)
        The angles in ``unit``, in the order of ``seq``.
    unit : str, default "rad"
        Unit of ``angles``: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"``.

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        Rotation matrix (or stack), acting as ``R @ x``.

    Raises
    ------
    InputError
        For an invalid ``seq``, ``angles`` whose last axis is not 3, or an unknown ``unit``.
    """
    _check_sequence(seq)
    a = to_radians(angles, unit)
    if np.ndim(a) == 0 or np.shape(a)[-1] != 3:
        raise InputError(f"Euler angles: expected shape (3,) or (..., 3), got {np.shape(a)}")
    return _Rotation().from_euler(seq, a).as_matrix()


def _check_sequence(seq) -> None:
    """Refuse an Euler sequence scipy would not take, in photogeom's words."""
    ok = (
        isinstance(seq, str)
        and len(seq) == 3
        and (set(seq) <= set("xyz") or set(seq) <= set("XYZ"))
        and seq[0] != seq[1] != seq[2]
    )
    if not ok:
        raise InputError(
            f"Euler sequence {seq!r}: give three axis letters from x, y, z, all lower case "
            "(extrinsic) or all upper case (intrinsic), no axis twice in a row (e.g. 'xyz', "
            "'ZYX', 'zxz')"
        )


# --- helpers ---------------------------------------------------------------------------------


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]x`` with ``[v]x @ u = v x u``.

    Parameters
    ----------
    v : array_like, shape (3,) or (..., 3)
        Vector(s), any unit.

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        The skew-symmetric matrix (or stack), in the unit of ``v``.
    """
    v = np.asarray(v, dtype=float)
    z = np.zeros_like(v[..., 0])
    return _stack(
        [[z, -v[..., 2], v[..., 1]], [v[..., 2], z, -v[..., 0]], [-v[..., 1], v[..., 0], z]]
    )


def orthogonality_defect(R) -> np.ndarray | float:
    """Frobenius norm ``|R.T R - I|`` (0 for an exact rotation).

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Matrix (or stack) to test.

    Returns
    -------
    float or numpy.ndarray, shape (...)
        The defect, unitless: a float for one matrix.
    """
    R = np.asarray(R, dtype=float)
    d = np.linalg.norm(np.swapaxes(R, -1, -2) @ R - np.eye(3), axis=(-2, -1))
    return float(d) if np.ndim(d) == 0 else d


def nearest_rotation(A) -> np.ndarray:
    """Closest proper rotation to ``A`` in the Frobenius norm (polar decomposition, det = +1).

    Parameters
    ----------
    A : array_like, shape (3, 3) or (..., 3, 3)
        Matrix (or stack), e.g. a rotation spoilt by rounding or a linear estimate.

    Returns
    -------
    numpy.ndarray, shape (3, 3) or (..., 3, 3)
        Orthonormal matrix (or stack) with determinant +1.

    Raises
    ------
    InputError
        When ``A`` is not of shape ``(..., 3, 3)``.
    """
    A = np.asarray(A, dtype=float)
    if A.ndim < 2 or A.shape[-2:] != (3, 3):
        raise InputError(f"nearest_rotation: expected shape (3, 3) or (..., 3, 3), got {A.shape}")
    U, _, Vt = np.linalg.svd(A)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones((*np.shape(d), 3))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt


def is_rotation(R, tol: float = 1e-9) -> bool:
    """``True`` when every matrix of ``R`` is orthonormal with determinant +1 (within ``tol``).

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Matrix (or stack) to test.
    tol : float, default 1e-9
        Tolerance on the orthogonality defect and on ``|det R - 1|`` (unitless).

    Returns
    -------
    bool
    """
    R = np.asarray(R, dtype=float)
    return bool(
        np.all(np.asarray(orthogonality_defect(R)) < tol)
        and np.all(np.abs(np.linalg.det(R) - 1.0) < tol)
    )
