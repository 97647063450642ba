"""The rational polynomial camera model (RPC00B): ground (lon, lat, h) <-> image (col, row).

Pixel convention: ``(col, row) = (0, 0)`` is the **centre** of the first (top-left) pixel,
columns to the right, rows down. This is the convention of the RPC00B standard and of the
``LINE_OFF`` / ``SAMP_OFF`` values of DigitalGlobe/Maxar, GeoEye/IKONOS, SkySat and GDAL's RPC
metadata; readers of formats with another origin (DIMAP v2: first pixel centre at (1, 1))
convert the offsets when reading. GDAL's RPC *transformer* reports pixel/line with the
top-left *corner* at (0, 0): GDAL ``(x, y) = (col + 0.5, row + 0.5)``.

Ground coordinates: geodetic longitude and latitude in degrees (WGS84), ellipsoidal height
in metres.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError, PrecisionWarning
from ..records import setstate_read_only
from ..validation import _caller_level, as_float64
from . import polynomial as poly
from .domain import DOMAIN_LIMIT, check_domain, longitude_difference, wrap_longitude

_FIELDS_OFF_SCALE = (
    "line_off", "samp_off", "lat_off", "long_off", "height_off",
    "line_scale", "samp_scale", "lat_scale", "long_scale", "height_scale",
)  # fmt: skip

#: GDAL metadata key of each offset/scale field.
GDAL_KEYS = {
    "line_off": "LINE_OFF",
    "samp_off": "SAMP_OFF",
    "lat_off": "LAT_OFF",
    "long_off": "LONG_OFF",
    "height_off": "HEIGHT_OFF",
    "line_scale": "LINE_SCALE",
    "samp_scale": "SAMP_SCALE",
    "lat_scale": "LAT_SCALE",
    "long_scale": "LONG_SCALE",
    "height_scale": "HEIGHT_SCALE",
}

#: GDAL metadata key of each coefficient vector.
GDAL_COEFF_KEYS = {
    "line_num": "LINE_NUM_COEFF",
    "line_den": "LINE_DEN_COEFF",
    "samp_num": "SAMP_NUM_COEFF",
    "samp_den": "SAMP_DEN_COEFF",
}


def _coeff_vector(values, name: str) -> np.ndarray:
    # a read-only copy: a view of the caller's array would change with it while the stacked
    # coefficients the model computes with (RPC._cache["C"]) would not
    arr = np.array(values, dtype=np.float64).reshape(-1)
    if arr.size != poly.N_TERMS:
        raise InputError(
            f"RPC {name}: {arr.size} coefficient(s) given, a cubic RPC polynomial has exactly "
            f"{poly.N_TERMS} (RPC00B order 1, L, P, H, LP, ...)"
        )
    if not np.all(np.isfinite(arr)):
        raise InputError(f"RPC {name}: NaN or infinite coefficient(s)")
    arr.setflags(write=False)
    return arr


def _check_denominator(arr: np.ndarray, key: str) -> None:
    if not np.any(arr):
        raise InputError(
            f"RPC {key}: all 20 coefficients are zero, so every projection divides by zero; "
            "a denominator needs a non-zero term (usually the first, 1.0)"
        )


def _check_error(value, key: str) -> float | None:
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"RPC {key}: not a number ({exc})") from exc
    if not np.isfinite(v) or v < 0:
        raise InputError(
            f"RPC {key} is {v!r}: give a finite error in metres (or leave it out / -1 in a "
            "file when unknown)"
        )
    return v


@dataclass(frozen=True, eq=False)
class DirectModel:
    """Image-to-ground rational polynomials shipped by some vendors (DIMAP ``Direct_Model``).

    ``lon = LONG_SCALE * lon_num/lon_den + LONG_OFF`` (likewise ``lat``), evaluated on the
    normalised column (in the place of L), row (in the place of P) and height, with the offsets
    and scales of the :class:`RPC` it belongs to. It approximates the inverse of the
    projection (its accuracy is the vendor's fit error); :meth:`RPC.localize` does not use it
    and inverts the projection exactly instead.

    Parameters
    ----------
    lon_num, lon_den, lat_num, lat_den : array_like, shape (20,)
        Coefficients in RPC00B term order; a denominator with all 20 coefficients zero
    raises :class:`InputError`.
    """

    lon_num: np.ndarray
    lon_den: np.ndarray
    lat_num: np.ndarray
    lat_den: np.ndarray

    def __post_init__(self) -> None:
        for name in ("lon_num", "lon_den", "lat_num", "lat_den"):
            object.__setattr__(self, name, _coeff_vector(getattr(self, name), name))
        for name in ("lon_den", "lat_den"):
            _check_denominator(getattr(self, name), f"{name.upper()}_COEFF")

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: arrays stay read-only

    @property
    def coefficients(self) -> np.ndarray:
        """``(4, 20)``: lon_num, lon_den, lat_num, lat_den."""
        return np.stack([self.lon_num, self.lon_den, self.lat_num, self.lat_den])


@dataclass(frozen=True, eq=False)
class RPC:
    """Rational polynomial camera (RPC00B) of one satellite image.

    ``row = LINE_SCALE * Num_L(P, L, H) / Den_L(P, L, H) + LINE_OFF`` and
    ``col = SAMP_SCALE * Num_S / Den_S + SAMP_OFF`` with the normalised ground coordinates
    ``L = (lon - LONG_OFF) / LONG_SCALE``, ``P = (lat - LAT_OFF) / LAT_SCALE``,
    ``H = (h - HEIGHT_OFF) / HEIGHT_SCALE`` and the 20 cubic terms of
    :mod:`photogeom.rpc.polynomial`. Pixel ``(0, 0)`` is the centre of the first pixel.

    Attributes
    ----------
    line_off, samp_off : float
        Image offsets (pixels, first pixel centre at 0).
    lat_off, long_off : float
        Ground offsets (degrees).
    height_off : float
        Height offset (metres, ellipsoidal).
    line_scale, samp_scale, lat_scale, long_scale, height_scale : float
        Scales (pixels, degrees, metres).
    line_num, line_den, samp_num, samp_den : numpy.ndarray, shape (20,)
        Coefficients in RPC00B term order.
    err_bias, err_rand : float or None
        Vendor's bias and random error (metres per horizontal axis) when the file gives them.
        ``err_bias`` describes the model before any bias compensation: a corrected model
        written to a file (:meth:`with_correction_folded`, or a re-fit) has none.
    direct : DirectModel or None
        Vendor's image-to-ground polynomials (DIMAP) when present.
    correction : numpy.ndarray or None, shape (2, 3)
        Image-space correction from bias compensation: ``[[a1, a2, a0], [b1, b2, b0]]``,
        applied as ``col' = col + a0 + a1 col + a2 row``, ``row' = row + b0 + b1 col + b2 row``
        to the RPC's own ``(col, row)``.
    image_size : (int, int) or None
        ``(columns, rows)`` of the image when the file gives it.
    source : str
        Format the model was read from (or how it was made).
    notes : tuple of str
        Conversions made while reading (e.g. of the pixel origin).
    """

    line_off: float
    samp_off: float
    lat_off: float
    long_off: float
    height_off: float
    line_scale: float
    samp_scale: float
    lat_scale: float
    long_scale: float
    height_scale: float
    line_num: np.ndarray
    line_den: np.ndarray
    samp_num: np.ndarray
    samp_den: np.ndarray
    err_bias: float | None = None
    err_rand: float | None = None
    direct: DirectModel | None = None
    correction: np.ndarray | None = None
    image_size: tuple[int, int] | None = None
    source: str = ""
    notes: tuple[str, ...] = ()
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in _FIELDS_OFF_SCALE:
            try:
                v = float(getattr(self, name))
            except (TypeError, ValueError) as exc:
                raise InputError(f"RPC {GDAL_KEYS[name]}: not a number ({exc})") from exc
            if not np.isfinite(v):
                raise InputError(f"RPC {GDAL_KEYS[name]}: NaN or infinite value")
            if name.endswith("_scale") and v == 0.0:
                raise InputError(f"RPC {GDAL_KEYS[name]} is 0: a scale must be non-zero")
            object.__setattr__(self, name, v)
        for name, key in GDAL_COEFF_KEYS.items():
            object.__setattr__(self, name, _coeff_vector(getattr(self, name), key))
        _check_denominator(self.line_den, "LINE_DEN_COEFF")
        _check_denominator(self.samp_den, "SAMP_DEN_COEFF")
        object.__setattr__(self, "err_bias", _check_error(self.err_bias, "ERR_BIAS"))
        object.__setattr__(self, "err_rand", _check_error(self.err_rand, "ERR_RAND"))
        if self.correction is not None:
            D = np.array(self.correction, dtype=np.float64)  # a copy: made read-only below
            if D.shape != (2, 3) or not np.all(np.isfinite(D)):
                raise InputError("RPC correction: expected a finite (2, 3) array")
            if abs(np.linalg.det(np.eye(2) + D[:, :2])) < 1e-12:
                raise InputError("RPC correction: the affine part is singular")
            D.setflags(write=False)
            object.__setattr__(self, "correction", D)
        if self.image_size is not None:
            try:
                w, h = (int(v) for v in self.image_size)
            except (TypeError, ValueError, OverflowError) as exc:
                raise InputError(
                    f"RPC image_size must be two positive integers, got {self.image_size!r}"
                ) from exc
            if w <= 0 or h <= 0:
                raise InputError(f"RPC image_size must be positive, got {self.image_size}")
            object.__setattr__(self, "image_size", (w, h))
        object.__setattr__(self, "notes", tuple(self.notes))
        C = np.stack([self.samp_num, self.samp_den, self.line_num, self.line_den])
        C.setflags(write=False)
        self._cache["C"] = C

    def __setstate__(self, state: dict) -> None:
        # pickle / deepcopy rebuild arrays writable: make them read-only again, the stacked
        # coefficients of the cache too (a changed coefficient would leave them stale)
        setstate_read_only(self, state)
        for value in self._cache.values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False

    # --- construction and files --------------------------------------------------------------

    @classmethod
    def from_file(cls, path: str | Path) -> RPC:
        """Read an RPC file; the format is detected from the content.

        Formats: IKONOS-style ``_RPC.TXT`` (numbered keys), ``KEY: value`` text with
        coefficient lists, DigitalGlobe ``.RPB``, DIMAP XML (Pleiades/SPOT), DigitalGlobe/Maxar
        XML with an ``RPB`` block (WorldView), GeoTIFF RPC tags (needs the ``geotiff`` extra).

        Parameters
        ----------
        path : str or pathlib.Path
            The file.

        Returns
        -------
        RPC

        Raises
        ------
        FileFormatError
            As :func:`photogeom.rpc.read_rpc`.
        """
        from .readers import read_rpc

        return read_rpc(path)

    @classmethod
    def from_dict(cls, d: Mapping[str, object], source: str = "dictionary") -> RPC:
        """Build from GDAL RPC metadata keys (``LINE_OFF``, ..., ``LINE_NUM_COEFF``, ...).

        Values may be numbers, strings, lists, or space-separated strings of 20 coefficients
        (as in GDAL's / rasterio's ``RPC`` metadata domain).

        Parameters
        ----------
        d : Mapping
            The keys and values (``IMAGE_CORRECTION`` as written by :meth:`to_dict` accepted).
        source : str, default "dictionary"
            Name of the data in error messages and in :attr:`source`.

        Returns
        -------
        RPC

        Raises
        ------
        FileFormatError
            For a missing key (named), a coefficient vector without 20 values, or a value that
            is not a number.
        """
        from .readers import rpc_from_mapping

        return rpc_from_mapping(d, source=source)

    def to_dict(self) -> dict[str, object]:
        """GDAL RPC metadata keys -> values (floats and lists of 20 floats).

        A correction that folds into the offsets (shift, per-axis scale) is folded; any other
        is given as ``IMAGE_CORRECTION`` (``[[a1, a2, a0], [b1, b2, b0]]``, read back by
        :meth:`from_dict`; not a GDAL key).

        Returns
        -------
        dict
            Offsets/scales (px, deg, m), the four ``*_COEFF`` lists, ``ERR_BIAS``/``ERR_RAND``
            (m) when known, the vendor's direct model and ``IMAGE_CORRECTION`` when present.
        """
        if self.correction is not None and self.correction_is_foldable:
            return self.with_correction_folded().to_dict()
        out: dict[str, object] = {GDAL_KEYS[k]: getattr(self, k) for k in _FIELDS_OFF_SCALE}
        for k, key in GDAL_COEFF_KEYS.items():
            out[key] = [float(v) for v in getattr(self, k)]
        if self.err_bias is not None:
            out["ERR_BIAS"] = self.err_bias
        if self.err_rand is not None:
            out["ERR_RAND"] = self.err_rand
        if self.direct is not None:
            for name in ("lon_num", "lon_den", "lat_num", "lat_den"):
                out[f"{name.upper()}_COEFF"] = [float(v) for v in getattr(self.direct, name)]
        if self.correction is not None:
            out["IMAGE_CORRECTION"] = self.correction.tolist()
        return out

    def to_gdal_metadata(self) -> dict[str, str]:
        """GDAL RPC metadata as strings (for ``rasterio``'s ``update_tags(ns="RPC", ...)``).

        Returns
        -------
        dict of str to str
            GDAL keys; coefficient vectors as 20 space-separated numbers.

        Raises
        ------
        InputError
            For a correction with cross terms (GDAL has no place for it; re-fit the corrected
            model first).
        """
        d = self.with_correction_folded().to_dict()
        keys = (*GDAL_KEYS.values(), *GDAL_COEFF_KEYS.values(), "ERR_BIAS", "ERR_RAND")
        return {
            k: (" ".join(repr(float(x)) for x in v) if isinstance(v, list) else repr(float(v)))
            for k, v in d.items()
            if k in keys
        }

    def write(self, path: str | Path, style: str = "ikonos") -> Path:
        """Write as text (see :func:`photogeom.rpc.writer.write_rpc`).

        Parameters
        ----------
        path : str or pathlib.Path
            Output file; replaced atomically.
        style : {"ikonos", "lists"}, default "ikonos"
            Text layout, as in :func:`~photogeom.rpc.writer.write_rpc`.

        Returns
        -------
        pathlib.Path
            The file written.

        Raises
        ------
        InputError
            Unknown style, or an image-space correction with cross terms.
        """
        from .writer import write_rpc

        return write_rpc(self, path, style=style)

    # --- basic properties ----------------------------------------------------------------------

    @property
    def coefficients(self) -> np.ndarray:
        """``(4, 20)``: samp_num, samp_den, line_num, line_den (read-only)."""
        return self._cache["C"]

    @property
    def image_bounds(self) -> tuple[float, float, float, float]:
        """``(col_min, col_max, row_min, row_max)`` of pixel centres (pixels).

        From ``image_size`` when known, otherwise the normalised domain ``OFF -+ SCALE``.
        """
        if self.image_size is not None:
            return (0.0, self.image_size[0] - 1.0, 0.0, self.image_size[1] - 1.0)
        sa, la = abs(self.samp_scale), abs(self.line_scale)
        return (self.samp_off - sa, self.samp_off + sa, self.line_off - la, self.line_off + la)

    @property
    def height_range(self) -> tuple[float, float]:
        """``(HEIGHT_OFF - HEIGHT_SCALE, HEIGHT_OFF + HEIGHT_SCALE)`` in metres."""
        s = abs(self.height_scale)
        return (self.height_off - s, self.height_off + s)

    def same_as(self, other: RPC, rtol: float = 0.0) -> bool:
        """True when offsets, scales and all coefficients agree (exactly for ``rtol=0``).

        The direct model and the image-space correction are compared too.

        Parameters
        ----------
        other : RPC
            The model to compare with.
        rtol : float, default 0.0
            Relative tolerance per value.

        Returns
        -------
        bool
        """
        for name in _FIELDS_OFF_SCALE:
            a, b = getattr(self, name), getattr(other, name)
            if abs(a - b) > rtol * max(abs(a), abs(b)):
                return False
        if not np.allclose(self.coefficients, other.coefficients, rtol=rtol, atol=0.0):
            return False
        if (self.direct is None) != (other.direct is None):
            return False
        if self.direct is not None and not np.allclose(
            self.direct.coefficients, other.direct.coefficients, rtol=rtol, atol=0.0
        ):
            return False
        ca = np.zeros((2, 3)) if self.correction is None else self.correction
        cb = np.zeros((2, 3)) if other.correction is None else other.correction
        return bool(np.allclose(ca, cb, rtol=rtol, atol=0.0))

    # --- normalisation -------------------------------------------------------------------------

    def normalize_ground(self, lon, lat, h) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(L, P, H)`` normalised ground coordinates (arrays of the broadcast shape).

        Parameters
        ----------
        lon, lat : float or array_like
            Longitude and latitude, deg (longitude differences taken across the antimeridian).
        h : float or array_like
            Ellipsoidal height, m.

        Returns
        -------
        L, P, H : numpy.ndarray
            Unitless, of the broadcast shape of the inputs.
        """
        lon, lat, h = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (lon, lat, h)))
        return (
            longitude_difference(lon, self.long_off) / self.long_scale,
            (lat - self.lat_off) / self.lat_scale,
            (h - self.height_off) / self.height_scale,
        )

    def normalize_image(self, col, row) -> tuple[np.ndarray, np.ndarray]:
        """Normalised image coordinates of the RPC itself (before any correction).

        Parameters
        ----------
        col, row : float or array_like
            Pixel coordinates (px, (0, 0) = centre of the first pixel).

        Returns
        -------
        col_n, row_n : numpy.ndarray
            Unitless.
        """
        col = np.asarray(col, dtype=np.float64)
        row = np.asarray(row, dtype=np.float64)
        return (col - self.samp_off) / self.samp_scale, (row - self.line_off) / self.line_scale

    # --- projection ---------------------------------------------------------------------------

    def project(self, lon, lat, h, *, domain_limit: float | None = DOMAIN_LIMIT):
        """Project ground points into the image.

        Parameters
        ----------
        lon, lat : array_like
            Geodetic longitude and latitude (degrees); broadcast together with ``h``.
        h : array_like
            Ellipsoidal height (metres). Required: an RPC has no image position without one.
        domain_limit : float or None
            Warn (:class:`~photogeom.rpc.domain.RPCExtrapolationWarning`) when a normalised
            ground coordinate exceeds this in absolute value; ``None`` disables the check.

        Returns
        -------
        col, row : numpy.ndarray
            Pixel coordinates (first pixel centre at (0, 0)), of the broadcast shape.
        """
        lon, lat, h, shape = _prepare(("lon", lon), ("lat", lat), ("h", h), what="RPC projection")
        col, row = self._project_flat(lon, lat, h, domain_limit)
        return _shaped(col, shape), _shaped(row, shape)

    def _project_flat(self, lon, lat, h, domain_limit=DOMAIN_LIMIT):
        L = longitude_difference(lon, self.long_off) / self.long_scale
        P = (lat - self.lat_off) / self.lat_scale
        H = (h - self.height_off) / self.height_scale
        check_domain({"longitude": L, "latitude": P, "height": H}, domain_limit, "RPC projection")
        V = poly.evaluate(self.coefficients, L, P, H)
        col = V[0]
        np.divide(col, V[1], out=col)
        col *= self.samp_scale
        col += self.samp_off
        row = V[2]
        np.divide(row, V[3], out=row)
        row *= self.line_scale
        row += self.line_off
        if self.correction is not None:
            col, row = self._apply_correction(col, row)
        return col, row

    def _apply_correction(self, col, row):
        D = self.correction
        return (
            col + D[0, 2] + D[0, 0] * col + D[0, 1] * row,
            row + D[1, 2] + D[1, 0] * col + D[1, 1] * row,
        )

    def _undo_correction(self, col, row):
        D = self.correction
        A = np.eye(2) + D[:, :2]
        Ai = np.linalg.inv(A)
        c0, r0 = col - D[0, 2], row - D[1, 2]
        return Ai[0, 0] * c0 + Ai[0, 1] * r0, Ai[1, 0] * c0 + Ai[1, 1] * r0

    def jacobian(self, lon, lat, h) -> np.ndarray:
        """Partial derivatives of ``(col, row)`` w.r.t. ``(lon, lat, h)``.

        Parameters
        ----------
        lon, lat : float or array_like
            Longitude and latitude, deg.
        h : float or array_like
            Ellipsoidal height, m (broadcast with ``lon``, ``lat``).

        Returns
        -------
        numpy.ndarray, shape (n, 2, 3)
            One row per broadcast point (n = 1 for scalars); rows col, row; columns d/dlon
            (px/deg), d/dlat (px/deg), d/dh (px/m).

        Raises
        ------
        InputError
            For a missing ``h``, non-finite values or shapes that do not broadcast.
        """
        lon, lat, h, _ = _prepare(("lon", lon), ("lat", lat), ("h", h), what="RPC Jacobian")
        return self._jacobian_flat(lon, lat, h)[2]

    def _jacobian_flat(self, lon, lat, h):
        """Image coordinates and their Jacobian (n, 2, 3) at flat inputs."""
        L = longitude_difference(lon, self.long_off) / self.long_scale
        P = (lat - self.lat_off) / self.lat_scale
        H = (h - self.height_off) / self.height_scale
        V, dV = poly.evaluate_with_derivatives(self.coefficients, L, P, H, wrt="LPH")
        n = L.size
        J = np.empty((n, 2, 3))
        s = V[0] / V[1]
        li = V[2] / V[3]
        ground_scale = (self.long_scale, self.lat_scale, self.height_scale)
        for j, c in enumerate("LPH"):
            d = dV[c]
            J[:, 0, j] = (d[0] - s * d[1]) / V[1] * (self.samp_scale / ground_scale[j])
            J[:, 1, j] = (d[2] - li * d[3]) / V[3] * (self.line_scale / ground_scale[j])
        col = s * self.samp_scale + self.samp_off
        row = li * self.line_scale + self.line_off
        if self.correction is not None:
            col, row = self._apply_correction(col, row)
            A = np.eye(2) + self.correction[:, :2]
            J = np.einsum("ij,njk->nik", A, J)
        return col, row, J

    # --- localisation -------------------------------------------------------------------------

    def localize(
        self,
        col,
        row,
        h,
        *,
        tol: float = 1e-6,
        max_iter: int = 20,
        on_failure: str = "nan",
        full_output: bool = False,
        domain_limit: float | None = DOMAIN_LIMIT,
    ):
        """Ground position of image points at given heights (inverse of :meth:`project`).

        Newton iteration on the exact projection, started from an approximate inverse (a
        cubic polynomial fitted once per model on a grid of points solved by continuation from
        the image centre); points that do not converge from there are re-solved by continuation.

        Parameters
        ----------
        col, row : array_like
            Pixel coordinates (first pixel centre at (0, 0)).
        h : array_like
            Ellipsoidal heights (metres), broadcast with ``col`` and ``row``.
        tol : float
            Convergence tolerance (pixels): the projection of the result reproduces
            ``(col, row)`` to within ``tol`` in both coordinates.
        max_iter : int
            Newton iterations per point (per stage).
        on_failure : {"nan", "raise"}
            Non-converged points: NaN with a :class:`~photogeom.rpc.domain.LocalizationWarning`
            (``"nan"``), or :class:`~photogeom.errors.ConvergenceError` (``"raise"``; the
            :class:`~photogeom.rpc.localization.LocalizationResult` is attached as ``result``).
        full_output : bool
            Return a :class:`~photogeom.rpc.localization.LocalizationResult` (lon, lat, status
            per point, iterations, residuals) instead of ``(lon, lat)``; no warning then.
        domain_limit : float or None
            Warn when normalised image coordinates or heights exceed this.

        Returns
        -------
        (lon, lat) : numpy.ndarray (degrees), or LocalizationResult
        """
        from .localization import localize

        return localize(
            self,
            col,
            row,
            h,
            tol=tol,
            max_iter=max_iter,
            on_failure=on_failure,
            full_output=full_output,
            domain_limit=domain_limit,
        )

    def localize_direct(self, col, row, h):
        """Evaluate the vendor's image-to-ground polynomials (:class:`DirectModel`).

        Approximate (the vendor's fit error); only for files that ship them (DIMAP).

        Parameters
        ----------
        col, row : float or array_like
            Pixel coordinates (px, (0, 0) = centre of the first pixel).
        h : float or array_like
            Ellipsoidal height, m (broadcast with ``col``, ``row``).

        Returns
        -------
        lon, lat : float or numpy.ndarray
            Degrees, of the broadcast shape of the inputs.

        Raises
        ------
        InputError
            When the RPC has no image-to-ground polynomials (use :meth:`localize`), ``h`` is
            missing, or the inputs are not finite or do not broadcast.
        """
        if self.direct is None:
            raise InputError(
                f"this RPC ({self.source or 'no source'}) has no image-to-ground polynomials; "
                "use localize() (exact inversion of the projection)"
            )
        col, row, h, shape = _prepare(("col", col), ("row", row), ("h", h), what="RPC localisation")
        if self.correction is not None:
            col, row = self._undo_correction(col, row)
        cn = (col - self.samp_off) / self.samp_scale
        rn = (row - self.line_off) / self.line_scale
        hn = (h - self.height_off) / self.height_scale
        V = poly.evaluate(self.direct.coefficients, cn, rn, hn)
        lon = wrap_longitude(V[0] / V[1] * self.long_scale + self.long_off)
        lat = V[2] / V[3] * self.lat_scale + self.lat_off
        return _shaped(lon, shape), _shaped(lat, shape)

    # --- corrections --------------------------------------------------------------------------

    def with_correction(self, correction) -> RPC:
        """A copy whose projection is followed by an image-space affine correction.

        ``correction`` is composed with an existing correction (the new one applied last).

        Parameters
        ----------
        correction : array_like, shape (2, 3)
            ``[[a1, a2, a0], [b1, b2, b0]]`` (see the class docstring); ``a0, b0`` in px.

        Returns
        -------
        RPC

        Raises
        ------
        InputError
            For another shape.
        """
        D = np.asarray(correction, dtype=np.float64)
        if D.shape != (2, 3):
            raise InputError(f"correction: expected shape (2, 3), got {D.shape}")
        if self.correction is not None:
            A1 = np.eye(2) + self.correction[:, :2]
            t1 = self.correction[:, 2]
            A2 = np.eye(2) + D[:, :2]
            A = A2 @ A1
            t = A2 @ t1 + D[:, 2]
            D = np.column_stack([A - np.eye(2), t])
        return _replace(self, correction=D)

    @property
    def uncorrected(self) -> RPC:
        """The model without its image-space correction."""
        return _replace(self, correction=None)

    @property
    def correction_is_foldable(self) -> bool:
        """True when the correction can be written into offsets and scales exactly.

        That is the case for a shift and for per-axis scale changes (no cross terms:
        ``a2 = b1 = 0``).
        """
        return self.correction is None or (
            self.correction[0, 1] == 0.0 and self.correction[1, 0] == 0.0
        )

    def with_correction_folded(self) -> RPC:
        """An equivalent RPC with the correction written into SAMP/LINE offsets and scales.

        Exact for shifts and per-axis scales. The vendor's ``err_bias`` (m) described the bias
        the correction removes, so the folded model has none (unknown); ``err_rand`` is kept.

        Returns
        -------
        RPC
            ``self`` when there is no correction.

        Raises
        ------
        InputError
            For cross terms (re-fit the corrected model with :func:`photogeom.rpc.fitting.fit_rpc`
            instead).
        """
        if self.correction is None:
            return self
        notes = (*self.notes, "image-space correction folded into SAMP/LINE offsets and scales")
        if self.err_bias is not None:
            notes = (
                *notes,
                f"vendor ERR_BIAS ({self.err_bias:g} m) dropped: it described the bias that the "
                "image-space correction removes",
            )
        if not self.correction_is_foldable:
            raise InputError(
                "this RPC carries an image-space correction with cross terms (col depends on "
                "row or row on col); it cannot be written into RPC00B offsets exactly. Re-fit "
                "the corrected model first (photogeom.rpc.fit_rpc(rpc, bounds); 'photogeom rpc "
                "refine --output' does this)"
            )
        D = self.correction
        ks, kl = 1.0 + D[0, 0], 1.0 + D[1, 1]
        return _replace(
            self,
            samp_off=ks * self.samp_off + D[0, 2],
            samp_scale=ks * self.samp_scale,
            line_off=kl * self.line_off + D[1, 2],
            line_scale=kl * self.line_scale,
            correction=None,
            err_bias=None,
            notes=notes,
        )

    # --- description ----------------------------------------------------------------------------

    def footprint(self, h: float | None = None) -> np.ndarray:
        """Ground positions of the four image corners at height ``h``.

        Parameters
        ----------
        h : float, optional
            Ellipsoidal height, m; default ``HEIGHT_OFF``.

        Returns
        -------
        numpy.ndarray, shape (4, 2)
            ``(lon, lat)`` in deg of top-left, top-right, bottom-right, bottom-left.
        """
        c0, c1, r0, r1 = self.image_bounds
        hh = self.height_off if h is None else float(h)
        lon, lat = self.localize([c0, c1, c1, c0], [r0, r0, r1, r1], hh, domain_limit=None)
        return np.column_stack([lon, lat])

    def summary(self) -> str:
        """Plain-text description: offsets, scales, image and ground extent.

        Returns
        -------
        str
        """
        c0, c1, r0, r1 = self.image_bounds
        lines = [f"RPC00B model ({self.source or 'unknown source'})"]
        lines.append("  pixel convention: (0, 0) = centre of the first pixel; col right, row down")
        lines.append(
            f"  image offset/scale: col {self.samp_off:g} / {self.samp_scale:g} px, "
            f"row {self.line_off:g} / {self.line_scale:g} px"
        )
        lines.append(
            f"  ground offset/scale: lon {self.long_off:.8g} / {self.long_scale:.6g} deg, "
            f"lat {self.lat_off:.8g} / {self.lat_scale:.6g} deg, "
            f"h {self.height_off:g} / {self.height_scale:g} m"
        )
        size = (
            f"{self.image_size[0]} x {self.image_size[1]} px"
            if self.image_size
            else "not given (domain from offsets/scales)"
        )
        lines.append(f"  image size: {size}; cols {c0:g}..{c1:g}, rows {r0:g}..{r1:g}")
        if self.err_bias is not None or self.err_rand is not None:
            bias, rand = (
                "not given" if v is None else f"{v:g} m" for v in (self.err_bias, self.err_rand)
            )
            lines.append(f"  vendor errors: bias {bias}, random {rand}")
        if self.direct is not None:
            lines.append("  image-to-ground polynomials: present (vendor's approximation)")
        if self.correction is not None:
            D = self.correction
            lines.append(
                "  image-space correction: "
                f"dcol = {D[0, 2]:.4g} + {D[0, 0]:.3g} col + {D[0, 1]:.3g} row; "
                f"drow = {D[1, 2]:.4g} + {D[1, 0]:.3g} col + {D[1, 1]:.3g} row (px)"
            )
        for note in self.notes:
            lines.append(f"  note: {note}")
        return "\n".join(lines)


def _replace(rpc: RPC, **changes) -> RPC:
    """``dataclasses.replace`` that leaves the cache behind."""
    return replace(rpc, **changes)


#: Rounding of an input (degrees for lon/lat, metres for h, pixels for col/row) above which a
#: float16/float32 array is reported: about 1 cm on the ground, 1/1000 pixel.
LOW_PRECISION_LIMIT = {"lon": 1e-7, "lat": 1e-7, "h": 1e-3, "col": 1e-3, "row": 1e-3}


def _check_low_precision(value, arr: np.ndarray, name: str, what: str) -> None:
    """Warn (:class:`~photogeom.errors.PrecisionWarning`) when a float16/float32 input was
    rounded more coarsely than :data:`LOW_PRECISION_LIMIT` before photogeom received it."""
    dtype = getattr(value, "dtype", None)
    if dtype is None or dtype.kind != "f" or dtype.itemsize >= 8 or arr.size == 0:
        return
    finite = np.abs(arr[np.isfinite(arr)])
    if finite.size == 0:
        return
    big = float(finite.max())
    res = float(np.spacing(dtype.type(big)))
    unit = {"lon": "deg", "lat": "deg", "h": "m"}.get(name, "px")
    if res > LOW_PRECISION_LIMIT[name]:
        warnings.warn(
            f"{what}: {name} in {dtype.name} up to {big:.6g} {unit} has a resolution of "
            f"{res:.3g} {unit}: the values were rounded to that before photogeom (which "
            "computes in float64) received them. Pass float64 values",
            PrecisionWarning,
            stacklevel=_caller_level(),
        )


def _prepare(*named, what: str):
    """Broadcast named array inputs, check them, return flat float arrays and the shape."""
    arrays = []
    for name, v in named:
        if v is None:
            if name == "h":
                raise InputError(
                    f"{what}: no height given; an RPC maps a ground point only with its "
                    "ellipsoidal height h (metres). Pass h (e.g. from a DEM, or HEIGHT_OFF as "
                    "a rough value)"
                )
            raise InputError(f"{what}: {name} is missing")
        # masked values and imaginary parts are refused, not used (as everywhere in photogeom)
        arr = as_float64(v, f"{what}: {name}", coordinates=False)
        _check_low_precision(v, arr, name, what)
        arrays.append(arr)
    try:
        b = np.broadcast_arrays(*arrays)
    except ValueError as exc:
        shapes = ", ".join(f"{n} {a.shape}" for (n, _), a in zip(named, arrays))
        raise InputError(f"{what}: the shapes do not broadcast together ({shapes})") from exc
    shape = b[0].shape
    flat = []
    for (name, _), a in zip(named, b):
        a = np.ascontiguousarray(a).reshape(-1)
        if not np.all(np.isfinite(a)):
            bad = int(np.count_nonzero(~np.isfinite(a)))
            extra = (
                " (a height without a value: every point needs its height)" if name == "h" else ""
            )
            raise InputError(f"{what}: {bad} NaN or infinite value(s) in {name}{extra}")
        flat.append(a)
    return (*flat, shape)


def _shaped(a: np.ndarray, shape: tuple) -> np.ndarray:
    out = a.reshape(shape)
    return out[()] if shape == () else out
