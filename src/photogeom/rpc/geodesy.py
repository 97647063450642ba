"""Metres per degree of longitude and latitude on WGS84 (RPC ground coordinates are
geodetic longitude and latitude in degrees, heights in metres above the ellipsoid)."""

from __future__ import annotations

import numpy as np

__all__ = ["metres_per_degree"]

#: WGS84 semi-major axis (m) and first eccentricity squared.
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3


def metres_per_degree(lat, h) -> tuple[np.ndarray, np.ndarray]:
    """Metres per degree east and north at geodetic latitude ``lat`` (deg) and ellipsoidal
    height ``h`` (m), from the WGS84 radii of curvature: ``(N + h) cos(lat)`` and
    ``M + h``, times pi / 180."""
    phi = np.radians(np.asarray(lat, dtype=np.float64))
    h = np.asarray(h, dtype=np.float64)
    w = np.sqrt(1.0 - WGS84_E2 * np.sin(phi) ** 2)
    east = np.radians(WGS84_A / w + h) * np.cos(phi)
    north = np.radians(WGS84_A * (1.0 - WGS84_E2) / w**3 + h)
    return east, north
