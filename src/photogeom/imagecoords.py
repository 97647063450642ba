"""Image coordinate systems: pixel <-> image (mm), fiducial -> image centre, handedness.

Systems (see ``docs/transforms.md`` and the conventions table of the README):

=====================  ==========================================  ======  ============
system                 axes                                        unit    handedness
=====================  ==========================================  ======  ============
``"pixel"``            col to the right, row down                  pixel   left
``"comparator"``       instrument axes (also ``"machine"``)        mm      right
``"fiducial"``         x along flight, y up                        mm      right
``"image"``            as fiducial, origin at the principal point  mm      right
=====================  ==========================================  ======  ============

Pixel coordinates are given as **(col, row)** pairs, i.e. the first column is the
horizontal coordinate, like ``x``. The pixel origin is stated explicitly:

* ``origin="center"`` (default): the *centre* of the top-left pixel is (0, 0), so pixel
  ``(i, j)`` covers ``[i - 0.5, i + 0.5]``;
* ``origin="corner"``: the *top-left corner* of the top-left pixel is (0, 0), so the centre of
  that pixel is (0.5, 0.5).

Pixel to image (mm) with pixel size ``d`` (mm per pixel, ``dx`` and ``dy`` may differ) and the
principal point ``(col_pp, row_pp)`` in the same pixel convention::

    x = dx * (col - col_pp)
    y = -dy * (row - row_pp)        # the minus sign makes the system right-handed
    z = -f

and back ``col = col_pp + x / dx``, ``row = row_pp - y / dy``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .errors import InputError
from .records import setstate_read_only, value_eq, value_key
from .validation import as_float64, as_points

PixelOrigin = Literal["center", "corner"]
PIXEL_ORIGINS: tuple[str, ...] = ("center", "corner")

#: Handedness of the named 2D coordinate systems (``"left"`` or ``"right"``).
HANDEDNESS: dict[str, str] = {
    "pixel": "left",
    "comparator": "right",
    "machine": "right",
    "fiducial": "right",
    "image": "right",
    "photo": "right",
    "calibrated": "right",
    "ground": "right",
    "map": "right",
    "local": "right",
}


def _check_origin(origin: str) -> None:
    if origin not in PIXEL_ORIGINS:
        raise InputError(
            f"unknown pixel origin {origin!r}; use 'center' (the centre of the top-left pixel is "
            "(0, 0)) or 'corner' (its top-left corner is (0, 0))"
        )


def _pair(value, name: str) -> np.ndarray:
    """``value`` as a read-only float pair of its own (never a view of the caller's array)."""
    arr = np.array(value, dtype=float).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: expected one finite number or a pair, got {value!r}")
    arr.flags.writeable = False
    return arr


def _pixel_size(pixel_size) -> np.ndarray:
    d = _pair(pixel_size, "pixel_size")
    if np.any(d <= 0):
        raise InputError(f"pixel_size must be > 0 (mm per pixel), got {pixel_size!r}")
    return d


def _focal(focal_length) -> float | None:
    if focal_length is None:
        return None
    f = float(focal_length)
    if not np.isfinite(f) or f <= 0:
        raise InputError(f"focal_length must be a positive number in mm, got {focal_length!r}")
    return f


def convert_pixel_origin(points, from_origin: PixelOrigin, to_origin: PixelOrigin) -> np.ndarray:
    """Re-express pixel coordinates (col, row) between the two pixel-origin conventions.

    ``corner = center + 0.5`` in both col and row.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (2,)
        Pixel coordinates (col, row) in pixels.
    from_origin, to_origin : {"center", "corner"}
        Convention of the input and of the output.

    Returns
    -------
    numpy.ndarray, shape (n, 2) or (2,)
        Pixel coordinates in ``to_origin``, px.

    Raises
    ------
    InputError
        For an unknown origin, or points not of shape (n, 2) / (2,) or not finite.
    """
    _check_origin(from_origin)
    _check_origin(to_origin)
    arr = as_float64(points, "pixel coordinates")
    p = as_points(arr, 2, "pixel coordinates")
    shift = {"center": 0.0, "corner": 0.5}
    out = p + (shift[to_origin] - shift[from_origin])
    return out[0] if arr.ndim == 1 else out


def image_center(image_size, origin: PixelOrigin = "center") -> np.ndarray:
    """Pixel coordinates (col, row) of the geometric centre of an image.

    Parameters
    ----------
    image_size : (width, height)
        Number of columns and rows (pixels); one number for a square image.
    origin : {"center", "corner"}, default "center"
        Pixel-origin convention of the result: ``((w - 1) / 2, (h - 1) / 2)`` for
        ``"center"``, ``(w / 2, h / 2)`` for ``"corner"``.

    Returns
    -------
    numpy.ndarray, shape (2,)
        ``(col, row)`` in px.

    Raises
    ------
    InputError
        For an unknown origin or a size that is not positive.
    """
    _check_origin(origin)
    size = _pair(image_size, "image_size")
    if np.any(size <= 0):
        raise InputError(f"image_size must be positive (columns, rows), got {image_size!r}")
    return size / 2.0 - (0.5 if origin == "center" else 0.0)


@dataclass(frozen=True, eq=False)
class PixelSystem:
    """A digital image's pixel system and its link to image (photo-centre) coordinates in mm.

    Parameters
    ----------
    pixel_size : float or (dx, dy)
        Pixel size in mm per pixel (``dx`` along columns, ``dy`` along rows).
    principal_point : (col_pp, row_pp)
        Principal point in pixels, in the ``origin`` convention.
    focal_length : float, optional
        Principal distance ``f`` in mm; with it :meth:`to_image` returns ``(x, y, -f)``.
    origin : {"center", "corner"}
        Pixel-origin convention of ``principal_point`` and of every pixel coordinate given to or
        returned by this object.
    """

    pixel_size: np.ndarray
    principal_point: np.ndarray
    focal_length: float | None = None
    origin: PixelOrigin = "center"

    # value equality (arrays element by element) and a hash agreeing with it: the pair
    # arrays are read-only copies
    __eq__ = value_eq

    def __hash__(self) -> int:
        return hash((type(self), value_key(self)))

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the pairs stay read-only

    def __post_init__(self) -> None:
        _check_origin(self.origin)
        object.__setattr__(self, "pixel_size", _pixel_size(self.pixel_size))
        object.__setattr__(self, "principal_point", _pair(self.principal_point, "principal_point"))
        object.__setattr__(self, "focal_length", _focal(self.focal_length))

    @classmethod
    def centered(
        cls,
        image_size,
        pixel_size,
        focal_length: float | None = None,
        origin: PixelOrigin = "center",
    ) -> PixelSystem:
        """A pixel system whose principal point is the image centre (see :func:`image_center`).

        Parameters
        ----------
        image_size : (width, height)
            Image size, px.
        pixel_size : float or (dx, dy)
            mm per pixel.
        focal_length : float, optional
            Principal distance ``f``, mm.
        origin : {"center", "corner"}, default "center"
            Pixel-origin convention.

        Returns
        -------
        PixelSystem

        Raises
        ------
        InputError
            For an unknown pixel origin, a pixel size that is not positive, a focal length that
            is not positive, or points not of shape (n, 2) / (2,) or not finite.
        """
        return cls(pixel_size, image_center(image_size, origin), focal_length, origin)

    def to_image(self, pixels) -> np.ndarray:
        """Pixel (col, row) -> image coordinates in mm.

        Parameters
        ----------
        pixels : array_like, shape (n, 2) or (2,)
            Pixel coordinates (col, row) in this system's ``origin`` convention.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (n, 3), or (2,) / (3,) for one point
            ``(x, y)`` in mm, or ``(x, y, -f)`` when the focal length is known.

        Raises
        ------
        InputError
            For points not of shape (n, 2) / (2,) or not finite.
        """
        arr = as_float64(pixels, "pixel coordinates (col, row)")
        p = as_points(arr, 2, "pixel coordinates (col, row)")
        d, pp = self.pixel_size, self.principal_point
        x = d[0] * (p[:, 0] - pp[0])
        y = -d[1] * (p[:, 1] - pp[1])
        cols = [x, y] if self.focal_length is None else [x, y, np.full_like(x, -self.focal_length)]
        out = np.column_stack(cols)
        return out[0] if arr.ndim == 1 else out

    def to_pixel(self, image_points) -> np.ndarray:
        """Image coordinates in mm, (x, y) or (x, y, z), -> pixel (col, row).

        Parameters
        ----------
        image_points : array_like, shape (n, 2), (n, 3), (2,) or (3,)
            Image coordinates in mm; a third coordinate, when given, must equal ``-f`` (points
            on the image plane).

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            ``(col, row)`` in px, this system's ``origin`` convention.

        Raises
        ------
        InputError
            For a z column without a focal length or with values other than ``-f``, or points
            of another shape or not finite.
        """
        arr = as_float64(image_points, "image coordinates (mm)")
        p = as_points(arr, (2, 3), "image coordinates (mm)")
        if p.shape[1] == 3:
            if self.focal_length is None:
                raise InputError(
                    "image coordinates with a z column need the focal length of the pixel system"
                )
            if not np.allclose(p[:, 2], -self.focal_length, rtol=0, atol=1e-9 * self.focal_length):
                raise InputError(
                    f"image coordinates: z must be -f = {-self.focal_length} mm (points on the "
                    "image plane); scale 3D rays onto the plane first"
                )
        d, pp = self.pixel_size, self.principal_point
        col = pp[0] + p[:, 0] / d[0]
        row = pp[1] - p[:, 1] / d[1]
        out = np.column_stack([col, row])
        return out[0] if arr.ndim == 1 else out

    def with_origin(self, origin: PixelOrigin) -> PixelSystem:
        """The same system with pixel coordinates in another origin convention.

        Parameters
        ----------
        origin : {"center", "corner"}
            The new convention.

        Returns
        -------
        PixelSystem
            With the principal point re-expressed in ``origin``.

        Raises
        ------
        InputError
            For an unknown origin.
        """
        pp = convert_pixel_origin(self.principal_point, self.origin, origin)
        return PixelSystem(self.pixel_size, pp, self.focal_length, origin)


def pixel_to_image(
    pixels,
    *,
    pixel_size,
    principal_point,
    focal_length: float | None = None,
    origin: PixelOrigin = "center",
) -> np.ndarray:
    """Pixel (col, row) -> image coordinates (x, y[, -f]) in mm; see :class:`PixelSystem`.

    Parameters
    ----------
    pixels : array_like, shape (n, 2) or (2,)
        Pixel coordinates **(col, row)**.
    pixel_size : float or (dx, dy)
        mm per pixel.
    principal_point : (col_pp, row_pp)
        Pixels, in the ``origin`` convention (as ``pixels``).
    focal_length : float, optional
        mm; adds the column ``z = -f``.
    origin : {"center", "corner"}, default "center"
        Pixel-origin convention of ``pixels`` and ``principal_point``.

    Returns
    -------
    numpy.ndarray, shape (n, 2) or (n, 3), or (2,) / (3,) for one point
        Image coordinates in mm.

    Raises
    ------
    InputError
        For an unknown pixel origin, a pixel size that is not positive, a focal length that
        is not positive, or points not of shape (n, 2) / (2,) or not finite.
    """
    return PixelSystem(pixel_size, principal_point, focal_length, origin).to_image(pixels)


def image_to_pixel(
    image_points,
    *,
    pixel_size,
    principal_point,
    focal_length: float | None = None,
    origin: PixelOrigin = "center",
) -> np.ndarray:
    """Image coordinates in mm -> pixel (col, row); inverse of :func:`pixel_to_image`.

    Parameters
    ----------
    image_points : array_like, shape (n, 2), (n, 3), (2,) or (3,)
        Image coordinates in mm; a z column must equal ``-focal_length``.
    pixel_size : float or (dx, dy)
        mm per pixel.
    principal_point : (col_pp, row_pp)
        Pixels, in the ``origin`` convention.
    focal_length : float, optional
        mm; needed when ``image_points`` has a z column.
    origin : {"center", "corner"}, default "center"
        Pixel-origin convention of ``principal_point`` and of the result.

    Returns
    -------
    numpy.ndarray, shape (n, 2) or (2,)
        ``(col, row)`` in px.

    Raises
    ------
    InputError
        For an unknown pixel origin, a pixel size that is not positive, a focal length that
        is not positive, or points not of shape (n, 2) / (2,) or not finite.
    """
    return PixelSystem(pixel_size, principal_point, focal_length, origin).to_pixel(image_points)


def fiducial_to_image(points, principal_point, focal_length: float) -> np.ndarray:
    """Fiducial (photo) coordinates in mm -> image coordinates ``(x - x0, y - y0, -f)``.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (2,)
        Fiducial coordinates (x, y) in mm.
    principal_point : (x0, y0)
        Principal point in the fiducial system, mm.
    focal_length : float
        Principal distance ``f`` in mm.

    Returns
    -------
    numpy.ndarray, shape (n, 3) or (3,)
    """
    arr = as_float64(points, "fiducial coordinates (mm)")
    p = as_points(arr, 2, "fiducial coordinates (mm)")
    pp = _pair(principal_point, "principal_point")
    f = _focal(focal_length)
    if f is None:
        raise InputError("fiducial_to_image needs the focal length (mm)")
    out = np.column_stack([p - pp, np.full(p.shape[0], -f)])
    return out[0] if arr.ndim == 1 else out


def image_to_fiducial(points, principal_point) -> np.ndarray:
    """Image coordinates (x, y[, z]) in mm -> fiducial coordinates ``(x + x0, y + y0)``.

    Parameters
    ----------
    points : array_like, shape (n, 2), (n, 3), (2,) or (3,)
        Image coordinates in mm (a z column is dropped).
    principal_point : (x0, y0)
        Principal point in the fiducial system, mm.

    Returns
    -------
    numpy.ndarray, shape (n, 2) or (2,)
        Fiducial coordinates in mm.

    Raises
    ------
    InputError
        For points of another shape or not finite, or a principal point that is not a
        finite pair.
    """
    arr = as_float64(points, "image coordinates (mm)")
    p = as_points(arr, (2, 3), "image coordinates (mm)")
    out = p[:, :2] + _pair(principal_point, "principal_point")
    return out[0] if arr.ndim == 1 else out


# --- handedness ------------------------------------------------------------------------------


def handedness(system: str) -> str:
    """``"left"`` or ``"right"`` for a named 2D system (see :data:`HANDEDNESS`).

    Parameters
    ----------
    system : str
        System name, case-insensitive (``"pixel"``, ``"image"``, ``"fiducial"``, ...).

    Returns
    -------
    str
        ``"left"`` or ``"right"``.

    Raises
    ------
    InputError
        For an unknown name (the known ones are listed).
    """
    key = str(system).lower()
    if key not in HANDEDNESS:
        raise InputError(
            f"unknown coordinate system {system!r}; known: {', '.join(sorted(HANDEDNESS))}"
        )
    return HANDEDNESS[key]


def flip_y(points) -> np.ndarray:
    """Negate the second coordinate (row or y).

    Turns a left-handed 2D system right-handed and back.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (2,)
        Coordinates, any unit.

    Returns
    -------
    numpy.ndarray, shape (n, 2) or (2,)
        A new array.

    Raises
    ------
    InputError
        For points of another shape or not finite.
    """
    arr = as_float64(points, "points")
    p = as_points(arr, 2, "points").copy()
    p[:, 1] = -p[:, 1]
    return p[0] if arr.ndim == 1 else p


@dataclass(frozen=True)
class HandednessPlan:
    """What to do with two named 2D systems before fitting a transformation between them.

    Parameters
    ----------
    source_system, target_system : str or None
        Names of the two systems (None when not named).
    flip_source, flip_target : bool
        Whether the second coordinate of that side is negated (the left-handed side of a
        mixed pair is the one flipped).
    note : str
        Explanation for reports (empty when nothing is flipped).
    """

    source_system: str | None
    target_system: str | None
    flip_source: bool
    flip_target: bool
    note: str

    def apply(self, source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The point sets with the planned flips applied (copies where flipped).

        Parameters
        ----------
        source, target : numpy.ndarray, shape (n, 2)
            The two point sets.

        Returns
        -------
        source, target : numpy.ndarray, shape (n, 2)
        """
        return (flip_y(source) if self.flip_source else source,
                flip_y(target) if self.flip_target else target)


_UNNAMED = HandednessPlan(None, None, False, False, "")


def handedness_plan(source_system: str | None, target_system: str | None) -> HandednessPlan:
    """Decide the row/y flip for a 2D fit between named systems.

    * neither system named: nothing is flipped (the caller vouches for the coordinates);
    * only one named: :class:`InputError` (the handedness of the pair cannot be judged);
    * same handedness: nothing is flipped;
    * mixed handedness: the second coordinate of the left-handed (pixel) side is negated, and
      the note says so. The fitted transformation then maps ``(col, -row)``.

    Parameters
    ----------
    source_system, target_system : str or None
        System names (see :data:`HANDEDNESS`).

    Returns
    -------
    HandednessPlan

    Raises
    ------
    InputError
        When only one system is named, or a name is unknown.
    """
    if source_system is None and target_system is None:
        return _UNNAMED
    if source_system is None or target_system is None:
        raise InputError(
            "give both source_system and target_system (or neither): the handedness of the "
            "pair cannot be judged from one side"
        )
    hs, ht = handedness(source_system), handedness(target_system)
    if hs == ht:
        return HandednessPlan(source_system, target_system, False, False, "")
    flip_source = hs == "left"
    side, sysname = ("source", source_system) if flip_source else ("target", target_system)
    note = (
        f"{side} system {sysname!r} is left-handed and the other is right-handed: the {side} "
        "row/y coordinate was negated before the fit, so the transformation maps "
        + ("(col, -row) of the source" if flip_source else "into (col, -row) of the target")
        + "; residuals are reported in the target system as given"
    )
    return HandednessPlan(source_system, target_system, flip_source, not flip_source, note)
