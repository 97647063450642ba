"""Frame-camera calibration as Agisoft Metashape defines it: model, XML file, OpenCV conversion.

Metashape's camera system has x to the right, y down and z forward (the viewing direction).
A camera-frame point ``(X, Y, Z)`` with ``Z > 0`` maps to

    x = X / Z,  y = Y / Z,  r^2 = x^2 + y^2
    x' = x (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + P1 (r^2 + 2 x^2) + 2 P2 x y
    y' = y (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + P2 (r^2 + 2 y^2) + 2 P1 x y
    u = w / 2 + cx + x' f + x' B1 + y' B2
    v = h / 2 + cy + y' f

with ``f, cx, cy, B1, B2, u, v`` in pixels, ``cx, cy`` offsets of the principal point from
the image centre, ``w, h`` the image size. Metashape's ``(u, v)`` have their origin at the
top-left *corner* of the image (the top-left pixel's centre is (0.5, 0.5)): photogeom calls
this ``pixel_origin="corner"``. photogeom's default pixel convention (and OpenCV's) puts the
top-left pixel's *centre* at (0, 0): ``pixel_origin="center"``, i.e. ``u - 0.5``.

Against the photogrammetric camera system (x right, y up, z backwards, image plane at
``z = -f``): ``X_metashape = x``, ``Y_metashape = -y``, ``Z_metashape = -z``.

OpenCV (``cv2.projectPoints``) has the same camera axes and the pixel-centre origin; its
``p1, p2`` are Metashape's ``P2, P1``, its principal point is absolute
(``cx_cv = w / 2 + cx - 0.5``) and ``fx = f + B1``, ``fy = f``. Metashape's ``B2`` (shear)
and ``K4`` (r^8) have no OpenCV equivalent; OpenCV's rational (k4..k6), thin-prism
(s1..s4) and tilt terms have no Metashape equivalent.
"""

from __future__ import annotations

import math
import os
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, fields, replace

import numpy as np

from ..errors import DegenerateGeometryError, FileFormatError, InputError
from ..numbers import parse_decimal
from ..validation import as_finite_scalar, as_points, as_points_single, one_or_many
from .distortion import CHUNK, BrownDistortion, UndistortResult
from .interior import InteriorOrientation, _pixel_shift

#: Tags of the calibration XML, in the order they are written.
XML_TAGS = (
    "projection",
    "width",
    "height",
    "f",
    "cx",
    "cy",
    "b1",
    "b2",
    "k1",
    "k2",
    "k3",
    "k4",
    "p1",
    "p2",
)
#: Largest calibration XML read (bytes); Metashape writes about 1 kB.
MAX_XML_BYTES = 1 << 20
#: Largest Metashape camera export read (bytes): about 1.1 kB per image with the poses and
#: their covariances, so some 55 000 images.
MAX_CAMERA_EXPORT_BYTES = 64 << 20
#: Largest image side accepted (pixels); a larger value is a corrupt file.
MAX_IMAGE_SIDE = 10**6
#: Largest focal length accepted, in image diagonals (a field of view of ~0.06 degree).
MAX_FOCAL_DIAGONALS = 1000.0

#: Tags that are read but carry nothing photogeom uses (Metashape writes them).
IGNORED_TAGS = ("date", "covariance")


def check_xml_size(data: bytes, where: str) -> None:
    """Refuse a calibration XML over ``MAX_XML_BYTES`` or a camera export (root
    ``<document>`` or ``<chunk>``) over ``MAX_CAMERA_EXPORT_BYTES``.

    Raises
    ------
    FileFormatError
        For a document over its limit, naming the limit.
    """
    if len(data) <= MAX_XML_BYTES:
        return
    from ..xmlsafe import root_tag

    if root_tag(data) in ("document", "chunk"):
        if len(data) <= MAX_CAMERA_EXPORT_BYTES:
            return
        raise FileFormatError(
            f"{where}: more than {MAX_CAMERA_EXPORT_BYTES} bytes; photogeom reads Metashape "
            "camera exports of up to 64 MiB (some 55 000 images): export a chunk of fewer "
            "images, or the calibration alone (Tools > Camera Calibration, Export)"
        )
    raise FileFormatError(
        f"{where}: more than {MAX_XML_BYTES} bytes; a calibration XML is about 1 kB: wrong file?"
    )


def parse_decimal_or_none(text: str) -> float | None:
    """``text`` as a number, or None when it is not one (compared, not reported)."""
    try:
        return parse_decimal(text)
    except ValueError:
        return None


class MetashapeXMLWarning(UserWarning):
    """A calibration XML holds tags photogeom does not know (they are ignored)."""


@dataclass(frozen=True)
class MetashapeCalibration:
    """Metashape frame-camera calibration (pixels; see the module docstring).

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    f : float
        Focal length in pixels.
    cx, cy : float
        Principal point offset from the image centre, pixels.
    k1, k2, k3, k4 : float
        Radial coefficients (dimensionless).
    p1, p2 : float
        Tangential coefficients, Metashape's order (dimensionless).
    b1, b2 : float
        Affinity and non-orthogonality (pixels).
    """

    width: int
    height: int
    f: float
    cx: float = 0.0
    cy: float = 0.0
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    b1: float = 0.0
    b2: float = 0.0

    def __post_init__(self) -> None:
        for fl in fields(self):
            v = getattr(self, fl.name)
            if fl.name in ("width", "height"):
                try:
                    iv = int(v)
                except (TypeError, ValueError, OverflowError) as exc:
                    raise InputError(f"{fl.name}: not an integer ({v!r})") from exc
                if iv != v or not 0 < iv <= MAX_IMAGE_SIDE:
                    raise InputError(
                        f"{fl.name} must be a whole number of pixels from 1 to "
                        f"{MAX_IMAGE_SIDE}, got {v!r}"
                    )
                object.__setattr__(self, fl.name, iv)
                continue
            object.__setattr__(self, fl.name, as_finite_scalar(v, fl.name))
        if self.f <= 0 or self.f + self.b1 <= 0:
            raise InputError(
                f"focal length must be > 0 (f = {self.f:g}, f + b1 = {self.f + self.b1:g})"
            )
        diagonal = math.hypot(self.width, self.height)
        if max(self.f, self.f + self.b1) > MAX_FOCAL_DIAGONALS * diagonal:
            raise InputError(
                f"focal length f = {self.f:g} px is more than {MAX_FOCAL_DIAGONALS:g} image "
                f"diagonals ({diagonal:.0f} px): not a camera calibration (f is in pixels)"
            )
        limit = MAX_FOCAL_DIAGONALS * diagonal
        for name in ("cx", "cy", "b2"):
            if abs(getattr(self, name)) > limit:
                raise InputError(
                    f"{name} = {getattr(self, name):g} px is more than {MAX_FOCAL_DIAGONALS:g} "
                    f"image diagonals from the centre: not a camera calibration"
                )

    # --- pieces ------------------------------------------------------------------------------

    @property
    def distortion(self) -> BrownDistortion:
        """The dimensionless distortion terms."""
        return BrownDistortion(self.k1, self.k2, self.k3, self.k4, self.p1, self.p2)

    def principal_point(self, pixel_origin: str = "center") -> tuple[float, float]:
        """Absolute principal point ``(w/2 + cx, h/2 + cy)`` shifted to ``pixel_origin``.

        Parameters
        ----------
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).

        Returns
        -------
        tuple of float
            ``(u, v)`` in px.

        Raises
        ------
        InputError
            For an unknown ``pixel_origin``.
        """
        s = 0.5 - _pixel_shift(pixel_origin)
        return self.width / 2 + self.cx - s, self.height / 2 + self.cy - s

    # --- forward -----------------------------------------------------------------------------

    def project_normalized(self, xy, *, pixel_origin: str = "center") -> np.ndarray:
        """Pixels ``(u, v)`` of ideal normalised coordinates ``(X/Z, Y/Z)`` (Metashape axes).

        Vectorised over points.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Ideal normalised coordinates, unitless (x right, y down).
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            Pixels ``(u, v)`` with distortion, B1, B2 applied.

        Raises
        ------
        InputError
            When ``xy`` is not of shape (n, 2) or (2,).
        """
        a, single = as_points_single(xy, 2, "normalised coordinates", finite=False)
        out = np.empty_like(a)
        for s in range(0, a.shape[0], CHUNK):  # blocks, not points
            e = min(s + CHUNK, a.shape[0])
            out[s:e] = self._pixels_from_xy(a[s:e, 0], a[s:e, 1], pixel_origin)
        return one_or_many(out, single)

    def _pixels_from_xy(self, x: np.ndarray, y: np.ndarray, pixel_origin: str) -> np.ndarray:
        # Written for speed on 1e7 points: few temporaries, in-place updates.
        r2 = x * x
        r2 += y * y
        rad = self.k4 * r2 if self.k4 else np.zeros_like(r2)
        rad += self.k3
        rad *= r2
        rad += self.k2
        rad *= r2
        rad += self.k1
        rad *= r2
        rad += 1.0
        xy2 = x * y
        xy2 *= 2.0
        out = np.empty((x.shape[0], 2))
        xd = out[:, 0]
        yd = out[:, 1]
        np.multiply(x, rad, out=xd)
        np.multiply(y, rad, out=yd)
        if self.p1 or self.p2:
            xd += self.p1 * (r2 + 2.0 * x * x) + self.p2 * xy2
            yd += self.p2 * (r2 + 2.0 * y * y) + self.p1 * xy2
        u0, v0 = self.principal_point(pixel_origin)
        xd *= self.f + self.b1
        if self.b2:
            xd += self.b2 * yd  # yd is still the distorted normalised y here
        xd += u0
        yd *= self.f
        yd += v0
        return out

    def project_camera(
        self, xyz, *, pixel_origin: str = "center", behind: str = "raise"
    ) -> np.ndarray:
        """Pixels of camera-frame points (Metashape axes: x right, y down, z forward).

        Parameters
        ----------
        xyz : array_like, shape (n, 3) or (3,)
            Camera-frame coordinates, any length unit.
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).
        behind : {"raise", "nan"}, default "raise"
            Points with ``Z <= 0`` are behind the camera: ``"raise"`` raises
            :class:`~photogeom.errors.DegenerateGeometryError`, ``"nan"`` returns NaN for them.

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (3,))
            Pixels ``(u, v)``.

        Raises
        ------
        InputError
            When ``xyz`` is not of shape (n, 3) or (3,) or holds NaN/infinite values.
        DegenerateGeometryError
            For points behind the camera with ``behind="raise"``.
        """
        p, single = as_points_single(xyz, 3, "camera-frame points")
        Z = p[:, 2]
        back = ~(Z > 0)
        if np.any(back) and behind == "raise":
            raise DegenerateGeometryError(
                f"{int(back.sum())} point(s) have Z <= 0 (behind the camera, whose z axis points "
                "forward in Metashape's convention); pass behind='nan' to get NaN for them"
            )
        uv = np.empty((p.shape[0], 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            for s in range(0, p.shape[0], CHUNK):  # blocks, not points
                e = min(s + CHUNK, p.shape[0])
                iz = 1.0 / Z[s:e]
                uv[s:e] = self._pixels_from_xy(p[s:e, 0] * iz, p[s:e, 1] * iz, pixel_origin)
        uv[back] = np.nan
        return one_or_many(uv, single)

    def distort_pixels(self, uv_ideal, *, pixel_origin: str = "center") -> np.ndarray:
        """Distorted pixels of ideal pixels (a distortion-free camera with the same f, cx, cy).

        The ideal camera has no distortion and no B1, B2: ``u = w/2 + cx + x f``.

        Parameters
        ----------
        uv_ideal : array_like, shape (n, 2) or (2,)
            Ideal pixels ``(u, v)``.
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            Observed (distorted) pixels ``(u, v)``.

        Raises
        ------
        InputError
            When ``uv_ideal`` is not of shape (n, 2) or (2,).
        """
        a, single = as_points_single(uv_ideal, 2, "ideal pixels", finite=False)
        u0, v0 = self.principal_point(pixel_origin)
        out = self.project_normalized((a - np.array([u0, v0])) / self.f, pixel_origin=pixel_origin)
        return one_or_many(out, single)

    # --- inverse -----------------------------------------------------------------------------

    def unproject(
        self, uv, *, pixel_origin: str = "center", tol: float = 1e-9, max_iter: int = 30
    ) -> UndistortResult:
        """Ideal normalised coordinates ``(X/Z, Y/Z)`` of observed pixels (iterative).

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)
            Pixel coordinates in the ``pixel_origin`` convention.
        pixel_origin : {"center", "corner"}
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).
        tol : float
            Tolerance in pixels on the re-projected position.
        max_iter : int
            Newton iteration limit.

        Returns
        -------
        UndistortResult
            ``points`` (n, 2) normalised; ``status`` per point (0 = converged); ``residual``
            in px. A result keeps the point axis, also for a single point (2,) (n = 1).

        Raises
        ------
        InputError
            When ``uv`` is not of shape (n, 2) or (2,).
        """
        a = as_points(uv, 2, "pixels", finite=False)
        u0, v0 = self.principal_point(pixel_origin)
        yd = (a[:, 1] - v0) / self.f
        xd = (a[:, 0] - u0 - self.b2 * yd) / (self.f + self.b1)
        return self.distortion.undistort(
            np.stack([xd, yd], axis=1), tol=tol, max_iter=max_iter, scale=(self.f + self.b1, self.f)
        )

    def undistort_pixels(
        self, uv, *, pixel_origin: str = "center", tol: float = 1e-9, max_iter: int = 30
    ) -> UndistortResult:
        """Ideal pixels (distortion-free camera with the same f, cx, cy) of observed pixels.

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)
            Observed pixels ``(u, v)``.
        pixel_origin : {"center", "corner"}, default "center"
            ``"center"``: the centre of the top-left pixel is (0, 0) (photogeom, OpenCV);
            ``"corner"``: its top-left corner is (0, 0) (Metashape).
        tol : float, default 1e-9
            Convergence tolerance, as in :meth:`unproject`.
        max_iter : int, default 30
            Newton iterations at most.

        Returns
        -------
        UndistortResult
            ``points`` are ideal pixels (n, 2); ``status`` flags points that did not converge
            (their values are the last iterate).
        """
        res = self.unproject(uv, pixel_origin=pixel_origin, tol=tol, max_iter=max_iter)
        u0, v0 = self.principal_point(pixel_origin)
        pts = res.points * self.f + np.array([u0, v0])
        return replace(res, points=pts)

    # --- photogrammetric interior orientation --------------------------------------------------

    def interior_orientation(self) -> InteriorOrientation:
        """The equivalent :class:`InteriorOrientation` in pixels.

        Image system origin at the image centre (pixel ``(w/2 - 0.5, h/2 - 0.5)``, centre
        convention), y up: ``x0 = cx``, ``y0 = -cy``, ``f``, ``b1``, ``b2`` and the distortion
        unchanged.

        Returns
        -------
        InteriorOrientation
            ``unit="px"``, with ``origin_px`` and ``image_size`` set.
        """
        return InteriorOrientation(
            f=self.f,
            x0=self.cx,
            y0=-self.cy,
            unit="px",
            b1=self.b1,
            b2=self.b2,
            distortion=self.distortion,
            origin_px=(self.width / 2 - 0.5, self.height / 2 - 0.5),
            image_size=(self.width, self.height),
        )

    @classmethod
    def from_interior_orientation(
        cls, io: InteriorOrientation, image_size=None
    ) -> MetashapeCalibration:
        """Inverse of :meth:`interior_orientation` (needs ``unit="px"``, pixel geometry, size).

        Parameters
        ----------
        io : InteriorOrientation
            In px, with pixel geometry (``origin_px``).
        image_size : (int, int), optional
            ``(width, height)`` in px; default ``io.image_size``.

        Returns
        -------
        MetashapeCalibration

        Raises
        ------
        InputError
            When ``io`` is not in px, has no pixel geometry, or no image size is known.
        """
        if io.unit != "px":
            raise InputError(
                "a Metashape calibration is in pixels: convert the orientation to 'px'"
            )
        size = image_size or io.image_size
        if size is None:
            raise InputError("a Metashape calibration needs the image size (width, height)")
        w, h = int(size[0]), int(size[1])
        col, row = io.principal_point_px("corner")
        d = io.distortion or BrownDistortion()
        return cls(w, h, io.f, cx=col - w / 2, cy=row - h / 2, b1=io.b1, b2=io.b2, **d.to_dict())

    # --- OpenCV ------------------------------------------------------------------------------

    def to_opencv(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV camera matrix and distortion vector ``(k1, k2, p1, p2, k3)``.

        Exact: ``fx = f + B1``, ``fy = f``, ``cx_cv = w/2 + cx - 0.5``,
        ``cy_cv = h/2 + cy - 0.5`` (OpenCV's pixel origin is the top-left pixel's centre),
        OpenCV ``p1 = P2``, ``p2 = P1``.

        Returns
        -------
        camera_matrix : numpy.ndarray, shape (3, 3)
            ``[[fx, 0, cx_cv], [0, fy, cy_cv], [0, 0, 1]]``, px.
        dist_coeffs : numpy.ndarray, shape (5,)
            ``(k1, k2, p1, p2, k3)``, unitless.

        Raises
        ------
        InputError
            When ``K4`` or ``B2`` are non-zero: OpenCV's model has no r^8 term and its
            projection ignores the shear entry of the camera matrix.
        """
        bad = [n for n in ("k4", "b2") if getattr(self, n) != 0.0]
        if bad:
            raise InputError(
                f"{', '.join(n.upper() for n in bad)} have no OpenCV equivalent (OpenCV has no r^8 "
                "radial term and cv2.projectPoints ignores the shear of the camera matrix); the "
                "conversion would not be exact"
            )
        cxa, cya = self.principal_point("center")
        K = np.array([[self.f + self.b1, 0.0, cxa], [0.0, self.f, cya], [0.0, 0.0, 1.0]])
        dist = np.array([self.k1, self.k2, self.p2, self.p1, self.k3])
        return K, dist

    @classmethod
    def from_opencv(
        cls, camera_matrix, dist_coeffs, width: int, height: int
    ) -> MetashapeCalibration:
        """From an OpenCV camera matrix and distortion vector (4, 5, 8, 12 or 14 terms).

        ``fx != fy`` is kept as ``B1 = fx - fy``; OpenCV ``p1, p2`` become ``P2, P1``.

        Parameters
        ----------
        camera_matrix : array_like, shape (3, 3)
            ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``, px, OpenCV's pixel-centre origin.
        dist_coeffs : array_like
            OpenCV distortion vector of 4, 5, 8, 12 or 14 terms.
        width, height : int
            Image size, px.

        Returns
        -------
        MetashapeCalibration

        Raises
        ------
        InputError
            When ``camera_matrix`` is not a finite 3x3 matrix of that layout (a skew entry is
            refused), ``dist_coeffs`` has another length, or terms without a Metashape equivalent
            (rational k4..k6, thin prism s1..s4, tilt) are non-zero.
        """
        K = np.asarray(camera_matrix, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise InputError("camera_matrix must be a finite 3x3 matrix")
        if K[0, 1] != 0:
            raise InputError(
                f"camera_matrix has a skew entry ({K[0, 1]!r}): OpenCV's projection ignores it, "
                "so it cannot be converted exactly; it must be [[fx, 0, cx], [0, fy, cy], "
                "[0, 0, 1]]"
            )
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise InputError(
                "camera_matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got rows "
                f"{K[1].tolist()} and {K[2].tolist()} below the first"
            )
        d = np.asarray(dist_coeffs, dtype=float).reshape(-1)
        if d.size not in (4, 5, 8, 12, 14):
            raise InputError(
                f"OpenCV distortion vectors have 4, 5, 8, 12 or 14 terms, got {d.size}"
            )
        if d.size > 5 and np.any(d[5:] != 0):
            raise InputError(
                "OpenCV's rational (k4, k5, k6), thin-prism (s1..s4) and tilt (tx, ty) terms "
                "have no Metashape equivalent; they must be zero for an exact conversion"
            )
        k1, k2, p1cv, p2cv = d[:4]
        k3 = d[4] if d.size >= 5 else 0.0
        fx, fy = K[0, 0], K[1, 1]
        return cls(
            width,
            height,
            fy,
            cx=K[0, 2] + 0.5 - width / 2,
            cy=K[1, 2] + 0.5 - height / 2,
            k1=k1,
            k2=k2,
            k3=k3,
            p1=p2cv,
            p2=p1cv,
            b1=fx - fy,
        )

    # --- XML -----------------------------------------------------------------------------------

    def to_xml_string(self) -> str:
        """Metashape calibration XML (``<calibration>`` with projection, width, height, ...).

        Returns
        -------
        str
            The document, UTF-8 declaration included.
        """
        root = ET.Element("calibration")
        for tag in XML_TAGS:
            el = ET.SubElement(root, tag)
            if tag == "projection":
                el.text = "frame"
            elif tag in ("width", "height"):
                el.text = str(getattr(self, tag))
            else:
                el.text = repr(float(getattr(self, tag)))
        ET.indent(root, space="  ")
        return (
            '<?xml version="1.0" encoding="UTF-8"?>\n'
            + ET.tostring(root, encoding="unicode")
            + "\n"
        )

    @classmethod
    def from_xml_string(
        cls,
        text: str | bytes,
        *,
        strict: bool = False,
        source: str = "calibration XML",
        sensor: int | str | None = None,
    ) -> MetashapeCalibration:
        """Parse Metashape calibration XML or camera export; see :func:`read_metashape_xml`.

        Parameters
        ----------
        text : str or bytes
            The document; bytes are decoded by the encoding declared in it (UTF-8, UTF-16
            with a byte-order mark, ISO-8859-1, ...).
        strict : bool, default False
            Refuse unknown tags (else they are ignored with a ``MetashapeXMLWarning``).
        source : str, default "calibration XML"
            Name of the document in error messages (e.g. the file path).
        sensor : int or str, optional
            For a camera export (root ``<document>`` or ``<chunk>``) with several sensors:
            the sensor's id or label (see
            :func:`photogeom.camera.metashape_export.sensor_calibration`).

        Returns
        -------
        MetashapeCalibration

        Raises
        ------
        FileFormatError
            As :func:`read_metashape_xml`.
        InputError
            ``sensor`` given for a calibration XML (root ``<calibration>``).
        """
        from ..xmlsafe import parse_xml, root_tag

        if root_tag(text) in ("document", "chunk"):  # a camera export, parsed once
            from .metashape_export import read_sensor

            return read_sensor(text, source, sensor, strict=strict).calibration
        root = parse_xml(text, source)
        if sensor is not None:
            raise InputError(
                f"sensor {sensor!r}: {source} is a calibration XML of one camera (root "
                "<calibration>), not a camera export with sensors; leave the sensor out"
            )
        return cls._from_calibration_element(root, strict=strict, source=source)

    @classmethod
    def _from_calibration_element(
        cls,
        root: ET.Element,
        *,
        strict: bool,
        source: str,
        size: tuple[str, str] | None = None,
    ) -> MetashapeCalibration:
        """The calibration of a ``<calibration>`` element (the root of a calibration XML, or
        a sensor's in a camera export, whose ``size``, ``(width, height)`` as written in
        the sensor's ``<resolution>``, is taken when the element has none)."""
        if root.tag != "calibration":
            raise FileFormatError(
                f"{source}: root element is <{root.tag}>, expected <calibration> (a Metashape "
                "calibration XML) or <document> (a Metashape camera export)"
            )
        values: dict[str, str] = {}
        unknown: list[str] = []
        projection = root.get("type")
        for child in root:
            tag = child.tag
            if tag == "resolution":  # <resolution width=".." height=".."/> (project files)
                for k in ("width", "height"):
                    if child.get(k) is not None:
                        values[k] = child.get(k)
                continue
            if tag == "projection":
                projection = (child.text or "").strip()
                continue
            if tag in IGNORED_TAGS:
                continue
            if tag in XML_TAGS or tag in ("p3", "p4"):
                if tag in values:
                    raise FileFormatError(f"{source}: tag <{tag}> appears twice")
                values[tag] = (child.text or "").strip()
                continue
            unknown.append(tag)
        if "f" not in values and {"fx", "fy"} & set(unknown):
            raise FileFormatError(
                f"{source}: a calibration in the older Agisoft format of PhotoScan and "
                "Agisoft Lens (<fx>, <fy>, <skew>, the principal point <cx>, <cy> as absolute "
                "pixel coordinates), not Metashape's (<f>, <b1>, <b2>, <cx>, <cy> from the image "
                "centre), which photogeom reads: import it into Metashape and export it "
                "again (Camera Calibration dialog, Export)"
            )
        if unknown:
            msg = (
                f"{source}: unknown tag(s) {', '.join('<' + t + '>' for t in unknown)} "
                "(not part of Metashape's frame calibration; ignored)"
            )
            if strict:
                raise FileFormatError(msg)
            warnings.warn(msg, MetashapeXMLWarning, stacklevel=3)
        if size is not None:
            for k, v in zip(("width", "height"), size):
                if k not in values:
                    values[k] = v
                elif parse_decimal_or_none(values[k]) != parse_decimal_or_none(v):
                    raise FileFormatError(
                        f"{source}: the calibration's <resolution> {k}={values[k]!r} differs "
                        f"from the sensor's {k}={v!r}; a calibration holds for the sensor's "
                        "image size"
                    )
        if projection is None:
            raise FileFormatError(f"{source}: missing <projection> (expected 'frame')")
        if projection != "frame":
            raise FileFormatError(
                f"{source}: projection {projection!r} is not supported; only 'frame' (the Brown "
                "frame camera) is"
            )
        missing = [t for t in ("width", "height", "f") if t not in values]
        if missing:
            raise FileFormatError(
                f"{source}: missing required tag(s) {', '.join('<' + t + '>' for t in missing)}"
            )
        parsed: dict[str, float] = {}
        for tag, txt in values.items():
            try:
                parsed[tag] = parse_decimal(txt)
            except ValueError:
                raise FileFormatError(
                    f"{source}: <{tag}> is not a number ({txt[:40]!r}); write it as an ASCII "
                    "decimal number (digits, '.', an exponent; no '_' digit grouping)"
                ) from None
            if not math.isfinite(parsed[tag]):
                raise FileFormatError(f"{source}: <{tag}> is NaN or infinite")
        for t in ("p3", "p4"):
            if parsed.pop(t, 0.0) != 0.0:
                raise FileFormatError(
                    f"{source}: <{t}> is non-zero; photogeom's Brown model has P1, P2 only"
                )
        for t in ("width", "height"):
            if not 0 < parsed[t] <= MAX_IMAGE_SIDE or parsed[t] != int(parsed[t]):
                raise FileFormatError(
                    f"{source}: <{t}> must be a whole number of pixels from 1 to "
                    f"{MAX_IMAGE_SIDE}, got {values[t][:40]!r}"
                )
            parsed[t] = int(parsed[t])
        try:
            return cls(**parsed)
        except InputError as exc:
            raise FileFormatError(f"{source}: {exc}") from exc

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"model": "metashape_frame", <every field by name>}`` (px; coefficients unitless).
        """
        return {
            "model": "metashape_frame",
            **{fl.name: getattr(self, fl.name) for fl in fields(self)},
        }


def read_metashape_xml(
    path: str | os.PathLike, *, strict: bool = False, sensor: int | str | None = None
) -> MetashapeCalibration:
    """Read a Metashape camera calibration XML file or camera export (frame camera).

    Both the exported calibration (``<projection>``, ``<width>``, ``<height>`` children) and
    the form inside project/camera exports (``<calibration type="frame">`` with
    ``<resolution width=".." height=".."/>``) are read. Missing optional terms are zero;
    ``<date>`` and ``<covariance>`` are ignored. A camera export (File > Export > Export
    Cameras, root ``<document>``) gives the calibration of one sensor: the adjusted one, or
    the initial one when the sensor has no adjusted calibration (with a
    ``MetashapeXMLWarning``); see :func:`photogeom.camera.metashape_export.sensor_calibration`.

    Parameters
    ----------
    path : str or os.PathLike
        The XML file (at most ``MAX_XML_BYTES``; a camera export at most
        ``MAX_CAMERA_EXPORT_BYTES``).
    strict : bool, default False
        Refuse unknown tags instead of warning and ignoring them.
    sensor : int or str, optional
        The sensor of a camera export, by id or label (needed when it has several).

    Returns
    -------
    MetashapeCalibration
        Pixels; coefficients unitless.

    Raises
    ------
    FileFormatError
        Unreadable file or XML, a file larger than ``MAX_XML_BYTES`` (a camera export:
        ``MAX_CAMERA_EXPORT_BYTES``), missing
        ``width``/``height``/``f``, non-numeric values, a projection other than ``frame``,
        (with ``strict=True``) unknown tags; for a camera export, several sensors and no
        ``sensor``, an unknown or ambiguous ``sensor`` (the sensors are listed), a sensor
        without a calibration, or of another camera type (named).
    InputError
        ``sensor`` given for a calibration XML of one camera.

    Warns
    -----
    MetashapeXMLWarning
        Unknown tags (ignored) when ``strict`` is False.
    """
    from ..io.sources import read_input_bytes

    try:
        data = read_input_bytes(path, MAX_CAMERA_EXPORT_BYTES)  # a pipe: read once per command
    except OSError as exc:
        raise FileFormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    check_xml_size(data, str(path))
    return MetashapeCalibration.from_xml_string(
        data, strict=strict, source=str(path), sensor=sensor
    )


def write_metashape_xml(calibration: MetashapeCalibration, path: str | os.PathLike) -> None:
    """Write a Metashape calibration XML file (atomically: old or complete new file).

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration to write.
    path : str or os.PathLike
        Output file; replaced if it exists.

    Raises
    ------
    OutputError
        When the file cannot be written.
    """
    from ..atomicfile import atomic_write_text

    atomic_write_text(path, calibration.to_xml_string())
