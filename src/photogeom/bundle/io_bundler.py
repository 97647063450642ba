"""Bundler files (``bundle.out``, v0.3): read and write.

Bundler (Snavely et al.), Metashape (File > Export > Export Cameras > Bundler),
RealityCapture, VisualSFM, OpenMVG and other tools write an oriented block as::

    # Bundle file v0.3
    <num_cameras> <num_points>
    <f> <k1> <k2>                       \\
    <R row 1>                            |  5 lines per camera
    <R row 2>                            |
    <R row 3>                            |
    <t>                                 /
    <X> <Y> <Z>                         \\
    <red> <green> <blue>                 |  3 lines per point
    <n> <camera> <key> <x> <y> ...      /   the view list: n views of 4 numbers

and an image list (``list.txt``), one image a line in camera order, its name first
(Bundler's lists may go on with ``0 <focal>``).

Bundler's conventions and how photogeom maps them:

* ``P = R X + t``, the camera looking down its -z axis, x right, y up; ``p = -P / P_z``,
  ``(x, y) = f (1 + k1 |p|^2 + k2 |p|^4) p`` in pixels from the image centre, y up: the
  camera model of BAL files (:mod:`photogeom.bundle.io_bal`), so ``M = R``,
  ``X0 = -R^T t``, ``K1 = k1``, ``K2 = k2`` (``p`` is divided by ``P_z``, not by ``f``: the
  terms are those of Metashape's normalised coordinates, unscaled) and the principal point is
  the image centre.
* Pixels: Bundler puts the image's lower-left *corner* at ``(-w/2, -h/2)`` and its
  upper-right corner at ``(w/2, h/2)``; photogeom's origin is the centre of the first
  (top-left) pixel, so ``u = x + (w - 1) / 2`` and ``v = (h - 1) / 2 - y``. The file holds no
  image size: it comes from ``image_size`` or from the image files the list names (their
  header only, as stored), and a block whose sizes are unknown is refused. An image whose
  EXIF orientation turns it by 90 degrees (5-8) takes the size its observations fit:
  as stored (Bundler, COLMAP), or as shown (a tool that applied the orientation; an
  :class:`ExifOrientationWarning` says so); observations that fit both are refused.
* A camera of all zeros is an image that was not oriented: it is left out, the other cameras
  keep their index (view lists refer to cameras by index; a view of a left-out camera is
  refused).
* Ids: the images are named by the list (as written there) or, without a list, by their
  camera index; points are numbered ``0 .. p - 1``. Each image is its own camera group (id:
  its camera index), ``f, k1, k2`` free and the principal point fixed, as Bundler adjusts
  it; ``group_cameras=True`` makes one group of the images with equal ``f, k1, k2`` and
  size (Metashape writes a shared sensor so), with the smallest camera index as its id.
* Not kept: point colours and key indices (written as 0 0 0 and the observation's rank in
  its image). Observations get one standard deviation (``sigma``, default 1 px).
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path, PureWindowsPath

import numpy as np

from ..errors import FileFormatError, InputError
from ._textio import (
    NO_NAME_CHARS,
    format_floats,
    numbers,
    read_text,
    rotation_defects,
    token_starts,
    write_files_atomically,
)
from .block import Block
from .io_bal import (
    SIZES_FIX,
    block_from_centred,
    centred_cameras,
    refuse_extras,
    warn_outside,
)

#: First line of a Bundler file.
BUNDLER_HEADER = "# Bundle file v0.3"
#: Most characters a value may take with the white space around it (the counts of the header
#: bound the size of the file).
BUNDLER_VALUE_CHARS = 64
#: Largest deviation of a camera's ``R R^T`` from the identity that is read (files hold R to
#: 6 to 10 digits); R is then replaced by the nearest rotation.
ROTATION_TOLERANCE = 1e-5
#: Names of the image list looked for next to ``NAME.out`` (in this order), besides
#: ``NAME.out.list.txt``.
LIST_NAMES = ("list.txt", "bundle.out.list.txt")
_LIST_TAIL = re.compile(r"\s+0\s+[-+0-9.eE]+\s*$")


def is_bundler_file(path: str | os.PathLike) -> bool:
    """Whether a regular file or a pipe begins with Bundler's header line.

    A regular file: its first bytes are read. A pipe inside a
    :func:`photogeom.io.sources.pipe_reads` scope (every command): read once, whole (bounded
    by the header's counts as the BAL or Bundler reader bounds it, :func:`read_text`), and
    its bytes kept for the reader that follows; a pipe already read in the scope: the bytes
    kept. A pipe outside every scope is not read (it could not be read again): False. A
    missing file: False.

    Raises
    ------
    FileFormatError
        A pipe that cannot be read, or longer than its header allows (the reader's
        message).
    """
    from ..io.sources import input_kind, kept_pipe_bytes, kept_pipes

    p = Path(path)
    kind = input_kind(p)
    if kind == "pipe":
        head = kept_pipe_bytes(p)
        if head is None and kept_pipes() is not None:
            _read_pipe_once(p)  # kept whole for the reader that follows
            head = kept_pipe_bytes(p)
        head = head or b""
    elif kind == "file":
        try:
            with open(p, "rb") as fh:
                head = fh.read(64)
        except OSError:
            return False
    else:
        return False
    return head[:64].lstrip(b"\xef\xbb\xbf").startswith(BUNDLER_HEAD)


#: The first bytes of a Bundler file (``# Bundle file v0.3``).
BUNDLER_HEAD = b"# Bundle file"


def _read_pipe_once(p: Path) -> None:
    """Read the pipe ``p`` whole in the current scope, bounded as the reader of its format
    (BAL, or Bundler by its first line) bounds it, so that the reader that follows gets the
    bytes kept."""
    from .io_bal import _size_limit as bal_limit

    label = str(p)

    def limit(head: str) -> tuple[int, str]:
        bundler = head.lstrip("\ufeff").startswith(BUNDLER_HEAD.decode())
        return (_size_limit(label) if bundler else bal_limit(label))(head)

    read_text(p, "BAL or Bundler file", limit=limit)


def list_path(path: str | os.PathLike) -> Path | None:
    """The image list of a Bundler file found next to it: ``NAME.list.txt`` (as
    ``bundle.out.list.txt``), else ``list.txt`` in its folder, or above a folder ``bundle``
    (Bundler's own layout, ``bundle/bundle.out`` with ``list.txt``, or only the
    ``prepare/list.txt`` its ``RunBundler.sh`` writes first); None when there is none."""
    p = Path(path)
    up = p.parent.parent
    for cand in (
        p.with_name(p.name + ".list.txt"),
        p.with_name(p.stem + ".list.txt"),
        *(p.parent / n for n in LIST_NAMES),
        *([up / "list.txt", up / "prepare" / "list.txt"] if p.parent.name == "bundle" else []),
    ):
        if cand.is_file():
            return cand
    return None


def list_base(list_file: Path) -> Path:
    """The folder the names of an image list are relative to: the list's own, or for
    Bundler's ``prepare/list.txt`` the folder Bundler ran in (its parent), as the names of
    ``RunBundler.sh``'s list (``./IMG_0001.jpg``) are."""
    folder = list_file.parent
    if list_file.name == "list.txt" and folder.name == "prepare":
        return folder.parent
    return folder


def listed_image(list_file: Path, name: str) -> Path:
    """The image file that ``name`` of the image list ``list_file`` names: relative to
    :func:`list_base` (an absolute name as it is). A name with backslashes that is no file
    as written, on a system whose paths use slashes, is read as a Windows path (a list
    written on Windows: ``images\\IMG_0001.JPG``, ``.\\IMG_0001.JPG``), its parts joined
    with slashes."""
    base = list_base(list_file)
    img = base / name
    if "\\" not in name or os.sep == "\\" or img.exists():
        return img
    win = PureWindowsPath(name)
    if win.drive or win.root:  # an absolute Windows path: not a path of this system
        return img
    return base.joinpath(*win.parts)


def _read_list(path: Path, m: int) -> list[str]:
    lines = [ln.strip() for ln in read_text(path, "Bundler image list").splitlines()]
    while lines and not lines[-1]:
        lines.pop()
    if len(lines) != m:
        raise FileFormatError(
            f"{path}: the image list names {len(lines)} image(s), the Bundler file has {m} "
            "cameras; give the list of that file (image_list=)"
        )
    names = [_LIST_TAIL.sub("", ln) for ln in lines]
    empty = [k for k, n in enumerate(names) if not n]
    if empty:
        raise FileFormatError(f"{path}, line {empty[0] + 1}: no image name")
    seen: dict[str, int] = {}
    for k, n in enumerate(names):
        if n in seen:
            raise FileFormatError(
                f"{path}, line {k + 1}: image {n!r} is named on line {seen[n] + 1} too"
            )
        seen[n] = k
    return names


#: EXIF orientations (tag 274) under which an image is shown turned by 90 degrees: its
#: stored width is its shown height.
_TURNED = (5, 6, 7, 8)


class ExifOrientationWarning(UserWarning):
    """A Bundler file's coordinates refer to an image as shown (its EXIF orientation
    applied, turned by 90 degrees), not as its pixels are stored."""


def _image_file_size(path: Path) -> tuple[int, int, int]:
    """Width, height (px, as stored) and EXIF orientation (1 when none) of an image file
    (a TIFF's from its tags 256, 257: Pillow turns a TIFF's size by its Orientation)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:  # the header only: no pixel is decoded
            try:
                turn = int(im.getexif().get(274, 1))
            except (TypeError, ValueError):  # a damaged tag: the image as stored
                turn = 1
            if im.format == "TIFF":  # Pillow gives a TIFF's size turned by its Orientation
                return int(im.tag_v2[256]), int(im.tag_v2[257]), turn
            return int(im.size[0]), int(im.size[1]), turn
    except (OSError, UnidentifiedImageError, ValueError, KeyError) as exc:
        raise FileFormatError(
            f"cannot read the size of image {path}: {exc}; give the images' size "
            "(image_size=(width, height))"
        ) from None


def _size_limit(label: str):
    """:func:`read_text`'s ``limit``: the most bytes the header's counts leave room for, a
    point seen at most once by each camera (:data:`BUNDLER_VALUE_CHARS` a value, 4 bytes a
    character)."""

    def limit(head: str) -> tuple[int, str]:
        lines = head.split("\n", 2)
        tokens = lines[1].split() if len(lines) > 2 else []
        try:
            m, p = (int(t) for t in tokens)
        except ValueError:
            m = p = -1
        if m < 0 or p < 0:  # the reader says the same of a short file
            raise FileFormatError(
                f"{label}, line 2: the header must be two non-negative integers "
                f"(num_cameras num_points), got {' '.join(tokens)[:80]!r}"
            )
        need = 2 + 15 * m + p * (7 + 4 * m)
        most = 4 * BUNDLER_VALUE_CHARS * need + len(head)
        return most, (
            f"{label}: more than {most} bytes, more than its header's {m} cameras and {p} "
            f"points can take ({need} values at {BUNDLER_VALUE_CHARS} characters each, every "
            "point seen by every camera): the header does not match the file"
        )

    return limit


def _token_lines(body: str, first_line: int) -> np.ndarray:
    """Line number of each whitespace-separated token of ``body`` (its first line is
    ``first_line``), vectorised over the bytes."""
    b = np.frombuffer(body.encode("utf-8"), dtype=np.uint8)
    return first_line + np.cumsum(b == 10)[np.flatnonzero(token_starts(b))]


def _sizes(
    image_size, names: list[str] | None, ids, list_file: Path | None, label: str
) -> tuple[np.ndarray, np.ndarray]:
    """(m, 2) image sizes (one size, a mapping image id -> size, or the image files as
    stored) and (m,) EXIF orientations of the image files read (1 for sizes given)."""
    m = len(ids)
    turn = np.ones(m, dtype=np.int64)
    if image_size is not None and not isinstance(image_size, Mapping):
        w, h = (int(s) for s in image_size)
        return np.tile([w, h], (m, 1)), turn
    given = image_size or {}  # the mapping as given: its own lookups (--image-size's refusals)
    out = np.zeros((m, 2), dtype=np.int64)
    for k, key in enumerate(ids.tolist()):
        if key in given:
            out[k] = [int(s) for s in given[key]]
            continue
        if names is None or list_file is None:
            raise InputError(
                f"{label}: a Bundler file holds no image size and there is no image list "
                f"(list.txt) naming image files to read it from; give the images' size "
                f"(image_size=(width, height), or a mapping image id -> size; image {key} "
                "has none)"
            )
        img = listed_image(list_file, names[k])
        if not img.is_file():
            win = PureWindowsPath(names[k])
            where = (
                f"names a Windows path (drive {win.drive or win.root}), which is no path "
                "of this system"
                if os.sep != "\\" and "\\" in names[k] and (win.drive or win.root)
                else f"is not at {img}"
            )
            raise InputError(
                f"{label}: a Bundler file holds no image size, and image {names[k]!r} of "
                f"{list_file} {where}; give the images' size (image_size=(width, "
                "height)), or put the images where the list says (names relative to "
                "the list's folder)"
            )
        *out[k], turn[k] = _image_file_size(img)
    return out, turn


def _turned_sizes(
    sizes: np.ndarray, turn: np.ndarray, obs_image: np.ndarray, xy: np.ndarray, names, label
) -> np.ndarray:
    """The sizes of images whose EXIF orientation turns them by 90 degrees, as their
    observations show them: Bundler itself and COLMAP use the pixels as stored, a tool that
    applies the orientation the image as shown (width and height swapped). The observations
    (``xy`` from the image centre, px) decide; a size both fit is refused (ambiguous)."""
    turned = np.isin(turn, _TURNED)
    if not np.any(turned):
        return sizes
    m = sizes.shape[0]
    reach = np.zeros((m, 2))
    np.maximum.at(reach, obs_image, np.abs(xy))
    w, h = sizes[:, 0] / 2, sizes[:, 1] / 2
    stored = (reach[:, 0] <= w) & (reach[:, 1] <= h)
    shown = (reach[:, 0] <= h) & (reach[:, 1] <= w)
    both = turned & stored & shown & (sizes[:, 0] != sizes[:, 1])
    if np.any(both):
        k = int(np.flatnonzero(both)[0])
        W, H = (int(v) for v in sizes[k])
        raise InputError(
            f"{label}: image {names[k]!r} is {W} x {H} px as stored, and its EXIF orientation "
            f"({int(turn[k])}) shows it turned, {H} x {W} px; its observations fit both, so "
            "the file does not say which its coordinates refer to (Bundler and COLMAP use the "
            "image as stored, a tool that applies the orientation the image as shown); give "
            "the images' size (image_size=(width, height))"
        )
    swap = turned & shown & ~stored
    if not np.any(swap):
        return sizes
    import warnings

    k = int(np.flatnonzero(swap)[0])
    W, H = (int(v) for v in sizes[k])
    warnings.warn(
        f"{label}: the observations of {int(swap.sum())} image(s) (first {names[k]!r}, "
        f"{W} x {H} px as stored, EXIF orientation {int(turn[k])}) fit the image as shown, "
        f"{H} x {W} px, not as stored: read with the shown size; their coordinates refer to "
        "the image turned as its EXIF orientation says, not to its stored pixels",
        ExifOrientationWarning,
        stacklevel=3,
    )
    out = sizes.copy()
    out[swap] = sizes[swap][:, ::-1]
    return out


def read_bundler(
    path: str | os.PathLike,
    *,
    image_list: str | os.PathLike | None = None,
    image_size: tuple[int, int] | Mapping[object, tuple[int, int]] | None = None,
    group_cameras: bool = False,
    sigma: float = 1.0,
) -> Block:
    """Read a Bundler file (``bundle.out``, v0.3) as a :class:`Block`.

    Parameters
    ----------
    path : path-like
        The Bundler file.
    image_list : path-like, optional
        The image list (one image a line, in camera order). Default: the list next to the
        file (:func:`list_path`); without one the images are named by camera index.
    image_size : (width, height) or mapping image id -> (width, height), optional
        Pixel size of every image, or of each. Default: read from the image files the list
        names (relative to the list's folder, Windows paths too: :func:`listed_image`;
        headers only).
    group_cameras : bool
        One camera group for the images with equal f, k1, k2 and size (default: a group per
        image, as Bundler adjusts them).
    sigma : float
        Standard deviation of every image coordinate, px.

    Returns
    -------
    Block
        The oriented images (cameras of all zeros left out), points ``0 .. p - 1`` and
        their views, in photogeom's pixel convention (see the module docstring).

    Raises
    ------
    FileFormatError
        A missing or other header, a token that is not a number, counts that do not match
        the header, a truncated file, a point that is not three lines (position, colour,
        view list), views of missing or left-out cameras, two views of one camera in a view
        list, no oriented camera, a rotation that is not one,
        a non-positive focal length or non-finite values, each naming the file and line;
        an image list of another length.
    InputError
        Image sizes that are not given and cannot be read from image files.

    Warns
    -----
    ImageSizeWarning
        An image whose observations reach outside the size given or read from its file
        (:func:`photogeom.bundle.io_bal.warn_outside`).
    """
    label = str(path)
    text = read_text(path, "Bundler file", limit=_size_limit(label))
    first, _, body = text.partition("\n")
    if not first.strip().startswith("# Bundle file"):
        raise FileFormatError(
            f"{label}, line 1: not a Bundler file: it must begin with {BUNDLER_HEADER!r}, "
            f"got {first.strip()[:60]!r}"
        )
    if first.split()[3:4] != ["v0.3"]:
        raise FileFormatError(
            f"{label}, line 1: {first.strip()[:60]!r}: only version v0.3 is read "
            f"({BUNDLER_HEADER!r})"
        )
    vals = numbers("\n" + body, label)  # the line numbers of the file
    lines = _token_lines(body, 2)

    def line(k: int) -> int:
        return int(lines[k]) if k < lines.size else int(lines[-1]) if lines.size else 2

    if vals.size < 2:
        raise FileFormatError(
            f"{label}: truncated: no header line (num_cameras num_points) after line 1"
        )
    head = vals[:2]
    on_line = int(np.count_nonzero(lines == lines[0]))
    if (
        on_line != 2
        or not np.all(np.isfinite(head))
        or np.any(head != np.round(head))
        or np.any(head < 0)
    ):
        got = " ".join(format_floats(vals[:on_line][:4]))
        raise FileFormatError(
            f"{label}, line {line(0)}: the header must be two non-negative integers "
            f"(num_cameras num_points), got {got!r}"
        )
    m, p = (int(v) for v in head)
    if m == 0:
        raise FileFormatError(f"{label}, line {line(0)}: the header announces no cameras")
    start = 2 + 15 * m
    if vals.size < start:
        k = (vals.size - 2) // 15
        raise FileFormatError(
            f"{label}: truncated: the header announces {m} cameras (15 numbers each), the "
            f"file ends in camera {k}"
        )
    cams = vals[2:start].reshape(m, 15)
    nf = ~np.all(np.isfinite(cams), axis=1)
    if np.any(nf):
        k = int(np.flatnonzero(nf)[0])
        raise FileFormatError(f"{label}, line {line(2 + 15 * k)}: camera {k} holds NaN or infinity")
    oriented = np.any(cams != 0, axis=1)
    nonpos = oriented & (cams[:, 0] <= 0)
    if np.any(nonpos):
        k = int(np.flatnonzero(nonpos)[0])
        raise FileFormatError(
            f"{label}, line {line(2 + 15 * k)}: camera {k} has focal length {cams[k, 0]:g}; "
            "an oriented camera needs f > 0 (a camera that is not oriented is all zeros)"
        )
    R = cams[:, 3:12].reshape(m, 3, 3)
    bad, dev, det = rotation_defects(R, ROTATION_TOLERANCE)
    bad &= oriented
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{label}, line {line(2 + 15 * k + 3)}: camera {k}: R is not a rotation (R R^T "
            f"differs from the identity by {dev[k]:.3g}, det {det[k]:.6g})"
        )
    # the points: three lines each (position, colour, view list), found by the tokens' lines
    pl = lines[start:]
    brk = np.flatnonzero(np.diff(pl) != 0) + 1 if pl.size else np.zeros(0, dtype=np.int64)
    lstart = np.concatenate([[0], brk]).astype(np.int64) if pl.size else brk
    lcount = np.diff(np.concatenate([lstart, [pl.size]]))
    nl = lstart.size
    q = min(p, nl // 3)
    if q:
        n_views = vals[start + lstart[2 : 3 * q : 3]]
        want = np.column_stack([np.full(q, 3.0), np.full(q, 3.0), 1 + 4 * n_views])
        got = lcount[: 3 * q].reshape(q, 3)
        wrong = np.any(got != want, axis=1) | (n_views != np.round(n_views)) | (n_views < 0)
        if np.any(wrong):
            k = int(np.flatnonzero(wrong)[0])
            j = int(np.flatnonzero(got[k] != want[k])[0]) if np.any(got[k] != want[k]) else 2
            what = ("its position X Y Z", "its colour R G B", "its view list (n, then n views "
                    "of camera key x y)")[j]  # fmt: skip
            raise FileFormatError(
                f"{label}, line {int(pl[lstart[3 * k + j]])}: point {k}: the line of {what} "
                f"holds {int(got[k, j])} numbers"
                + (f" for {n_views[k]:g} views" if j == 2 else "")
                + "; each point is three lines (position, colour, view list)"
            )
    if nl < 3 * p:
        raise FileFormatError(
            f"{label}: truncated: the header announces {p} points (three lines each), the "
            f"file ends in point {nl // 3}"
        )
    if nl > 3 * p:
        raise FileFormatError(
            f"{label}, line {int(pl[lstart[3 * p]])}: counts do not match: the header "
            f"announces {m} cameras and {p} points, but the file goes on after them"
        )
    pos0 = start + lstart[0 : 3 * p : 3]
    xyz = vals[pos0[:, None] + np.arange(3)].reshape(p, 3)
    nf = ~np.all(np.isfinite(xyz), axis=1)
    if np.any(nf):
        k = int(np.flatnonzero(nf)[0])
        raise FileFormatError(
            f"{label}, line {line(int(pos0[k]))}: point {k} holds NaN or infinity"
        )
    nv = lcount[2 : 3 * p : 3] // 4 if p else np.zeros(0, dtype=np.int64)
    vstart = start + lstart[2 : 3 * p : 3] + 1
    n = int(nv.sum())
    obs_point = np.repeat(np.arange(p), nv)
    first_view = np.cumsum(nv) - nv
    at = np.repeat(vstart, nv) + 4 * (np.arange(n) - np.repeat(first_view, nv))
    views = vals[at[:, None] + np.arange(4)].reshape(n, 4)
    ci = views[:, 0]
    badc = (ci != np.round(ci)) | (ci < 0) | (ci >= m)
    badc[~badc] = ~oriented[ci[~badc].astype(np.int64)]
    if np.any(badc):
        k = int(np.flatnonzero(badc)[0])
        c = ci[k]
        why = (
            f"camera {int(c)} is not oriented (all zeros)"
            if c == np.round(c) and 0 <= c < m
            else f"cameras are 0..{m - 1}"
        )
        raise FileFormatError(
            f"{label}, line {line(int(at[k]))}: point {int(obs_point[k])} has a view of camera "
            f"{c:g}; {why}"
        )
    nfv = ~np.all(np.isfinite(views[:, 2:]), axis=1)
    if np.any(nfv):
        k = int(np.flatnonzero(nfv)[0])
        raise FileFormatError(
            f"{label}, line {line(int(at[k]))}: a view of point {int(obs_point[k])} holds NaN "
            "or infinity"
        )
    key = obs_point * m + ci.astype(np.int64)
    order = np.argsort(key, kind="stable")
    twice = np.flatnonzero(np.diff(key[order]) == 0)
    if twice.size:
        k = int(order[twice[0] + 1])
        raise FileFormatError(
            f"{label}, line {line(int(at[k]))}: point {int(obs_point[k])} has two views of "
            f"camera {int(ci[k])}; a point is seen once by a camera: remove one of them"
        )
    cam_index = np.flatnonzero(oriented)
    if cam_index.size == 0:
        raise FileFormatError(
            f"{label}: none of its {m} cameras is oriented (all are zeros): no block to read"
        )
    list_file = Path(image_list) if image_list is not None else list_path(path)
    names = _read_list(list_file, m) if list_file is not None else None
    oriented_names = None if names is None else [names[k] for k in cam_index.tolist()]
    ids = cam_index.copy() if names is None else np.array(oriented_names, dtype=object)
    sizes, turn = _sizes(image_size, oriented_names, ids, list_file, label)
    where = np.full(m, -1, dtype=np.int64)
    where[cam_index] = np.arange(cam_index.size)
    sizes = _turned_sizes(sizes, turn, where[ci.astype(np.int64)], views[:, 2:], ids, label)
    given = image_size if isinstance(image_size, Mapping) else {}

    def size_from(k: int) -> str:
        if image_size is not None and (not isinstance(image_size, Mapping) or ids[k] in given):
            return "the image size given (image_size)"
        return f"the size of its image file {listed_image(list_file, oriented_names[k])}"

    warn_outside(
        label, ids, sizes, where[ci.astype(np.int64)], views[:, 2:], size_from,
        f"give each image its size {SIZES_FIX}, or the image files the list names",
    )  # fmt: skip
    fk = cams[cam_index, :3]
    Ro = R[cam_index]
    u, _, vt = np.linalg.svd(Ro)
    Ro = u @ vt  # the nearest rotation (R holds 6 to 10 digits)
    if group_cameras:
        key = np.column_stack([fk, sizes])
        _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        group = cam_index[first][inv.ravel()]
    else:
        group = cam_index
    return block_from_centred(
        label=label,
        image_ids=ids,
        image_group=group,
        rotations=Ro,
        translations=cams[cam_index, 12:15],
        fk=fk,
        sizes=sizes,
        point_ids=np.arange(p),
        xyz=xyz,
        obs_image=where[ci.astype(np.int64)],
        obs_point_ids=obs_point,
        xy=views[:, 2:],
        sigma=sigma,
    )


def refuse_unlisted_names(ids) -> None:
    """Refuse image ids that a Bundler image list cannot hold so that they read back as
    they are.

    Parameters
    ----------
    ids : array-like
        The block's image ids (checked as Python strings: no NUL dropped).

    Raises
    ------
    InputError
        An id empty, with white space at an end, a line break or NUL character, or ending
        in ``" 0 NUMBER"`` (read back as Bundler's focal length after the name); named.
    """
    names = [str(i) for i in (ids.tolist() if hasattr(ids, "tolist") else list(ids))]
    bad = [s for s in names if not s.strip() or s != s.strip() or NO_NAME_CHARS.search(s)]
    if bad:
        raise InputError(
            f"image id {bad[0]!r}: an image list holds one name a line, without leading or "
            "trailing white space, line breaks or NUL characters; rename the image"
        )
    tail = [s for s in names if _LIST_TAIL.search(s)]
    if tail:
        raise InputError(
            f"image id {tail[0]!r}: an image list line 'NAME 0 FOCAL' gives the focal length "
            f"after the name, so the name would be read back as "
            f"{_LIST_TAIL.sub('', tail[0])!r}; rename the image"
        )


def bundler_texts(block: Block, *, drop_extras: bool = False) -> tuple[str, str]:
    """The Bundler file and image list of a block (see :func:`write_bundler`)."""
    if not drop_extras:
        refuse_extras(block, "Bundler")
    M, t, C, x, y = centred_cameras(block, "Bundler")
    off = np.flatnonzero(np.any(C[:, 1:3] != 0, axis=1))
    if off.size and not drop_extras:
        i = int(off[0])
        raise InputError(
            f"image {block.image_ids[i]}: principal point cx = {float(C[i, 1])!r}, "
            f"cy = {float(C[i, 2])!r} "
            "px off the image centre, where a Bundler camera has it; pass drop_extras=True "
            "to write the observations from the principal point (the projections exact, the "
            "image positions moved by cx, cy)"
        )
    refuse_unlisted_names(block.image_ids)
    names = [str(i) for i in block.image_ids.tolist()]  # as given (no NUL dropped)
    m, p, n = block.n_images, block.n_points, block.n_observations
    cam = np.column_stack([C[:, 0], C[:, 3], C[:, 4], M.reshape(m, 9), t])
    cf = np.array(format_floats(cam), dtype=object).reshape(m, 15)
    cam_lines = [" ".join(r) for r in cf.reshape(m * 5, 3).tolist()]
    # views point by point; key: the observation's rank among its image's observations
    oi, op = block.obs_image, block.obs_point
    per_image = np.bincount(oi, minlength=m)
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(oi, kind="stable")] = np.arange(n) - np.repeat(
        np.cumsum(per_image) - per_image, per_image
    )
    order = np.argsort(op, kind="stable")
    nv = np.bincount(op, minlength=p)
    view = [
        f" {c} {k} {a} {b}"
        for c, k, a, b in zip(
            oi[order].tolist(), rank[order].tolist(), format_floats(x[order]),
            format_floats(y[order]),
        )
    ]  # fmt: skip
    xyz = np.array(format_floats(block.xyz), dtype=object).reshape(p, 3)
    heads = [f"{a} {b} {c}\n0 0 0\n{k}" for (a, b, c), k in zip(xyz.tolist(), nv.tolist())]
    pieces = np.empty(2 * p + n, dtype=object)
    at_head = np.arange(p) * 2 + np.cumsum(nv) - nv
    pieces[at_head] = heads
    pieces[at_head + nv + 1] = "\n"
    mask = np.ones(pieces.size, dtype=bool)
    mask[at_head] = False
    mask[at_head + nv + 1] = False
    pieces[mask] = view
    out = "\n".join([BUNDLER_HEADER, f"{m} {p}", *cam_lines]) + "\n" + "".join(pieces.tolist())
    return out, "\n".join(names) + "\n"


def write_bundler(block: Block, path: str | os.PathLike, *, drop_extras: bool = False) -> Path:
    """Write a block as a Bundler file and its image list ``NAME.list.txt``, atomically
    (both or neither).

    Parameters
    ----------
    block : Block
        The block to write.
    path : path-like
        The Bundler file (``bundle.out``); the list goes next to it (``bundle.out.list.txt``,
        image ids one a line, in block order).
    drop_extras : bool
        Write without control or check points, GNSS/IMU, unequal standard deviations, and
        with observations measured from a principal point off the image centre, instead of
        refusing.

    Returns
    -------
    pathlib.Path
        The Bundler file.

    Raises
    ------
    InputError
        Non-zero K3, K4, P1, P2, B1 or B2 (a Bundler camera has f, k1, k2 only), image ids
        that cannot be list lines, or, unless ``drop_extras=True``, a principal point off the
        centre, control or check points, GNSS/IMU or unequal standard deviations.
    """
    target = Path(path)
    out, names = bundler_texts(block, drop_extras=drop_extras)
    write_files_atomically(
        {target: out.encode("ascii"), target.with_name(target.name + ".list.txt"): names.encode()}
    )
    return target
