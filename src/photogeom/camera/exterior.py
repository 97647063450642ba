"""Exterior orientation of an image: projection centre and attitude (omega, phi, kappa)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..rotation import opk_from_matrix, opk_matrix
from ..units import from_radians, to_radians
from ..validation import as_finite_scalar, as_points_single, one_or_many

NAMES = ("X0", "Y0", "Z0", "omega", "phi", "kappa")


@dataclass(frozen=True)
class ExteriorOrientation:
    """Projection centre ``(X0, Y0, Z0)`` and attitude angles in radians.

    The rotation matrix is ``M = M3(kappa) M2(phi) M1(omega)`` (01-conventions.md) and maps
    object-space differences into the camera system: ``p = M (X - X0)``; the camera looks
    along its -z axis, so points in front of it have ``p_z < 0``.

    Parameters
    ----------
    X0, Y0, Z0 : float
        Projection centre in the object (ground) system, e.g. metres.
    omega, phi, kappa : float
        Angles in radians.
    """

    X0: float
    Y0: float
    Z0: float
    omega: float = 0.0
    phi: float = 0.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        for name in NAMES:
            v = as_finite_scalar(getattr(self, name), f"exterior orientation {name}")
            object.__setattr__(self, name, v)

    @classmethod
    def from_matrix(cls, position, M, *, on_gimbal_lock: str = "raise") -> ExteriorOrientation:
        """From a projection centre and a rotation matrix ``M`` (camera <- object).

        Parameters
        ----------
        position : array_like, shape (3,)
            Projection centre ``(X0, Y0, Z0)``, object units.
        M : array_like, shape (3, 3)
            ``M = M3(kappa) M2(phi) M1(omega)``.
        on_gimbal_lock : {"raise", "omega-zero"}, default "raise"
            As in :func:`photogeom.opk_from_matrix`.

        Returns
        -------
        ExteriorOrientation

        Raises
        ------
        InputError
            When ``position`` has not 3 values or ``M`` not the shape (3, 3).
        GimbalLockError
            At phi = +-90 deg with ``on_gimbal_lock="raise"``.
        """
        p = np.asarray(position, dtype=float).reshape(-1)
        if p.size != 3:
            raise InputError(f"projection centre must have 3 coordinates, got {p.size}")
        w, ph, k = opk_from_matrix(np.asarray(M, dtype=float), on_gimbal_lock=on_gimbal_lock)
        return cls(p[0], p[1], p[2], w, ph, k)

    @classmethod
    def from_degrees(cls, X0, Y0, Z0, omega, phi, kappa, unit: str = "deg") -> ExteriorOrientation:
        """From angles in degrees (or ``unit``).

        Parameters
        ----------
        X0, Y0, Z0 : float
            Projection centre, object units.
        omega, phi, kappa : float
            Angles in ``unit``.
        unit : str, default "deg"
            Angle unit (``"deg"``, ``"gon"``, ``"rad"``, ...).

        Returns
        -------
        ExteriorOrientation
        """
        return cls(X0, Y0, Z0, *(float(to_radians(a, unit)) for a in (omega, phi, kappa)))

    @property
    def position(self) -> np.ndarray:
        """Projection centre as an array (3,)."""
        return np.array([self.X0, self.Y0, self.Z0])

    @property
    def angles(self) -> np.ndarray:
        """``(omega, phi, kappa)`` in radians."""
        return np.array([self.omega, self.phi, self.kappa])

    @property
    def matrix(self) -> np.ndarray:
        """Rotation matrix ``M = M3(kappa) M2(phi) M1(omega)`` (3, 3)."""
        return opk_matrix(self.omega, self.phi, self.kappa)

    @property
    def parameters(self) -> np.ndarray:
        """``(X0, Y0, Z0, omega, phi, kappa)`` (angles in radians)."""
        return np.array([getattr(self, n) for n in NAMES])

    def angles_in(self, unit: str = "deg") -> np.ndarray:
        """Angles converted to ``unit``.

        Parameters
        ----------
        unit : str, default "deg"
            Angle unit (``"deg"``, ``"gon"``, ``"rad"``, ...).

        Returns
        -------
        numpy.ndarray, shape (3,)
            ``(omega, phi, kappa)`` in ``unit``.
        """
        return np.asarray(from_radians(self.angles, unit), dtype=float)

    def to_camera(self, ground) -> np.ndarray:
        """Camera-frame coordinates ``M (X - X0)`` of ground points.

        Parameters
        ----------
        ground : array_like, shape (n, 3) or (3,)
            Object coordinates, object units.

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            ``(u, v, w)``, object units; ``w < 0`` in front of the camera.

        Raises
        ------
        InputError
            When ``ground`` is not of shape (n, 3) or (3,).
        """
        g, single = as_points_single(ground, 3, "ground points", finite=False)
        return one_or_many((g - self.position) @ self.matrix.T, single)

    def to_dict(self, angle_unit: str = "rad") -> dict:
        """JSON-ready parameters (angles in ``angle_unit``, labelled).

        Parameters
        ----------
        angle_unit : str, default "rad"
            Unit of the angles in the result.

        Returns
        -------
        dict
            ``{"X0", "Y0", "Z0", "omega", "phi", "kappa", "angle_unit"}``.
        """
        a = self.angles_in(angle_unit)
        return {
            "X0": self.X0,
            "Y0": self.Y0,
            "Z0": self.Z0,
            "omega": float(a[0]),
            "phi": float(a[1]),
            "kappa": float(a[2]),
            "angle_unit": angle_unit,
        }

    @classmethod
    def from_dict(cls, data: Mapping) -> ExteriorOrientation:
        """Inverse of :meth:`to_dict` (``angle_unit`` defaults to radians).

        Parameters
        ----------
        data : Mapping
            With the keys ``X0, Y0, Z0, omega, phi, kappa`` and optionally ``angle_unit``.

        Returns
        -------
        ExteriorOrientation

        Raises
        ------
        InputError
            When a key is missing (named in the message) or ``angle_unit`` is unknown.
        """
        missing = [n for n in NAMES if n not in data]
        if missing:
            raise InputError(f"exterior orientation: missing {', '.join(missing)}")
        unit = data.get("angle_unit", "rad")
        return cls(
            data["X0"],
            data["Y0"],
            data["Z0"],
            *(float(to_radians(float(data[n]), unit)) for n in ("omega", "phi", "kappa")),
        )
