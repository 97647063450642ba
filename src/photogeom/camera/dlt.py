"""Direct linear transformation (Abdel-Aziz & Karara 1971) and the 3x4 camera matrix.

    x = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1)
    y = (L5 X + L6 Y + L7 Z + L8) / (L9 X + L10 Y + L11 Z + 1)

The camera matrix is ``P = [[L1..L4], [L5..L8], [L9, L10, L11, 1]]``. In terms of interior
and exterior orientation (see :mod:`photogeom.camera.interior`)

    P = Q K M [I | -X0],   K = [[-fx, b2, x0], [0, -f, y0], [0, 0, 1]],   Q = -1 / (m3 . X0)

which, for ``b2 = 0``, gives the textbook formulas of ``L1 .. L11``. The eleven DLT
parameters carry six exterior and five interior parameters (x0, y0, cx = fx, cy = fy and
the shear b2); the *constrained* DLT imposes the two orthogonality conditions (cx = cy,
no shear) and needs only five control points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError, InputError, ReflectionError
from ..records import setstate_read_only
from ..validation import as_float64, as_points
from .exterior import ExteriorOrientation
from .interior import InteriorOrientation

NAMES = tuple(f"L{i}" for i in range(1, 12))


def _as_L(L) -> np.ndarray:
    """The 11 parameters as a read-only array of their own (never a view of the caller's)."""
    if isinstance(L, DLT):
        return L.L
    a = np.array(L, dtype=float)
    if a.shape == (3, 4):
        if not np.all(np.isfinite(a)):
            raise InputError("camera matrix contains NaN or infinite values")
        if abs(a[2, 3]) < 1e-300:
            raise DegenerateGeometryError(
                "camera matrix has P[2, 3] = 0 (the object-system origin lies in the camera's "
                "principal plane); the DLT normalisation L12 = 1 is impossible: shift the origin"
            )
        out = (a / a[2, 3]).reshape(-1)[:11]
        out.flags.writeable = False
        return out
    a = a.reshape(-1)
    if a.size != 11:
        raise InputError(f"a DLT has 11 parameters L1..L11 (or a 3x4 matrix), got {a.size} values")
    if not np.all(np.isfinite(a)):
        raise InputError("DLT parameters contain NaN or infinite values")
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class DLT:
    """The eleven DLT parameters ``L1 .. L11``.

    Parameters
    ----------
    L : array_like, shape (11,)
        Parameters in the order of :data:`NAMES`; image coordinates in the unit the DLT was
        estimated in (``unit``), object coordinates in object units.
    unit : str
        Unit of the image coordinates (informational; used by :meth:`orientation`).
    """

    L: np.ndarray
    unit: str = "mm"

    def __post_init__(self) -> None:
        object.__setattr__(self, "L", _as_L(self.L))

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: L stays read-only

    @classmethod
    def from_matrix(cls, P, unit: str = "mm") -> DLT:
        """From a 3x4 camera matrix (any scale; normalised to ``P[2, 3] = 1``).

        Parameters
        ----------
        P : array_like, shape (3, 4) (or 12 values)
            Camera matrix mapping homogeneous object points to homogeneous image points.
        unit : str, default "mm"
            Unit of the image coordinates (informational; used by :meth:`orientation`).

        Returns
        -------
        DLT

        Raises
        ------
        InputError
            When ``P`` holds NaN or infinite values.
        DegenerateGeometryError
            When ``P[2, 3] = 0`` (the object origin lies in the principal plane).
        """
        return cls(_as_L(np.asarray(P, dtype=float).reshape(3, 4)), unit)

    @property
    def matrix(self) -> np.ndarray:
        """The 3x4 camera matrix with ``P[2, 3] = 1``."""
        return np.append(self.L, 1.0).reshape(3, 4)

    def project(self, ground_xyz) -> np.ndarray:
        """Image coordinates of ground points.

        Parameters
        ----------
        ground_xyz : array_like, shape (n, 3) or (3,)
            Object coordinates, object units.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            Image coordinates in :attr:`unit`; inf/NaN for points in the principal plane.

        Raises
        ------
        InputError
            When ``ground_xyz`` is not of shape (n, 3) or holds NaN/infinite values.
        """
        arr = as_float64(ground_xyz, "ground points")
        single = arr.ndim == 1
        g = as_points(arr, 3, "ground points")
        h = g @ self.matrix[:, :3].T + self.matrix[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = h[:, :2] / h[:, 2:3]
        return xy[0] if single else xy

    def orientation(self, points=None) -> tuple[InteriorOrientation, ExteriorOrientation]:
        """``orientation_from_dlt(self, unit=self.unit, points=points)``.

        Parameters
        ----------
        points : array_like, shape (n, 3), optional
            Object points the camera is known to see; see :func:`orientation_from_dlt`.

        Returns
        -------
        io : InteriorOrientation
            In :attr:`unit`.
        eo : ExteriorOrientation
            Projection centre in object units, angles in rad.
        """
        return orientation_from_dlt(self, unit=self.unit, points=points)

    @property
    def projection_centre(self) -> np.ndarray:
        """``-inv([[L1,L2,L3],[L5,L6,L7],[L9,L10,L11]]) @ (L4, L8, 1)``."""
        P = self.matrix
        return -np.linalg.solve(P[:, :3], P[:, 3])

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"model": "dlt", "unit": ..., "L1": ..., ..., "L11": ...}``.
        """
        return {"model": "dlt", "unit": self.unit, **{n: float(v) for n, v in zip(NAMES, self.L)}}

    @classmethod
    def from_dict(cls, data) -> DLT:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : Mapping
            With the keys ``"L1"`` .. ``"L11"`` and optionally ``"unit"`` (default ``"mm"``).

        Returns
        -------
        DLT

        Raises
        ------
        InputError
            When a parameter is missing (named in the message) or not finite.
        """
        missing = [n for n in NAMES if n not in data]
        if missing:
            raise InputError(f"DLT: missing parameter(s) {', '.join(missing)}")
        return cls(np.array([float(data[n]) for n in NAMES]), data.get("unit", "mm"))


def camera_matrix(io: InteriorOrientation, eo: ExteriorOrientation) -> np.ndarray:
    """The 3x4 camera matrix ``K M [I | -X0]`` (not normalised) of a distortion-free camera.

    Parameters
    ----------
    io : InteriorOrientation
        Interior orientation without distortion; its unit is that of the image coordinates.
    eo : ExteriorOrientation
        Exterior orientation (object units, rad).

    Returns
    -------
    numpy.ndarray, shape (3, 4)
        ``P`` with ``(x, y, 1) ~ P (X, Y, Z, 1)``.

    Raises
    ------
    InputError
        When ``io`` has lens distortion (remove it with ``io.with_distortion(None)``).
    """
    if io.distortion is not None:
        raise InputError(
            "the DLT / camera matrix has no lens distortion terms; remove the distortion from "
            "the image coordinates first (InteriorOrientation.with_distortion(None))"
        )
    M = eo.matrix
    KM = io.calibration_matrix @ M
    return np.hstack([KM, -(KM @ eo.position)[:, None]])


def dlt_from_orientation(io: InteriorOrientation, eo: ExteriorOrientation) -> np.ndarray:
    """The eleven DLT parameters of a camera given by its interior and exterior orientation.

    With ``Q = -1 / (m31 X0 + m32 Y0 + m33 Z0)``: ``L1 = (x0 m31 - cx m11) Q`` etc.
    (04-camera-models.md), generalised to the shear ``b2``.

    Parameters
    ----------
    io : InteriorOrientation
        Without distortion (the DLT cannot represent it).
    eo : ExteriorOrientation

    Returns
    -------
    numpy.ndarray, shape (11,)
        ``L1 .. L11`` for image coordinates in the unit of ``io``.
    """
    P = camera_matrix(io, eo)
    if abs(P[2, 3]) < 1e-12 * np.abs(P[2, :3]).max() * max(1.0, np.abs(eo.position).max()):
        raise DegenerateGeometryError(
            "m3 . X0 = 0: the object-system origin lies in the camera's principal plane, so the "
            "DLT normalisation (L12 = 1) does not exist; shift the object coordinates"
        )
    return (P / P[2, 3]).reshape(-1)[:11]


def orientation_from_dlt(
    L, unit: str = "mm", *, points=None
) -> tuple[InteriorOrientation, ExteriorOrientation]:
    """Interior and exterior orientation from the eleven DLT parameters.

    Decomposes ``A = P[:, :3] = lam K M`` with ``K = [[-cx, b2, x0], [0, -cy, y0], [0, 0, 1]]``
    (cx, cy > 0) and ``M`` a proper rotation: the sign of ``lam`` (the sign of L in the
    textbook formulas) is that of ``det(A)``. For ``b2 = 0`` this equals the textbook
    formulas ``x0 = (L1 L9 + L2 L10 + L3 L11) / L^2`` ..., ``m3j = L(8+j) / L``.

    Parameters
    ----------
    L : array_like (11,), 3x4 matrix, or DLT
    unit : {"mm", "px"}
        Unit of the image coordinates the DLT refers to.
    points : array_like, shape (n, 3), optional
        Object points the camera is known to see (e.g. the control). If they lie behind
        the recovered camera, the image coordinates were left-handed (e.g. pixel rows
        pointing down) and :class:`~photogeom.errors.ReflectionError` is raised.

    Returns
    -------
    (InteriorOrientation, ExteriorOrientation)
        ``io.f = cy``, ``io.b1 = cx - cy``, ``io.b2`` the shear.
    """
    if isinstance(L, DLT) and unit == "mm":
        unit = L.unit
    P = np.append(_as_L(L), 1.0).reshape(3, 4)
    A = P[:, :3]
    detA = np.linalg.det(A)
    scale = np.abs(A).max() ** 3
    if not np.isfinite(detA) or abs(detA) <= 1e-14 * scale:
        raise DegenerateGeometryError(
            "the DLT's 3x3 part is singular: it is not a central projection (projection centre "
            "at infinity or degenerate parameters)"
        )
    X0 = -np.linalg.solve(A, P[:, 3])
    lam = np.sign(detA) * np.linalg.norm(A[2])
    B = A / lam
    m3 = B[2]
    y0 = float(B[1] @ m3)
    r2 = B[1] - y0 * m3
    cy = float(np.linalg.norm(r2))
    m2 = -r2 / cy
    x0 = float(B[0] @ m3)
    b2 = float(B[0] @ m2)
    r1 = B[0] - b2 * m2 - x0 * m3
    cx = float(np.linalg.norm(r1))
    m1 = -r1 / cx
    M = np.vstack([m1, m2, m3])
    # Re-orthonormalise against round-off (M is orthogonal by construction up to eps).
    U, _, Vt = np.linalg.svd(M)
    M = U @ Vt
    eo = ExteriorOrientation.from_matrix(X0, M, on_gimbal_lock="omega-zero")
    io = InteriorOrientation(f=cy, x0=x0, y0=y0, unit=unit, b1=cx - cy, b2=b2)
    if points is not None:
        g = as_points(points, 3, "points")
        w = (g - X0) @ M[2]
        if np.all(w > 0):
            raise ReflectionError(
                "the points lie behind the camera recovered from the DLT: the image coordinates "
                "are left-handed (e.g. pixel rows pointing down). Convert them to the right-handed "
                "image system (y up: y = -d (row - row_pp)) before estimating the DLT"
            )
        if np.any(w > 0):
            raise DegenerateGeometryError(
                f"{int(np.sum(w > 0))} of {len(w)} point(s) lie behind the camera recovered from "
                "the DLT; the DLT does not describe a camera that sees all of them"
            )
    return io, eo
