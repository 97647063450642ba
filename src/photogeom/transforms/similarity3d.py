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
    skew,
)
from ..units import from_radians, to_radians
from ._common import check_proper_rotation, homogeneous, matrix_and_shift
from .base import Transform


@dataclass(frozen=True, eq=False, repr=False)
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
        s = float(self.scale)
        R, t = matrix_and_shift(self.rotation, self.translation, "Similarity3D", "rotation")
        if not np.isfinite(s):
            raise InputError("Similarity3D: parameters must be finite")
        if s <= 0:
            raise InputError(f"Similarity3D: scale must be > 0, got {s}")
        if self.check:
            check_proper_rotation(R, "Similarity3D", "; pass check=False to keep it")
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
        """From scale, angles (in ``unit``, ``convention``) and translation.

        Parameters
        ----------
        scale : float
            Scale factor (unitless).
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
        Similarity3D
        """
        R = rotation_from_angles(omega, phi, kappa, convention=convention, unit=unit)
        return cls(scale, R, translation)

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
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 matrix."""
        return homogeneous(self.scale * self.rotation, self.translation)

    # --- geodetic (EPSG) parameters -------------------------------------------------------------

    @classmethod
    def from_helmert(
        cls,
        tx: float,
        ty: float,
        tz: float,
        rx: float,
        ry: float,
        rz: float,
        ds: float,
        *,
        convention: str,
        rotation: str = "exact",
        angle_unit: str = "arcsec",
    ) -> Similarity3D:
        """A datum transformation from published 7-parameter Helmert values.

        ``X = (1 + ds * 1e-6) R x + t`` with

        * ``convention="position_vector"`` (EPSG methods 1033 / 9606): exact
          ``R = Rx(rx) Ry(ry) Rz(rz)`` (active rotations, i.e. ``R = M(rx, ry, rz).T``: the
          ``"transposed"`` convention), small-angle ``R = I + [r]x`` with
          ``[r]x = [[0, -rz, ry], [rz, 0, -rx], [-ry, rx, 0]]``;
        * ``convention="coordinate_frame"`` (EPSG 1032 / 9607): the transpose of the
          position-vector ``R`` (rotations of opposite sign).

        These are the formulas of PROJ's ``+proj=helmert`` (with ``+exact`` for
        ``rotation="exact"``).

        Parameters
        ----------
        tx, ty, tz : float
            Shifts in metres (target units).
        rx, ry, rz : float
            Rotations in ``angle_unit`` (default arc-seconds).
        ds : float
            Scale difference in ppm (parts per million).
        convention : str
            ``"position_vector"`` (also ``"1033"``, ``"9606"``, ``"pv"``) or
            ``"coordinate_frame"`` (``"1032"``, ``"9607"``, ``"cf"``). Required: the two
            differ only in the sign of the rotations, and a wrong guess is a silent error.
        rotation : {"exact", "small-angle"}
            Exact rotation matrix or the linearised (small-angle) one the published parameters
            may have been fitted with. A small-angle matrix is not orthogonal and is kept as
            given (``check=False``).
        angle_unit : str, default "arcsec"
            Unit of ``rx, ry, rz``.

        Returns
        -------
        Similarity3D
            With ``check=False`` for ``rotation="small-angle"``.

        Raises
        ------
        InputError
            For an unknown ``convention``, ``rotation`` or ``angle_unit``.
        """
        conv = _helmert_convention(convention)
        kind = _helmert_rotation(rotation)
        r = np.array([float(to_radians(v, angle_unit)) for v in (rx, ry, rz)])
        if kind == "exact":
            R = rotation_from_angles(r[0], r[1], r[2], convention="transposed")
        else:
            R = np.eye(3) + skew(r)
        if conv == "coordinate_frame":
            R = R.T
        scale = 1.0 + float(ds) * 1e-6
        return cls(scale, R, [tx, ty, tz], check=kind == "exact")

    def helmert_parameters(
        self, convention: str, rotation: str = "exact", angle_unit: str = "arcsec"
    ) -> dict[str, float]:
        """The 7 Helmert parameters of this similarity in geodetic units and an EPSG convention.

        Such that :meth:`from_helmert` with the same ``convention`` and ``rotation`` gives this
        transformation back. ``rotation="exact"`` needs a proper rotation matrix;
        ``"small-angle"`` reads the angles from the antisymmetric part ``(R - R.T) / 2`` (exact
        for a small-angle matrix, a first-order approximation otherwise).

        Parameters
        ----------
        convention : str
            ``"position_vector"`` or ``"coordinate_frame"`` (aliases as in :meth:`from_helmert`).
        rotation : {"exact", "small-angle"}, default "exact"
            How the angles are read from the matrix.
        angle_unit : str, default "arcsec"
            Unit of ``rx, ry, rz``.

        Returns
        -------
        dict of str to float
            ``tx, ty, tz`` (metres/target units), ``rx, ry, rz`` (``angle_unit``), ``ds`` (ppm).

        Raises
        ------
        InputError
            For an unknown ``convention`` or ``rotation``, or ``rotation="exact"`` with a
            non-orthogonal matrix.
        """
        conv = _helmert_convention(convention)
        kind = _helmert_rotation(rotation)
        R = self.rotation if conv == "position_vector" else self.rotation.T
        if kind == "exact":
            if not self.check:
                raise InputError(
                    "helmert_parameters: the rotation matrix is not orthogonal (a small-angle "
                    "matrix?); use rotation='small-angle'"
                )
            r = np.array(angles_from_rotation(R, convention="transposed"))
        else:
            r = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
        rx, ry, rz = (float(from_radians(v, angle_unit)) for v in r)
        tx, ty, tz = (float(v) for v in self.translation)
        return {"tx": tx, "ty": ty, "tz": tz, "rx": rx, "ry": ry, "rz": rz,
                "ds": (self.scale - 1.0) * 1e6}

    def to_proj_string(self, convention: str = "position_vector", rotation: str = "exact") -> str:
        """A PROJ ``+proj=helmert`` definition of this transformation.

        Rotations in arc-seconds, scale in ppm, e.g. for ``pyproj.Transformer.from_pipeline``.

        Parameters
        ----------
        convention : str, default "position_vector"
            ``"position_vector"`` or ``"coordinate_frame"`` (aliases as in :meth:`from_helmert`).
        rotation : {"exact", "small-angle"}, default "exact"
            ``"exact"`` adds ``+exact``.

        Returns
        -------
        str
            ``"+proj=helmert +x=.. +y=.. +z=.. +rx=.. +ry=.. +rz=.. +s=.. +convention=.."``.

        Raises
        ------
        InputError
            As :meth:`helmert_parameters`.
        """
        conv = _helmert_convention(convention)
        kind = _helmert_rotation(rotation)
        p = self.helmert_parameters(conv, kind, "arcsec")
        parts = ["+proj=helmert"]
        for key, name in (
            ("tx", "x"),
            ("ty", "y"),
            ("tz", "z"),
            ("rx", "rx"),
            ("ry", "ry"),
            ("rz", "rz"),
            ("ds", "s"),
        ):
            value = p[key]
            if key == "ds":  # s - 1 of a double near 1 resolves about 2e-10 ppm
                value = round(value, 9)
            parts.append(f"+{name}={_proj_number(value)}")
        parts.append(f"+convention={conv}")
        if kind == "exact":
            parts.append("+exact")
        return " ".join(parts)

    # --- Transform interface ------------------------------------------------------------------

    def apply(self, points) -> np.ndarray:
        """``s R x + t`` for points (n, 3) or one point (3,).

        Parameters
        ----------
        points : array_like, shape (n, 3) or (3,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            Target coordinates (target units); one point for one point.

        Raises
        ------
        InputError
            When ``points`` is not of shape (n, 3) or (3,) or holds NaN/infinite values.
        """
        p, single = self._points(points)
        out = self.scale * (p @ self.rotation.T) + self.translation
        return out[0] if single else out

    def inverse(self) -> Similarity3D:
        """``x = (1/s) R^-1 (X - t)``; for a non-orthogonal R the true inverse matrix is used.

        Returns
        -------
        Similarity3D
        """
        Rinv = self.rotation.T if self.check else np.linalg.inv(self.rotation)
        return Similarity3D(
            1.0 / self.scale, Rinv, -(Rinv @ self.translation) / self.scale, check=self.check
        )

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Scale, rotation, translation, ``check`` (``False`` for a non-orthogonal matrix kept as
        given) and, for a proper rotation, its angles in both conventions (radians; at gimbal
        lock omega is set to zero).

        Returns
        -------
        dict
            ``model, scale, rotation (3x3 list), translation, check`` and, with ``check``,
            ``angles_transposed_rad``, ``angles_direct_rad``.
        """
        d = {
            "model": self.name,
            "scale": self.scale,
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "check": self.check,
        }
        if self.check:
            for conv in ("transposed", "direct"):
                w, p, k = angles_from_rotation(
                    self.rotation, convention=conv, on_gimbal_lock="omega-zero"
                )
                d[f"angles_{conv}_rad"] = {"omega": float(w), "phi": float(p), "kappa": float(k)}
        return d

    @classmethod
    def from_dict(cls, data: dict) -> Similarity3D:
        """From :meth:`to_dict` output, or from ``scale``, ``omega``, ``phi``, ``kappa``
        (radians, optional ``convention``) and ``translation``.

        ``check`` (default ``True``) must be ``true`` or ``false``; ``false`` keeps a
        non-orthogonal ``rotation`` (small-angle Helmert, closed-form absolute orientation).

        Parameters
        ----------
        data : dict
            ``scale, rotation, translation`` (and ``check``) when ``rotation`` is present,
            else ``scale, omega, phi, kappa, translation`` (and ``convention``).

        Returns
        -------
        Similarity3D

        Raises
        ------
        InputError
            For a ``check`` that is not a boolean, or a ``rotation`` that is not a proper
            rotation with ``check`` true.
        KeyError
            When a parameter of the chosen form is missing.
        """
        if "rotation" in data:
            check = data.get("check", True)
            if not isinstance(check, bool | np.bool_):
                raise InputError(
                    f"Similarity3D: 'check' must be true or false, got {check!r}"
                )
            return cls(data["scale"], data["rotation"], data["translation"], check=bool(check))
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
            w, p, k = angles_from_rotation(
                self.rotation, convention="transposed", unit="deg", on_gimbal_lock="omega-zero"
            )
            ang = f"omega={w:.6f} deg, phi={p:.6f} deg, kappa={k:.6f} deg (transposed)"
        else:
            ang = f"rotation (non-orthogonal, defect {orthogonality_defect(self.rotation):.2e})"
        t = ", ".join(f"{v:.6f}" for v in self.translation)
        return f"Similarity3D(scale={self.scale:.9f}, {ang}, translation=({t}))"


_HELMERT_CONVENTIONS = {
    "position_vector": "position_vector",
    "position-vector": "position_vector",
    "position vector": "position_vector",
    "pv": "position_vector",
    "1033": "position_vector",
    "9606": "position_vector",
    "coordinate_frame": "coordinate_frame",
    "coordinate-frame": "coordinate_frame",
    "coordinate frame": "coordinate_frame",
    "cf": "coordinate_frame",
    "1032": "coordinate_frame",
    "9607": "coordinate_frame",
}


def _helmert_convention(convention) -> str:
    key = str(convention).strip().lower()
    if key not in _HELMERT_CONVENTIONS:
        raise InputError(
            f"unknown Helmert convention {convention!r}; use 'position_vector' (EPSG 1033/9606) "
            "or 'coordinate_frame' (EPSG 1032/9607)"
        )
    return _HELMERT_CONVENTIONS[key]


def _helmert_rotation(rotation) -> str:
    key = str(rotation).strip().lower().replace("_", "-")
    if key == "exact":
        return "exact"
    if key in ("small-angle", "linearised", "linearized", "linear"):
        return "small-angle"
    raise InputError(f"rotation must be 'exact' or 'small-angle', not {rotation!r}")


def _proj_number(value: float) -> str:
    """A number for a PROJ string: 15 significant digits (the precision of a double), so
    that the conversions to arc-seconds and ppm leave no trailing float noise
    (-0.247, not -0.24699999999999994)."""
    text = f"{float(value):.15g}"
    return "0" if text == "-0" else text
