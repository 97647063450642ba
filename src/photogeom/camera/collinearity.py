"""Collinearity equations: ground -> image, image -> ray, image + height -> ground.

    x - x0 = -f (m11 dX + m12 dY + m13 dZ) / (m31 dX + m32 dY + m33 dZ)
    y - y0 = -f (m21 dX + m22 dY + m23 dZ) / (m31 dX + m32 dY + m33 dZ)

with ``(dX, dY, dZ) = X - X0`` and ``M = M3(kappa) M2(phi) M1(omega)``; affinity, shear
and Brown distortion as described in :mod:`photogeom.camera.interior`. Everything is
vectorised over points. A point is *in front of* the camera when its camera-frame
``w = m3 . (X - X0)`` is negative (the camera looks along its -z axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError, InputError
from ..rotation import opk_matrix_and_derivatives
from ..validation import as_float64, as_points, as_points_single, one_or_many
from .distortion import CHUNK
from .exterior import ExteriorOrientation
from .interior import InteriorOrientation

BEHIND_CHOICES = ("raise", "nan", "keep")

#: Names of interior-orientation parameters that can be differentiated (self-calibration).
IO_PARAMETERS = ("f", "x0", "y0", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")


def _check_behind(behind: str) -> None:
    if behind not in BEHIND_CHOICES:
        raise InputError(f"behind must be one of {', '.join(BEHIND_CHOICES)}, not {behind!r}")


def in_front(ground, eo: ExteriorOrientation) -> np.ndarray:
    """Which ground points lie in front of the camera (camera-frame ``w < 0``).

    Parameters
    ----------
    ground : array_like, shape (n, 3) or (3,)
        Object-space coordinates, object units (e.g. m).
    eo : ExteriorOrientation
        Orientation of the image.

    Returns
    -------
    numpy.ndarray of bool, shape (n,) (or a 0-d bool for a single point (3,))
        ``True`` for points in front of the camera.

    Raises
    ------
    InputError
        When ``ground`` is not of shape (n, 3) or holds NaN/infinite values.
    """
    g, single = as_points_single(ground, 3, "ground points")
    return one_or_many(eo.to_camera(g)[:, 2] < 0, single)


def _behind_error(mask_behind: np.ndarray) -> DegenerateGeometryError:
    idx = np.flatnonzero(mask_behind)
    shown = ", ".join(str(int(i)) for i in idx[:10]) + (" ..." if idx.size > 10 else "")
    return DegenerateGeometryError(
        f"{idx.size} point(s) lie behind the camera or in its principal plane (row index "
        f"{shown}); their projection is meaningless. Check the exterior orientation (angles "
        "are radians; the camera looks along its -z axis) or pass behind='nan' to get NaN "
        "for those points"
    )


def project(
    ground_xyz,
    io: InteriorOrientation,
    eo: ExteriorOrientation,
    *,
    system: str = "image",
    behind: str = "raise",
    pixel_origin: str = "center",
) -> np.ndarray:
    """Project ground points into the image with the collinearity equations.

    Parameters
    ----------
    ground_xyz : array_like, shape (n, 3) or (3,)
        Object-space coordinates (e.g. metres).
    io : InteriorOrientation
    eo : ExteriorOrientation
    system : {"image", "pixel"}
        ``"image"``: image coordinates ``(x, y)`` in the unit of ``io`` (right-handed, y up).
        ``"pixel"``: ``(col, row)`` through ``io.image_to_pixel`` (needs pixel geometry).
    behind : {"raise", "nan", "keep"}
        Points behind the camera (``w >= 0``): raise :class:`DegenerateGeometryError`,
        return NaN for them, or keep the (meaningless) mirrored projection.
    pixel_origin : {"center", "corner"}
        Pixel convention for ``system="pixel"``.

    Returns
    -------
    numpy.ndarray, shape (n, 2) (or (2,) for a single point)
    """
    _check_behind(behind)
    arr = as_float64(ground_xyz, "ground points")
    single = arr.ndim == 1
    g = as_points(arr, 3, "ground points")
    n = g.shape[0]
    xy = np.empty((n, 2))
    back = np.zeros(n, dtype=bool)
    MT = eo.matrix.T
    X0 = eo.position
    with np.errstate(divide="ignore", invalid="ignore"):
        for s in range(0, n, CHUNK):  # blocks keep temporaries in cache (not a per-point loop)
            e = min(s + CHUNK, n)
            p = (g[s:e] - X0) @ MT
            iw = 1.0 / p[:, 2]
            back[s:e] = ~(p[:, 2] < 0)
            p[:, 0] *= -iw
            p[:, 1] *= iw
            xy[s:e] = io.image_from_normalized(p[:, :2])
    if np.any(back):
        if behind == "raise":
            raise _behind_error(back)
        if behind == "nan":
            xy[back] = np.nan
    if system == "pixel":
        xy = io.image_to_pixel(xy, pixel_origin)
    elif system != "image":
        raise InputError(f"system must be 'image' or 'pixel', not {system!r}")
    return xy[0] if single else xy


def image_rays(
    image_xy,
    io: InteriorOrientation,
    eo: ExteriorOrientation,
    *,
    system="image",
    pixel_origin: str = "center",
    tol: float = 1e-9,
):
    """Rays from the projection centre through image points.

    Parameters
    ----------
    image_xy : array_like, shape (n, 2) or (2,)
        Image coordinates in the unit of ``io`` (or pixels with ``system="pixel"``).
    io, eo
        Orientation of the image.
    system : {"image", "pixel"}
        ``"image"``: ``(x, y)`` in the unit of ``io`` (right-handed, y up); ``"pixel"``:
        ``(col, row)``, converted by ``io.pixel_to_image`` (needs pixel geometry).
    pixel_origin : {"center", "corner"}
        Pixel convention for ``system="pixel"``: ``"center"`` puts the centre of the
        top-left pixel at (0, 0), ``"corner"`` its top-left corner.
    tol : float
        Undistortion tolerance in the unit of ``io``; points that do not converge raise
        :class:`~photogeom.errors.ConvergenceError`.

    Returns
    -------
    origin : numpy.ndarray, shape (3,)
        The projection centre.
    directions : numpy.ndarray, shape (n, 3) (or (3,) for a single point (2,))
        Unit direction vectors in the object system, pointing away from the camera into
        the scene.
    """
    a, single = as_points_single(image_xy, 2, "image points")
    if system == "pixel":
        a = io.pixel_to_image(a, pixel_origin)
    elif system != "image":
        raise InputError(f"system must be 'image' or 'pixel', not {system!r}")
    xn = io.normalized_from_image(a, tol=tol)
    # camera frame: u = -xn * (-w) ... with w = -1: (u, v, w) = (xn, -yn, -1)
    pc = np.stack([xn[:, 0], -xn[:, 1], -np.ones(len(xn))], axis=1)
    d = pc @ eo.matrix  # M.T @ pc for each row
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return eo.position, one_or_many(d, single)


def ground_at_height(
    image_xy,
    io: InteriorOrientation,
    eo: ExteriorOrientation,
    Z,
    *,
    system: str = "image",
    pixel_origin: str = "center",
    behind: str = "raise",
) -> np.ndarray:
    """Intersect image rays with horizontal planes ``Z = const`` (monoplotting).

    Parameters
    ----------
    image_xy : array_like, shape (n, 2) or (2,)
        Image coordinates in the unit of ``io`` (or pixels with ``system="pixel"``).
    io, eo
        Orientation of the image.
    Z : float or array_like, shape (n,)
        Height of the plane per point, in object units.
    system, pixel_origin
        As in :func:`image_rays`.
    behind : {"raise", "nan"}
        A plane that the ray meets behind the camera (or never: ray parallel to it):
        raise :class:`DegenerateGeometryError` or return NaN for the point.

    Returns
    -------
    numpy.ndarray, shape (n, 3) (or (3,) for a single point (2,))
        Ground points, object units.
    """
    if behind not in ("raise", "nan"):
        raise InputError("behind must be 'raise' or 'nan' for ground_at_height")
    a, single = as_points_single(image_xy, 2, "image points")
    C, d = image_rays(a, io, eo, system=system, pixel_origin=pixel_origin)
    Zs = (
        np.broadcast_to(as_float64(Z, "heights Z", coordinates=False).reshape(-1), (d.shape[0],))
        if np.ndim(Z)
        else (np.full(d.shape[0], float(Z)))
    )
    if not np.all(np.isfinite(Zs)):
        raise InputError("heights Z contain NaN or infinite values")
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (Zs - C[2]) / d[:, 2]
    bad = ~(np.isfinite(t) & (t > 0))
    if np.any(bad) and behind == "raise":
        idx = np.flatnonzero(bad)
        raise DegenerateGeometryError(
            f"{idx.size} ray(s) do not meet their height plane in front of the camera (row index "
            f"{', '.join(str(int(i)) for i in idx[:10])}): the ray is parallel to the plane or "
            "the plane lies behind the camera. Check Z and the orientation, or pass behind='nan'"
        )
    out = C + t[:, None] * d
    out[bad] = np.nan
    return one_or_many(out, single)


# --- derivatives (used by resection, intersection and self-calibration) --------------------


@dataclass(frozen=True)
class ProjectionDerivatives:
    """Image coordinates and their derivatives for n points.

    Attributes
    ----------
    xy : (n, 2) image coordinates (unit of the interior orientation).
    d_eo : (n, 2, 6) w.r.t. X0, Y0, Z0, omega, phi, kappa (angles in radians).
    d_io : (n, 2, k) w.r.t. the requested interior parameters.
    d_ground : (n, 2, 3) w.r.t. the ground point X, Y, Z.
    w : (n,) camera-frame depth (negative in front of the camera).
    """

    xy: np.ndarray
    d_eo: np.ndarray
    d_io: np.ndarray
    d_ground: np.ndarray
    w: np.ndarray


def projection_derivatives(
    ground, io: InteriorOrientation, eo: ExteriorOrientation, io_parameters=()
) -> ProjectionDerivatives:
    """Analytic derivatives of the collinearity projection (vectorised over points).

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Object-space coordinates, object units (e.g. m).
    io, eo
        Orientation.
    io_parameters : sequence of str, default ()
        Interior parameters to differentiate, from :data:`IO_PARAMETERS`.

    Returns
    -------
    ProjectionDerivatives
        Image coordinates ``xy`` (n, 2) in the unit of ``io`` and their derivatives
        ``d_eo`` (n, 2, 6; per object unit and per rad), ``d_io`` (n, 2, k), ``d_ground``
        (n, 2, 3), with the camera-frame depth ``w`` (n,).
    """
    g = np.asarray(ground, dtype=float).reshape(-1, 3)
    return _projection_derivatives(
        g, io, eo.position, (eo.omega, eo.phi, eo.kappa), tuple(io_parameters)
    )


def _projection_derivatives(
    g: np.ndarray, io: InteriorOrientation, position, angles, names: tuple
) -> ProjectionDerivatives:
    """:func:`projection_derivatives` for ground points (n, 3), the projection centre (3,)
    and the angles (radians) as plain values."""
    M, dMs = opk_matrix_and_derivatives(*angles)
    n = g.shape[0]
    d = g - position
    p = d @ M.T
    u, v, w = p[:, 0], p[:, 1], p[:, 2]
    iw = 1.0 / w
    # d(xn, yn)/dp  (n, 2, 3)
    Np = np.zeros((n, 2, 3))
    Np[:, 0, 0] = -iw
    Np[:, 0, 2] = u * iw * iw
    Np[:, 1, 1] = iw
    Np[:, 1, 2] = -v * iw * iw
    dist = io.distortion
    xy_n = np.empty((n, 2))
    np.multiply(u, -iw, out=xy_n[:, 0])
    np.multiply(v, iw, out=xy_n[:, 1])
    C = np.array([[io.fx, io.b2], [0.0, -io.f]])
    if dist is not None:
        xd_yd = dist.distort(xy_n)
        G = np.einsum("ij,njk->nik", C, dist.jacobian(xy_n))  # d(x, y)/d(xn, yn)
        Gp = np.matmul(G, Np)  # d(x, y)/dp  (n, 2, 3)
    else:
        xd_yd = xy_n
        Gp = np.matmul(C, Np)
    xd, yd = xd_yd[:, 0], xd_yd[:, 1]
    xy = xd_yd @ C.T
    xy += (io.x0, io.y0)
    d_ground = Gp @ M  # dp/dX = M
    d_eo = np.empty((n, 2, 6))
    np.negative(d_ground, out=d_eo[:, :, :3])
    # the three angles at once: rows j of dp_all are dM_j (X - X0)
    dp_all = (d @ np.concatenate(dMs).T).reshape(n, 3, 3)
    np.matmul(Gp, np.swapaxes(dp_all, 1, 2), out=d_eo[:, :, 3:])
    d_io = np.zeros((g.shape[0], 2, len(names)))
    dist_names = [n for n in names if n in ("k1", "k2", "k3", "k4", "p1", "p2")]
    if dist_names:
        from .distortion import BrownDistortion

        dd = (dist or BrownDistortion()).coefficient_jacobian(xy_n, dist_names)
        dd = np.einsum("ij,njk->nik", C, dd)
    for j, name in enumerate(names):
        if name == "f":
            d_io[:, 0, j], d_io[:, 1, j] = xd, -yd
        elif name == "b1":
            d_io[:, 0, j] = xd
        elif name == "b2":
            d_io[:, 0, j] = yd
        elif name == "x0":
            d_io[:, 0, j] = 1.0
        elif name == "y0":
            d_io[:, 1, j] = 1.0
        elif name in dist_names:
            d_io[:, :, j] = dd[:, :, dist_names.index(name)]
        else:
            raise InputError(
                f"unknown interior parameter {name!r}; known: {', '.join(IO_PARAMETERS)}"
            )
    return ProjectionDerivatives(xy, d_eo, d_io, d_ground, w)


# --- an oriented camera ----------------------------------------------------------------------


@dataclass(frozen=True)
class FrameCamera:
    """An oriented frame camera: interior and exterior orientation together.

    Attributes
    ----------
    interior : InteriorOrientation
    exterior : ExteriorOrientation
    """

    interior: InteriorOrientation
    exterior: ExteriorOrientation

    def project(self, ground_xyz, **kwargs) -> np.ndarray:
        """:func:`project` with this camera's orientations.

        Parameters
        ----------
        ground_xyz : array_like, shape (n, 3) or (3,)
            Object-space coordinates, object units (e.g. m).
        **kwargs
            ``system``, ``behind``, ``pixel_origin`` of :func:`project`.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            Image coordinates in the unit of the interior orientation (or pixels with
            ``system="pixel"``).
        """
        return project(ground_xyz, self.interior, self.exterior, **kwargs)

    def rays(self, image_xy, **kwargs):
        """:func:`image_rays` with this camera's orientations.

        Parameters
        ----------
        image_xy : array_like, shape (n, 2) or (2,)
            Image coordinates in the unit of the interior orientation (or pixels with
            ``system="pixel"``).
        **kwargs
            ``system``, ``pixel_origin``, ``tol`` of :func:`image_rays`.

        Returns
        -------
        origin : numpy.ndarray, shape (3,)
            The projection centre, object units.
        directions : numpy.ndarray, shape (n, 3) or (3,)
            Unit direction vectors in the object system, pointing into the scene.
        """
        return image_rays(image_xy, self.interior, self.exterior, **kwargs)

    def ground_at_height(self, image_xy, Z, **kwargs) -> np.ndarray:
        """:func:`ground_at_height` with this camera's orientations.

        Parameters
        ----------
        image_xy : array_like, shape (n, 2) or (2,)
            Image coordinates in the unit of the interior orientation (or pixels with
            ``system="pixel"``).
        Z : float or array_like, shape (n,)
            Height of the plane per point, object units.
        **kwargs
            ``system``, ``pixel_origin``, ``behind`` of :func:`ground_at_height`.

        Returns
        -------
        numpy.ndarray, shape (n, 3) or (3,)
            Ground points, object units.
        """
        return ground_at_height(image_xy, self.interior, self.exterior, Z, **kwargs)

    def to_dict(self, angle_unit: str = "rad") -> dict:
        """JSON-ready parameters.

        Parameters
        ----------
        angle_unit : str, default "rad"
            Unit of the exterior angles in the result (``"rad"``, ``"deg"``, ``"gon"``, ...).

        Returns
        -------
        dict
            ``{"model": "frame_camera", "interior": {...}, "exterior": {...}}`` as written by
            :meth:`InteriorOrientation.to_dict` and :meth:`ExteriorOrientation.to_dict`.
        """
        return {
            "model": "frame_camera",
            "interior": self.interior.to_dict(),
            "exterior": self.exterior.to_dict(angle_unit),
        }

    @classmethod
    def from_dict(cls, data) -> FrameCamera:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : Mapping
            With the keys ``"interior"`` and ``"exterior"``.

        Returns
        -------
        FrameCamera

        Raises
        ------
        InputError
            When a key is missing (named in the message), or from the orientations' ``from_dict``.
        """
        try:
            return cls(
                InteriorOrientation.from_dict(data["interior"]),
                ExteriorOrientation.from_dict(data["exterior"]),
            )
        except KeyError as exc:
            raise InputError(f"frame camera: missing {exc.args[0]!r}") from exc
