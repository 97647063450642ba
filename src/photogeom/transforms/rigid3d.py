"""3D rigid-body (6-parameter) transformation ``X = R x + t``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..rotation import (
    DEFAULT_CONVENTION,
    Convention,
    angles_from_rotation,
    orthogonality_defect,
    rotation_from_angles,
)
from ..units import from_radians
from ._common import Parametric, fmt_params, frozen, vector
from .base import Transform

#: Largest orthogonality defect ``|R.T R - I|`` accepted for a rotation.
ROTATION_TOLERANCE = 1e-6

_PARAM_NAMES = (*(f"r{i}{j}" for i in range(1, 4) for j in range(1, 4)), "tx", "ty", "tz")


@dataclass(frozen=True, repr=False)
class Rigid3D(Parametric, Transform):
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
        R = np.array(self.rotation, dtype=float)
        t = np.array(self.translation, dtype=float).reshape(-1)
        if R.shape != (3, 3) or t.shape != (3,):
            raise InputError("Rigid3D: rotation must be 3x3 and translation of length 3")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise InputError("Rigid3D: parameters must be finite")
        defect = orthogonality_defect(R)
        if defect > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
            raise InputError(
                f"Rigid3D: rotation is not a proper rotation (orthogonality defect {defect:.2e}, "
                f"det {np.linalg.det(R):.6f})"
            )
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
        """From angles (in ``unit``, ``convention``) and translation."""
        return cls(rotation_from_angles(omega, phi, kappa, convention=convention, unit=unit),
                   translation)

    def angles(self, convention: Convention = DEFAULT_CONVENTION, unit: str = "rad") -> tuple:
        """(omega, phi, kappa) of ``rotation`` in ``convention`` and ``unit``."""
        return angles_from_rotation(self.rotation, convention=convention, unit=unit)

    @property
    def scale(self) -> float:
        """Always 1 (a rigid transformation does not scale)."""
        return 1.0

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 matrix."""
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.translation
        return T

    def textbook(self, convention: Convention = DEFAULT_CONVENTION) -> dict[str, float]:
        """``omega, phi, kappa`` (rad, ``convention``) and ``tx, ty, tz``."""
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
    def parameters(self) -> np.ndarray:
        return np.concatenate([self.rotation.reshape(-1), self.translation])

    def with_parameters(self, values) -> Rigid3D:
        v = vector(values, 12, "Rigid3D")
        return Rigid3D(v[:9].reshape(3, 3), v[9:])

    def apply(self, points) -> np.ndarray:
        """``R x + t`` for points (n, 3) or one point (3,)."""
        p, single = self._points(points)
        out = p @ self.rotation.T + self.translation
        return out[0] if single else out

    def inverse(self) -> Rigid3D:
        """Closed form ``x = R.T (X - t)``."""
        return Rigid3D(self.rotation.T, -(self.rotation.T @ self.translation))

    def to_dict(self) -> dict:
        w, p, k = angles_from_rotation(self.rotation, on_gimbal_lock="omega-zero")
        return {
            "model": self.name,
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "angles_transposed_rad": {"omega": float(w), "phi": float(p), "kappa": float(k)},
        }

    @classmethod
    def from_dict(cls, data: dict) -> Rigid3D:
        """From :meth:`to_dict` output or ``omega, phi, kappa`` (rad, optional ``convention``)
        and ``translation``."""
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
