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
    """Canonical name of an angle unit.

    Parameters
    ----------
    unit : str
        Unit name, case-insensitive, surrounding blanks ignored: ``"rad"``, ``"deg"``,
        ``"gon"``, ``"arcsec"``, ``"mrad"`` or an alias (``"radians"``, ``"degrees"``,
        ``"°"``, ``"grad"``, ``"gons"``, ``"as"``, ``'"'``, ...).

    Returns
    -------
    str
        One of ``'rad'``, ``'deg'``, ``'gon'``, ``'arcsec'``, ``'mrad'``.

    Raises
    ------
    InputError
        When ``unit`` is none of these; the message lists the accepted units.
    """
    key = str(unit).strip().lower()
    key = _ALIASES.get(key, key)
    if key not in _TO_RAD:
        raise InputError(f"unknown angle unit {unit!r}; use one of {', '.join(ANGLE_UNITS)}")
    return key


def to_radians(value, unit: str):
    """Convert angle(s) in ``unit`` to radians.

    Parameters
    ----------
    value : float or array_like
        Angle(s) in ``unit``; any shape.
    unit : str
        Unit of ``value``: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"`` or an
        alias accepted by :func:`normalize_angle_unit`.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        Angle(s) in rad, float, the shape of ``value`` (a numpy float for a scalar).

    Raises
    ------
    InputError
        For an unknown ``unit``.
    """
    return np.asarray(value, dtype=float) * _TO_RAD[normalize_angle_unit(unit)]


def from_radians(value, unit: str):
    """Convert angle(s) in radians to ``unit``.

    Parameters
    ----------
    value : float or array_like
        Angle(s) in rad; any shape.
    unit : str
        Target unit: ``"rad"``, ``"deg"``, ``"gon"``, ``"arcsec"``, ``"mrad"`` or an alias
        accepted by :func:`normalize_angle_unit`.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        Angle(s) in ``unit``, float, the shape of ``value`` (a numpy float for a scalar).

    Raises
    ------
    InputError
        For an unknown ``unit``.
    """
    return np.asarray(value, dtype=float) / _TO_RAD[normalize_angle_unit(unit)]


def deg2gon(value):
    """Degrees to gon (400 gon per turn).

    Parameters
    ----------
    value : float or array_like
        Angle(s) in deg; any shape.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        Angle(s) in gon, float, the shape of ``value`` (a numpy float for a scalar).
    """
    return np.asarray(value, dtype=float) * (400.0 / 360.0)


def gon2deg(value):
    """Gon to degrees (360 deg per turn).

    Parameters
    ----------
    value : float or array_like
        Angle(s) in gon; any shape.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        Angle(s) in deg, float, the shape of ``value`` (a numpy float for a scalar).
    """
    return np.asarray(value, dtype=float) * (360.0 / 400.0)


def wrap_angle(value, unit: str = "rad"):
    """Wrap angle(s) to the half-open interval [-half turn, +half turn).

    Parameters
    ----------
    value : float or array_like
        Angle(s) in ``unit``; any shape.
    unit : str, default "rad"
        Unit of ``value`` and of the result (half a turn is pi rad, 180 deg, 200 gon).

    Returns
    -------
    numpy.float64 or numpy.ndarray
        The wrapped angle(s) in ``unit``, the shape of ``value`` (a numpy float for a scalar).

    Raises
    ------
    InputError
        For an unknown ``unit``.
    """
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
    unit : str, default "rad"
        Angle unit of ``value`` (and of the result).
    name : str, default ""
        Parameter name; ``"kappa"`` selects the [0, one turn) range.

    Returns
    -------
    float or numpy.ndarray
        The angle(s) in ``unit`` in the printed range: a float for a scalar ``value``, else
        an array of its shape.

    Raises
    ------
    InputError
        For an unknown ``unit``.
    """
    full = 2.0 * float(from_radians(np.pi, unit))
    v = np.asarray(value, dtype=float)
    if name == "kappa":
        out = np.mod(v, full)
        out = np.where(out >= full, 0.0, out)  # -tiny % full rounds to full
    else:
        out = wrap_angle(v, unit)
    return float(out) if out.ndim == 0 else out
