"""3D rigid-body (6-parameter) transformation ``X = R x + t``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotation import DEFAULT_CONVENTION, Convention, angles_from_rotation, rotation_from_angles
from ..units import from_radians
from ._common import MatrixShift3D, check_proper_rotation, fmt_params, frozen, matrix_and_shift
from .base import Transform

_PARAM_NAMES = (*(f"r{i}{j}" for i in range(1, 4) for j in range(1, 4)), "tx", "ty", "tz")


@dataclass(frozen=True, eq=False, repr=False)
class Rigid3D(MatrixShift3D, Transform):
    """Rotation and translation ``X = rotation @ x + translation`` (no scale).

    Textbook parameters: ``omega, phi, kappa`` (radians, ``"transposed"`` convention
    ``R = M(omega, phi, kappa).T`` by default, as :class:`Similarity3D`) and ``tx, ty, tz``.
    Parametric form: the nine matrix elements ``r11 .. r33`` and the shifts.

    Parameters
    ----------
    rotation : array_like, shape (3, 3)
        Proper rotation (orthogonality defect <= 1e-6, det +1).
    translation : array_like, shape (3,)
        Target units.
    """

    name = "rigid3d"
    dim = 3

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        R, t = matrix_and_shift(self.rotation, self.translation, "Rigid3D", "rotation")
        check_proper_rotation(R, "Rigid3D")
        object.__setattr__(self, "rotation", frozen(R))
        object.__setattr__(self, "translation", frozen(t))

    @classmethod
    def from_angles(
        cls,
        omega: float,
        phi: float,
        kappa: float,
        translation,
        *,
        convention: Convention = DEFAULT_CONVENTION,
        unit: str = "rad",
    ) -> Rigid3D:
        """From angles (in ``unit``, ``convention``) and translation.

        Parameters
        ----------
        omega, phi, kappa : float
            Rotation angles in ``unit``.
        translation : array_like, shape (3,)
            ``t``, target units.
        convention : {"transposed", "direct"}, default "transposed"
            As in :func:`photogeom.rotation_from_angles`.
        unit : str, default "rad"
            Angle unit.

        Returns
        -------
        Rigid3D
        """
        return cls(rotation_from_angles(omega, phi, kappa, convention=convention, unit=unit),
                   translation)

    def angles(self, convention: Convention = DEFAULT_CONVENTION, unit: str = "rad") -> tuple:
        """(omega, phi, kappa) of ``rotation`` in ``convention`` and ``unit``.

        Parameters
        ----------
        convention : {"transposed", "direct"}, default "transposed"
            As in :func:`photogeom.rotation_from_angles`.
        unit : str, default "rad"
            Angle unit (``"rad"``, ``"deg"``, ``"gon"``, ...).

        Returns
        -------
        tuple of float
            ``(omega, phi, kappa)`` in ``unit``.

        Raises
        ------
        GimbalLockError
            At phi = +-90 deg (omega and kappa not separable).
        """
        return angles_from_rotation(self.rotation, convention=convention, unit=unit)

    @property
    def scale(self) -> float:
        """Always 1 (a rigid transformation does not scale)."""
        return 1.0

    def textbook(self, convention: Convention = DEFAULT_CONVENTION) -> dict[str, float]:
        """``omega, phi, kappa`` (rad, ``convention``) and ``tx, ty, tz``.

        Parameters
        ----------
        convention : {"transposed", "direct"}, default "transposed"
            Convention of the angles (see :func:`photogeom.rotation_from_angles`); at gimbal
            lock omega is set to zero.

        Returns
        -------
        dict of str to float
            Angles in rad, shifts in target units.
        """
        w, p, k = angles_from_rotation(self.rotation, convention=convention,
                                       on_gimbal_lock="omega-zero")
        tx, ty, tz = (float(v) for v in self.translation)
        return {"omega": float(w), "phi": float(p), "kappa": float(k), "tx": tx, "ty": ty, "tz": tz}

    @property
    def textbook_units(self) -> dict[str, str]:
        return {"omega": "rad", "phi": "rad", "kappa": "rad", "tx": "", "ty": "", "tz": ""}

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return _PARAM_NAMES

    @property
    def _matrix3(self) -> np.ndarray:
        return self.rotation

    def inverse(self) -> Rigid3D:
        """Closed form ``x = R.T (X - t)``.

        Returns
        -------
        Rigid3D
        """
        return Rigid3D(self.rotation.T, -(self.rotation.T @ self.translation))

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``model, rotation (3x3 list), translation, angles_transposed_rad`` (omega set to zero
            at gimbal lock).
        """
        w, p, k = angles_from_rotation(self.rotation, on_gimbal_lock="omega-zero")
        return {
            "model": self.name,
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "angles_transposed_rad": {"omega": float(w), "phi": float(p), "kappa": float(k)},
        }

    @classmethod
    def from_dict(cls, data: dict) -> Rigid3D:
        """From :meth:`to_dict` output or angles (rad, optional ``convention``) and translation.

        Parameters
        ----------
        data : dict
            ``rotation, translation`` when ``rotation`` is present, else
            ``omega, phi, kappa, translation`` (and ``convention``).

        Returns
        -------
        Rigid3D

        Raises
        ------
        InputError
            When ``rotation`` is not a proper rotation.
        KeyError
            When a parameter of the chosen form is missing.
        """
        if "rotation" in data:
            return cls(data["rotation"], data["translation"])
        return cls.from_angles(data["omega"], data["phi"], data["kappa"], data["translation"],
                               convention=data.get("convention", DEFAULT_CONVENTION))

    def __repr__(self) -> str:
        tb = self.textbook()
        ang = fmt_params(("omega", "phi", "kappa"),
                         [float(from_radians(tb[n], "deg")) for n in ("omega", "phi", "kappa")], 10)
        t = ", ".join(f"{v:.6f}" for v in self.translation)
        return f"Rigid3D({ang} deg (transposed), translation=({t}))"
