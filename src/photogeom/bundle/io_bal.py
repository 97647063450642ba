"""BAL files (Bundle Adjustment in the Large, Agarwal et al. 2010): read and write.

The format (plain text, optionally bzip2-compressed)::

    <num_cameras> <num_points> <num_observations>
    <camera_index> <point_index> <x> <y>          one line per observation
    ...
    <camera parameters>                           9 numbers per camera
    ...
    <point coordinates>                           3 numbers per point
    ...

BAL's conventions and how photogeom maps them:

* A camera is 9 numbers: a Rodrigues (axis-angle) vector ``r`` and a translation ``t``
  (world -> camera: ``P = R(r) X + t``), the focal length ``f`` and radial terms ``k1, k2``.
* The camera looks down its -z axis, x right, y up: ``p = -P / P_z``,
  ``x = f (1 + k1 |p|^2 + k2 |p|^4) p_x`` and likewise y; ``(x, y)`` in pixels from the
  principal point (the image centre), y up.
* BAL's camera frame *is* the photogrammetric image system (x right, y up, z backwards), so
  ``M = R(r)`` and the projection centre is ``X0 = -R^T t``; omega, phi, kappa are the angles
  of ``M``. The radial model is Metashape's with ``K1 = k1, K2 = k2`` and everything else
  zero (``|p|`` is the same in both camera frames).
* Every image has its own camera: one camera group per image (group id = image id), with
  ``f, k1, k2`` free and the principal point fixed at the image centre (``cx = cy = 0``), the
  problem BAL's own solvers (Ceres' ``bundle_adjuster``) solve.
* BAL has no image size. photogeom needs one to place its pixel origin (centre of the first
  pixel at (0, 0)); the reader picks the smallest even width and height that hold every
  observation, the same for all images, unless ``image_size`` is given (one size, or one
  per image; observations outside the size given are warned of, :func:`warn_outside`). Then
  ``u = x + (w - 1) / 2`` and ``v = (h - 1) / 2 - y`` exactly (even sizes make
  ``(w - 1) / 2`` a half-integer, exact in binary); the choice moves the pixel origin only,
  never a projection.
* Cameras, points and observations are indexed by position: ids are ``0 .. n - 1`` on
  reading; on writing, images and points go in block order (their ids are not stored).
* BAL's cost is the plain sum of squared residuals: observations are read with one
  standard deviation (``sigma``, default 1 px), which changes no minimum.
"""

from __future__ import annotations

import bz2
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..camera.metashape import MAX_IMAGE_SIDE, MetashapeCalibration
from ..errors import FileFormatError, InputError
from ._angles import opk_from_rotations
from ._textio import format_floats, numbers, read_text, token_line, write_files_atomically
from .block import CALIBRATION_NAMES, Block

#: Calibration parameters a BAL camera holds (the free ones of a block read from BAL).
BAL_FREE = ("f", "k1", "k2")
#: Most characters a value of a BAL file may take with the white space around it: the
#: header's counts bound the size of the file (a number is at most 24 characters).
BAL_VALUE_CHARS = 64


def _header_message(label: str, head: np.ndarray | list[str]) -> str:
    got = " ".join(format_floats(head)) if isinstance(head, np.ndarray) else " ".join(head)
    return (
        f"{label}, line 1: the header must be three non-negative integers "
        f"(num_cameras num_points num_observations), got {got}"
    )


def _refuse_bundler(text: str, label: str) -> None:
    """Refuse a Bundler file read as BAL (a pipe, whose format is not looked at)."""
    if text.lstrip().startswith("# Bundle file"):
        raise FileFormatError(
            f"{label}, line 1: a Bundler file, not a BAL file: read it as Bundler "
            "(kind='bundler')"
        )


def _size_limit(label: str):
    """The ``limit`` of :func:`read_text` for a BAL file: the most bytes the counts of its
    header leave room for (:data:`BAL_VALUE_CHARS` characters a value, 4 bytes a character
    for UTF-32 text), so that a stream that never ends (a pipe), a bzip2 bomb or a file far
    longer than its header says is refused after reading at most that much."""

    def limit(head: str) -> tuple[int, str]:
        _refuse_bundler(head, label)
        tokens = head.split(None, 3)
        if len(tokens) < 4:  # no three tokens before the end of the head
            raise FileFormatError(
                f"{label}: no header (num_cameras num_points num_observations) in its first "
                f"{len(head)} characters; not a BAL file"
            )
        try:
            counts = np.array(tokens[:3], dtype=float)
        except ValueError:
            counts = None
        if counts is None or not np.all(np.isfinite(counts)):
            raise FileFormatError(_header_message(label, tokens[:3]))
        if np.any(counts != np.round(counts)) or np.any(counts < 0):
            raise FileFormatError(_header_message(label, counts))
        m, p, n = (int(v) for v in counts)
        need = 3 + 4 * n + 9 * m + 3 * p
        most = 4 * BAL_VALUE_CHARS * need + len(head)
        return most, (
            f"{label}: more than {most} bytes, more than the {need} values its header "
            f"announces ({m} cameras, {p} points, {n} observations) can take at "
            f"{BAL_VALUE_CHARS} characters each: the header does not match the file (or "
            "it is not a BAL file)"
        )

    return limit


def read_bal(
    path: str | os.PathLike,
    *,
    image_size: tuple[int, int] | Mapping[int, tuple[int, int]] | None = None,
    sigma: float = 1.0,
) -> Block:
    """Read a BAL problem file (``.bz2`` compressed or plain) as a :class:`Block`.

    Parameters
    ----------
    path : path-like
        The BAL file (bzip2-compressed files are recognised by content, any name), or a
        pipe (read once). A device (``/dev/zero``) is refused.
    image_size : (width, height), or mapping image id -> (width, height), optional
        Pixel size of every image, or of each (ids ``0 .. m - 1``, every image: images of
        cameras of several formats). Default: the smallest even sizes that hold every
        observation (BAL stores none; see the module docstring).
    sigma : float
        Standard deviation of every image coordinate, pixels (BAL's cost is unweighted).

    Returns
    -------
    Block
        Image ids and camera group ids ``0 .. m - 1`` (one group per image, ``f, k1, k2``
        free), tie points with ids ``0 .. p - 1``, observations in file order.

    Raises
    ------
    FileFormatError
        A token that is not a number, counts that do not match the header, a truncated
        file, camera or point indices out of range, a camera's second observation of one
        point, a non-positive focal length or non-finite values, each naming the line; a
        file (decompressed) longer than its header's counts leave room for
        (:data:`BAL_VALUE_CHARS` characters a value): a stream that never ends or a bzip2
        bomb is refused after reading that much.
    InputError
        An ``image_size`` mapping without a size for every image.

    Warns
    -----
    ImageSizeWarning
        ``image_size`` smaller than an image's observations reach (:func:`warn_outside`).
    """
    label = str(path)
    text = read_text(path, "BAL file", limit=_size_limit(label))
    _refuse_bundler(text, label)
    vals = numbers(text, label)
    if vals.size < 3:
        raise FileFormatError(
            f"{label}: truncated: the header needs 3 numbers (cameras, points, observations), "
            f"found {vals.size}"
        )
    head = vals[:3]
    if not np.all(np.isfinite(head)) or np.any(head != np.round(head)) or np.any(head < 0):
        raise FileFormatError(_header_message(label, head))
    m, p, n = (int(v) for v in head)
    if m == 0:
        raise FileFormatError(
            f"{label}, line 1: the header announces no cameras (an empty problem)"
        )
    need = 3 + 4 * n + 9 * m + 3 * p
    if vals.size < need:
        have = vals.size - 3
        section = (
            "observations"
            if have < 4 * n
            else "camera parameters"
            if have < 4 * n + 9 * m
            else "point coordinates"
        )
        raise FileFormatError(
            f"{label}: truncated: the header announces {m} cameras, {p} points and {n} "
            f"observations ({need} numbers in all), the file holds {vals.size}; it ends in the "
            f"{section}"
        )
    if vals.size > need:
        line, tok = token_line(text, need)
        raise FileFormatError(
            f"{label}, line {line}: counts do not match: the header announces {m} cameras, "
            f"{p} points and {n} observations ({need} numbers), but the file holds "
            f"{vals.size} (first extra value {tok!r})"
        )
    obs = vals[3 : 3 + 4 * n].reshape(n, 4)
    cams = vals[3 + 4 * n : 3 + 4 * n + 9 * m].reshape(m, 9)
    pts = vals[3 + 4 * n + 9 * m :].reshape(p, 3)

    def where(row: int, width: int, offset: int) -> int:
        return token_line(text, offset + row * width)[0]

    ci, pi = obs[:, 0], obs[:, 1]
    bad = (ci != np.round(ci)) | (ci < 0) | (ci >= m) | (pi != np.round(pi)) | (pi < 0) | (pi >= p)
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{label}, line {where(k, 4, 3)}: observation {k} refers to camera {ci[k]:g} and "
            f"point {pi[k]:g}; indices "
            f"must be integers in 0..{m - 1} (cameras) and 0..{p - 1} (points)"
        )
    key = ci.astype(np.int64) * p + pi.astype(np.int64)
    order = np.argsort(key, kind="stable")
    again = np.flatnonzero(np.diff(key[order]) == 0)
    if again.size:  # the first row (in file order) that repeats an earlier one
        k = int(np.min(order[again + 1]))
        first = int(np.flatnonzero(key == key[k])[0])
        raise FileFormatError(
            f"{label}, line {where(k, 4, 3)}: observation {k} is camera {int(ci[k])}'s "
            f"observation of point {int(pi[k])} again (observation {first}, line "
            f"{where(first, 4, 3)}); a camera observes a point once: remove one of them"
        )
    for arr, width, offset, what in (
        (obs[:, 2:], 4, 3, "observation"),
        (cams, 9, 3 + 4 * n, "camera"),
        (pts, 3, 3 + 4 * n + 9 * m, "point"),
    ):
        nf = ~np.all(np.isfinite(arr), axis=1)
        if np.any(nf):
            k = int(np.flatnonzero(nf)[0])
            raise FileFormatError(
                f"{label}, line {where(k, width, offset)}: {what} {k} holds NaN or infinity"
            )
    nonpos = cams[:, 6] <= 0
    if np.any(nonpos):
        k = int(np.flatnonzero(nonpos)[0])
        line = token_line(text, 3 + 4 * n + 9 * k + 6)[0]
        raise FileFormatError(
            f"{label}, line {line}: camera {k} has focal length "
            f"{cams[k, 6]:g}; the Metashape model needs f > 0"
        )
    xy = obs[:, 2:]
    if image_size is None and len(xy) == 0:
        raise FileFormatError(
            f"{label}: the file has no observations, and a BAL file states no image size, "
            "which is taken from the observations; give image_size=(width, height) (px)"
        )
    if image_size is None:
        w = max(2, 2 * int(np.ceil(np.max(np.abs(xy[:, 0]), initial=0.0))))
        h = max(2, 2 * int(np.ceil(np.max(np.abs(xy[:, 1]), initial=0.0))))
        if max(w, h) > MAX_IMAGE_SIDE:  # an image no camera has: name the observation
            reach = np.max(np.abs(xy) / [w, h], axis=1)
            k = int(np.argmax(reach))
            raise FileFormatError(
                f"{label}, line {where(k, 4, 3)}: observation {k} lies at ({xy[k, 0]:g}, "
                f"{xy[k, 1]:g}) px from the image centre; a BAL file states no image size, "
                f"which is taken from the observations (the smallest even size holding them "
                f"all), and {w} x {h} px is more than the {MAX_IMAGE_SIDE} px of an image "
                "side: remove that observation (a blunder?), or give the images' size "
                "(image_size=(width, height)), observations outside it read with a warning"
            )
        sizes = np.tile([w, h], (m, 1))
    elif isinstance(image_size, Mapping):
        missing = [i for i in range(m) if i not in image_size]
        if missing:
            raise InputError(
                f"{label}: image_size gives no size for image {missing[0]} (of "
                f"{len(missing)} without one); a mapping gives every image's: ids 0..{m - 1}"
            )
        sizes = np.array([[int(s) for s in image_size[i]] for i in range(m)], dtype=np.int64)
    else:
        sizes = np.tile([int(s) for s in image_size], (m, 1))
    R = Rotation.from_rotvec(cams[:, :3]).as_matrix().reshape(m, 3, 3)
    ids = np.arange(m)
    if image_size is not None:
        warn_outside(
            label, ids, sizes, ci.astype(np.int64), xy,
            lambda k: "the image size given (image_size)",
            f"give each image its size {SIZES_FIX}, or leave image_size out (the smallest even "
            "size holding every observation, the same for all images)",
        )  # fmt: skip
    return block_from_centred(
        label=label,
        image_ids=ids,
        image_group=ids,
        rotations=R,
        translations=cams[:, 3:6],
        fk=cams[:, 6:9],
        sizes=sizes,
        point_ids=np.arange(p),
        xyz=pts,
        obs_image=ci.astype(np.int64),
        obs_point_ids=pi.astype(np.int64),
        xy=xy,
        sigma=sigma,
        size_note=(
            " (image_size)"
            if isinstance(image_size, Mapping)
            else f" (image_size={(int(sizes[0, 0]), int(sizes[0, 1]))})"
        ),
    )


#: How :func:`warn_outside` says to give the images' sizes (the command line says it in
#: its options).
SIZES_FIX = (
    "(image_size=(width, height) for all, or a mapping image id -> (width, height) for "
    "images of several sizes)"
)


class ImageSizeWarning(UserWarning):
    """Observations of a BAL or Bundler file reach outside the image size given or read for
    their image: the size is likely not that of the image (a camera of another format, a
    resized copy), which moves the pixel origin and the grids' extent."""


def warn_outside(
    label: str,
    ids: np.ndarray,
    sizes: np.ndarray,
    obs_image: np.ndarray,
    xy: np.ndarray,
    size_from: Callable[[int], str],
    fix: str,
) -> None:
    """Warn (:class:`ImageSizeWarning`) of observations outside the image size an image was
    given: BAL and Bundler coordinates are from the image centre (the principal point), so
    ``|x| <= w / 2`` and ``|y| <= h / 2`` hold for every point of an image of ``w x h`` px
    with its principal point at the centre.

    Parameters
    ----------
    label : str
        The file, for the message.
    ids : numpy.ndarray
        (m,) the images' ids.
    sizes : numpy.ndarray
        (m, 2) int, each image's width and height, px.
    obs_image : numpy.ndarray
        (n,) int, the image (row of ``ids``) of each observation.
    xy : numpy.ndarray
        (n, 2) the observations from the image centre, px (either sign of y).
    size_from : callable
        ``size_from(k)``: where image ``k``'s size came from (words for the message).
    fix : str
        How to give the right sizes, in the words of the caller.
    """
    import warnings

    m = len(ids)
    reach = np.zeros((m, 2))
    np.maximum.at(reach, np.asarray(obs_image, dtype=np.int64), np.abs(xy))
    out = np.any(reach > np.asarray(sizes, dtype=float) / 2, axis=1)
    if not np.any(out):
        return
    k = int(np.flatnonzero(out)[0])
    need = 2 * np.ceil(reach[k]).astype(np.int64)
    others = f" (and {int(out.sum()) - 1} more)" if out.sum() > 1 else ""
    warnings.warn(
        f"{label}: image {ids.tolist()[k]!r}{others} has observations outside {size_from(k)}, "
        f"{int(sizes[k, 0])} x {int(sizes[k, 1])} px: up to {reach[k, 0]:.1f} px from the "
        f"centre in x and {reach[k, 1]:.1f} px in y, an image of at least {need[0]} x "
        f"{need[1]} px; read as given, but unless the file's principal points are off the "
        f"centre the size is not that of the image (a camera of another format, a resized "
        f"copy), which moves the pixel origin and the grids' extent: {fix}",
        ImageSizeWarning,
        stacklevel=3,
    )


def block_from_centred(
    *,
    label: str,
    image_ids: np.ndarray,
    image_group: np.ndarray,
    rotations: np.ndarray,
    translations: np.ndarray,
    fk: np.ndarray,
    sizes: np.ndarray,
    point_ids: np.ndarray,
    xyz: np.ndarray,
    obs_image: np.ndarray,
    obs_point_ids: np.ndarray,
    xy: np.ndarray,
    sigma: float,
    size_note: str = "",
) -> Block:
    """The block of a camera model shared by BAL and Bundler files: ``P = R X + t``,
    ``p = -P / P_z``, ``(x, y) = f (1 + k1 |p|^2 + k2 |p|^4) p`` in pixels from the image
    centre, y up (see the module docstring).

    Parameters
    ----------
    label : str
        The file, for errors.
    image_ids : numpy.ndarray (m,)
        Image ids.
    image_group : numpy.ndarray of int (m,)
        Camera group id of each image; the images of one group have equal ``fk`` and
        ``sizes`` (the group takes its first image's).
    rotations, translations : numpy.ndarray (m, 3, 3), (m, 3)
        ``R`` and ``t`` of each image (world -> camera, camera looking down -z, y up).
    fk : numpy.ndarray (m, 3)
        Focal length (px), k1, k2 (of the normalised coordinates ``p``) of each image.
    sizes : numpy.ndarray of int (m, 2)
        Width and height of each image, px.
    point_ids, xyz : numpy.ndarray (p,), (p, 3)
        Point ids and object coordinates.
    obs_image : numpy.ndarray of int (n,)
        Position (0 .. m - 1) of the image of each observation.
    obs_point_ids : numpy.ndarray (n,)
        Point id of each observation.
    xy : numpy.ndarray (n, 2)
        Observations in pixels from the image centre, y up.
    sigma : float
        Standard deviation of every image coordinate, px.
    size_note : str
        Said after a calibration refused for its image size (where the size came from).

    Returns
    -------
    Block
        ``u = x + (w - 1) / 2``, ``v = (h - 1) / 2 - y`` (centre of the first pixel at
        (0, 0)); ``M = R``, ``X0 = -R^T t``; f, k1, k2 free, principal point fixed at the
        centre.
    """
    m = len(image_ids)
    R = np.asarray(rotations, dtype=float).reshape(m, 3, 3)
    X0 = -np.einsum("nji,nj->ni", R, np.asarray(translations, dtype=float).reshape(m, 3))
    exterior = np.column_stack([X0, opk_from_rotations(R)]).reshape(m, 6)
    groups, first = np.unique(image_group, return_index=True)
    try:
        cameras = {
            g.item(): MetashapeCalibration(
                int(sizes[i, 0]), int(sizes[i, 1]), float(fk[i, 0]), k1=float(fk[i, 1]),
                k2=float(fk[i, 2]),
            )
            for g, i in zip(groups, first.tolist())
        }  # fmt: skip
    except InputError as exc:
        raise FileFormatError(f"{label}: {exc}{size_note}") from None
    n = len(xy)
    half = (np.asarray(sizes, dtype=float) - 1) / 2
    i = np.asarray(obs_image, dtype=np.int64)
    uv = np.column_stack([xy[:, 0] + half[i, 0], half[i, 1] - xy[:, 1]]).reshape(n, 2)
    return Block.from_arrays(
        cameras=cameras,
        image_ids=image_ids,
        image_camera=image_group,
        exterior=exterior,
        point_ids=point_ids,
        xyz=xyz,
        obs_image_ids=np.asarray(image_ids)[i],
        obs_point_ids=obs_point_ids,
        uv=uv,
        sigma=sigma,
        free=BAL_FREE,
    )

def _extras(block: Block) -> list[str]:
    """What a block holds that the format has no room for (empty: nothing)."""
    out = []
    for role in ("control", "check"):
        k = int(np.sum(block.role == role))
        if k:
            out.append(f"{k} {role} point(s)")
    for name, arr in (("GNSS", block.gnss), ("IMU", block.imu)):
        k = int(np.sum(np.all(np.isfinite(arr), axis=1)))
        if k:
            out.append(f"{name} observations of {k} image(s)")
    if block.crs:
        out.append(f"the block's coordinate reference system ({block.crs})")
    s = block.observations.sigma
    if s.size and np.any(s != s[0]):
        out.append("observation standard deviations that differ between observations")
    return out


def refuse_extras(block: Block, fmt: str) -> None:
    extras = _extras(block)
    if extras:
        raise InputError(
            f"{fmt} has no room for {'; '.join(extras)}: pass drop_extras=True to write the "
            "images, points and observations only (all points as tie points, one standard "
            "deviation)"
        )


#: Calibration terms the camera of BAL and Bundler files cannot hold (it has f, k1, k2; the
#: principal point is held through the observations, measured from it).
TERMS_NOT_HELD = ("k3", "k4", "p1", "p2", "b1", "b2")


def centred_cameras(
    block: Block, fmt: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The cameras and observations of a block in the model of BAL and Bundler files.

    Parameters
    ----------
    block : Block
    fmt : str
        The format's name, for errors.

    Returns
    -------
    M, t, C, x, y : numpy.ndarray
        Rotations (m, 3, 3) and translations (m, 3) (``P = M X + t``), the calibration
        matrix of each image (:meth:`Block.calibration_matrix`), the observations (n,) in
        pixels from each image's principal point (the projections exact, whatever the
        principal point), y up.

    Raises
    ------
    InputError
        Non-zero K3, K4, P1, P2, B1 or B2 (the format's camera has f, k1, k2 only).
    """
    C = block.calibration_matrix()
    names = TERMS_NOT_HELD
    idx = [CALIBRATION_NAMES.index(nm) for nm in names]
    extra = C[:, idx]
    bad = np.any(extra != 0, axis=1)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        nz = [f"{nm} = {v!r}" for nm, v in zip(names, extra[i].tolist()) if v != 0]
        raise InputError(
            f"image {block.image_ids[i]} (camera {block.camera_ids[block.image_camera[i]]}): "
            f"{', '.join(nz)}; a {fmt} camera has only f, k1, k2, so it cannot be "
            f"written exactly ({fmt}'s tools would use a different camera)"
        )
    sizes = block.image_sizes()
    # BAL and Bundler measure from the principal point, y up
    u0 = sizes[:, 0] / 2 - 0.5 + C[:, 1]
    v0 = sizes[:, 1] / 2 - 0.5 + C[:, 2]
    uv = block.observations.uv
    i = block.obs_image
    M = block.rotations()
    t = -np.einsum("nij,nj->ni", M, block.exterior[:, :3])
    return M, t, C, uv[:, 0] - u0[i], v0[i] - uv[:, 1]


def bal_text(block: Block, *, drop_extras: bool = False) -> str:
    """The BAL text of a block (see :func:`write_bal`)."""
    if not drop_extras:
        refuse_extras(block, "BAL")
    m, p, n = block.n_images, block.n_points, block.n_observations
    M, t, C, x, y = centred_cameras(block, "BAL")
    r = Rotation.from_matrix(M).as_rotvec().reshape(m, 3) if m else np.zeros((0, 3))
    cam = np.column_stack([r, t, C[:, 0], C[:, 3], C[:, 4]])
    xs = format_floats(x)
    ys = format_floats(y)
    ci = map(str, block.obs_image.tolist())
    pi = map(str, block.obs_point.tolist())
    lines = [f"{m} {p} {n}"]
    lines.extend(map(" ".join, zip(ci, pi, xs, ys)))
    lines.extend(format_floats(cam))
    lines.extend(format_floats(block.xyz))
    return "\n".join(lines) + "\n"


def write_bal(block: Block, path: str | os.PathLike, *, drop_extras: bool = False) -> Path:
    """Write a block as a BAL problem file, atomically (``.bz2`` names are compressed).

    Images, points and observations are written in block order (BAL indexes them by
    position). Observations are measured from each image's principal point (BAL's origin),
    so a fixed principal point off the image centre is written exactly.

    Parameters
    ----------
    block : Block
        The block to write.
    path : path-like
        The file (compressed with bzip2 when the name ends in ``.bz2``).
    drop_extras : bool
        Write a block with control or check points, GNSS/IMU observations or unequal
        observation standard deviations anyway, without them.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    InputError
        A calibration BAL cannot hold (non-zero K3, K4, P1, P2, B1 or B2: BAL's camera has
        f, k1, k2 only), or, unless ``drop_extras=True``, control or check points, GNSS/IMU
        observations or unequal observation standard deviations (BAL has none of them).
    """
    data = bal_text(block, drop_extras=drop_extras).encode("ascii")
    target = Path(path)
    if target.suffix == ".bz2":
        data = bz2.compress(data)
    write_files_atomically({target: data})
    return target
