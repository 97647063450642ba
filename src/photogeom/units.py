"""Angle units: radians inside the library, degrees and gon at the edges."""

from __future__ import annotations

import numpy as np

from .errors import InputError

#: Factor from one unit to radians.
_TO_RAD = {
    "rad": 1.0,
    "deg": np.pi / 180.0,
    "gon": np.pi / 200.0,
    "arcsec": np.pi / (180.0 * 3600.0),
    "mrad": 1e-3,
}
_ALIASES = {
    "radian": "rad",
    "radians": "rad",
    "degree": "deg",
    "degrees": "deg",
    "°": "deg",
    "grad": "gon",
    "grads": "gon",
    "gons": "gon",
    "as": "arcsec",
    '"': "arcsec",
}
ANGLE_UNITS = tuple(_TO_RAD)


def normalize_angle_unit(unit: str) -> str:
    """Return the canonical name of an angle unit ('rad', 'deg', 'gon', 'arcsec', 'mrad')."""
    key = str(unit).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in _TO_RAD:
        raise InputError(f"unknown angle unit {unit!r}; use one of {', '.join(ANGLE_UNITS)}")
    return key


def to_radians(value, unit: str):
    """Convert angle(s) in ``unit`` to radians."""
    return np.asarray(value, dtype=float) * _TO_RAD[normalize_angle_unit(unit)]


def from_radians(value, unit: str):
    """Convert angle(s) in radians to ``unit``."""
    return np.asarray(value, dtype=float) / _TO_RAD[normalize_angle_unit(unit)]


def deg2gon(value):
    """Degrees to gon (400 gon per turn)."""
    return np.asarray(value, dtype=float) * (400.0 / 360.0)


def gon2deg(value):
    """Gon to degrees."""
    return np.asarray(value, dtype=float) * (360.0 / 400.0)


def wrap_angle(value, unit: str = "rad"):
    """Wrap angle(s) to the half-open interval [-half turn, +half turn)."""
    half = float(from_radians(np.pi, unit))
    v = np.asarray(value, dtype=float)
    return (v + half) % (2 * half) - half


def display_angle(value, unit: str = "rad", name: str = ""):
    """An angle as photogeom prints it in tables, reports and the command line's JSON.

    One rule for every printed angle: ``kappa`` (the rotation about the vertical, an azimuth
    in the textbooks) in ``[0, one turn)``; every other angle (omega, phi, theta, ...) in
    ``[-half turn, +half turn)``. Kraus' kappa of -101.3201 gon is printed 298.6799 gon,
    an omega of 399.8 gon is printed -0.2 gon. Values returned by the API (``fit.angles()``,
    ``fit.parameters``) are not changed.

    Parameters
    ----------
    value : float or array_like
        Angle(s) in ``unit``.
    unit : str
        Angle unit of ``value`` (and of the result).
    name : str
        Parameter name; ``"kappa"`` selects the [0, one turn) range.
    """
    full = 2.0 * float(from_radians(np.pi, unit))
    v = np.asarray(value, dtype=float)
    if name == "kappa":
        out = np.mod(v, full)
        out = np.where(out >= full, 0.0, out)  # -tiny % full rounds to full
    else:
        out = wrap_angle(v, unit)
    return float(out) if out.ndim == 0 else out
