"""Coordinates on the Earth: geodetic, geocentric (ECEF) and local topocentric (ENU) frames.

Conventions (see ``docs/crs-and-clouds.md``):

* geodetic latitude and longitude in **degrees**, ellipsoidal height in **metres**;
* geocentric Cartesian coordinates (ECEF) in metres, X towards (lat 0, lon 0), Z towards the
  north pole;
* a local topocentric frame (ENU) at an origin ``(lat0, lon0, h0)``: E east, N north, U along
  the ellipsoid normal of the origin, in metres; it is a rigid transformation of ECEF, so the
  Earth's surface curves *down* in it (a point on the ellipsoid at 1 km from the origin has
  U = -7.8 cm);
* the ellipsoid is WGS 84 unless ``ellipsoid=`` names another (``"GRS80"``, ``"Bessel1841"``
  ..., any ellipsoid PROJ knows by name, or a pair ``(a, 1/f)``).

The conversions between these frames are closed formulas in numpy (vectorised, no PROJ
needed; tests compare them with PROJ). Any other coordinate reference system (EPSG code, WKT,
PROJ string) is handled by pyproj: :func:`parse_crs`, :func:`transform_points`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError
from .validation import as_points_single, one_or_many

__all__ = [
    "ELLIPSOIDS",
    "CrsInfo",
    "Ellipsoid",
    "LocalFrame",
    "ProjTransform",
    "axis_units",
    "cartesian_crs",
    "crs_label",
    "crs_name",
    "curvature_drop",
    "curvature_note",
    "ecef_to_enu",
    "ecef_to_geodetic",
    "enu_rotation",
    "enu_to_ecef",
    "frame_from_text",
    "geodetic_to_ecef",
    "get_ellipsoid",
    "parse_crs",
    "points_between",
    "points_converter",
    "transform_points",
]


@dataclass(frozen=True)
class Ellipsoid:
    """A reference ellipsoid of revolution.

    Attributes
    ----------
    name : str
    a : float
        Semi-major axis (m).
    inv_f : float
        Inverse flattening ``1/f`` (``inf`` for a sphere).
    """

    name: str
    a: float
    inv_f: float

    @property
    def f(self) -> float:
        """Flattening."""
        return 0.0 if math.isinf(self.inv_f) else 1.0 / self.inv_f

    @property
    def b(self) -> float:
        """Semi-minor axis (m)."""
        return self.a * (1.0 - self.f)

    @property
    def e2(self) -> float:
        """First eccentricity squared ``f (2 - f)``."""
        return self.f * (2.0 - self.f)

    @property
    def ep2(self) -> float:
        """Second eccentricity squared ``e2 / (1 - e2)``."""
        return self.e2 / (1.0 - self.e2)


#: Ellipsoids known without PROJ (parameters as defined by EPSG).
ELLIPSOIDS: dict[str, Ellipsoid] = {
    e.name.upper(): e
    for e in (
        Ellipsoid("WGS84", 6378137.0, 298.257223563),
        Ellipsoid("GRS80", 6378137.0, 298.257222101),
        Ellipsoid("Bessel1841", 6377397.155, 299.1528128),
        Ellipsoid("Clarke1866", 6378206.4, 294.978698214),
        Ellipsoid("International1924", 6378388.0, 297.0),
        Ellipsoid("Krassowsky1940", 6378245.0, 298.3),
        Ellipsoid("Airy1830", 6377563.396, 299.3249646),
    )
}
_ALIASES = {
    "WGS 84": "WGS84",
    "WGS-84": "WGS84",
    "GRS 1980": "GRS80",
    "BESSEL": "BESSEL1841",
    "INTL": "INTERNATIONAL1924",
    "KRASS": "KRASSOWSKY1940",
    "AIRY": "AIRY1830",
    "CLRK66": "CLARKE1866",
}


def get_ellipsoid(ellipsoid: str | tuple[float, float] | Ellipsoid = "WGS84") -> Ellipsoid:
    """An :class:`Ellipsoid` from a name, a pair ``(a, 1/f)`` or an :class:`Ellipsoid`.

    Names not in :data:`ELLIPSOIDS` are looked up in PROJ (``pyproj.get_ellps_map``), e.g.
    ``"helmert"`` or ``"evrst30"``.

    Parameters
    ----------
    ellipsoid : str, (float, float) or Ellipsoid, default "WGS84"
        Name (case-insensitive), or semi-major axis ``a`` in m and inverse flattening
        ``1/f`` (``inf`` for a sphere).

    Returns
    -------
    Ellipsoid

    Raises
    ------
    InputError
        For an unknown name, or a pair with ``a <= 0`` or ``1/f <= 1``.
    """
    if isinstance(ellipsoid, Ellipsoid):
        return ellipsoid
    if isinstance(ellipsoid, str):
        key = ellipsoid.strip().upper()
        key = _ALIASES.get(key, key)
        if key in ELLIPSOIDS:
            return ELLIPSOIDS[key]
        try:
            from pyproj import get_ellps_map
        except ImportError:  # pragma: no cover - pyproj is a dependency of the tests
            get_ellps_map = None
        if get_ellps_map is not None:
            for name, p in get_ellps_map().items():
                if name.upper() == key:
                    a = float(p["a"])
                    if "rf" in p:
                        rf = float(p["rf"])
                    else:
                        b = float(p["b"])
                        rf = math.inf if b == a else a / (a - b)
                    return Ellipsoid(name, a, rf)
        known = ", ".join(e.name for e in ELLIPSOIDS.values())
        raise InputError(
            f"unknown ellipsoid {ellipsoid!r}; known: {known} (any PROJ ellipsoid name with "
            "pyproj installed), or pass (a, 1/f)"
        )
    try:
        a, rf = (float(v) for v in ellipsoid)
    except (TypeError, ValueError):
        raise InputError(
            f"ellipsoid must be a name or a pair (a, 1/f), got {ellipsoid!r}"
        ) from None
    if not (a > 0 and rf > 1):
        raise InputError(f"ellipsoid (a, 1/f) = ({a}, {rf}): need a > 0 and 1/f > 1 (inf: sphere)")
    return Ellipsoid("custom", a, rf)


def _arrays(*values, names: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    arrs = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in values))
    for name, arr in zip(names, arrs):
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name} contains NaN or infinite values")
    return tuple(arrs)


def _scalar_or_array(arr: np.ndarray):
    return float(arr) if arr.ndim == 0 else arr


def geodetic_to_ecef(lat, lon, h, *, ellipsoid="WGS84"):
    """Geodetic latitude, longitude (degrees) and ellipsoidal height (m) to ECEF X, Y, Z (m).

    ``X = (N + h) cos(lat) cos(lon)``, ``Y = (N + h) cos(lat) sin(lon)``,
    ``Z = (N (1 - e^2) + h) sin(lat)`` with ``N = a / sqrt(1 - e^2 sin^2(lat))``.

    Parameters
    ----------
    lat, lon : float or array_like
        Geodetic latitude (within [-90, 90]) and longitude, degrees; latitude first.
    h : float or array_like
        Ellipsoidal height, m. The three broadcast against each other.
    ellipsoid : str or (float, float)
        ``"WGS84"`` (default), ``"GRS80"``, ``"Bessel1841"``, ... or any ellipsoid name
        PROJ knows, or ``(a, 1/f)`` with ``a`` in metres.

    Returns
    -------
    (X, Y, Z) : tuple of numpy.ndarray (or floats for scalar inputs)
        Geocentric coordinates, m, of the broadcast shape.
    """
    lat, lon, h = _arrays(lat, lon, h, names=("lat", "lon", "h"))
    if np.any(np.abs(lat) > 90.0):
        raise InputError("lat must be within [-90, 90] degrees (latitude first, then longitude)")
    ell = get_ellipsoid(ellipsoid)
    phi = np.radians(lat)
    lam = np.radians(lon)
    sp, cp = np.sin(phi), np.cos(phi)
    N = ell.a / np.sqrt(1.0 - ell.e2 * sp * sp)
    r = (N + h) * cp
    X = r * np.cos(lam)
    Y = r * np.sin(lam)
    Z = (N * (1.0 - ell.e2) + h) * sp
    return _scalar_or_array(X), _scalar_or_array(Y), _scalar_or_array(Z)


def ecef_to_geodetic(X, Y, Z, *, ellipsoid="WGS84"):
    """ECEF X, Y, Z (m) to geodetic latitude, longitude (degrees) and ellipsoidal height (m).

    Bowring's parametric-latitude iteration (three steps, converged to rounding for points
    from the Earth's centre region out to beyond geostationary orbit; tested against PROJ
    and by round trips: 5e-10 m RMS, below the 9.3e-10 m spacing of doubles at 6.4e6 m); the
    height ``h = (p - N cos(lat)) cos(lat) + (Z - N (1 - e^2) sin(lat)) sin(lat)`` has no
    singularity at the poles. Longitude in (-180, 180].

    Parameters
    ----------
    X, Y, Z : float or array_like
        Geocentric coordinates, m (broadcast against each other).
    ellipsoid : str or (float, float)
        ``"WGS84"`` (default), ``"GRS80"``, ``"Bessel1841"``, ... or any ellipsoid name
        PROJ knows, or ``(a, 1/f)`` with ``a`` in metres.

    Returns
    -------
    (lat, lon, h) : tuple of numpy.ndarray (or floats for scalar inputs)
        Latitude and longitude in degrees, ellipsoidal height in m.
    """
    X, Y, Z = _arrays(X, Y, Z, names=("X", "Y", "Z"))
    ell = get_ellipsoid(ellipsoid)
    a, b, e2, ep2 = ell.a, ell.b, ell.e2, ell.ep2
    p = np.hypot(X, Y)
    if np.any((p < 1e-3 * a) & (np.abs(Z) < 1e-3 * a)):
        raise InputError(
            "ECEF point within 6 km of the Earth's centre: geodetic coordinates undefined there "
            "(are the coordinates geocentric metres?)"
        )
    beta = np.arctan2(Z * a, p * b)
    for _ in range(3):
        sb, cb = np.sin(beta), np.cos(beta)
        phi = np.arctan2(Z + ep2 * b * sb**3, p - e2 * a * cb**3)
        beta = np.arctan2((1.0 - ell.f) * np.sin(phi), np.cos(phi))
    sp, cp = np.sin(phi), np.cos(phi)
    N = a / np.sqrt(1.0 - e2 * sp * sp)
    # distance from the foot point along the normal: the differences are exact (Sterbenz),
    # so the height carries about one rounding of the coordinates
    h = (p - N * cp) * cp + (Z - N * (1.0 - e2) * sp) * sp
    lon = np.degrees(np.arctan2(Y, X))
    return (
        _scalar_or_array(np.degrees(phi)),
        _scalar_or_array(lon),
        _scalar_or_array(h),
    )


def enu_rotation(lat0: float, lon0: float) -> np.ndarray:
    """The rotation ``R`` with ``enu = R @ (xyz - origin)`` at (lat0, lon0).

    Rows: east ``(-sin lon, cos lon, 0)``, north ``(-sin lat cos lon, -sin lat sin lon,
    cos lat)``, up (the ellipsoid normal) ``(cos lat cos lon, cos lat sin lon, sin lat)``.

    Parameters
    ----------
    lat0, lon0 : float
        Geodetic latitude and longitude of the origin, deg.

    Returns
    -------
    numpy.ndarray, shape (3, 3)

    Raises
    ------
    InputError
        For non-finite values or ``|lat0| > 90``.
    """
    lat0, lon0 = float(lat0), float(lon0)
    if not (math.isfinite(lat0) and math.isfinite(lon0)) or abs(lat0) > 90.0:
        raise InputError(f"origin lat0={lat0}, lon0={lon0}: need finite values, |lat0| <= 90")
    phi, lam = math.radians(lat0), math.radians(lon0)
    sp, cp, sl, cl = math.sin(phi), math.cos(phi), math.sin(lam), math.cos(lam)
    return np.array(
        [
            [-sl, cl, 0.0],
            [-sp * cl, -sp * sl, cp],
            [cp * cl, cp * sl, sp],
        ]
    )


def _points3(values, name: str) -> tuple[np.ndarray, bool]:
    arr = np.asarray(values, dtype=float)
    single = arr.ndim == 1
    if single:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3) or (3,), got {np.shape(values)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or infinite values")
    return arr, single


def ecef_to_enu(xyz, lat0, lon0, h0, *, ellipsoid="WGS84") -> np.ndarray:
    """ECEF points to local east, north, up at an origin.

    Parameters
    ----------
    xyz : array_like, shape (n, 3) or (3,)
        Geocentric coordinates, m.
    lat0, lon0 : float
        Origin, geodetic degrees.
    h0 : float
        Origin ellipsoidal height, m.
    ellipsoid : str or (float, float)
        ``"WGS84"`` (default), ``"GRS80"``, ``"Bessel1841"``, ... or any ellipsoid name
        PROJ knows, or ``(a, 1/f)`` with ``a`` in metres.

    Returns
    -------
    numpy.ndarray, shape (n, 3) or (3,)
        East, north, up (m); up along the ellipsoid normal at the origin.
    """
    pts, single = _points3(xyz, "xyz")
    R = enu_rotation(lat0, lon0)
    o = np.array(geodetic_to_ecef(lat0, lon0, h0, ellipsoid=ellipsoid))
    out = (pts - o) @ R.T
    return out[0] if single else out


def enu_to_ecef(enu, lat0, lon0, h0, *, ellipsoid="WGS84") -> np.ndarray:
    """Local east, north, up at an origin to ECEF: the inverse of :func:`ecef_to_enu`.

    Parameters
    ----------
    enu : array_like, shape (n, 3) or (3,)
        East, north, up, m.
    lat0, lon0 : float
        Origin, geodetic degrees.
    h0 : float
        Origin ellipsoidal height, m.
    ellipsoid : str or (float, float)
        ``"WGS84"`` (default), ``"GRS80"``, ``"Bessel1841"``, ... or any ellipsoid name
        PROJ knows, or ``(a, 1/f)`` with ``a`` in metres.

    Returns
    -------
    numpy.ndarray, shape (n, 3) or (3,)
        Geocentric coordinates, m.
    """
    pts, single = _points3(enu, "enu")
    R = enu_rotation(lat0, lon0)
    o = np.array(geodetic_to_ecef(lat0, lon0, h0, ellipsoid=ellipsoid))
    out = pts @ R + o
    return out[0] if single else out


def curvature_drop(distance, *, lat0: float = 45.0, ellipsoid="WGS84"):
    """How far below the local horizontal plane the ellipsoid lies at a horizontal distance.

    The magnitude of the (negative) U coordinate of the ellipsoid point at ``distance``
    from the origin of an ENU frame on the ellipsoid, ``~ d^2 / (2 R)`` with the
    Gaussian mean radius ``R = sqrt(M N)`` at ``lat0`` (about 7.8 cm at 1 km, 7.8 m at
    10 km; the radius of curvature depends on the direction, from the meridian radius M
    to N, so the true drop differs by up to 0.7 %). It is what a block adjusted in a local
    Cartesian frame must carry as height, not an error of the frame
    (see ``docs/crs-and-clouds.md``).

    Parameters
    ----------
    distance : float or array_like
        Horizontal distance(s) from the frame origin, m.
    lat0 : float, default 45.0
        Latitude of the origin, deg.
    ellipsoid : str, (a, 1/f) or Ellipsoid, default "WGS84"
        As :func:`get_ellipsoid` takes it.

    Returns
    -------
    float or numpy.ndarray
        The drop(s), m (>= 0), of the shape of ``distance``.
    """
    d = np.asarray(distance, dtype=float)
    ell = get_ellipsoid(ellipsoid)
    s2 = math.sin(math.radians(lat0)) ** 2
    w = math.sqrt(1.0 - ell.e2 * s2)
    R = ell.a * math.sqrt(1.0 - ell.e2) / (w * w)  # sqrt(M N)
    out = R - np.sqrt(np.maximum(R * R - d * d, 0.0))
    return _scalar_or_array(out)


@dataclass(frozen=True)
class LocalFrame:
    """A local topocentric (ENU) frame: where a block is adjusted, and GNSS positions go.

    Parameters
    ----------
    lat0, lon0 : float
        Origin, geodetic degrees.
    h0 : float
        Origin ellipsoidal height (m).
    ellipsoid : str or (a, 1/f)
        Ellipsoid of the geodetic coordinates (WGS 84 by default).

    Examples
    --------
    >>> lat, lon, h = [47.10, 47.11], [8.50, 8.52], [520.0, 540.0]   # GNSS positions
    >>> frame = LocalFrame.at_centroid(lat, lon, h)
    >>> enu = frame.from_geodetic(lat, lon, h)            # (n, 3) m, for the adjustment
    >>> enu.shape
    (2, 3)
    >>> lat2, lon2, h2 = frame.to_geodetic(enu)           # back to WGS 84
    >>> bool(np.allclose(lat2, lat, atol=1e-12) and np.allclose(h2, h, atol=1e-6))
    True
    """

    lat0: float
    lon0: float
    h0: float = 0.0
    ellipsoid: Any = "WGS84"

    @classmethod
    def at_centroid(cls, lat, lon, h, *, ellipsoid="WGS84") -> LocalFrame:
        """The frame at the geodetic point below the ECEF centroid of the given points
        (its height: the mean height), so that the points sit around E = N = 0.

        Parameters
        ----------
        lat, lon : array_like
            Geodetic latitude and longitude of the points, degrees.
        h : array_like
            Their ellipsoidal heights, m.
        ellipsoid : str or (float, float)
            As in :func:`geodetic_to_ecef`.

        Returns
        -------
        LocalFrame
        """
        X, Y, Z = geodetic_to_ecef(lat, lon, h, ellipsoid=ellipsoid)
        c = [float(np.mean(v)) for v in (X, Y, Z)]
        la, lo, _ = ecef_to_geodetic(*c, ellipsoid=ellipsoid)
        return cls(float(la), float(lo), float(np.mean(h)), ellipsoid)

    @property
    def rotation(self) -> np.ndarray:
        """``R`` with ``enu = R @ (ecef - origin)``."""
        return enu_rotation(self.lat0, self.lon0)

    @property
    def origin_ecef(self) -> np.ndarray:
        """The origin in ECEF (m)."""
        return np.array(geodetic_to_ecef(self.lat0, self.lon0, self.h0, ellipsoid=self.ellipsoid))

    def from_ecef(self, xyz) -> np.ndarray:
        """ECEF -> ENU of the same shape (:func:`ecef_to_enu`).

        Parameters
        ----------
        xyz : array_like, shape (n, 3) or (3,)
            Geocentric coordinates on this frame's ellipsoid, m.

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            East, north, up, m.
        """
        return ecef_to_enu(xyz, self.lat0, self.lon0, self.h0, ellipsoid=self.ellipsoid)

    def to_ecef(self, enu) -> np.ndarray:
        """ENU -> ECEF of the same shape (:func:`enu_to_ecef`).

        Parameters
        ----------
        enu : array_like, shape (n, 3) or (3,)
            East, north, up in this frame, m.

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            Geocentric coordinates, m.
        """
        return enu_to_ecef(enu, self.lat0, self.lon0, self.h0, ellipsoid=self.ellipsoid)

    def from_geodetic(self, lat, lon, h) -> np.ndarray:
        """Geodetic coordinates to ENU.

        Parameters
        ----------
        lat, lon : float or array_like
            Geodetic latitude and longitude, degrees (on the frame's ellipsoid).
        h : float or array_like
            Ellipsoidal height, m.

        Returns
        -------
        numpy.ndarray, shape (n, 3)
            East, north, up, m (one row per point, also for scalar inputs).
        """
        X, Y, Z = geodetic_to_ecef(lat, lon, h, ellipsoid=self.ellipsoid)
        return self.from_ecef(np.column_stack([np.ravel(X), np.ravel(Y), np.ravel(Z)]))

    def to_geodetic(self, enu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU coordinates to geodetic ones.

        Parameters
        ----------
        enu : array_like, shape (n, 3) or (3,)
            East, north, up, m.

        Returns
        -------
        (lat, lon, h) : tuple of numpy.ndarray, shape (n,)
            Latitude and longitude in degrees, ellipsoidal height in m.
        """
        xyz = np.atleast_2d(self.to_ecef(enu))
        return ecef_to_geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2], ellipsoid=self.ellipsoid)

    def covariance_from_ecef(self, cov) -> np.ndarray:
        """Rotate covariance matrices of ECEF coordinates into ENU: ``R C R.T``.

        Parameters
        ----------
        cov : array_like, shape (..., 3, 3)
            Covariances of geocentric coordinates, m^2.

        Returns
        -------
        numpy.ndarray, shape (..., 3, 3)
            The same covariances in east, north, up, m^2.
        """
        R = self.rotation
        return R @ np.asarray(cov, dtype=float) @ R.T

    def to_text(self) -> str:
        """The frame as a CRS text, ``"enu:lat0,lon0,h0"`` (WGS 84 only).

        What the ``# crs:`` line of a point or block file and ``--crs`` options take for a
        local frame (see :func:`frame_from_text`).

        Returns
        -------
        str

        Raises
        ------
        InputError
            For a frame on another ellipsoid (it has no text form).
        """
        if get_ellipsoid(self.ellipsoid).name != "WGS84":
            raise InputError(
                "only local frames on WGS 84 have a text form (enu:lat0,lon0,h0); this one is "
                f"on {get_ellipsoid(self.ellipsoid).name}"
            )
        return f"enu:{self.lat0!r},{self.lon0!r},{self.h0!r}"

    def describe(self) -> str:
        """``"local ENU frame at lat 47.1, lon 8.5, h 500 m (WGS 84)"``.

        Returns
        -------
        str
        """
        return (
            f"local ENU frame at lat {self.lat0:.9g}, lon {self.lon0:.9g}, h {self.h0:.6g} m "
            f"({get_ellipsoid(self.ellipsoid).name})"
        )

    def to_dict(self) -> dict:
        """JSON-ready description (for results and reports).

        Returns
        -------
        dict
            ``frame`` ("ENU"), ``lat0_deg``, ``lon0_deg``, ``h0_m``, ``ellipsoid`` (name).
        """
        return {
            "frame": "ENU",
            "lat0_deg": self.lat0,
            "lon0_deg": self.lon0,
            "h0_m": self.h0,
            "ellipsoid": get_ellipsoid(self.ellipsoid).name,
        }


# --- any CRS, through pyproj ------------------------------------------------------------------


def _pyproj():
    try:
        import pyproj
    except ImportError:  # pragma: no cover - depends on the installation
        raise InputError(
            "coordinate reference systems need pyproj: pip install 'photogeom[crs]'"
        ) from None
    return pyproj


def parse_crs(crs, *, what: str = "crs"):
    """A ``pyproj.CRS`` from an EPSG code, WKT, a PROJ string or a ``pyproj.CRS``.

    Parameters
    ----------
    crs : str, int or pyproj.CRS
        ``"EPSG:4979"``, ``4979``, WKT or a PROJ string.
    what : str, default "crs"
        The option or argument that gave it, named in the error message.

    Returns
    -------
    pyproj.CRS

    Raises
    ------
    InputError
        For a CRS PROJ does not know.
    """
    pyproj = _pyproj()
    if isinstance(crs, pyproj.CRS):
        return crs
    try:
        return pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError as exc:
        raise InputError(
            f"{what}: {crs!r} is not a coordinate reference system PROJ knows "
            f"(give e.g. EPSG:4979, a WKT string or a PROJ string): {exc}"
        ) from None


def crs_name(crs) -> str:
    """A short readable name: ``"EPSG:32632 (WGS 84 / UTM zone 32N)"`` or the CRS's name.

    Parameters
    ----------
    crs : str, int or pyproj.CRS
        As :func:`parse_crs` takes it.

    Returns
    -------
    str

    Raises
    ------
    InputError
        For a CRS PROJ does not know.
    """
    c = parse_crs(crs)
    auth = c.to_authority()
    return f"{auth[0]}:{auth[1]} ({c.name})" if auth else c.name


def transform_points(points, src_crs, dst_crs, *, allow_ballpark: bool = False) -> np.ndarray:
    """Transform points (n, 2) or (n, 3) from ``src_crs`` to ``dst_crs`` with PROJ.

    Axis order is always x/easting/longitude first (``always_xy``), whatever the CRS
    definition says. ``allow_ballpark=False`` (default) refuses a transformation PROJ can
    only do approximately (a "ballpark" datum shift without the grids or parameters it needs)
    instead of returning coordinates metres off; points PROJ cannot transform raise.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (n, 3), or (2,) / (3,) for one point
        Coordinates in ``src_crs``, x/easting/longitude first (degrees for geographic,
        the CRS's unit otherwise).
    src_crs, dst_crs : str or int
        EPSG code (``"EPSG:25832"``, ``4979``), WKT or PROJ string.
    allow_ballpark : bool
        Accept an approximate datum shift.

    Returns
    -------
    numpy.ndarray, shape of ``points``
        Coordinates in ``dst_crs``, x first.

    Raises
    ------
    InputError
        For points of another shape, an unknown CRS, a ballpark transformation (unless
        allowed), or points PROJ cannot transform.
    """
    pts, single = as_points_single(points, (2, 3), "points", finite=False)
    out = _proj_apply(_proj_transformer(src_crs, dst_crs, allow_ballpark), pts)
    return one_or_many(out, single)


def _proj_transformer(src_crs, dst_crs, allow_ballpark: bool):
    """The pyproj Transformer of :func:`transform_points` (x first; ballpark refused unless
    allowed, with a message saying how to allow it)."""
    pyproj = _pyproj()
    src = parse_crs(src_crs, what="source crs")
    dst = parse_crs(dst_crs, what="target crs")
    try:
        return pyproj.Transformer.from_crs(src, dst, always_xy=True, allow_ballpark=allow_ballpark)
    except pyproj.exceptions.ProjError as exc:
        raise InputError(
            f"no transformation from {crs_name(src)} to {crs_name(dst)} without a ballpark "
            f"datum shift ({exc}); allow it explicitly (allow_ballpark=True / --allow-ballpark) "
            "or install the PROJ grids it needs"
        ) from None


def _proj_apply(tr, pts: np.ndarray) -> np.ndarray:
    """Points (n, 2) or (n, 3) through the Transformer ``tr`` (errors checked)."""
    pyproj = _pyproj()
    cols = [pts[:, i] for i in range(pts.shape[1])]
    try:
        out = tr.transform(*cols, errcheck=True)
    except pyproj.exceptions.ProjError as exc:
        raise InputError(f"PROJ could not transform the points: {exc}") from None
    return np.column_stack(out)


class ProjTransform:
    """A PROJ coordinate operation as a photogeom transformation (``apply`` on (n, 3)).

    Parameters
    ----------
    src_crs, dst_crs : str or pyproj.CRS
        Source and target CRS (EPSG code, WKT, PROJ string). x/easting/longitude first.
    allow_ballpark : bool
        Accept an approximate ("ballpark") datum shift; refused by default.

    Used by :func:`photogeom.io.transform_cloud`, which records ``target_crs`` in the output.
    PROJ picks the most accurate operation available (``transformer.description`` says
    which): this is the reference when a datum transformation by PROJ is asked for.
    """

    dim = 3
    name = "proj"

    def __init__(self, src_crs, dst_crs, *, allow_ballpark: bool = False) -> None:
        pyproj = _pyproj()
        self.source_crs = parse_crs(src_crs, what="source crs")
        self.target_crs = parse_crs(dst_crs, what="target crs")
        self._ballpark = bool(allow_ballpark)
        try:
            self.transformer = pyproj.Transformer.from_crs(
                self.source_crs, self.target_crs, always_xy=True, allow_ballpark=allow_ballpark
            )
        except pyproj.exceptions.ProjError as exc:
            raise InputError(
                f"no transformation from {crs_name(self.source_crs)} to "
                f"{crs_name(self.target_crs)} without a ballpark datum shift ({exc}); allow "
                "it explicitly (allow_ballpark=True / --allow-ballpark)"
            ) from None

    def __getstate__(self) -> dict:
        # rebuilt on the other side (Dask workers): PROJ objects are not shared
        return {
            "src": self.source_crs.to_wkt(),
            "dst": self.target_crs.to_wkt(),
            "ballpark": self._ballpark,
        }

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["src"], state["dst"], allow_ballpark=state["ballpark"])

    @property
    def description(self) -> str:
        """PROJ's name of the operation used."""
        return self.transformer.description

    def apply(self, points) -> np.ndarray:
        """Transform points (n, 3) (or one point (3,)).

        Parameters
        ----------
        points : array_like, shape (n, 3) or (3,)
            Coordinates in the source CRS, x/easting/longitude first.

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            Coordinates in the target CRS, x first.

        Raises
        ------
        InputError
            For points of another shape, or points PROJ cannot transform.
        """
        pts, single = _points3(points, "points")
        pyproj = _pyproj()
        try:
            out = self.transformer.transform(pts[:, 0], pts[:, 1], pts[:, 2], errcheck=True)
        except pyproj.exceptions.ProjError as exc:
            raise InputError(f"PROJ could not transform the points: {exc}") from None
        res = np.column_stack(out)
        return res[0] if single else res

    __call__ = apply

    def __repr__(self) -> str:
        return f"ProjTransform({crs_name(self.source_crs)!r} -> {crs_name(self.target_crs)!r})"


# --- CRS of the coordinates a command or a result works in -------------------------------------

#: Geocentric WGS 84: the way between a local ENU frame (``enu:lat,lon,h``) and any CRS.
GEOCENTRIC_WGS84 = "EPSG:4978"

_UNIT_ABBREV = {"metre": "m", "meter": "m", "foot": "ft", "us survey foot": "ftUS"}


def axis_units(crs) -> list[str]:
    """The unit of each axis of a CRS as photogeom labels numbers: ``m``, ``ft``, ``ftUS``,
    ``deg`` for degrees, else PROJ's name; ``m`` for every axis of a local frame
    (``enu:lat0,lon0,h0``).

    Parameters
    ----------
    crs : str, int or pyproj.CRS
        As :func:`parse_crs` takes it, or ``"enu:lat0,lon0,h0"``.

    Returns
    -------
    list of str
        One per axis, in PROJ's axis order (two for a 2D CRS).

    Raises
    ------
    InputError
        A CRS PROJ does not know.
    """
    if isinstance(crs, str) and frame_from_text(crs) is not None:
        return ["m", "m", "m"]
    return [
        "deg" if "degree" in a.unit_name.lower()
        else _UNIT_ABBREV.get(a.unit_name.lower(), a.unit_name)
        for a in parse_crs(crs).axis_info
    ]  # fmt: skip
_UNIT_WORDS = {
    "m": {"m", "metre", "meter", "metres", "meters"},
    "ft": {"ft", "foot", "feet"},
    "ftUS": {"ftus", "us-ft", "usft", "us survey foot", "us survey feet"},
}


def frame_from_text(text) -> LocalFrame | None:
    """The :class:`LocalFrame` of a CRS text ``"enu:lat0,lon0,h0"`` (degrees, metres, WGS 84).

    Parameters
    ----------
    text : str or LocalFrame or object
        The CRS text; a :class:`LocalFrame` is returned as it is.

    Returns
    -------
    LocalFrame or None
        None when ``text`` is not of that form (then it is an EPSG code, WKT, ...).

    Raises
    ------
    InputError
        For an ``enu:`` text without three numbers, or an origin that is not finite or has
        ``|lat0| > 90``.
    """
    if isinstance(text, LocalFrame):
        return text
    if not isinstance(text, str) or not text.strip().lower().startswith("enu:"):
        return None
    parts = text.strip()[4:].split(",")
    try:
        lat0, lon0, h0 = (float(p) for p in parts)
    except ValueError:
        raise InputError(
            f"{text!r}: a local frame is written enu:lat0,lon0,h0 (degrees, degrees, metres)"
        ) from None
    enu_rotation(lat0, lon0)  # validates the origin
    if not math.isfinite(h0):
        raise InputError(f"{text!r}: the origin height must be finite")
    return LocalFrame(lat0, lon0, h0)


@dataclass(frozen=True)
class CrsInfo:
    """A coordinate reference system as photogeom records it in results.

    Attributes
    ----------
    text : str
        What to store and read back: the CRS as given (``"EPSG:25832"``, WKT, a PROJ string,
        ``"enu:lat0,lon0,h0"``), stripped; the WKT of a ``pyproj.CRS`` given as an object.
    name : str
        Readable: ``"EPSG:25832 (ETRS89 / UTM zone 32N)"``.
    kind : str
        ``"projected"``, ``"geographic"``, ``"geocentric"``, ``"engineering"``,
        ``"vertical"``, ``"local ENU"`` or PROJ's type name for others.
    unit : str or None
        The unit of the first axis (``"m"``, ``"ft"``, ``"ftUS"``, ``"degree"``, ...).
    angular : bool
        Horizontal coordinates are angles (degrees): not Cartesian.
    dim : int
        Number of axes (2 or 3).
    """

    text: str
    name: str
    kind: str
    unit: str | None
    angular: bool
    dim: int

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
            ``{"crs": text, "name", "kind", "unit"}``.
        """
        return {"crs": self.text, "name": self.name, "kind": self.kind, "unit": self.unit}


def _crs_info(crs, what: str) -> CrsInfo:
    frame = frame_from_text(crs)
    if frame is not None:
        text = frame.to_text() if isinstance(crs, LocalFrame) else crs.strip()
        return CrsInfo(text, frame.describe(), "local ENU", "m", False, 3)
    if isinstance(crs, str):
        text = crs.strip()
        if not text:
            raise InputError(f"{what}: empty; give e.g. EPSG:25832, a WKT or a PROJ string")
    elif isinstance(crs, int):
        text = f"EPSG:{crs}"
    else:
        text = None
    c = parse_crs(text if text is not None else crs, what=what)
    if text is None:
        auth = c.to_authority()
        text = f"{auth[0]}:{auth[1]}" if auth else c.to_wkt()
    axes = c.axis_info
    unit_name = axes[0].unit_name if axes else None
    angular = any(
        a.unit_name.lower() in ("degree", "grad", "radian", "arc-second", "arc-minute")
        or "degree" in a.unit_name.lower()
        for a in axes[:2]
    )
    if c.is_geographic:
        kind = "geographic"
    elif c.is_projected:
        kind = "projected"
    elif c.is_geocentric:
        kind = "geocentric"
    elif c.is_vertical and not c.is_compound:
        kind = "vertical"
    elif getattr(c, "is_engineering", False):
        kind = "engineering"
    else:
        kind = c.type_name
    unit = None
    if unit_name is not None:
        unit = _UNIT_ABBREV.get(unit_name.lower(), unit_name)
    return CrsInfo(text, crs_name(c), kind, unit, angular, len(axes))


def crs_label(crs) -> str:
    """A readable name of a recorded CRS text, for reports.

    Falls back to the text itself when PROJ is not installed or does not know it.

    Parameters
    ----------
    crs : str or pyproj.CRS or LocalFrame
        The recorded CRS (``"enu:lat0,lon0,h0"`` gives the frame's description).

    Returns
    -------
    str
        Never raises for an unknown CRS.
    """
    frame = frame_from_text(crs) if isinstance(crs, str) else None
    if frame is not None:
        return frame.describe()
    try:
        return crs_name(crs)
    except Exception:  # reports never fail on a record they cannot name
        return str(crs)


def cartesian_crs(
    crs, *, what: str = "crs", dim: int = 3, unit: str | None = None, fix: str | None = None
) -> CrsInfo:
    """Validate a CRS for a computation in Cartesian coordinates and describe it.

    Parameters
    ----------
    crs : str, int, pyproj.CRS or LocalFrame
        EPSG code, WKT, PROJ string, or ``"enu:lat0,lon0,h0"`` (a local ENU frame on WGS 84).
    what : str
        The option or argument that gave it, for the messages (``"--target-crs"``).
    dim : int
        Dimension of the coordinates computed with (2 or 3).
    unit : str, optional
        A unit the caller was told the coordinates are in (``--unit``): refused when the
        CRS says another length unit.
    fix : str, optional
        How to convert the coordinates, for the message refusing a geographic CRS (default:
        ``photogeom crs convert`` to a local ENU frame or a projected CRS).

    Returns
    -------
    CrsInfo
        The CRS as recorded in results: text, readable name, kind, unit, dimension.

    Raises
    ------
    InputError
        Unknown CRS; geographic coordinates (degrees: latitude and longitude are not
        Cartesian axes, and a degree of longitude is shorter than one of latitude); a
        vertical CRS alone; a geocentric CRS for 2D coordinates; a unit that contradicts
        the CRS.
    """
    info = _crs_info(crs, what)
    if info.angular or info.kind == "geographic":
        how = fix or (
            "convert the points first, e.g. 'photogeom crs convert points.csv --from "
            f"{_short(info.text)} --to enu --origin LAT,LON,H' (a local east-north-up frame in "
            "metres) or '--to EPSG:326zz' (the UTM zone of the area), and give the new CRS"
        )
        raise InputError(
            f"{what} {info.name} is geographic (latitude and longitude in degrees): this "
            "computation needs Cartesian coordinates (a degree of longitude is shorter than "
            f"one of latitude, and angles do not mix with heights in metres); {how}"
        )
    if info.kind == "vertical":
        raise InputError(
            f"{what} {info.name} is a vertical CRS (heights only): give the CRS of all "
            "coordinates, e.g. a compound CRS EPSG:25832+5783"
        )
    if dim == 2 and info.kind in ("geocentric", "local ENU"):
        raise InputError(
            f"{what} {info.name} is a 3D Cartesian system: a 2D transformation of two of its "
            "axes is not a map of anything; use a 3D model or a projected CRS"
        )
    if (
        unit
        and info.unit in _UNIT_WORDS
        and unit.strip().lower() not in {u.lower() for u in _UNIT_WORDS[info.unit]}
    ):
        raise InputError(
            f"{what} {info.name} has coordinates in {info.unit}, but the unit given is "
            f"{unit!r}: leave the unit out (it is taken from the CRS) or give the CRS of the "
            "coordinates"
        )
    return info


def _short(text: str) -> str:
    return text if len(text) <= 40 else "CRS"


def curvature_note(info: CrsInfo, points, *, what: str = "coordinates") -> str | None:
    """A note on how far map coordinates with heights are from Cartesian.

    For a projected CRS used in 3D: the Earth-curvature drop at the largest horizontal
    distance of ``points`` from their centre (see ``docs/crs-and-clouds.md``).

    Parameters
    ----------
    info : CrsInfo
        The CRS of the points (from :func:`cartesian_crs`).
    points : array_like, shape (n, 3)
        The coordinates, in the CRS's unit (m, ft or US survey ft).
    what : str, default "coordinates"
        What the points are, for the note.

    Returns
    -------
    str or None
        None for other systems, fewer than 2 points, or a drop under 1 mm (points within
        113 m of their centre).
    """
    pts = np.asarray(points, dtype=float)
    if info.kind != "projected" or pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        return None
    c = pts[:, :2].mean(axis=0)
    d = float(np.sqrt(np.max(np.sum((pts[:, :2] - c) ** 2, axis=1))))
    if info.unit == "ft":
        d *= 0.3048
    elif info.unit == "ftUS":
        d *= 1200.0 / 3937.0
    drop = float(curvature_drop(d))
    if drop < 1e-3:
        return None
    return (
        f"{what} in {info.name}: map coordinates with heights are not Cartesian; at "
        f"{d:.4g} m from the centre of the points the Earth's surface is {drop:.2g} m below "
        "the map plane, and the map scale factor changes distances; if that matters, work in "
        "a local ENU frame (photogeom crs convert --to enu)"
    )


def points_between(points, src, dst, *, allow_ballpark: bool = False) -> np.ndarray:
    """Points from ``src`` to ``dst``.

    Either may be a local ENU frame (``"enu:lat0,lon0,h0"`` or a :class:`LocalFrame`;
    through geocentric WGS 84, EPSG:4978) or any CRS PROJ knows. x/easting/longitude first.

    Parameters
    ----------
    points : array_like, shape (n, 3) or (3,)
        Coordinates in ``src`` (deg for geographic, the CRS's unit otherwise).
    src, dst : str, int, pyproj.CRS or LocalFrame
        Source and target CRS.
    allow_ballpark : bool, default False
        Accept an approximate ("ballpark") datum shift.

    Returns
    -------
    numpy.ndarray, shape (n, 3) (or (3,) for one point (3,))
        Coordinates in ``dst``, x first (an empty copy for no points).

    Raises
    ------
    InputError
        For points of another shape, an unknown CRS, or a conversion PROJ can only do
        approximately (unless ``allow_ballpark``).
    """
    pts, single = as_points_single(points, 3, "points", finite=False)
    if not len(pts):
        return pts.copy()
    return one_or_many(points_converter(src, dst, allow_ballpark=allow_ballpark)(pts), single)


def points_converter(
    src, dst, *, allow_ballpark: bool = False
) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`points_between` from ``src`` to ``dst`` as a function of the points, for many
    calls (the blocks of a file): the PROJ operation is built once, here, instead of once
    per call (which doubled the time of PROJ on blocks of 16 000 points).

    Parameters
    ----------
    src, dst : str, LocalFrame or pyproj.CRS
        As in :func:`points_between`.
    allow_ballpark : bool
        Accept an approximate ("ballpark") datum shift.

    Returns
    -------
    callable
        ``convert(points)``: points (n, 3) in ``src`` to (n, 3) in ``dst``, the units of
        each CRS (metres in a local frame; degrees and metres in a geographic CRS). Without
        a local frame on either side, points (n, 2) are taken too.

    Raises
    ------
    InputError
        An unknown CRS, or a conversion PROJ can only do approximately (unless
        ``allow_ballpark``).
    """
    f_src, f_dst = frame_from_text(src), frame_from_text(dst)
    mid_src = GEOCENTRIC_WGS84 if f_src is not None else src
    mid_dst = GEOCENTRIC_WGS84 if f_dst is not None else dst
    if f_dst is not None:
        needs_proj = mid_src != GEOCENTRIC_WGS84
    else:
        needs_proj = (f_src is not None or src != dst) and mid_src != mid_dst
    tr = _proj_transformer(mid_src, mid_dst, allow_ballpark) if needs_proj else None
    frames = f_src is not None or f_dst is not None

    def convert(points) -> np.ndarray:
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] not in ((3,) if frames else (2, 3)):
            shape = "(n, 3)" if frames else "(n, 2) or (n, 3)"
            raise InputError(f"points must have shape {shape}, got {pts.shape}")
        if not len(pts) or (not frames and tr is None):
            return pts.copy()
        if f_src is not None:
            pts = f_src.to_ecef(pts)
        if tr is not None:
            pts = _proj_apply(tr, pts)
        return f_dst.from_ecef(pts) if f_dst is not None else pts

    return convert


@dataclass(frozen=True)
class AreaOfUse:
    """Where a projected CRS is meant to be used (its authority's bounds, degrees).

    Attributes
    ----------
    west, south, east, north : float
        Bounds in degrees of longitude and latitude; ``west > east`` when the area crosses
        the antimeridian.
    crs : str
        The CRS's readable name (:func:`crs_name`).
    """

    west: float
    south: float
    east: float
    north: float
    crs: str

    def outside(self, lon, lat) -> np.ndarray:
        """Mask of the points (degrees) outside the bounds; NaN counts as inside (not known)."""
        lon = (np.asarray(lon, dtype=float) + 180.0) % 360.0 - 180.0
        lat = np.asarray(lat, dtype=float)
        if self.west <= self.east:
            out_lon = (lon < self.west) | (lon > self.east)
        else:  # across the antimeridian
            out_lon = (lon < self.west) & (lon > self.east)
        return out_lon | (lat < self.south) | (lat > self.north)

    def describe(self) -> str:
        """``"EPSG:32632 (...): 6.0 to 12.0 deg E, 0.0 to 84.0 deg N"``."""

        def lon_text(v: float) -> str:
            return f"{abs(v):g} deg {'W' if v < 0 else 'E'}"

        def lat_text(v: float) -> str:
            return f"{abs(v):g} deg {'S' if v < 0 else 'N'}"

        return (
            f"{self.crs}: {lon_text(self.west)} to {lon_text(self.east)}, "
            f"{lat_text(self.south)} to {lat_text(self.north)}"
        )


def projected_area_of_use(crs) -> AreaOfUse | None:
    """The :class:`AreaOfUse` of a projected CRS (or a compound one with a projected
    horizontal part) as its authority records it; None for other CRSs or without a record.

    Map projections are exact everywhere PROJ computes them, but their distortion grows away
    from the area they were defined for (a transverse Mercator zone: scale error 0.1 % at
    3.5 deg from its central meridian, 1 % at 8 deg), and points far outside it usually mean
    the wrong CRS (the wrong UTM zone).
    """
    c = parse_crs(crs)
    horizontal = c.sub_crs_list[0] if c.is_compound and c.sub_crs_list else c
    if not horizontal.is_projected:
        return None
    area = horizontal.area_of_use or c.area_of_use
    if area is None:
        return None
    return AreaOfUse(
        float(area.west), float(area.south), float(area.east), float(area.north), crs_name(c)
    )
