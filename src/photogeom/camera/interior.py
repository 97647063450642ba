"""Interior orientation of a frame camera: principal distance, principal point, distortion.

Image coordinate system (01-conventions.md, section 1): right-handed, x to the right,
y up, origin at the fiducial centre (film) or at a declared pixel position (digital);
a point is ``(x - x0, y - y0, -f)`` in the 3D camera system. All lengths of one interior
orientation share one declared unit: ``"mm"`` or ``"px"``.

The image coordinates of a camera-frame point ``p = M (X - X0) = (u, v, w)`` are

    xn = -u / w,  yn = v / w                     (normalised, Metashape axes: y down)
    (xd, yd) = Brown distortion of (xn, yn)      (identity without distortion)
    x = x0 + (f + b1) xd + b2 yd
    y = y0 - f yd

which, without distortion and with b1 = b2 = 0, is the collinearity equation
``x - x0 = -f u / w``, ``y - y0 = -f v / w``. ``b1`` (affinity: the x principal distance is
``f + b1``) and ``b2`` (shear) are Metashape's B1, B2 expressed in the unit of the
orientation; a digital camera with ``fx != fy`` has ``f = fy`` and ``b1 = fx - fy``.

Pixel coordinates: column to the right, row down, the top-left pixel's *centre* is (0, 0)
(``pixel_origin="center"``, the default) or its top-left *corner* is (0, 0)
(``pixel_origin="corner"``, Metashape's convention). With ``origin_px = (col_o, row_o)``
the pixel position of the image-system origin and ``(dx, dy)`` the pixel size in the unit
of the orientation (1 for ``"px"``):

    x = dx (col - col_o),   y = -dy (row - row_o)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..validation import as_finite_scalar, as_points, as_points_single, one_or_many
from .distortion import BrownDistortion

_UNIT_ALIASES = {"mm": "mm", "px": "px", "pixel": "px", "pixels": "px", "pix": "px"}
PIXEL_ORIGINS = ("center", "corner")


def normalize_unit(unit: str) -> str:
    """Canonical image unit (``"mm"`` or ``"px"``)."""
    key = str(unit).strip().lower()
    if key not in _UNIT_ALIASES:
        raise InputError(f"unknown image unit {unit!r}; use 'mm' (film/metric) or 'px' (pixels)")
    return _UNIT_ALIASES[key]


def _pixel_shift(pixel_origin: str) -> float:
    """Offset added to centre-convention pixel coordinates to get ``pixel_origin`` ones."""
    if pixel_origin == "center":
        return 0.0
    if pixel_origin == "corner":
        return 0.5
    raise InputError(
        f"unknown pixel_origin {pixel_origin!r}; use 'center' (top-left pixel centre = (0, 0)) "
        "or 'corner' (top-left pixel corner = (0, 0), pixel centres at half-integers)"
    )


@dataclass(frozen=True)
class InteriorOrientation:
    """Interior orientation of a frame camera.

    Parameters
    ----------
    f : float
        Principal distance (camera constant) in ``unit``; > 0. With ``b1 != 0`` this is
        the y principal distance and ``f + b1`` the x one.
    x0, y0 : float
        Principal point in the image coordinate system (right-handed, y up), in ``unit``.
    unit : {"mm", "px"}
        The one unit of every length of this orientation and of the image coordinates it
        produces.
    b1, b2 : float
        Affinity and shear (Metashape's B1, B2) in ``unit``; see the module docstring.
    distortion : BrownDistortion, optional
        Radial/tangential lens distortion (dimensionless coefficients).
    pixel_size : float or (float, float), optional
        Size of one pixel (width, height) in millimetres; needed to convert between pixels
        and an orientation in ``"mm"``.
    origin_px : (float, float), optional
        Pixel position ``(col, row)`` of the image-system origin, centre convention (the
        top-left pixel's centre is (0, 0)). Needed for pixel conversions.
    image_size : (int, int), optional
        Image width and height in pixels (informational; used by Metashape conversion).
    """

    f: float
    x0: float = 0.0
    y0: float = 0.0
    unit: str = "mm"
    b1: float = 0.0
    b2: float = 0.0
    distortion: BrownDistortion | None = None
    pixel_size: tuple[float, float] | None = None
    origin_px: tuple[float, float] | None = None
    image_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("f", "x0", "y0", "b1", "b2"):
            set_(self, name, as_finite_scalar(getattr(self, name), name))
        if self.f <= 0:
            raise InputError(f"principal distance f must be > 0 (got {self.f:g})")
        if self.f + self.b1 <= 0:
            raise InputError(f"x principal distance f + b1 must be > 0 (got {self.f + self.b1:g})")
        set_(self, "unit", normalize_unit(self.unit))
        if self.distortion is not None:
            if isinstance(self.distortion, Mapping):
                set_(self, "distortion", BrownDistortion.from_dict(dict(self.distortion)))
            elif not isinstance(self.distortion, BrownDistortion):
                raise InputError("distortion must be a BrownDistortion (or a dict of its terms)")
            if self.distortion.is_zero:
                set_(self, "distortion", None)
        if self.pixel_size is not None:
            ps = np.broadcast_to(np.asarray(self.pixel_size, dtype=float).reshape(-1), (2,))
            if not np.all(np.isfinite(ps)) or np.any(ps <= 0):
                raise InputError(f"pixel_size must be > 0 mm (got {self.pixel_size!r})")
            set_(self, "pixel_size", (float(ps[0]), float(ps[1])))
        if self.origin_px is not None:
            o = np.asarray(self.origin_px, dtype=float).reshape(-1)
            if o.size != 2 or not np.all(np.isfinite(o)):
                raise InputError(
                    f"origin_px must be two finite numbers (col, row), got {self.origin_px!r}"
                )
            set_(self, "origin_px", (float(o[0]), float(o[1])))
        if self.image_size is not None:
            s = tuple(int(v) for v in self.image_size)
            if len(s) != 2 or min(s) <= 0:
                raise InputError(
                    f"image_size must be (width, height) > 0 pixels, got {self.image_size!r}"
                )
            set_(self, "image_size", s)

    # --- constructors ----------------------------------------------------------------------

    @classmethod
    def digital(
        cls,
        f: float,
        col_pp: float,
        row_pp: float,
        *,
        fy: float | None = None,
        unit: str = "px",
        pixel_size=None,
        b2: float = 0.0,
        distortion: BrownDistortion | None = None,
        image_size=None,
        pixel_origin: str = "center",
    ) -> InteriorOrientation:
        """Interior orientation of a digital camera with the principal point given in pixels.

        The image-system origin is put at the principal point (01-conventions.md:
        ``x = d (col - col_pp)``, ``y = -d (row - row_pp)``), so ``x0 = y0 = 0``.

        Parameters
        ----------
        f : float
            Principal distance in ``unit`` (the x one when ``fy`` is given).
        col_pp, row_pp : float
            Principal point in pixels (``pixel_origin`` convention).
        fy : float, optional
            Principal distance along y when it differs from ``f`` (non-square pixels).
        unit : {"px", "mm"}
            Unit of ``f`` and of the image coordinates; ``"mm"`` needs ``pixel_size``.
        pixel_size : float or (float, float), optional
            Pixel size in millimetres.
        b2, distortion, image_size
            As in the class.
        pixel_origin : {"center", "corner"}
            Convention of ``col_pp, row_pp``.

        Returns
        -------
        InteriorOrientation
            With ``x0 = y0 = 0`` and ``origin_px`` at the principal point.
        """
        unit = normalize_unit(unit)
        if unit == "mm" and pixel_size is None:
            raise InputError("a digital camera in 'mm' needs pixel_size (mm per pixel)")
        shift = _pixel_shift(pixel_origin)
        fy_ = f if fy is None else fy
        return cls(
            f=fy_,
            x0=0.0,
            y0=0.0,
            unit=unit,
            b1=float(f) - float(fy_),
            b2=b2,
            distortion=distortion,
            pixel_size=pixel_size,
            origin_px=(float(col_pp) - shift, float(row_pp) - shift),
            image_size=image_size,
        )

    @classmethod
    def from_focal_lengths(cls, fx: float, fy: float, x0: float = 0.0, y0: float = 0.0, **kw):
        """Orientation with different principal distances along x and y (``b1 = fx - fy``).

        Parameters
        ----------
        fx, fy : float
            Principal distances along x and y, in the orientation's unit.
        x0, y0 : float, default 0.0
            Principal point, same unit.
        **kw
            Other fields of :class:`InteriorOrientation` (``unit``, ``b2``, ``distortion``, ...).

        Returns
        -------
        InteriorOrientation
            With ``f = fy`` and ``b1 = fx - fy``.
        """
        return cls(f=fy, x0=x0, y0=y0, b1=float(fx) - float(fy), **kw)

    # --- derived -----------------------------------------------------------------------------

    @property
    def fx(self) -> float:
        """Principal distance along x (``f + b1``)."""
        return self.f + self.b1

    @property
    def fy(self) -> float:
        """Principal distance along y (``f``)."""
        return self.f

    @property
    def has_distortion(self) -> bool:
        """True when lens distortion terms are set."""
        return self.distortion is not None

    @property
    def calibration_matrix(self) -> np.ndarray:
        """3x3 matrix ``K`` with ``(x, y, 1) ~ K (u, v, w)`` for camera-frame points.

        ``K = [[-fx, b2, x0], [0, -f, y0], [0, 0, 1]]`` (no distortion): the photogrammetric
        camera looks along -w, hence the negative diagonal.
        """
        return np.array([[-self.fx, self.b2, self.x0], [0.0, -self.f, self.y0], [0.0, 0.0, 1.0]])

    def for_image(self, dx0: float = 0.0, dy0: float = 0.0, dc: float = 0.0) -> InteriorOrientation:
        """Image-variant orientation: principal point ``(x0 + dx0, y0 + dy0)``, distance ``f + dc``.

        Parameters
        ----------
        dx0, dy0 : float, default 0.0
            Principal-point offsets, unit of this orientation.
        dc : float, default 0.0
            Principal-distance offset, unit of this orientation.

        Returns
        -------
        InteriorOrientation
        """
        return replace(self, x0=self.x0 + dx0, y0=self.y0 + dy0, f=self.f + dc)

    def with_distortion(self, distortion: BrownDistortion | None) -> InteriorOrientation:
        """A copy with other distortion terms.

        Parameters
        ----------
        distortion : BrownDistortion or None
            The new terms; ``None`` for a distortion-free camera.

        Returns
        -------
        InteriorOrientation
        """
        return replace(self, distortion=distortion)

    # --- normalised <-> image ---------------------------------------------------------------

    def image_from_normalized(self, xy_norm) -> np.ndarray:
        """Image coordinates (unit of this orientation) from ideal normalised coordinates.

        ``xy_norm`` are ``(xn, yn) = (-u/w, v/w)`` (Metashape axes, y down); distortion, the
        principal distance, b1, b2 and the principal point are applied.

        Parameters
        ----------
        xy_norm : array_like, shape (n, 2) or (2,)
            Ideal normalised coordinates, unitless.

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            Image coordinates ``(x, y)`` in the unit of this orientation (y up).

        Raises
        ------
        InputError
            When ``xy_norm`` is not of shape (n, 2) or (2,).
        """
        a, single = as_points_single(xy_norm, 2, "normalised coordinates", finite=False)
        if self.distortion is not None:
            a = self.distortion.distort(a)
        else:
            a = a.copy()
        xd, yd = a[:, 0], a[:, 1]  # views: updated in place
        xd *= self.fx
        if self.b2:
            xd += self.b2 * yd
        xd += self.x0
        yd *= -self.f
        yd += self.y0
        return one_or_many(a, single)

    def normalized_from_image(
        self, xy, *, tol: float = 1e-9, max_iter: int = 30, on_failure="raise"
    ):
        """Ideal normalised coordinates ``(-u/w, v/w)`` from image coordinates.

        Removes the principal point, b1, b2 and (iteratively) the distortion.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Image coordinates in the unit of this orientation.
        tol : float
            Undistortion tolerance in the unit of this orientation.
        max_iter : int
            Iteration limit of the undistortion.
        on_failure : {"raise", "nan", "keep"}
            What to do with points whose undistortion did not converge.

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            Unitless.
        """
        xy, single = as_points_single(xy, 2, "image coordinates", finite=False)
        res = self.undistort_image(xy, tol=tol, max_iter=max_iter)
        pts = res.points
        if not res.all_converged:
            if on_failure == "raise":
                from ..errors import ConvergenceError

                raise ConvergenceError(
                    f"undistortion: {res.describe_failures()}; the points may lie outside the "
                    "region where the distortion model is valid",
                    iterations=res.iterations,
                    result=res,
                )
            if on_failure == "nan":
                pts = pts.copy()
                pts[~res.converged] = np.nan
            elif on_failure != "keep":
                raise InputError("on_failure must be 'raise', 'nan' or 'keep'")
        return one_or_many(pts, single)

    def undistort_image(self, xy, *, tol: float = 1e-9, max_iter: int = 30):
        """Undistort image coordinates; return :class:`UndistortResult` of normalised points.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Image coordinates in the unit of this orientation.
        tol : float, default 1e-9
            Convergence tolerance, in the unit of this orientation.
        max_iter : int, default 30
            Newton iterations at most.

        Returns
        -------
        UndistortResult
            ``points`` (n, 2) ideal normalised coordinates (unitless), with a ``status`` per
            point; a result keeps the point axis, also for a single point (2,) (then n = 1).
            Points holding NaN/infinite values get status 2.

        Raises
        ------
        InputError
            When ``xy`` is not of shape (n, 2) or (2,).
        """
        from .distortion import UndistortResult

        a = as_points(xy, 2, "image coordinates", finite=False)
        yd = (self.y0 - a[:, 1]) / self.f
        xd = (a[:, 0] - self.x0 - self.b2 * yd) / self.fx
        d = np.stack([xd, yd], axis=1)
        if self.distortion is None:
            status = np.where(np.all(np.isfinite(d), axis=1), 0, 2).astype(np.int8)
            return UndistortResult(d, status, 0, np.zeros(d.shape[0]))
        return self.distortion.undistort(d, tol=tol, max_iter=max_iter, scale=(self.fx, self.f))

    # --- pixels <-> image --------------------------------------------------------------------

    def _pixel_geometry(self) -> tuple[float, float, float, float]:
        if self.origin_px is None:
            raise InputError(
                "this interior orientation has no pixel geometry: set origin_px (the pixel "
                "position of the image-system origin), e.g. with InteriorOrientation.digital(...)"
            )
        if self.unit == "px":
            dx = dy = 1.0
        else:
            if self.pixel_size is None:
                raise InputError("converting pixels to mm needs pixel_size (mm per pixel)")
            dx, dy = self.pixel_size
        return self.origin_px[0], self.origin_px[1], dx, dy

    def _pixel_system(self, pixel_origin: str):
        from ..imagecoords import PixelSystem

        co, ro, dx, dy = self._pixel_geometry()
        _pixel_shift(pixel_origin)
        return PixelSystem((dx, dy), (co, ro), origin="center").with_origin(pixel_origin)

    def image_to_pixel(self, xy, pixel_origin: str = "center") -> np.ndarray:
        """Pixel ``(col, row)`` of image coordinates ``(x, y)`` (unit of this orientation).

        ``col = col_o + x / dx``, ``row = row_o - y / dy`` (:mod:`photogeom.imagecoords`);
        rows holding NaN stay NaN.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Image coordinates in the unit of this orientation.
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0); ``"corner"``: its corner.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            ``(col, row)`` in px.

        Raises
        ------
        InputError
            When the orientation has no pixel geometry (``origin_px``; with ``unit="mm"`` also
            ``pixel_size``), or ``pixel_origin`` is neither value.
        """
        return self._convert(xy, self._pixel_system(pixel_origin).to_pixel)

    def pixel_to_image(self, colrow, pixel_origin: str = "center") -> np.ndarray:
        """Image coordinates ``(x, y)`` of pixel positions ``(col, row)``.

        ``x = dx (col - col_o)``, ``y = -dy (row - row_o)`` (the minus sign makes the image
        system right-handed); rows holding NaN stay NaN.

        Parameters
        ----------
        colrow : array_like, shape (n, 2) or (2,)
            Pixel positions ``(col, row)``, px.
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0); ``"corner"``: its corner.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            ``(x, y)`` in the unit of this orientation (y up).

        Raises
        ------
        InputError
            When the orientation has no pixel geometry (``origin_px``; with ``unit="mm"`` also
            ``pixel_size``), or ``pixel_origin`` is neither value.
        """
        return self._convert(colrow, self._pixel_system(pixel_origin).to_image)

    @staticmethod
    def _convert(points, fn) -> np.ndarray:
        a2, single = as_points_single(points, 2, "image or pixel coordinates", finite=False)
        ok = np.all(np.isfinite(a2), axis=1)
        out = np.full(a2.shape, np.nan)
        if np.any(ok):
            out[ok] = fn(a2[ok])
        return one_or_many(out, single)

    def principal_point_px(self, pixel_origin: str = "center") -> tuple[float, float]:
        """Principal point as pixel ``(col, row)``.

        Parameters
        ----------
        pixel_origin : {"center", "corner"}, default "center"
            Pixel convention, as in :meth:`image_to_pixel`.

        Returns
        -------
        tuple of float
            ``(col, row)`` in px.

        Raises
        ------
        InputError
            When the orientation has no pixel geometry (``origin_px``; with ``unit="mm"`` also
            ``pixel_size``), or ``pixel_origin`` is neither value.
        """
        c = self.image_to_pixel(np.array([self.x0, self.y0]), pixel_origin)
        return float(c[0]), float(c[1])

    # --- serialisation -----------------------------------------------------------------------

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``f, x0, y0, unit``; ``b1, b2`` when either is non-zero; ``distortion``,
            ``pixel_size_mm``, ``origin_px``, ``image_size`` when set.
        """
        out: dict = {"f": self.f, "x0": self.x0, "y0": self.y0, "unit": self.unit}
        if self.b1 or self.b2:
            out["b1"], out["b2"] = self.b1, self.b2
        if self.distortion is not None:
            out["distortion"] = self.distortion.to_dict()
        if self.pixel_size is not None:
            out["pixel_size_mm"] = list(self.pixel_size)
        if self.origin_px is not None:
            out["origin_px"] = list(self.origin_px)
        if self.image_size is not None:
            out["image_size"] = list(self.image_size)
        return out

    @classmethod
    def from_dict(cls, data: Mapping) -> InteriorOrientation:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : Mapping
            Keys of :meth:`to_dict`; ``f`` is required.

        Returns
        -------
        InteriorOrientation

        Raises
        ------
        InputError
            For an unknown key (named) or a missing ``f``, and for values the constructor
            refuses.
        """
        known = {
            "f",
            "x0",
            "y0",
            "unit",
            "b1",
            "b2",
            "distortion",
            "pixel_size_mm",
            "origin_px",
            "image_size",
        }
        unknown = set(data) - known
        if unknown:
            raise InputError(f"interior orientation: unknown key(s) {', '.join(sorted(unknown))}")
        if "f" not in data:
            raise InputError("interior orientation: 'f' (principal distance) is required")
        d = dict(data)
        dist = d.pop("distortion", None)
        ps = d.pop("pixel_size_mm", None)
        return cls(
            distortion=None if dist is None else BrownDistortion.from_dict(dist),
            pixel_size=ps,
            **{k: v for k, v in d.items()},
        )


@dataclass(frozen=True)
class ImageVariantInteriorOrientation:
    """A base interior orientation with per-image offsets ``(dx0, dy0, dc)``.

    Image-variant interior orientation (Hastedt et al. 2002): image ``i`` has the principal
    point ``(x0 + dx0_i, y0 + dy0_i)`` and the principal distance ``f + dc_i``.

    Parameters
    ----------
    base : InteriorOrientation
    offsets : mapping image id -> (dx0, dy0, dc)
        Offsets in the unit of ``base``; images not listed use the base values.
    """

    base: InteriorOrientation
    offsets: Mapping[object, tuple[float, float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        clean = {}
        for key, val in dict(self.offsets).items():
            v = np.asarray(val, dtype=float).reshape(-1)
            if v.size != 3 or not np.all(np.isfinite(v)):
                raise InputError(
                    f"image {key!r}: offsets must be three finite numbers (dx0, dy0, dc)"
                )
            clean[key] = (float(v[0]), float(v[1]), float(v[2]))
        object.__setattr__(self, "offsets", clean)

    def for_image(self, image_id) -> InteriorOrientation:
        """The interior orientation of one image.

        Parameters
        ----------
        image_id : hashable
            Image key of :attr:`offsets`; an image without offsets gets the base orientation.

        Returns
        -------
        InteriorOrientation
            The base orientation with the image's ``(dx0, dy0, dc)`` added to ``x0, y0, f``.
        """
        dx0, dy0, dc = self.offsets.get(image_id, (0.0, 0.0, 0.0))
        return self.base.for_image(dx0, dy0, dc)

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"base": {...}, "offsets": {image id (str): [dx0, dy0, dc]}}``, offsets in the unit
            of the base orientation.
        """
        return {
            "base": self.base.to_dict(),
            "offsets": {str(k): list(v) for k, v in self.offsets.items()},
        }
