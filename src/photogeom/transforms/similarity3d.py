"""3D similarity (7-parameter Helmert) ``X = s R x + t``."""

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
from .base import Transform

#: Largest orthogonality defect |R.T R - I| accepted for a rotation given by the user.
ROTATION_TOLERANCE = 1e-6


@dataclass(frozen=True, repr=False)
class Similarity3D(Transform):
    """3D similarity ``X = scale * rotation @ x + translation``.

    Parameters
    ----------
    scale : float
        Scale factor (> 0).
    rotation : array_like, shape (3, 3)
        The matrix ``R`` applied to source coordinates. Its angles follow the
        ``"transposed"`` convention ``R = M(omega, phi, kappa).T`` by default
        (see :mod:`photogeom.rotation`).
    translation : array_like, shape (3,)
        Shift ``t`` in target units.
    check : bool
        Refuse ``rotation`` unless it is a proper rotation (orthogonality defect
        <= 1e-6 and det = +1). ``False`` keeps a non-orthogonal matrix as given (e.g.
        the raw result of the closed-form method).
    """

    name = "similarity3d"
    dim = 3

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    check: bool = True

    def __post_init__(self) -> None:
        R = np.array(self.rotation, dtype=float)
        t = np.array(self.translation, dtype=float).reshape(-1)
        s = float(self.scale)
        if R.shape != (3, 3) or t.shape != (3,):
            raise InputError("Similarity3D: rotation must be 3x3 and translation of length 3")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t)) and np.isfinite(s)):
            raise InputError("Similarity3D: parameters must be finite")
        if s <= 0:
            raise InputError(f"Similarity3D: scale must be > 0, got {s}")
        if self.check:
            defect = orthogonality_defect(R)
            if defect > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
                raise InputError(
                    f"Similarity3D: rotation is not a proper rotation (orthogonality defect "
                    f"{defect:.2e}, det {np.linalg.det(R):.6f}); pass check=False to keep it"
                )
        R.flags.writeable = False
        t.flags.writeable = False
        object.__setattr__(self, "rotation", R)
        object.__setattr__(self, "translation", t)
        object.__setattr__(self, "scale", s)

    # --- textbook parameters ------------------------------------------------------------------

    @classmethod
    def from_angles(
        cls,
        scale: float,
        omega: float,
        phi: float,
        kappa: float,
        translation,
        *,
        convention: Convention = DEFAULT_CONVENTION,
        unit: str = "rad",
    ) -> Similarity3D:
        """From scale, angles (in ``unit``, ``convention``) and translation."""
        R = rotation_from_angles(omega, phi, kappa, convention=convention, unit=unit)
        return cls(scale, R, translation)

    def angles(self, convention: Convention = DEFAULT_CONVENTION, unit: str = "rad") -> tuple:
        """(omega, phi, kappa) of ``rotation`` in ``convention`` and ``unit``."""
        return angles_from_rotation(self.rotation, convention=convention, unit=unit)

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 matrix."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.rotation
        T[:3, 3] = self.translation
        return T

    # --- Transform interface ------------------------------------------------------------------

    def apply(self, points) -> np.ndarray:
        """``s R x + t`` for points (n, 3) or one point (3,)."""
        p, single = self._points(points)
        out = self.scale * (p @ self.rotation.T) + self.translation
        return out[0] if single else out

    def inverse(self) -> Similarity3D:
        """``x = (1/s) R^-1 (X - t)``; for a non-orthogonal R the true inverse matrix is used."""
        Rinv = self.rotation.T if self.check else np.linalg.inv(self.rotation)
        return Similarity3D(
            1.0 / self.scale, Rinv, -(Rinv @ self.translation) / self.scale, check=self.check
        )

    def to_dict(self) -> dict:
        """JSON-ready parameters (angles given for both conventions, in radians)."""
        d = {
            "model": self.name,
            "scale": self.scale,
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
        }
        if self.check:
            for conv in ("transposed", "direct"):
                w, p, k = self.angles(conv)
                d[f"angles_{conv}_rad"] = {"omega": w, "phi": p, "kappa": k}
        return d

    @classmethod
    def from_dict(cls, data: dict) -> Similarity3D:
        """From :meth:`to_dict` output, or from ``scale``, ``omega``, ``phi``, ``kappa``
        (radians, optional ``convention``) and ``translation``."""
        if "rotation" in data:
            return cls(
                data["scale"], data["rotation"], data["translation"], check=data.get("check", True)
            )
        return cls.from_angles(
            data["scale"],
            data["omega"],
            data["phi"],
            data["kappa"],
            data["translation"],
            convention=data.get("convention", DEFAULT_CONVENTION),
        )

    def __repr__(self) -> str:
        if self.check:
            w, p, k = self.angles("transposed", "deg")
            ang = f"omega={w:.6f} deg, phi={p:.6f} deg, kappa={k:.6f} deg (transposed)"
        else:
            ang = f"rotation (non-orthogonal, defect {orthogonality_defect(self.rotation):.2e})"
        t = ", ".join(f"{v:.6f}" for v in self.translation)
        return f"Similarity3D(scale={self.scale:.9f}, {ang}, translation=({t}))"
