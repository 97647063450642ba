"""The block: camera groups, images, points and image observations, keyed by ids.

A :class:`Block` is immutable and stored as arrays (fast at thousands of images and millions
of observations); mapping-style views (``block.images[image_id]``, ``block.points[point_id]``)
build small records on demand. Every table is keyed by ids, never by row position, so that
blocks can be filtered and merged.

Conventions (06-bundle-adjustment.md, 01-conventions.md):

* cameras are :class:`~photogeom.camera.MetashapeCalibration` (pixels);
* an image's exterior orientation is the photogrammetric one: projection centre
  ``(X0, Y0, Z0)`` and ``M = M3(kappa) M2(phi) M1(omega)`` (object -> image system);
* image observations ``(u, v)`` are pixels with the centre of the first pixel at (0, 0);
* point roles: ``"tie"`` (unknown), ``"control"`` (surveyed, enters the adjustment with its
  standard deviations), ``"check"`` (surveyed, kept out of the adjustment and compared
  afterwards).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..camera.exterior import ExteriorOrientation
from ..camera.metashape import MetashapeCalibration
from ..errors import InputError
from ..records import FrozenMapping, ReadOnlyRecord, read_only_fields, setstate_read_only, value_eq
from ..rotation import opk_matrix

#: Calibration parameters of the Metashape frame model, in the order of the flat vectors.
CALIBRATION_NAMES = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")
#: Parameters Metashape refines by default ("Optimize cameras").
DEFAULT_FREE = ("f", "cx", "cy", "k1", "k2", "k3", "p1", "p2")
#: Parameters that may vary per image ("image-variant" calibration, Hastedt et al. 2002).
IMAGE_VARIANT_NAMES = ("f", "cx", "cy")
ROLES = ("tie", "control", "check")
EO_NAMES = ("X0", "Y0", "Z0", "omega", "phi", "kappa")


def _ids(values, what: str) -> np.ndarray:
    a = np.array(values)  # a copy: the block must not share the caller's array
    if a.size == 0 and a.dtype.kind == "f":  # [] (numpy makes it float64): no ids
        a = a.astype(np.int64)
    if a.ndim != 1:
        raise InputError(f"{what}: ids must be a flat sequence, got shape {a.shape}")
    if a.dtype.kind not in "iuUO":
        raise InputError(f"{what}: ids must be integers or strings, got dtype {a.dtype}")
    if a.dtype.kind == "O":
        a = a.astype(str)
    return a


def _unique_check(ids: np.ndarray, what: str) -> None:
    u, c = np.unique(ids, return_counts=True)
    if u.size != ids.size:
        dup = u[c > 1][:5]
        raise InputError(f"{what}: duplicate id(s) {', '.join(map(str, dup))}")


def _lookup(keys: np.ndarray, ids: np.ndarray, what: str, table: str) -> np.ndarray:
    """Row index of each of ``ids`` in ``keys`` (vectorised); named error for unknown ids."""
    if ids.size == 0:
        return np.zeros(0, dtype=np.int64)
    if keys.dtype.kind != ids.dtype.kind and not (
        keys.dtype.kind in "iu" and ids.dtype.kind in "iu"
    ):
        raise InputError(
            f"{what}: ids are of type {ids.dtype} but the {table} ids are {keys.dtype}; use one "
            "kind of id (all integers or all strings)"
        )
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    pos = np.searchsorted(sk, ids)
    pos = np.clip(pos, 0, max(sk.size - 1, 0))
    ok = sk.size > 0 and True
    found = (sk[pos] == ids) if ok else np.zeros(ids.size, bool)
    if not np.all(found):
        bad = np.unique(ids[~found])[:5]
        raise InputError(
            f"{what}: unknown {table} id(s) {', '.join(map(str, bad))} (not in block.{table})"
        )
    return order[pos].astype(np.int64)


#: Replace every writable array field of a frozen dataclass by a read-only view of it, so
#: that blocks derived from one another (``replace``, ``with_observations``, the adjusted
#: block of :func:`~photogeom.bundle_adjust`) can share their arrays without a write through
#: one of them changing the others. The given arrays keep their flags.
_freeze_arrays = read_only_fields


@dataclass(frozen=True, eq=False)
class Image(ReadOnlyRecord):
    """One image of a block (a view; the block stores arrays).

    Attributes
    ----------
    id : object
        Image id.
    camera : object
        Id of its camera group (a key of ``Block.cameras``).
    exterior : ExteriorOrientation
        Projection centre (object units) and omega, phi, kappa (radians).
    gnss, gnss_sigma : numpy.ndarray, shape (3,), or None
        Observed projection centre and its standard deviations, object units; None
        without GNSS.
    imu, imu_sigma : numpy.ndarray, shape (3,), or None
        Observed omega, phi, kappa and their standard deviations, radians; None without IMU.
    calibration_offset : numpy.ndarray, shape (3,)
        The image's offsets of f, cx, cy from its group's calibration, px.
    """

    id: object
    camera: object
    exterior: ExteriorOrientation
    gnss: np.ndarray | None = None
    gnss_sigma: np.ndarray | None = None
    imu: np.ndarray | None = None
    imu_sigma: np.ndarray | None = None
    calibration_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    __eq__ = value_eq  # by value, arrays element by element (not hashable: arrays writable)
    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class Point(ReadOnlyRecord):
    """One object point of a block (a view).

    Attributes
    ----------
    id : object
        Point id.
    xyz : numpy.ndarray, shape (3,)
        Object coordinates, object units.
    role : {"tie", "control", "check"}
        The point's role.
    sigma : numpy.ndarray, shape (3,), or None
        Standard deviations of the surveyed coordinates, object units; None when none
        were given.
    """

    id: object
    xyz: np.ndarray
    role: str
    sigma: np.ndarray | None = None

    __eq__ = value_eq  # by value, arrays element by element (not hashable: arrays writable)
    __hash__ = None  # type: ignore[assignment]


class _View(Mapping):
    def __init__(self, keys: np.ndarray, make) -> None:
        self._keys = keys
        self._make = make
        self._index: dict | None = None

    def _idx(self) -> dict:
        if self._index is None:
            self._index = {k: i for i, k in enumerate(self._keys.tolist())}
        return self._index

    def __getitem__(self, key):
        try:
            i = self._idx()[key]
        except (KeyError, TypeError):
            raise KeyError(key) from None
        return self._make(i)

    def __iter__(self) -> Iterator:
        return iter(self._keys.tolist())

    def __len__(self) -> int:
        return int(self._keys.size)


@dataclass(frozen=True, eq=False)
class Observations:
    """Image observations: one row per (image, point) measurement.

    Attributes
    ----------
    image_ids, point_ids : numpy.ndarray, shape (n,)
    uv : numpy.ndarray, shape (n, 2)
        Pixels, centre of the first pixel at (0, 0).
    sigma : numpy.ndarray, shape (n,)
        A-priori standard deviation of u and of v, pixels.
    """

    image_ids: np.ndarray
    point_ids: np.ndarray
    uv: np.ndarray
    sigma: np.ndarray

    def __post_init__(self) -> None:
        _freeze_arrays(self)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only

    def __len__(self) -> int:
        return int(self.uv.shape[0])


@dataclass(frozen=True, eq=False)
class ColmapImages:
    """The COLMAP identity of the images of a block read from a COLMAP text model.

    COLMAP's ``IMAGE_ID`` and ``CAMERA_ID`` are keys of its database and ``NAME`` the image's
    file name; a block keys its images by one of ``IMAGE_ID`` and ``NAME`` only
    (``read_colmap(image_key=...)``). :func:`~photogeom.bundle.write_colmap` writes the other
    one back from here, so that a read-adjust-write round trip keeps both.

    Attributes
    ----------
    keys : numpy.ndarray, shape (k,)
        Block image ids (``Block.image_ids`` as read).
    image_id : numpy.ndarray of int64, shape (k,)
        COLMAP's ``IMAGE_ID`` of each key.
    name : numpy.ndarray of str, shape (k,)
        COLMAP's ``NAME`` of each key.
    """

    keys: np.ndarray
    image_id: np.ndarray
    name: np.ndarray

    def __post_init__(self) -> None:
        _freeze_arrays(self)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only

    def lookup(self, image_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """``IMAGE_ID`` and ``NAME`` of each of ``image_ids`` (vectorised).

        Parameters
        ----------
        image_ids : numpy.ndarray, shape (m,)
            Block image ids.

        Returns
        -------
        tuple of numpy.ndarray (m,), or None
            The COLMAP ids and names, or None when one of ``image_ids`` is not a key (a
            block whose images were renamed or added after reading).
        """
        keys = self.keys
        if image_ids.size == 0 or keys.size == 0:
            return None
        if keys.dtype.kind != image_ids.dtype.kind and not (
            keys.dtype.kind in "iu" and image_ids.dtype.kind in "iu"
        ):
            return None
        order = np.argsort(keys, kind="stable")
        pos = np.clip(np.searchsorted(keys[order], image_ids), 0, keys.size - 1)
        if not np.all(keys[order][pos] == image_ids):
            return None
        row = order[pos]
        return self.image_id[row], self.name[row]


@dataclass(frozen=True, eq=False)
class Block:
    """An image block (see the module docstring). Build with :meth:`from_arrays`.

    Array rows are in the order of the ids: m images, p points, n image observations. The
    arrays are read-only views (blocks derived from one another share them); copy one to
    change it and pass the copy to :meth:`replace`.

    Attributes
    ----------
    camera_ids : numpy.ndarray, shape (g,)
        Camera group ids.
    calibrations : tuple of MetashapeCalibration
        The calibration of each group, in the order of ``camera_ids`` (f, cx, cy, b1, b2 in
        pixels).
    image_ids : numpy.ndarray, shape (m,)
        Image ids.
    image_camera : numpy.ndarray of int, shape (m,)
        Row of each image's group in ``camera_ids``.
    exterior : numpy.ndarray, shape (m, 6)
        X0, Y0, Z0 (object units) and omega, phi, kappa (rad) per image.
    calibration_offset : numpy.ndarray, shape (m, 3)
        Per-image offsets of f, cx, cy (px) of image-variant calibration; zero otherwise.
    gnss, gnss_sigma : numpy.ndarray, shape (m, 3)
        Observed projection centres (object units) and their standard deviations; NaN rows
        for images without GNSS.
    imu, imu_sigma : numpy.ndarray, shape (m, 3)
        Observed omega, phi, kappa (rad) and their standard deviations; NaN rows for images
        without IMU.
    point_ids : numpy.ndarray, shape (p,)
        Point ids.
    xyz : numpy.ndarray, shape (p, 3)
        Object coordinates (approximate for tie points before an adjustment).
    role : numpy.ndarray of str, shape (p,)
        ``"tie"``, ``"control"`` or ``"check"`` per point.
    point_sigma : numpy.ndarray, shape (p, 3)
        Standard deviations of the surveyed coordinates, object units (those of ``xyz``);
        NaN where none were given
        (:meth:`from_arrays` broadcasts a given ``point_sigma`` to tie points too).
    observations : Observations
        The image observations: image and point ids, pixels ``uv`` (n, 2) and their sigma
        (n,), px.
    obs_image, obs_point : numpy.ndarray of int, shape (n,)
        Rows of the image and point of each observation.
    free : mapping group id -> tuple of str
        The calibration parameters the adjustment estimates for each group (read-only;
        ``replace(free=...)`` for others).
    image_variant : mapping group id -> tuple of str
        The parameters (of f, cx, cy) estimated per image for each group (read-only).
    crs : str or None
        CRS of the object coordinates, recorded and never used to compute; default None.
    surveyed : numpy.ndarray, shape (p, 3), or None
        The surveyed coordinates of control and check points (NaN for tie points) when
        ``xyz`` holds something else for them; default None (``xyz`` is the survey). The
        adjustment sets it: its block's ``xyz`` are the estimates (control points adjusted,
        check points triangulated), so an adjusted block adjusted again observes its
        control points where they were surveyed, not where the first adjustment put them,
        and compares its check points with the survey (:attr:`surveyed_xyz`).
    colmap_images : ColmapImages or None
        COLMAP's ``IMAGE_ID`` and ``NAME`` of the images of a block read from a COLMAP text
        model (both, whichever of them the image ids are), which
        :func:`~photogeom.bundle.write_colmap` writes back; default None. Kept by
        :meth:`replace` and the adjustment; a CSV block keeps it in the ``images.csv``
        columns ``colmap_image_id`` and ``colmap_name``; BAL has no place for it.
    joint_adjustment : JointAdjustmentRecord or None
        On the block of the final fit of :func:`~photogeom.calibration.adjust_with_grids`
        (``GridAdjustment.fit.block``): that joint adjustment (its estimate and settings),
        which :func:`~photogeom.calibration.readjust` takes as the first adjustment of its
        chain; default None. Kept by :meth:`replace` and every method deriving a block, by
        pickling and by a CSV block folder (its folder ``joint_adjustment``); an
        adjustment's block has none (it starts a chain of its own); COLMAP, BAL and
        Bundler files have no place for it (:func:`~photogeom.bundle.write_block` warns).
    """

    camera_ids: np.ndarray
    calibrations: tuple[MetashapeCalibration, ...]
    image_ids: np.ndarray
    image_camera: np.ndarray  # (m,) int index into camera_ids
    exterior: np.ndarray
    calibration_offset: np.ndarray
    gnss: np.ndarray
    gnss_sigma: np.ndarray
    imu: np.ndarray
    imu_sigma: np.ndarray
    point_ids: np.ndarray
    xyz: np.ndarray
    role: np.ndarray
    point_sigma: np.ndarray
    observations: Observations
    obs_image: np.ndarray
    obs_point: np.ndarray
    free: Mapping[object, tuple[str, ...]]
    image_variant: Mapping[object, tuple[str, ...]]
    crs: str | None = None
    surveyed: np.ndarray | None = None
    colmap_images: ColmapImages | None = None
    joint_adjustment: object | None = None

    def __post_init__(self) -> None:
        _freeze_arrays(self)
        d = self.__dict__
        for name in ("free", "image_variant"):  # shared by derived blocks: read-only
            if not isinstance(d[name], FrozenMapping):
                d[name] = FrozenMapping(d[name])

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only

    # --- construction --------------------------------------------------------------------

    @classmethod
    def from_arrays(
        cls,
        *,
        cameras: Mapping[object, MetashapeCalibration],
        image_ids: Sequence,
        image_camera: Sequence,
        exterior,
        point_ids: Sequence,
        xyz,
        obs_image_ids: Sequence,
        obs_point_ids: Sequence,
        uv,
        sigma=0.5,
        role: Sequence[str] | str = "tie",
        point_sigma=None,
        gnss=None,
        gnss_sigma=None,
        imu=None,
        imu_sigma=None,
        calibration_offset=None,
        free: Mapping[object, Sequence[str]] | Sequence[str] | None = None,
        image_variant: Mapping[object, Sequence[str]] | Sequence[str] | None = None,
        crs: str | None = None,
    ) -> Block:
        """Build a block from tables.

        Parameters
        ----------
        cameras : mapping group id -> MetashapeCalibration
        image_ids, image_camera : sequences (m,)
            Image ids and the camera group of each image.
        exterior : array_like (m, 6)
            X0, Y0, Z0, omega, phi, kappa (radians) per image: the current (initial) values.
        point_ids : sequence (p,)
            Point ids.
        xyz : array_like (p, 3)
            Object coordinates (approximate for tie points).
        obs_image_ids, obs_point_ids : sequences (n,)
            Image and point id of each image observation.
        uv : array_like (n, 2)
            Image observations in pixels (centre of the first pixel at (0, 0)).
        sigma : float or array_like (n,), default 0.5
            Standard deviation of u and v of each observation, pixels.
        role : str or sequence (p,), default "tie"
            ``"tie"``, ``"control"`` or ``"check"`` per point.
        point_sigma : array_like (p, 3) or (3,), optional
            Standard deviations of surveyed coordinates (control and check points), in the
            object units of ``xyz``.
        gnss, gnss_sigma : array_like (m, 3), optional
            Observed projection centres and their standard deviations, in the object units
            of ``xyz`` (NaN: none).
        imu, imu_sigma : array_like (m, 3), optional
            Observed omega, phi, kappa (radians) and standard deviations (NaN: none).
        calibration_offset : array_like (m, 3), optional
            Per-image offsets of f, cx, cy (pixels) for image-variant calibration.
        free : sequence of names, or mapping group -> names, optional
            Calibration parameters to estimate (default: f, cx, cy, k1, k2, k3, p1, p2).
        image_variant : sequence of names, or mapping group -> names, optional
            Subset of f, cx, cy estimated per image (default: none).
        crs : str, optional
            CRS of the object coordinates (exterior orientations, points, GNSS): an EPSG
            code, WKT, PROJ string or ``"enu:LAT,LON,H"``. Recorded, not converted:
            ``fit.crs`` of the adjustment and the ``# crs:`` line of a CSV block written.

        Returns
        -------
        Block
            The block; ids must be flat sequences of integers or strings.

        Raises
        ------
        InputError
            Duplicate camera, image or point ids; a camera that is not a
            :class:`MetashapeCalibration`; an unknown group, image or point id referenced;
            tables of the wrong shape or holding NaN or infinity; an unknown role; control
            or check points without positive, finite ``point_sigma``; sigmas that are not
            positive and finite; GNSS or IMU without their sigmas or with partly-NaN rows;
            unknown groups or parameter names in ``free`` or ``image_variant``.
        """
        cam_ids = _ids(list(cameras.keys()), "cameras")
        _unique_check(cam_ids, "cameras")
        cals = tuple(cameras[k] for k in cameras)
        for k, c in zip(cam_ids.tolist(), cals):
            if not isinstance(c, MetashapeCalibration):
                raise InputError(
                    f"camera {k!r}: expected a MetashapeCalibration, got {type(c).__name__}"
                )
        img = _ids(image_ids, "images")
        _unique_check(img, "images")
        m = img.size
        icam = _lookup(cam_ids, _ids(image_camera, "image cameras"), "images", "cameras")
        if icam.size != m:
            raise InputError(f"image_camera has {icam.size} entries for {m} images")
        eo = _table(exterior, (m, 6), "exterior")
        pid = _ids(point_ids, "points")
        _unique_check(pid, "points")
        p = pid.size
        X = _table(xyz, (p, 3), "xyz")
        if isinstance(role, str):
            roles = np.full(p, role, dtype="<U7")
        else:
            roles = np.array(role, dtype="<U7")  # a copy, as for the ids
            if roles.shape != (p,):
                raise InputError(f"role has shape {roles.shape}, expected ({p},)")
        bad = ~np.isin(roles, ROLES)
        if np.any(bad):
            raise InputError(
                f"point {pid[bad][0]}: role {roles[bad][0]!r} is not one of {', '.join(ROLES)}"
            )
        ps = np.full((p, 3), np.nan)
        if point_sigma is not None:
            ps = _broadcast(
                point_sigma, (p, 3), "point_sigma", f"(3,) for all points, or one row each ({p}, 3)"
            )
        surveyed = roles != "tie"
        if np.any(surveyed & ~np.all(np.isfinite(ps) & (ps > 0), axis=1)):
            first = pid[surveyed & ~np.all(np.isfinite(ps) & (ps > 0), axis=1)][0]
            raise InputError(
                f"point {first}: control and check points need positive standard deviations "
                "of their coordinates (point_sigma)"
            )
        oi = _ids(obs_image_ids, "observations")
        op = _ids(obs_point_ids, "observations")
        n = oi.size
        if op.size != n:
            raise InputError(f"observations: {n} image ids but {op.size} point ids")
        UV = _table(uv, (n, 2), "uv")
        sg = _observation_sigma(sigma, n)
        obs_i = _lookup(img, oi, "observations", "images")
        obs_p = _lookup(pid, op, "observations", "points")
        gn, gs = _optional_pair(gnss, gnss_sigma, m, "gnss")
        im, ims = _optional_pair(imu, imu_sigma, m, "imu")
        off = (
            np.zeros((m, 3))
            if calibration_offset is None
            else _table(calibration_offset, (m, 3), "calibration_offset")
        )
        freem = _per_group(free, cam_ids, DEFAULT_FREE, CALIBRATION_NAMES, "free")
        ivm = _per_group(image_variant, cam_ids, (), IMAGE_VARIANT_NAMES, "image_variant")
        return cls(
            camera_ids=cam_ids,
            calibrations=cals,
            image_ids=img,
            image_camera=icam,
            exterior=eo,
            calibration_offset=off,
            gnss=gn,
            gnss_sigma=gs,
            imu=im,
            imu_sigma=ims,
            point_ids=pid,
            xyz=X,
            role=roles,
            point_sigma=ps,
            observations=Observations(oi, op, UV, sg),
            obs_image=obs_i,
            obs_point=obs_p,
            free=freem,
            image_variant=ivm,
            crs=crs,
        )

    # --- mapping views (the public contract) ---------------------------------------------

    @property
    def cameras(self) -> Mapping[object, MetashapeCalibration]:
        """Camera group id -> :class:`MetashapeCalibration`."""
        return dict(zip(self.camera_ids.tolist(), self.calibrations))

    @property
    def images(self) -> Mapping[object, Image]:
        """Image id -> :class:`Image` (camera group id, exterior orientation, GNSS/IMU)."""
        return _View(self.image_ids, self._image)

    @property
    def points(self) -> Mapping[object, Point]:
        """Point id -> :class:`Point` (``xyz``, ``role``, ``sigma``)."""
        return _View(self.point_ids, self._point)

    def _image(self, i: int) -> Image:
        e = self.exterior[i]
        g = self.gnss[i] if np.all(np.isfinite(self.gnss[i])) else None
        u = self.imu[i] if np.all(np.isfinite(self.imu[i])) else None
        return Image(
            id=self.image_ids[i].item(),
            camera=self.camera_ids[self.image_camera[i]].item(),
            exterior=ExteriorOrientation(*e),
            gnss=None if g is None else g.copy(),
            gnss_sigma=None if g is None else self.gnss_sigma[i].copy(),
            imu=None if u is None else u.copy(),
            imu_sigma=None if u is None else self.imu_sigma[i].copy(),
            calibration_offset=self.calibration_offset[i].copy(),
        )

    def _point(self, j: int) -> Point:
        s = self.point_sigma[j]
        return Point(
            id=self.point_ids[j].item(),
            xyz=self.xyz[j].copy(),
            role=str(self.role[j]),
            sigma=None if not np.all(np.isfinite(s)) else s.copy(),
        )

    # --- sizes and derived arrays ----------------------------------------------------------

    @property
    def n_images(self) -> int:
        return int(self.image_ids.size)

    @property
    def n_points(self) -> int:
        return int(self.point_ids.size)

    @property
    def n_observations(self) -> int:
        return len(self.observations)

    def image_calibration(self, i: int) -> MetashapeCalibration:
        """The calibration of image row ``i`` (its group's, plus its image-variant offsets).

        Parameters
        ----------
        i : int
            Row of the image (not its id).

        Returns
        -------
        MetashapeCalibration
            The group's calibration itself when the image has no offsets, else a copy with
            f, cx, cy (px) shifted by them.
        """
        c = self.calibrations[self.image_camera[i]]
        d = self.calibration_offset[i]
        if not np.any(d):
            return c
        return replace(c, f=c.f + d[0], cx=c.cx + d[1], cy=c.cy + d[2])

    def calibration_matrix(self) -> np.ndarray:
        """Per-image calibration vectors in the order of ``CALIBRATION_NAMES``.

        Returns
        -------
        numpy.ndarray, shape (m, 11)
            The group's values plus the image-variant offsets of f, cx, cy (px).
        """
        G = np.array([[getattr(c, n) for n in CALIBRATION_NAMES] for c in self.calibrations])
        C = G[self.image_camera].copy() if G.size else np.zeros((0, 11))
        C[:, :3] += self.calibration_offset
        return C

    def image_sizes(self) -> np.ndarray:
        """Per-image (width, height) in pixels.

        Returns
        -------
        numpy.ndarray, shape (m, 2)
            Width and height of each image's camera group, px (float).
        """
        S = np.array([[c.width, c.height] for c in self.calibrations], dtype=float)
        return S[self.image_camera]

    def rotations(self) -> np.ndarray:
        """Rotation matrices ``M`` (object -> image system) per image.

        Returns
        -------
        numpy.ndarray, shape (m, 3, 3)
            From omega, phi, kappa of ``exterior``.
        """
        e = self.exterior
        return np.asarray(opk_matrix(e[:, 3], e[:, 4], e[:, 5])).reshape(-1, 3, 3)

    def observation_counts(self) -> tuple[np.ndarray, np.ndarray]:
        """Number of observations per image and per point.

        Returns
        -------
        per_image : numpy.ndarray of int, shape (m,)
        per_point : numpy.ndarray of int, shape (p,)
        """
        return (
            np.bincount(self.obs_image, minlength=self.n_images),
            np.bincount(self.obs_point, minlength=self.n_points),
        )

    def gsd(self) -> float:
        """Mean ground sample distance.

        Returns
        -------
        float
            Object units per pixel: the mean over the observations of the absolute depth of
            the point along the camera's viewing axis divided by the focal length (px, with
            the image-variant offset); NaN without observations.
        """
        if self.n_observations == 0:
            return float("nan")
        M = self.rotations()
        d = self.xyz[self.obs_point] - self.exterior[self.obs_image, :3]
        depth = -np.einsum("nj,nj->n", M[self.obs_image, 2, :], d)
        f = self.calibration_matrix()[self.obs_image, 0]
        return float(np.mean(np.abs(depth) / f))

    # --- new blocks ----------------------------------------------------------------------

    def replace(self, **changes) -> Block:
        """A new block with some arrays replaced (same ids and observations unless given).

        On a block without :attr:`surveyed` a new ``xyz`` is a new survey of its control and
        check points; on an adjusted block it changes the estimates and the survey stays.
        ``surveyed``, ``free`` and ``image_variant`` are checked; other values are taken as
        given, except that a writable array is copied (the block's arrays are read-only and
        its own: changing the array given afterwards does not change the block). ``free`` and
        ``image_variant`` take a sequence of names for every camera group or a mapping for
        some: groups the mapping leaves out keep the block's current names.

        Parameters
        ----------
        **changes
            New values of fields of the block by name (see the class attributes).

        Returns
        -------
        Block
            The new block; ``self`` is not modified.

        Raises
        ------
        InputError
            ``surveyed`` not of shape (p, 3), p the number of (new) point ids; ``free`` or
            ``image_variant`` naming an unknown camera group or parameter.
        TypeError
            An unknown field name.
        """
        cam_ids = np.asarray(changes.get("camera_ids", self.camera_ids))
        same_groups = "camera_ids" not in changes
        for name, default, allowed in (
            ("free", DEFAULT_FREE, CALIBRATION_NAMES),
            ("image_variant", (), IMAGE_VARIANT_NAMES),
        ):
            if name not in changes:
                continue
            value = changes[name]
            if isinstance(value, Mapping) and same_groups:
                # groups left out keep their names (unknown groups are refused below)
                value = {**getattr(self, name), **value}
            changes[name] = _per_group(value, cam_ids, default, allowed, name)
        s = changes.get("surveyed")
        if s is not None:
            s = np.array(s, dtype=float)
            p = len(changes.get("point_ids", self.point_ids))
            if s.shape != (p, 3):
                raise InputError(f"surveyed must have shape ({p}, 3), got {s.shape}")
            changes["surveyed"] = s
        for key, value in changes.items():
            if isinstance(value, np.ndarray) and value.flags.writeable:
                changes[key] = value.copy()
        return replace(self, **changes)

    @property
    def surveyed_xyz(self) -> np.ndarray:
        """(p, 3) coordinates of the points as surveyed: :attr:`surveyed` where it holds a
        value, ``xyz`` elsewhere (tie points: their current coordinates)."""
        if self.surveyed is None:
            return self.xyz
        return np.where(np.isfinite(self.surveyed), self.surveyed, self.xyz)

    @property
    def survey(self) -> np.ndarray:
        """(p, 3) the survey of the control and check points, NaN for tie points: what a
        block with new estimates in ``xyz`` passes as ``surveyed`` to keep it."""
        return np.where((self.role != "tie")[:, None], self.surveyed_xyz, np.nan)

    def without_datum_observations(self) -> Block:
        """A copy for a free network (``datum="free"``).

        Returns
        -------
        Block
            Control points become check points (kept out of the adjustment and compared
            with their survey, kept in ``surveyed``, afterwards); GNSS positions and IMU
            attitudes are removed (NaN).
        """
        return self.replace(
            role=np.where(self.role == "control", "check", self.role),
            gnss=np.full_like(self.gnss, np.nan),
            imu=np.full_like(self.imu, np.nan),
            surveyed=self.survey,
        )

    def with_calibrations(self, cameras: Mapping[object, MetashapeCalibration]) -> Block:
        """A new block with the calibrations of the given groups replaced.

        Parameters
        ----------
        cameras : mapping group id -> MetashapeCalibration
            The new calibrations (not type-checked); other groups keep theirs.

        Returns
        -------
        Block
            The new block; ``free`` and ``image_variant`` are unchanged.

        Raises
        ------
        InputError
            An unknown group id.
        """
        cals = list(self.calibrations)
        for k, c in cameras.items():
            idx = _lookup(self.camera_ids, _ids([k], "cameras"), "cameras", "cameras")[0]
            cals[idx] = c
        return replace(self, calibrations=tuple(cals))

    def select_observations(self, mask: np.ndarray) -> Block:
        """A new block keeping the observation rows where ``mask`` is true.

        Parameters
        ----------
        mask : array_like of bool, shape (n,)
            One value per observation row.

        Returns
        -------
        Block
            Images and points unchanged (points may be left with fewer observations).
        """
        mask = np.asarray(mask, dtype=bool)
        o = self.observations
        return replace(
            self,
            observations=Observations(
                o.image_ids[mask], o.point_ids[mask], o.uv[mask], o.sigma[mask]
            ),
            obs_image=self.obs_image[mask],
            obs_point=self.obs_point[mask],
        )

    def with_observations(self, uv=None, sigma=None) -> Block:
        """A new block with the observed pixels and/or their sigmas replaced (same rows).

        Parameters
        ----------
        uv : array_like (n, 2), optional
            Observed pixels (finite).
        sigma : float or array_like (n,), optional
            Standard deviation of u and v of each observation, pixels (positive, finite).

        Raises
        ------
        InputError
            ``uv`` of another shape or not finite; a ``sigma`` that is not positive and
            finite (the same checks as :meth:`from_arrays`).

        Returns
        -------
        Block
            The new block; the unchanged one of ``uv`` and ``sigma`` is kept.
        """
        o = self.observations
        n = len(o)
        UV = o.uv if uv is None else _table(uv, (n, 2), "uv")
        sg = o.sigma if sigma is None else _observation_sigma(sigma, n)
        return replace(self, observations=Observations(o.image_ids, o.point_ids, UV, sg))

    def same_observation_rows(self, other: Block) -> bool:
        """Whether ``other`` has the same observation rows as this block.

        Parameters
        ----------
        other : Block
            The block to compare with.

        Returns
        -------
        bool
            True when ``other`` observes the same point in the same image in every row of
            its observations as this block (ids compared; pixels and sigmas may differ).
        """
        return self.obs_image.size == other.obs_image.size and bool(
            np.array_equal(self.image_ids[self.obs_image], other.image_ids[other.obs_image])
            and np.array_equal(self.point_ids[self.obs_point], other.point_ids[other.obs_point])
        )

    def validate(self, *, min_image_observations: int = 3) -> None:
        """Refuse a block that no adjustment can solve, naming the ids at fault.

        Parameters
        ----------
        min_image_observations : int, default 3
            Fewest observations an image must have.

        Raises
        ------
        InputError
            Duplicate observations (an image observing a point twice), a block with one
            image that has observations, tie or control points
            observed in fewer than two images, check points with fewer than two observations
            (they cannot be triangulated) and images with fewer than
            ``min_image_observations`` observations.
        """
        key = self.obs_image.astype(np.int64) * max(self.n_points, 1) + self.obs_point
        u, c = np.unique(key, return_counts=True)
        if u.size != key.size:
            k = u[c > 1][0]
            i, j = divmod(int(k), max(self.n_points, 1))
            raise InputError(
                f"image {self.image_ids[i]} observes point {self.point_ids[j]} "
                f"{int(c[c > 1][0])} times: remove the duplicate observation(s)"
            )
        per_img, per_pt = self.observation_counts()
        seen = np.flatnonzero(per_img > 0)
        if seen.size == 1:  # every point "in fewer than two images": delete them all?
            raise InputError(
                f"the block has one image with observations ({self.image_ids[seen[0]]}): a "
                "bundle adjustment needs at least two images that observe the same points; "
                "add the block's other images and their observations"
            )
        once = per_pt < 2
        if np.any(once):
            tie = once & (self.role == "tie")
            parts = []
            if np.any(tie):
                parts.append(
                    f"{int(tie.sum())} tie point(s) are observed in fewer than two images and "
                    f"cannot be intersected: {_some(self.point_ids[tie])} (remove them with "
                    "Block.drop_weak_points(), or delete their rows from the block's files)"
                )
            if np.any(once & ~tie):
                parts.append(
                    f"{int((once & ~tie).sum())} control/check point(s) are observed in fewer "
                    f"than two images: {_some(self.point_ids[once & ~tie])} (measure them in "
                    "a second image, or remove them with Block.drop_weak_points(surveyed=True) "
                    "or by deleting their rows from the block's files)"
                )
            raise InputError("; ".join(parts))
        few = per_img < min_image_observations
        if np.any(few):
            ids = self.image_ids[few]
            raise InputError(
                f"{ids.size} image(s) have fewer than {min_image_observations} observations "
                f"and cannot be oriented: {_some(ids)} (measure more tie or control points in "
                "them, or delete the images and their observations from the block's files)"
            )

    def drop_weak_points(self, *, surveyed: bool = False) -> Block:
        """A new block without the points observed in fewer than two images (and their
        observations).

        Parameters
        ----------
        surveyed : bool
            Drop control and check points observed in fewer than two images too (the block
            then has fewer of them). Default: tie points only; such control and check
            points stay, and :meth:`validate` refuses them.

        Returns
        -------
        Block
            ``self`` when nothing is dropped, else the new block.
        """
        _, per_pt = self.observation_counts()
        keep_pt = (per_pt >= 2) | ((self.role != "tie") & (not surveyed))
        if np.all(keep_pt):
            return self
        return self.select_points(keep_pt)

    def select_points(self, keep: np.ndarray) -> Block:
        """A new block with only the points where ``keep`` is true, their observations,
        coordinates, roles, standard deviations and surveyed coordinates.

        Parameters
        ----------
        keep : numpy.ndarray of bool, shape (n_points,)
            The points to keep, in the block's point order.

        Returns
        -------
        Block
            The new block (the images and their cameras unchanged).
        """
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (self.n_points,):
            raise ValueError(f"keep has shape {keep.shape}; expected ({self.n_points},)")
        b = self.select_observations(keep[self.obs_point])
        newidx = np.cumsum(keep) - 1
        return replace(
            b,
            point_ids=self.point_ids[keep],
            xyz=self.xyz[keep],
            role=self.role[keep],
            point_sigma=self.point_sigma[keep],
            obs_point=newidx[b.obs_point],
            surveyed=None if self.surveyed is None else self.surveyed[keep],
        )

    def summary(self) -> str:
        """A few lines: sizes, roles, observations per image and per point.

        Returns
        -------
        str
            The lines joined by newlines (min, median, max per image and per point when
            there are images and points).
        """
        per_img, per_pt = self.observation_counts()
        roles = {r: int(np.sum(self.role == r)) for r in ROLES}
        lines = [
            f"block: {len(self.calibrations)} camera group(s), {self.n_images} images, "
            f"{self.n_points} points ({roles['tie']} tie, {roles['control']} control, "
            f"{roles['check']} check), {self.n_observations} image observations",
        ]
        if self.n_images:
            lines.append(
                f"observations per image: min {per_img.min()}, median "
                f"{int(np.median(per_img))}, max {per_img.max()}"
            )
        if self.n_points:
            lines.append(
                f"images per point: min {per_pt.min()}, median {int(np.median(per_pt))}, "
                f"max {per_pt.max()}"
            )
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (
            f"Block({len(self.calibrations)} cameras, {self.n_images} images, "
            f"{self.n_points} points, {self.n_observations} observations)"
        )


def _table(values, shape: tuple[int, int], name: str) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot be read as numbers ({exc})") from exc
    if a.shape == (shape[1],) and shape[0] == 1:
        a = a[None, :]
    if a.shape != shape:
        raise InputError(f"{name}: expected shape {shape}, got {a.shape}")
    bad = ~np.all(np.isfinite(a), axis=1)
    if np.any(bad):
        raise InputError(f"{name}: row {int(np.flatnonzero(bad)[0])} holds NaN or infinity")
    return a.copy()


def _some(ids: np.ndarray, k: int = 8) -> str:
    """The first ``k`` ids, comma-separated (`` ...`` when there are more)."""
    return ", ".join(map(str, ids[:k].tolist())) + (" ..." if ids.size > k else "")


def _broadcast(values, shape: tuple[int, ...], name: str, expected: str, exact: bool = False):
    """``values`` as a float array of ``shape`` (a copy), broadcast unless ``exact`` (a single
    row is also taken for a table of one row); :class:`InputError` naming ``name`` and the
    ``expected`` shapes otherwise."""
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot be read as numbers ({exc})") from None
    if exact and a.shape != shape and not (a.shape == shape[1:] and shape[0] == 1):
        raise InputError(f"{name}: shape {a.shape} does not fit; expected {expected}")
    try:
        return np.broadcast_to(a, shape).copy()
    except ValueError:
        raise InputError(f"{name}: shape {a.shape} does not fit; expected {expected}") from None


def _observation_sigma(sigma, n: int) -> np.ndarray:
    """Standard deviations of ``n`` observations (one value for all, or one each): positive
    and finite, else :class:`InputError` naming the first bad one."""
    sg = _broadcast(sigma, (n,), "sigma", f"one value, or one per observation ({n},)")
    bad = ~np.isfinite(sg) | (sg <= 0)
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"observation sigma must be positive and finite (pixels); observation row {k} has "
            f"{float(sg[k])!r}"
        )
    return sg


def _optional_pair(values, sigmas, m: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    if values is None:
        return np.full((m, 3), np.nan), np.full((m, 3), np.nan)
    v = _broadcast(values, (m, 3), name, f"one row per image ({m}, 3), NaN for none", exact=True)
    if sigmas is None:
        raise InputError(f"{name}: observations given without standard deviations ({name}_sigma)")
    s = _broadcast(
        sigmas, (m, 3), f"{name}_sigma", f"(3,) for every image, or one row per image ({m}, 3)"
    )
    has = np.all(np.isfinite(v), axis=1)
    partial = np.any(np.isfinite(v), axis=1) & ~has
    if np.any(partial):
        raise InputError(f"{name}: row {int(np.flatnonzero(partial)[0])} is partly NaN")
    if np.any(has & ~np.all(np.isfinite(s) & (s > 0), axis=1)):
        raise InputError(f"{name}_sigma must be positive and finite where {name} is given")
    s[~has] = np.nan
    return v, s


def _per_group(value, cam_ids, default, allowed, name) -> dict:
    if value is None or isinstance(value, (str, bytes)) or not isinstance(value, Mapping):
        names = default if value is None else ((value,) if isinstance(value, str) else value)
        out = {k: tuple(names) for k in cam_ids.tolist()}
    else:
        out = {k: tuple(value.get(k, default)) for k in cam_ids.tolist()}
        unknown = set(value) - set(cam_ids.tolist())
        if unknown:
            raise InputError(f"{name}: unknown camera group(s) {sorted(map(str, unknown))}")
    for k, names in out.items():
        bad = [n for n in names if n not in allowed]
        if bad:
            raise InputError(
                f"{name} of camera {k!r}: unknown parameter(s) {bad}; choose from "
                f"{', '.join(allowed)}"
            )
        out[k] = tuple(n for n in allowed if n in names)  # canonical order
    return out
