"""The normalised validity domain of an RPC and the warnings about leaving it.

Vendors fit RPCs to the physical sensor model over the normalised cube ``[-1, 1]^3`` of
(longitude, latitude, height) and the normalised image ``[-1, 1]^2``. Cubic rational
functions extrapolate badly: a point far outside that domain gets a number, but not one that
the sensor would give. The library warns (it does not refuse) when inputs leave the cube by
more than :data:`DOMAIN_LIMIT`.
"""

from __future__ import annotations

import warnings

import numpy as np

#: Largest absolute normalised coordinate accepted without a warning.
DOMAIN_LIMIT = 1.5


def longitude_difference(lon, lon0):
    """``lon - lon0`` in degrees, the short way round: within [-180, 180].

    RPCs of scenes on the antimeridian have a ``LONG_OFF`` near +-180 while ground data give
    the longitudes of the same area as both 179.9 and -179.9; a plain difference puts the
    second 360 degrees (thousands of normalised units) away. Differences already within
    [-180, 180] are returned unchanged (bit for bit).
    """
    d = np.subtract(lon, lon0)
    if np.any(np.abs(d) > 180.0):  # rare: a scene on the antimeridian
        d = np.where(d > 180.0, d - 360.0, np.where(d < -180.0, d + 360.0, d))
    return d


def wrap_longitude(lon):
    """Longitude(s) in degrees brought into [-180, 180] (values inside unchanged)."""
    lon = np.asarray(lon, dtype=np.float64)
    return np.where(lon > 180.0, lon - 360.0, np.where(lon < -180.0, lon + 360.0, lon))


class RPCExtrapolationWarning(UserWarning):
    """Points lie far outside the normalised domain the RPC was fitted on."""


class LocalizationWarning(RuntimeWarning):
    """Some points could not be localised (their results are NaN; see the status)."""


def check_domain(
    arrays: dict[str, np.ndarray], limit: float | None = DOMAIN_LIMIT, what: str = "RPC"
) -> None:
    """Warn with :class:`RPCExtrapolationWarning` when normalised values exceed ``limit``.

    Parameters
    ----------
    arrays : dict
        Name -> normalised coordinates (any shape).
    limit : float or None
        Largest absolute normalised value accepted silently; ``None`` disables the check.
    what : str
        Operation named in the message.
    """
    if limit is None:
        return
    parts = []
    for name, a in arrays.items():
        if a.size == 0:
            continue
        m = float(np.max(np.abs(a)))
        if m > limit:
            n = int(np.count_nonzero(np.abs(a) > limit))
            parts.append(f"{n} point(s) with |normalised {name}| up to {m:.3g}")
    if parts:
        warnings.warn(
            f"{what}: {', '.join(parts)} (outside +-{limit:g} of the normalised domain the "
            "RPC was fitted on); rational polynomials extrapolate badly, treat these results "
            "with caution",
            RPCExtrapolationWarning,
            stacklevel=3,
        )
