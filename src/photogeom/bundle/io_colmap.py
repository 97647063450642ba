"""COLMAP text models (``cameras.txt``, ``images.txt``, ``points3D.txt``): read and write.

The binary model (``cameras.bin``, ...) holds the same numbers and is read and written by
:mod:`photogeom.bundle.io_colmap_bin` through :func:`read_colmap` and :func:`write_colmap`
(``binary=True``); both forms share the checks of this module (:func:`cameras_from_records`,
:func:`check_images`, :func:`block_from_model`) and the numbers of the writer
(:func:`colmap_model`).

COLMAP's conventions and how photogeom maps them:

* Pose: world -> camera quaternion ``(QW, QX, QY, QZ)`` (scalar first) and translation
  ``T``: ``P = R(q) X + T`` in COLMAP's camera frame (x right, y down, z forward, as
  Metashape's). The photogrammetric image system is ``(x, -y, -z)`` of that frame, so
  ``M = diag(1, -1, -1) R(q)`` and the projection centre is ``X0 = -R(q)^T T``.
* Pixels: COLMAP's origin is the top-left *corner* of the image (the first pixel's centre is
  (0.5, 0.5)); photogeom's is the first pixel's centre: ``u = u_colmap - 0.5``. COLMAP's
  principal point is absolute (corner origin), Metashape's ``cx`` an offset from the image
  centre: ``cx = cx_colmap - w / 2``.
* Camera models read and written (exactly representable in the Metashape frame model):

  ==============  ==============================  =====================================
  COLMAP model    parameters                      Metashape
  ==============  ==============================  =====================================
  SIMPLE_PINHOLE  f, cx, cy                       f
  PINHOLE         fx, fy, cx, cy                  f = fy, B1 = fx - fy
  SIMPLE_RADIAL   f, cx, cy, k                    f, K1 = k
  RADIAL          f, cx, cy, k1, k2               f, K1, K2
  OPENCV          fx, fy, cx, cy, k1, k2, p1, p2  f = fy, B1, K1, K2, P1 = p2, P2 = p1
  FULL_OPENCV     ... + k3, k4, k5, k6            as OPENCV + K3, only if k4 = k5 = k6 = 0
  ==============  ==============================  =====================================

  FULL_OPENCV's rational terms k4..k6 (a denominator), and every fisheye, FOV, division,
  thin-prism or spherical model, have no Metashape equivalent: such cameras are refused.
  Metashape's K4 and B2 have no COLMAP equivalent: such calibrations are refused on
  writing.
* Free parameters: a block read from COLMAP refines what COLMAP's bundle adjuster refines by
  default: the focal length(s) and the distortion terms of the camera's model, the principal
  point fixed (``refine_principal_point=True`` frees it).
* Image-variant groups: COLMAP has no camera shared by images with per-image f, cx, cy; such a
  group is written as one camera per image (its f, cx, cy plus the image's offsets, the rest
  the group's) and a comment line ``# photogeom camera group: image_variant f cx cy; f F cx
  CX cy CY b1 B1; CAMERA_ID 1 2 ...`` (:func:`group_comment`; also for a group with
  image-variant names and no offsets yet, written as one camera), which COLMAP skips. The
  reader joins the cameras of such a line into one group again (id: the smallest of them;
  the group's f, cx, cy, b1 from the line, the images' offsets from their cameras, its
  image-variant names; free as for any camera of that model), so a write-read round trip
  adjusts the same problem; cameras of the line that differ in anything but f, cx, cy
  (an edited file) are refused by name. A model COLMAP wrote again has no such line: each
  camera is then its own group, as COLMAP adjusts it.
* Observations: each track element ``(IMAGE_ID, POINT2D_IDX)`` of ``points3D.txt`` is one
  observation, at that 2D point of ``images.txt``; they come in the order of ``images.txt``
  (image by image, 2D point by 2D point), the order the writer keeps. 2D points without a 3D
  point (``POINT3D_ID = -1``) are not observations and are not kept. Colours and COLMAP's ``ERROR``
  are not kept (written as 0 and -1).
* Ids: camera groups are COLMAP's ``CAMERA_ID``, points its ``POINT3D_ID``; images are keyed
  by ``NAME`` (default) or ``IMAGE_ID`` (``image_key="id"``), and the block keeps both in
  ``Block.colmap_images``. The writer writes the ``IMAGE_ID`` and ``NAME`` kept there when
  every image of the block has them (a read-adjust-write round trip keeps every id and name
  whichever the key); otherwise it keeps integer ids (non-negative) and numbers other ids
  1, 2, ... in block order (image ids that are text go to ``NAME``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..camera.metashape import MAX_IMAGE_SIDE, MetashapeCalibration
from ..errors import FileFormatError, InputError
from ._angles import opk_from_rotations
from ._textio import (
    exact_integers,
    format_floats,
    read_text,
    split_numeric_lines,
    split_numeric_tokens,
    unwritable_name,
)
from .block import Block, ColmapImages
from .io_bal import refuse_extras

#: Parameters of each supported COLMAP model (COLMAP's order).
COLMAP_MODELS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
#: Metashape parameters each model can hold besides the principal point (what COLMAP refines
#: by default: focal length(s) and distortion), in photogeom's names.
MODEL_FREE: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f",),
    "PINHOLE": ("f", "b1"),
    "SIMPLE_RADIAL": ("f", "k1"),
    "RADIAL": ("f", "k1", "k2"),
    "OPENCV": ("f", "b1", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("f", "b1", "k1", "k2", "k3", "p1", "p2"),
}
#: Calibration terms no COLMAP camera model holds (Metashape's r^8 radial term and shear).
TERMS_NOT_HELD = ("k4", "b2")
_FLIP = np.diag([1.0, -1.0, -1.0])
_UINT32_MAX = 2**32 - 1
_ID_RANGE = "(camera and image ids are 32-bit: 0 to 4294967294)"


def _calibration_from_colmap(model: str, w: int, h: int, q: list[float]) -> MetashapeCalibration:
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cxc, cyc = q[:3]
        k = q[3:] + [0.0] * (2 - len(q[3:]))
        return MetashapeCalibration(w, h, f, cx=cxc - w / 2, cy=cyc - h / 2, k1=k[0], k2=k[1])
    fx, fy, cxc, cyc = q[:4]
    d = q[4:] + [0.0] * (8 - len(q[4:]))
    return MetashapeCalibration(
        w,
        h,
        fy,
        cx=cxc - w / 2,
        cy=cyc - h / 2,
        b1=fx - fy,
        k1=d[0],
        k2=d[1],
        p1=d[3],
        p2=d[2],
        k3=d[4],
    )


def _colmap_from_calibration(model: str, c: MetashapeCalibration) -> list[float]:
    cxc, cyc = c.width / 2 + c.cx, c.height / 2 + c.cy
    if model == "SIMPLE_PINHOLE":
        return [c.f, cxc, cyc]
    if model == "SIMPLE_RADIAL":
        return [c.f, cxc, cyc, c.k1]
    if model == "RADIAL":
        return [c.f, cxc, cyc, c.k1, c.k2]
    q = [c.f + c.b1, c.f, cxc, cyc]
    if model == "PINHOLE":
        return q
    q += [c.k1, c.k2, c.p2, c.p1]
    if model == "OPENCV":
        return q
    return [*q, c.k3, 0.0, 0.0, 0.0]


def camera_line(camera_id: int, model: str, c: MetashapeCalibration) -> str:
    """One ``cameras.txt`` line ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`` (px, COLMAP's
    corner origin), ``model`` one of :data:`COLMAP_MODELS` that holds ``c``."""
    q = format_floats(np.array(_colmap_from_calibration(model, c)))
    return f"{camera_id} {model} {c.width} {c.height} {' '.join(q)}"


def colmap_camera_text(c: MetashapeCalibration, camera_id: int = 1) -> str:
    """A COLMAP ``cameras.txt`` holding one camera, in the smallest model that holds ``c``.

    Parameters
    ----------
    c : MetashapeCalibration
        The calibration (px); ``k4`` and ``b2`` must be zero.
    camera_id : int, default 1
        Its ``CAMERA_ID``.

    Returns
    -------
    str
        The file's text (COLMAP's comment header, one data line).

    Raises
    ------
    InputError
        Non-zero ``k4`` or ``b2`` (no COLMAP model has them).
    """
    model = colmap_model_for(c)
    return (
        "# Camera list with one line of data per camera:\n"
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        "# Number of cameras: 1\n" + camera_line(camera_id, model, c) + "\n"
    )


#: Start of the comment line of ``cameras.txt`` that joins image-variant cameras into one
#: photogeom camera group (COLMAP skips ``#`` lines).
GROUP_COMMENT = "# photogeom camera group:"
_GROUP_RE = re.compile(
    r"#\s*photogeom camera group:\s*image_variant\s+(?P<iv>\S+(?:\s+\S+)*?)\s*;"
    r"\s*f\s+(?P<f>\S+)\s+cx\s+(?P<cx>\S+)\s+cy\s+(?P<cy>\S+)\s+b1\s+(?P<b1>\S+)\s*;"
    r"\s*CAMERA_ID\s+(?P<ids>\d+(?:\s+\d+)*)\s*"
)
#: Terms that the cameras of one group share (besides the image size and the model).
_SHARED = ("b1", "k1", "k2", "k3", "k4", "p1", "p2", "b2")


def group_comment(image_variant, c: MetashapeCalibration, camera_ids) -> str:
    """The ``cameras.txt`` comment that makes ``camera_ids`` one camera group again on reading.

    Parameters
    ----------
    image_variant : sequence of str
        The group's image-variant parameters (of f, cx, cy); ``none`` when empty.
    c : MetashapeCalibration
        The group's calibration: its f, cx, cy (px, Metashape's ``cx, cy`` from the image
        centre) are the values the images' offsets are measured from; its b1 (px) is the
        cameras' ``fx - fy`` before rounding.
    camera_ids : sequence of int
        The ``CAMERA_ID`` of each camera written for the group (one per image).

    Returns
    -------
    str
        ``# photogeom camera group: image_variant f cx cy; f F cx CX cy CY b1 B1; CAMERA_ID
        1 2 ...`` (one line).
    """
    f, cx, cy, b1 = format_floats(np.array([c.f, c.cx, c.cy, c.b1]))
    names = " ".join(image_variant) or "none"
    ids = " ".join(str(int(i)) for i in camera_ids)
    return (
        f"{GROUP_COMMENT} image_variant {names}; f {f} cx {cx} cy {cy} b1 {b1}; CAMERA_ID {ids}"
    )


def _nonzero(c: MetashapeCalibration) -> set[str]:
    return {n for n in ("b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2") if getattr(c, n) != 0.0}


def colmap_model_for(c: MetashapeCalibration, free: tuple[str, ...] = ()) -> str:
    """The smallest COLMAP model that holds calibration ``c`` exactly and its free terms.

    The free parameters count too, so that a block read from COLMAP is written back with the
    model it came from. Raises :class:`InputError` for non-zero K4 or B2.
    """
    nz = _nonzero(c)
    bad = sorted(nz & set(TERMS_NOT_HELD))
    if bad:
        raise InputError(
            f"{', '.join(n.upper() for n in bad)} = "
            f"{', '.join(repr(getattr(c, n)) for n in bad)}: no COLMAP camera model has "
            "Metashape's r^8 radial term (K4) or its shear (B2); the calibration cannot be "
            "written exactly"
        )
    want = nz | (set(free) - {"cx", "cy", *TERMS_NOT_HELD})
    for model, names in MODEL_FREE.items():
        if want <= set(names):
            return model
    raise AssertionError("unreachable: FULL_OPENCV holds every remaining term")  # pragma: no cover


# --- reading ---------------------------------------------------------------------------------


def _data_lines(text: str, keep_blank: bool = False) -> tuple[list[str], list[int]]:
    lines, numbers = [], []
    for k, ln in enumerate(text.splitlines(), start=1):
        s = ln.strip()
        if s.startswith("#") or (not s and not keep_blank):
            continue
        lines.append(s)
        numbers.append(k)
    return lines, numbers


def _read_cameras(path: Path, refine_pp: bool):
    text = read_text(path, "COLMAP cameras file")
    return (*cameras_from_text(text, str(path), refine_pp), _camera_groups(text, str(path)))


def _camera_groups(text: str, where_file: str) -> list[tuple[int, tuple[str, ...], tuple, list]]:
    """The ``# photogeom camera group:`` lines of a ``cameras.txt`` (see
    :func:`group_comment`): ``(line, image_variant, (f, cx, cy, b1), camera ids)`` each."""
    out = []
    for k, ln in enumerate(text.splitlines(), start=1):
        s = ln.strip()
        if not s.startswith("#") or "photogeom camera group" not in s:
            continue
        where = f"{where_file}, line {k}"
        mt = _GROUP_RE.fullmatch(s)
        if mt is None:
            raise FileFormatError(
                f"{where}: a photogeom camera group line must read '{GROUP_COMMENT} "
                "image_variant NAMES; f F cx CX cy CY b1 B1; CAMERA_ID ID ID ...', got "
                f"{s[:120]!r}; delete the line to read its cameras as separate groups"
            )
        names = tuple(mt["iv"].split())
        names = () if names == ("none",) else names
        bad = [n for n in names if n not in ("f", "cx", "cy")]
        if bad or len(set(names)) != len(names):
            raise FileFormatError(
                f"{where}: image_variant {' '.join(names)}: give distinct names of f, cx, cy "
                "(or none)"
            )
        try:
            base = tuple(float(mt[n]) for n in ("f", "cx", "cy", "b1"))
        except ValueError:
            raise FileFormatError(
                f"{where}: f, cx, cy or b1 is not a number: {s[:120]!r}"
            ) from None
        if not all(np.isfinite(base)):
            raise FileFormatError(f"{where}: f, cx, cy or b1 is NaN or infinite")
        out.append((k, names, base, [int(t) for t in mt["ids"].split()]))
    return out


def _regroup(cams, free, cam_id, groups, where_file):
    """Join the cameras of each photogeom camera group into one group (id: its smallest
    ``CAMERA_ID``) whose images have f, cx, cy offsets: ``(cameras, free, image cameras,
    offsets (m, 3) px, image_variant)``."""
    from dataclasses import replace

    offset = np.zeros((cam_id.size, 3))
    image_cam = cam_id.copy()
    variant: dict[int, tuple[str, ...]] = {}
    seen: dict[int, int] = {}
    for line, names, base, ids in groups:
        where = f"{where_file}, line {line}"
        for i in ids:
            if i not in cams:
                raise FileFormatError(
                    f"{where}: the camera group lists CAMERA_ID {i}, which is not a camera of "
                    "the file; delete the line to read the cameras as separate groups"
                )
            if i in seen:
                raise FileFormatError(
                    f"{where}: CAMERA_ID {i} is listed in the camera group of line {seen[i]} too"
                )
            seen[i] = line
        c0 = cams[ids[0]]
        for i in ids:
            c = cams[i]
            if (c.width, c.height) != (c0.width, c0.height) or free[i] != free[ids[0]]:
                what = "the model or image size differs"
            else:
                diff = [
                    n for n in _SHARED
                    if getattr(c, n) != (base[3] if n == "b1" else getattr(c0, n))
                    and not (n == "b1" and abs(c.b1 - base[3]) <= 1e-9)  # fx - fy: rounding
                ]  # fmt: skip
                if not diff:
                    continue
                what = f"{', '.join(diff)} differ"
            raise FileFormatError(
                f"{where}: cameras {ids[0]} and {i} of one camera group must differ in f, cx, "
                f"cy only, but {what} (edited?); delete the line to read the cameras as "
                "separate groups"
            )
        gid = min(ids)
        try:
            group = replace(c0, f=base[0], cx=base[1], cy=base[2], b1=base[3])
        except InputError as exc:
            raise FileFormatError(f"{where}: the group's f, cx, cy: {exc}") from None
        member = np.isin(cam_id, ids)
        vals = np.array([[cams[i].f, cams[i].cx, cams[i].cy] for i in ids])
        pos = np.searchsorted(np.sort(ids), cam_id[member])
        offset[member] = vals[np.argsort(ids)][pos] - np.array(base[:3])
        image_cam[member] = gid
        group_free = free[ids[0]]
        for i in ids:
            del cams[i], free[i]
        cams[gid], free[gid], variant[gid] = group, group_free, names
    order = sorted(cams)
    return (
        {i: cams[i] for i in order},
        {i: free[i] for i in order},
        image_cam,
        offset,
        variant,
    )


def cameras_from_text(
    text: str, where_file: str = "cameras.txt", refine_pp: bool = False
) -> tuple[dict[int, MetashapeCalibration], dict[int, tuple[str, ...]]]:
    """The cameras of the text of a COLMAP ``cameras.txt``.

    Parameters
    ----------
    text : str
        The file's text (``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`` lines, ``#`` comments).
    where_file : str, default "cameras.txt"
        The file's name in error messages.
    refine_pp : bool, default False
        Count the principal point among the free parameters.

    Returns
    -------
    cameras : dict CAMERA_ID -> MetashapeCalibration
        Each camera (px; the table of the module docstring).
    free : dict CAMERA_ID -> tuple of str
        The parameters COLMAP's bundle adjuster refines for the camera's model.

    Raises
    ------
    FileFormatError
        A malformed line, an unsupported model, FULL_OPENCV with non-zero k4..k6, a
        repeated id, or no camera.
    """
    path = where_file
    lines, nums = _data_lines(text)
    records = []
    for ln, k in zip(lines, nums):
        tok = ln.split()
        where = f"{path}, line {k}"
        if len(tok) < 4:
            raise FileFormatError(
                f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got {ln!r}"
            )
        try:
            cid, w, h = int(tok[0]), int(tok[2]), int(tok[3])
        except ValueError:
            raise FileFormatError(
                f"{where}: CAMERA_ID, WIDTH and HEIGHT must be integers, got {ln!r}"
            ) from None
        model = tok[1].upper()
        if model not in COLMAP_MODELS:
            model = tok[1]  # refused by name in cameras_from_records
            q = []
        else:
            try:
                q = [float(t) for t in tok[4:]]
            except ValueError:
                raise FileFormatError(
                    f"{where}: a camera parameter is not a number: {ln!r}"
                ) from None
        records.append((where, cid, model, w, h, q))
    return cameras_from_records(records, path, refine_pp)


def cameras_from_records(
    records, where_file: str, refine_pp: bool = False
) -> tuple[dict[int, MetashapeCalibration], dict[int, tuple[str, ...]]]:
    """The cameras of a COLMAP model from its camera records, text or binary.

    Parameters
    ----------
    records : sequence of (str, int, str, int, int, list of float)
        ``(where, CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS)`` per camera, ``where`` the file
        and line (or byte offset) for errors; a ``MODEL`` that is not one of
        :data:`COLMAP_MODELS` is refused by its name.
    where_file : str
        The file, for errors about the whole file.
    refine_pp : bool, default False
        Count the principal point among the free parameters.

    Returns
    -------
    cameras : dict CAMERA_ID -> MetashapeCalibration
    free : dict CAMERA_ID -> tuple of str
        As :func:`cameras_from_text`.

    Raises
    ------
    FileFormatError
        As :func:`cameras_from_text`.
    """
    cams: dict[int, MetashapeCalibration] = {}
    free: dict[int, tuple[str, ...]] = {}
    for where, cid, model, w, h, q in records:
        if not 0 <= cid < _UINT32_MAX:
            raise FileFormatError(f"{where}: CAMERA_ID {cid} is not a COLMAP id {_ID_RANGE}")
        if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
            raise FileFormatError(
                f"{where}: camera {cid}: WIDTH x HEIGHT = {str(w)[:20]} x {str(h)[:20]} is not "
                f"an image size (whole pixels from 1 to {MAX_IMAGE_SIDE})"
            )
        if model not in COLMAP_MODELS:
            raise FileFormatError(
                f"{where}: camera {cid} has COLMAP model {model}, which the Metashape frame "
                f"model cannot represent exactly; supported: {', '.join(COLMAP_MODELS)}"
            )
        names = COLMAP_MODELS[model]
        if len(q) != len(names):
            raise FileFormatError(
                f"{where}: model {model} has {len(names)} parameters ({', '.join(names)}), "
                f"the line gives {len(q)}"
            )
        if not all(np.isfinite(q)):
            raise FileFormatError(f"{where}: camera {cid} has NaN or infinite parameters")
        if model == "FULL_OPENCV" and any(q[9:]):
            raise FileFormatError(
                f"{where}: camera {cid} (FULL_OPENCV) has rational terms k4, k5, k6 = "
                f"{q[9]!r}, {q[10]!r}, {q[11]!r}; the Metashape model has no denominator, so "
                "only FULL_OPENCV cameras with k4 = k5 = k6 = 0 can be read"
            )
        if cid in cams:
            raise FileFormatError(f"{where}: camera id {cid} appears twice")
        try:
            cams[cid] = _calibration_from_colmap(model, w, h, q)
        except InputError as exc:
            raise FileFormatError(f"{where}: camera {cid}: {exc}") from None
        free[cid] = MODEL_FREE[model] + (("cx", "cy") if refine_pp else ())
    if not cams:
        raise FileFormatError(f"{where_file}: no cameras")
    return cams, free


def _read_images(path: Path):
    text = read_text(path, "COLMAP images file")
    raw = text.splitlines()
    heads: list[list[str]] = []
    head_no: list[int] = []
    pts_lines: list[str] = []
    pts_no: list[int] = []
    k = 0
    while k < len(raw):
        s = raw[k].strip()
        if not s or s.startswith("#"):
            k += 1
            continue
        if k + 1 == len(raw):  # COLMAP's reader drops such an image without a word
            raise FileFormatError(
                f"{path}, line {k + 1}: the file ends after this image's header line, without "
                "its POINTS2D line (COLMAP writes one for every image, empty when the image "
                "has no 2D points): the file is cut short, and COLMAP would read it without "
                f"this image; write the model again, or end the file with an empty line after "
                f"line {k + 1} to keep the image with no 2D points"
            )
        heads.append(s.split())
        head_no.append(k + 1)
        pts_lines.append(raw[k + 1])
        pts_no.append(k + 2)
        k += 2
    m = len(heads)
    if m == 0:
        raise FileFormatError(f"{path}: no images")
    bad = [i for i, t in enumerate(heads) if len(t) != 10]
    if bad:
        i = bad[0]
        raise FileFormatError(
            f"{path}, line {head_no[i]}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME "
            f"(10 fields, names without spaces), got {len(heads[i])} field(s)"
        )
    try:
        image_id = np.array([int(t[0]) for t in heads], dtype=np.int64)
        cam_id = np.array([int(t[8]) for t in heads], dtype=np.int64)
    except ValueError:
        i = next(i for i, t in enumerate(heads) if not (_isint(t[0]) and _isint(t[8])))
        raise FileFormatError(
            f"{path}, line {head_no[i]}: IMAGE_ID and CAMERA_ID must be integers"
        ) from None
    except OverflowError:  # beyond 64 bits: out of COLMAP's range, named below
        image_id = np.array([_clip_id(t[0]) for t in heads], dtype=np.int64)
        cam_id = np.array([_clip_id(t[8]) for t in heads], dtype=np.int64)
    for what, ids, col in (("IMAGE_ID", image_id, 0), ("CAMERA_ID", cam_id, 8)):
        out = (ids < 0) | (ids >= _UINT32_MAX)
        if np.any(out):
            i = int(np.flatnonzero(out)[0])
            raise FileFormatError(
                f"{path}, line {head_no[i]}: {what} {heads[i][col]} is not a COLMAP id "
                f"{_ID_RANGE}"
            )
    names = np.array([t[9] for t in heads], dtype=str)
    pose_vals, _ = split_numeric_lines([" ".join(t[1:8]) for t in heads], head_no, str(path))
    pose = pose_vals.reshape(m, 7)
    vals, counts, tokens = split_numeric_tokens(pts_lines, pts_no, str(path))
    odd = counts % 3 != 0
    if np.any(odd):
        i = int(np.flatnonzero(odd)[0])
        raise FileFormatError(
            f"{path}, line {pts_no[i]}: POINTS2D must be triples (X, Y, POINT3D_ID), the line "
            f"holds {counts[i]} numbers"
        )
    p2d = vals.reshape(-1, 3)
    # POINT3D_ID is COLMAP's uint64 (-1: none): exact integers, also beyond 2^53
    p3d_pos = np.arange(2, vals.size, 3)
    p3d = exact_integers(
        vals, tokens, p3d_pos, np.repeat(pts_no, counts // 3), str(path), "POINT3D_ID"
    )
    nf = ~np.all(np.isfinite(pose), axis=1)
    if np.any(nf):
        i = int(np.flatnonzero(nf)[0])
        raise FileFormatError(f"{path}, line {head_no[i]}: the pose holds NaN or infinity")
    return image_id, cam_id, names, pose, p2d, p3d, counts // 3, np.array(head_no)


def _clip_id(s: str) -> int:
    """An integer id, beyond the int64 range clipped to -1 (reported as out of range)."""
    n = int(s)
    return n if -(2**63) <= n < 2**63 else -1


def _isint(s: str) -> bool:
    try:
        int(s)
    except ValueError:
        return False
    return True


def _read_points(path: Path):
    text = read_text(path, "COLMAP points3D file")
    lines, nums = _data_lines(text)
    vals, counts, tokens = split_numeric_tokens(lines, nums, str(path))
    bad = (counts < 8) | ((counts - 8) % 2 != 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{path}, line {nums[i]}: expected POINT3D_ID X Y Z R G B ERROR and a track of "
            f"(IMAGE_ID, POINT2D_IDX) pairs, got {counts[i]} numbers"
        )
    starts = (np.cumsum(counts) - counts).astype(np.int64)  # (0,) for a file without points
    head = vals[starts[:, None] + np.arange(8)] if len(lines) else np.zeros((0, 8))
    tlen = (counts - 8) // 2
    # positions of the track pairs in the flat value array
    owner = np.repeat(np.arange(len(lines)), tlen)
    first = np.repeat(starts + 8, tlen)
    within = np.arange(int(tlen.sum())) - np.repeat(np.cumsum(tlen) - tlen, tlen)
    pos = first + 2 * within
    track = np.column_stack([vals[pos], vals[pos + 1]]) if pos.size else np.zeros((0, 2))
    lines_no = np.array(nums, dtype=np.int64)
    pid = exact_integers(vals, tokens, starts, lines_no, str(path), "POINT3D_ID")
    return head, pid, track, owner, lines_no


#: The files of a COLMAP binary model (what COLMAP writes by default).
BINARY_FILES = ("cameras.bin", "images.bin", "points3D.bin")


#: The files of a COLMAP text model.
TEXT_FILES = ("cameras.txt", "images.txt", "points3D.txt")


def colmap_model_is_binary(directory: str | os.PathLike, binary: bool | None = None) -> bool:
    """Whether to read the COLMAP model of ``directory`` from its binary files.

    Parameters
    ----------
    directory : path-like
        A folder.
    binary : bool, optional
        True: the binary model (``cameras.bin``, ...), False: the text model
        (``cameras.txt``, ...); default: the one the folder holds (the binary one of a
        folder holding both; :func:`read_colmap` reads such a folder both ways first).

    Returns
    -------
    bool

    Raises
    ------
    FileFormatError
        With ``binary``, a folder that holds only the other model.
    """
    d = Path(directory)
    txt = [f for f in TEXT_FILES if (d / f).is_file()]
    bins = [f for f in BINARY_FILES if (d / f).is_file()]
    if binary is None:
        return bool(bins)
    if binary and bins == [] and txt:
        raise FileFormatError(
            f"{d} holds a COLMAP text model ({', '.join(txt)}), not a binary one: pass "
            "binary=False (or leave binary out)"
        )
    if not binary and txt == [] and bins:
        raise FileFormatError(
            f"{d} holds a COLMAP binary model ({', '.join(bins)}), not a text one: pass "
            "binary=True (or leave binary out)"
        )
    return bool(binary)


def read_colmap(
    directory: str | os.PathLike,
    *,
    image_key: str = "name",
    refine_principal_point: bool = False,
    sigma: float = 1.0,
    binary: bool | None = None,
) -> Block:
    """Read a COLMAP model: text (``cameras.txt``, ``images.txt``, ``points3D.txt``) or
    binary (``cameras.bin``, ``images.bin``, ``points3D.bin``, what COLMAP writes by
    default).

    Parameters
    ----------
    directory : path-like
        The folder holding the three files.
    image_key : {"name", "id"}
        Key images by their ``NAME`` (text ids, the default) or their ``IMAGE_ID``.
    refine_principal_point : bool
        Also free cx, cy (COLMAP's bundle adjuster keeps them fixed by default).
    sigma : float
        Standard deviation of every image coordinate, pixels (COLMAP's cost is unweighted).
    binary : bool, optional
        Read the binary model (True) or the text model (False); default: the one the folder
        holds. Both give the same block for the same model (the binary one has no
        ``# photogeom camera group:`` lines: each of its cameras is a group). A folder
        holding both (a binary model converted to text in place) is read both ways and
        taken when the two give the same block, refused when they differ.

    Returns
    -------
    Block
        One camera group per COLMAP camera (group id = ``CAMERA_ID``) with the parameters of
        its COLMAP model free, except that the cameras of a ``# photogeom camera group:``
        line (an image-variant group :func:`write_colmap` wrote) are one group with
        image-variant f, cx, cy again; images with their poses, tie points (ids
        ``POINT3D_ID``) and one observation per track element, in the order of
        ``images.txt`` (see the module docstring).

    Raises
    ------
    FileFormatError
        Missing files, malformed lines (naming file and line), camera models the Metashape
        model cannot represent, unknown ids, and tracks that disagree with ``images.txt``;
        a ``# photogeom camera group:`` line that is malformed, names unknown cameras or
        cameras that differ in more than f, cx, cy; a folder holding a text and a binary
        model that differ, without ``binary``; in a binary model, truncated files, counts larger
        than the file, unknown camera model ids (see :mod:`photogeom.bundle.io_colmap_bin`;
        the messages name the file and byte offset); a ``rigs.txt`` / ``rigs.bin`` that
        cannot be read (:func:`rig_sizes`); image poses that contradict the model's
        ``frames`` and ``rigs`` files, images in no frame, or rigs without a ``frames``
        file (:func:`check_frames`: COLMAP 3.12 and later would read the frames' poses, and
        cannot read rigs without frames).

    Warns
    -----
    ColmapRigWarning
        The model's ``rigs.txt`` (``rigs.bin``) holds a rig of several cameras (COLMAP 3.12
        and later): its images are read with the poses COLMAP composed for them and are
        independent images of the block; the rig is not a constraint.
    """
    if image_key not in ("name", "id"):
        raise InputError(f"image_key must be 'name' or 'id', not {image_key!r}")
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory (a COLMAP model is a folder)")
    options = {"image_key": image_key, "refine_principal_point": refine_principal_point}
    if binary is None and _holds_both_models(d):
        block = _read_both_models(d, sigma=sigma, **options)
        _warn_rigs(d, True)
        return block
    if colmap_model_is_binary(d, binary):
        from .io_colmap_bin import read_colmap_binary

        block = read_colmap_binary(d, sigma=sigma, **options)
        _warn_rigs(d, True)
        return block
    block = _read_text_model(d, sigma=sigma, **options)
    _warn_rigs(d, False)
    return block


class ColmapRigWarning(UserWarning):
    """A COLMAP model holds rigs of several cameras (COLMAP 3.12 and later): its images are
    read with the poses COLMAP composed for them and adjusted as independent images; the
    rigs' fixed relative poses are not a constraint of the adjustment."""


def rig_sizes(directory: str | os.PathLike, binary: bool) -> dict[int, int] | None:
    """The number of sensors of each rig in ``rigs.txt`` (``binary``: ``rigs.bin``) of a
    COLMAP model folder.

    Parameters
    ----------
    directory : path-like
        The model's folder.
    binary : bool
        Read ``rigs.bin`` instead of ``rigs.txt``.

    Returns
    -------
    dict of int -> int, or None
        ``{RIG_ID: NUM_SENSORS}``; None when the folder has no such file (a model of COLMAP
        before 3.12: one camera per rig).

    Raises
    ------
    FileFormatError
        A file that ends inside a rig or holds a line without RIG_ID NUM_SENSORS.
    """
    p = Path(directory) / ("rigs.bin" if binary else "rigs.txt")
    if not p.is_file():
        return None
    return _read_rigs(p, binary)[0]


def _warn_rigs(d: Path, binary: bool) -> None:
    """Warn (:class:`ColmapRigWarning`) when the model read holds a rig of several
    cameras."""
    import warnings

    sizes = rig_sizes(d, binary) or {}
    rigs = {r: n for r, n in sizes.items() if n > 1}
    if not rigs:
        return
    first = next(iter(rigs))
    name = "rigs.bin" if binary else "rigs.txt"
    warnings.warn(
        f"{d}: {name} holds {len(rigs)} rig(s) of several cameras (rig {first}: "
        f"{rigs[first]} cameras); each image is read with the pose COLMAP composed for it from "
        "its frame and rig and adjusted as an independent image: the rig's fixed relative "
        "poses are not a constraint of the adjustment",
        ColmapRigWarning,
        stacklevel=3,
    )


#: Largest disagreement of an image's pose in ``images.txt`` / ``images.bin`` with the pose its
#: frame and rig compose (rotation angle, rad; translation, relative to the model's largest
#: ``|T|``): COLMAP writes both from the same numbers to 17 digits, so they agree to about
#: 1e-15; a model whose images file another tool rewrote differs by far more.
FRAME_POSE_TOLERANCE = 1e-6


def _read_rigs(
    path: Path, binary: bool, poses: bool = False
) -> tuple[dict[int, int], dict[tuple[int, int], np.ndarray | None]]:
    """The rigs of ``rigs.txt`` / ``rigs.bin``: ``{RIG_ID: NUM_SENSORS}`` and, with
    ``poses``, per camera keyed ``(RIG_ID, CAMERA_ID)`` its ``sensor_from_rig`` pose (7: QW
    QX QY QZ TX TY TZ; the identity for the reference sensor, None for a sensor whose pose
    the rig does not hold; else an empty dict).

    Raises
    ------
    FileFormatError
        A line without RIG_ID NUM_SENSORS, sensors that do not parse (with ``poses``), a
        binary file that ends inside a rig.
    """
    import struct

    from ._textio import read_binary

    identity = np.array([1.0, 0, 0, 0, 0, 0, 0])
    sizes: dict[int, int] = {}
    sensors: dict[tuple[int, int], np.ndarray | None] = {}
    if not binary:
        lines, numbers = _data_lines(read_text(path, "COLMAP rigs file"))
        for line, k in zip(lines, numbers, strict=True):
            tok = line.split()
            if len(tok) < 2 or not (tok[0].isdigit() and tok[1].isdigit()):
                raise FileFormatError(
                    f"{path}, line {k}: expected RIG_ID NUM_SENSORS ..., got {line[:80]!r}"
                )
            rid, count, at = int(tok[0]), int(tok[1]), 4
            sizes[rid] = count
            if not poses:
                continue
            try:
                if count > 0:
                    if tok[2] == "CAMERA":
                        sensors[(rid, int(tok[3]))] = identity
                    for _ in range(count - 1):
                        kind, sid, has = tok[at], int(tok[at + 1]), tok[at + 2] == "1"
                        pose = np.array([float(x) for x in tok[at + 3 : at + 10]]) if has else None
                        if has and pose.size != 7:
                            raise IndexError
                        if kind == "CAMERA":
                            sensors[(rid, sid)] = pose
                        at += 10 if has else 3
            except (IndexError, ValueError):
                raise FileFormatError(
                    f"{path}, line {k}: expected RIG_ID NUM_SENSORS REF_SENSOR_TYPE "
                    f"REF_SENSOR_ID and the other sensors, got {line[:80]!r}"
                ) from None
        return sizes, sensors
    data, pos = read_binary(path, "COLMAP rigs file"), 8
    try:  # per rig: uint32 id, uint32 sensors, the reference (int32 type, uint32 id), then
        # per other sensor int32 type, uint32 id, uint8 has_pose [, 7 float64]
        (n,) = struct.unpack_from("<Q", data, 0)
        for _ in range(n):
            rid, count = struct.unpack_from("<II", data, pos)
            pos += 8
            sizes[rid] = count
            if count > 0:
                kind, sid = struct.unpack_from("<iI", data, pos)
                pos += 8
                if poses and kind == 0:
                    sensors[(rid, sid)] = identity
            for _ in range(max(count - 1, 0)):
                kind, sid, has = struct.unpack_from("<iIB", data, pos)
                pos += 9
                if poses and kind == 0:
                    sensors[(rid, sid)] = (
                        np.array(struct.unpack_from("<7d", data, pos)) if has else None
                    )
                pos += 56 if has else 0
    except struct.error:
        raise FileFormatError(
            f"{path}: truncated at byte {pos} of {len(data)} (a rig cut short)"
        ) from None
    return sizes, sensors


def _frame_records(path: Path, binary: bool):
    """The frames of ``frames.txt`` / ``frames.bin``: per camera image of a frame its
    ``IMAGE_ID``, ``RIG_ID``, ``CAMERA_ID`` and the frame's ``rig_from_world`` pose (7)."""
    import struct

    from ._textio import read_binary

    image, rig, camera, pose = [], [], [], []
    if not binary:
        lines, numbers = _data_lines(read_text(path, "COLMAP frames file"))
        for line, k in zip(lines, numbers, strict=True):
            tok = line.split()
            try:
                rid, rfw, n = int(tok[1]), [float(x) for x in tok[2:9]], int(tok[9])
                data = tok[10 : 10 + 3 * n]
                if len(rfw) != 7 or len(data) != 3 * n:
                    raise IndexError
                for kind, sid, did in zip(data[::3], data[1::3], data[2::3], strict=True):
                    if kind == "CAMERA":
                        image.append(int(did))
                        rig.append(rid)
                        camera.append(int(sid))
                        pose.append(rfw)
            except (IndexError, ValueError):
                raise FileFormatError(
                    f"{path}, line {k}: expected FRAME_ID RIG_ID QW QX QY QZ TX TY TZ "
                    f"NUM_DATA_IDS and the data ids, got {line[:80]!r}"
                ) from None
    else:
        data, pos = read_binary(path, "COLMAP frames file"), 8
        try:
            (n,) = struct.unpack_from("<Q", data, 0)
            for _ in range(n):
                _, rid, *rfw, count = struct.unpack_from("<II7dI", data, pos)
                pos += 68
                for _ in range(count):
                    kind, sid, did = struct.unpack_from("<iIQ", data, pos)
                    pos += 16
                    if kind == 0:
                        image.append(did)
                        rig.append(rid)
                        camera.append(sid)
                        pose.append(rfw)
        except struct.error:
            raise FileFormatError(
                f"{path}: truncated at byte {pos} of {len(data)} (a frame cut short)"
            ) from None
    return (
        np.array(image, dtype=np.int64),
        np.array(rig, dtype=np.int64),
        np.array(camera, dtype=np.int64),
        np.array(pose, dtype=float).reshape(-1, 7),
    )


def _check_frame_rigs(images, pf, pr, rigs, sensors, img, rig, cam, image_id, names) -> None:
    """Refuse frames (``pf``) whose images are in a rig the rigs file (``pr``) does not hold,
    or taken by a camera that is no sensor of their rig: COLMAP cannot read such a model
    ("Rig with ID .. does not exist", "rig.HasSensor" failed)."""
    no_rig = ~np.isin(rig, np.fromiter(rigs, dtype=np.int64, count=len(rigs)))
    no_sensor = ~no_rig & np.array(
        [(r, c) not in sensors for r, c in zip(rig.tolist(), cam.tolist(), strict=True)],
        dtype=bool,
    ).reshape(-1)
    bad = no_rig | no_sensor
    if not bad.any():
        return
    named = dict(zip(image_id.tolist(), map(str, names), strict=True))

    def image(j: int) -> str:
        i = int(img[j])
        return f"{i} {named[i]!r}" if i in named else str(i)

    shown = "; ".join(
        f"image {image(j)}: "
        + (
            f"rig {int(rig[j])}, which {pr.name} does not hold"
            if no_rig[j]
            else f"camera {int(cam[j])}, which is no sensor of rig {int(rig[j])}"
        )
        for j in np.flatnonzero(bad)[:3]
    )
    raise FileFormatError(
        f"{images.parent}: {pf.name} places {int(bad.sum())} image(s) in rigs that "
        f"{pr.name} does not give them ({shown}{'; ...' if bad.sum() > 3 else ''}); COLMAP "
        f"cannot read the model either. If {images.name} holds the poses meant, remove "
        f"{pr.name} and {pf.name} (COLMAP then reads {images.name} too); else put back the "
        f"{pr.name} written with {pf.name}"
    )


def check_frames(images: Path, image_id: np.ndarray, names: np.ndarray, pose: np.ndarray) -> None:
    """Refuse a model whose ``frames`` and ``rigs`` files (COLMAP 3.12 and later) contradict
    its images file: an image whose pose there differs from the one its frame and rig
    compose (by more than :data:`FRAME_POSE_TOLERANCE`), or that is in no frame (also: rigs
    without a frames file, frames in rigs the rigs file does not hold or taken by a camera
    that is no sensor of their rig, which COLMAP cannot read either).

    COLMAP 3.12 and later (pycolmap 4) take the poses from the frames and ignore those of the
    images file; photogeom reads the images file. When another tool (COLMAP before 3.12, a
    script) rewrote the images file and left the old frames, the two read different blocks
    from one folder, and which is meant cannot be told from the files.

    Parameters
    ----------
    images : Path
        The model's ``images.txt`` or ``images.bin`` (the folder and the form).
    image_id : numpy.ndarray
        (m,) int64, the images' ``IMAGE_ID``.
    names : numpy.ndarray
        (m,) str, their ``NAME``.
    pose : numpy.ndarray
        (m, 7) the images' camera-from-world poses, QW QX QY QZ, TX TY TZ (model units).

    Raises
    ------
    FileFormatError
        The poses contradict, images are in no frame, or a rigs file holding rigs has no
        frames file beside it; naming the files, the images and the fix.
    """
    binary = images.suffix == ".bin"
    ext = ".bin" if binary else ".txt"
    pf, pr = images.parent / f"frames{ext}", images.parent / f"rigs{ext}"
    if image_id.size == 0:
        return
    if not pf.is_file():
        # COLMAP 3.12+ reads a model without rigs and frames as one of an older version
        # (a trivial rig per camera, a frame per image); one with rigs looks up the frame of
        # every image and fails on the first
        rigs = _read_rigs(pr, binary)[0] if pr.is_file() else {}
        if rigs:
            raise FileFormatError(
                f"{pr} holds {len(rigs)} rig(s) but the model has no {pf.name}, which places "
                f"each image in a frame of a rig; COLMAP cannot read the model either (it "
                f"looks up the frame of each image of {images.name}): remove {pr.name} if "
                f"{images.name} holds the poses meant (COLMAP then reads them too), else put "
                f"back the {pf.name} written with {pr.name}"
            )
        return
    if not pr.is_file():
        raise FileFormatError(
            f"{pf} has no {pr.name} beside it, which its rigs need; COLMAP cannot read the "
            f"model either: remove {pf.name} (the poses are those of {images.name})"
        )
    rigs, sensors = _read_rigs(pr, binary, poses=True)
    img, rig, cam, rfw = _frame_records(pf, binary)
    _check_frame_rigs(images, pf, pr, rigs, sensors, img, rig, cam, image_id, names)
    sfr = [sensors.get((r, c)) for r, c in zip(rig.tolist(), cam.tolist(), strict=True)]
    known = np.array([s is not None for s in sfr], dtype=bool)
    sfr_pose = np.array([s if s is not None else np.zeros(7) for s in sfr]).reshape(-1, 7)
    # composed camera from world: R = R_s R_r, T = R_s T_r + T_s
    rs = Rotation.from_quat(sfr_pose[known][:, [1, 2, 3, 0]]) if known.any() else None
    rr = Rotation.from_quat(rfw[known][:, [1, 2, 3, 0]]) if known.any() else None
    order = np.argsort(img[known], kind="stable")
    frame_img = img[known][order]
    where = np.searchsorted(frame_img, image_id)
    inside = where < frame_img.size
    found = np.zeros(image_id.size, dtype=bool)
    found[inside] = frame_img[where[inside]] == image_id[inside]
    in_frames = np.isin(image_id, img)  # also an image of a sensor without a pose
    angle = np.zeros(image_id.size)
    shift = np.zeros(image_id.size)
    if found.any():
        k = order[where[found]]
        r_comp = rs[k] * rr[k]
        t_comp = rs[k].apply(rfw[known][k, 4:7]) + sfr_pose[known][k, 4:7]
        r_img = Rotation.from_quat(pose[found][:, [1, 2, 3, 0]])
        angle[found] = (r_img * r_comp.inv()).magnitude()
        shift[found] = np.linalg.norm(pose[found, 4:7] - t_comp, axis=1)
    scale = max(float(np.max(np.linalg.norm(pose[:, 4:7], axis=1))), 1e-300)
    bad = (angle > FRAME_POSE_TOLERANCE) | (shift > FRAME_POSE_TOLERANCE * scale)
    missing = ~in_frames
    if not (bad.any() or missing.any()):
        return
    parts = []
    if bad.any():
        i = np.flatnonzero(bad)
        shown = ", ".join(
            f"{int(image_id[j])} {str(names[j])!r}: {np.degrees(angle[j]):.3g} deg and "
            f"{shift[j]:.3g} model units apart"
            for j in i[:3]
        )
        parts.append(
            f"the poses of {i.size} image(s) contradict those their frames in {pf.name} and "
            f"rigs in {pr.name} compose (image {shown}{'; ...' if i.size > 3 else ''})"
        )
    if missing.any():
        i = np.flatnonzero(missing)
        shown = ", ".join(f"{int(image_id[j])} {str(names[j])!r}" for j in i[:3])
        parts.append(
            f"{i.size} image(s) are in no frame of {pf.name} (images {shown}"
            f"{', ...' if i.size > 3 else ''})"
        )
    raise FileFormatError(
        f"{images.parent}: {images.name} and the frames disagree: {'; '.join(parts)}. COLMAP "
        f"3.12 and later read the poses of the frames, photogeom those of {images.name}: "
        f"another tool (COLMAP before 3.12, a script) rewrote {images.name} and left the old "
        f"frames? If {images.name} holds the poses meant, remove {pr.name} and {pf.name} "
        f"(COLMAP then reads {images.name} too); if the frames do, write the model again "
        "with COLMAP 3.12 or later (colmap model_converter, or pycolmap's "
        "Reconstruction(folder).write_text), which writes both from the frames"
    )


def _holds_both_models(d: Path) -> bool:
    return any((d / f).is_file() for f in TEXT_FILES) and any(
        (d / f).is_file() for f in BINARY_FILES
    )


def _read_both_models(d: Path, **options) -> Block:
    """The block of a folder holding both COLMAP models, read both ways: the binary one
    (what COLMAP reads) when they give the same block, else :class:`FileFormatError` naming
    the first part that differs."""
    from dataclasses import fields

    from ..records import value_key
    from .io_colmap_bin import read_colmap_binary

    b, t = read_colmap_binary(d, **options), _read_text_model(d, **options)
    names = [f.name for f in fields(b) if f.compare]
    for name, kb, kt in zip(names, value_key(b), value_key(t), strict=True):
        if kb != kt:
            raise ColmapModelsDiffer(
                f"{d} holds both a COLMAP text model ({', '.join(TEXT_FILES)}) and a binary "
                f"model ({', '.join(BINARY_FILES)}), and they differ (their "
                f"{_BLOCK_PARTS.get(name, name)} first): COLMAP reads the binary one",
                "pass binary=True to read the .bin files or binary=False for the .txt files, "
                "or remove one of the two",
            )
    return b


class ColmapModelsDiffer(FileFormatError):
    """A folder holding a COLMAP text and a binary model that differ (:func:`read_colmap`
    without ``binary``): ``head`` says so, ``choose`` how the caller's interface picks one;
    :meth:`chosen_by` gives the same refusal in another interface's words.

    Parameters
    ----------
    head : str
        The folder, its files and the first part that differs.
    choose : str
        How to choose one model, in the caller's words.
    """

    def __init__(self, head: str, choose: str) -> None:
        super().__init__(f"{head}; {choose}")
        self.head = head

    def chosen_by(self, choose: str) -> ColmapModelsDiffer:
        """The same refusal with ``choose`` (e.g. command-line options) as the way to pick."""
        return ColmapModelsDiffer(self.head, choose)


#: How an error names the parts of a block that differ between two models.
_BLOCK_PARTS = {
    "camera_ids": "camera ids",
    "calibrations": "calibrations",
    "image_ids": "image ids",
    "image_camera": "cameras of the images",
    "exterior": "image poses",
    "point_ids": "point ids",
    "xyz": "point coordinates",
    "observations": "image observations",
    "free": "free calibration parameters",
    "image_variant": "camera groups",
    "colmap_images": "image ids and names",
}


def _read_text_model(
    d: Path, *, image_key: str, refine_principal_point: bool, sigma: float
) -> Block:
    """The block of the COLMAP text model in folder ``d`` (see :func:`read_colmap`)."""
    pc, pi, pp = d / "cameras.txt", d / "images.txt", d / "points3D.txt"
    cams, free, groups = _read_cameras(pc, refine_principal_point)
    image_id, cam_id, names, pose, p2d, p3d, n2d, head_no = _read_images(pi)
    check_images(cams, pc, pi, image_id, cam_id, names, image_key, lambda i: f"line {head_no[i]}")
    head, pid, track, owner, pnums = _read_points(pp)
    if np.any(pid < 0):
        i = int(np.flatnonzero(pid < 0)[0])
        raise FileFormatError(
            f"{pp}, line {pnums[i]}: POINT3D_ID {pid[i]} is negative; COLMAP's point ids are "
            "non-negative integers"
        )
    return block_from_model(
        ModelArrays(
            cams=cams,
            free=free,
            groups=groups,
            files=(pc, pi, pp),
            image_id=image_id,
            cam_id=cam_id,
            names=names,
            pose=pose,
            p2d=p2d[:, :2],
            p3d=p3d,
            n2d=n2d,
            image_at=lambda i: f"line {head_no[i]}",
            points2d_at=lambda i: f"line {head_no[i] + 1}",
            pid=pid,
            xyz=head[:, 1:4],
            track=track,
            owner=owner,
            point_at=lambda i: f"line {pnums[i]}",
        ),
        image_key,
        sigma,
    )


def check_images(cams, pc, pi, image_id, cam_id, names, image_key, image_at) -> None:
    """Refuse repeated ``IMAGE_ID``s (and ``NAME``s when they key the images) and images of
    unknown cameras; ``image_at(i)``: where image ``i`` is in its file (for errors)."""
    u, c = np.unique(image_id, return_counts=True)
    if np.any(c > 1):
        raise FileFormatError(f"{pi}: IMAGE_ID {int(u[c > 1][0])} appears twice")
    if image_key == "name":
        u, c = np.unique(names, return_counts=True)
        if np.any(c > 1):
            raise FileFormatError(
                f"{pi}: image NAME {str(u[c > 1][0])!r} appears twice; read with image_key='id'"
            )
    unknown = ~np.isin(cam_id, np.array(list(cams)))
    if np.any(unknown):
        i = int(np.flatnonzero(unknown)[0])
        raise FileFormatError(
            f"{pi}, {image_at(i)}: image {int(image_id[i])} refers to camera "
            f"{int(cam_id[i])}, which is not in {pc}"
        )


@dataclass(frozen=True)
class ModelArrays:
    """A COLMAP model as read from its files (text or binary), for :func:`block_from_model`.

    ``cams``, ``free``: the cameras (:func:`cameras_from_records`); ``groups``: the
    ``# photogeom camera group:`` lines (text only); ``files``: the cameras, images and
    points files; per image ``image_id``, ``cam_id`` (int64), ``names`` (str), ``pose``
    (m, 7: QW QX QY QZ TX TY TZ), ``n2d`` (its number of 2D points); ``p2d`` (k, 2) px the
    2D points of all images in file order (COLMAP's corner origin) and ``p3d`` (k,) int64
    their ``POINT3D_ID`` (-1: none); per point ``pid`` (int64), ``xyz`` (p, 3); the track
    elements ``track`` (t, 2: IMAGE_ID, POINT2D_IDX as float64) and ``owner`` (t,) the
    point of each; ``image_at(i)``, ``point_at(k)``: where image ``i`` and point ``k``
    are in their files ("line 12", "byte 4096"), for errors; ``points2d_at(i)``: where
    image ``i``'s 2D points are (its POINTS2D line; ``None``: at ``image_at(i)``).
    """

    cams: dict
    free: dict
    groups: list
    files: tuple[Path, Path, Path]
    image_id: np.ndarray
    cam_id: np.ndarray
    names: np.ndarray
    pose: np.ndarray
    p2d: np.ndarray
    p3d: np.ndarray
    n2d: np.ndarray
    image_at: Callable[[int], str]
    pid: np.ndarray
    xyz: np.ndarray
    track: np.ndarray
    owner: np.ndarray
    point_at: Callable[[int], str]
    points2d_at: Callable[[int], str] | None = None


def block_from_model(model: ModelArrays, image_key: str, sigma: float) -> Block:
    """The block of a COLMAP model read from text or binary files (see :func:`read_colmap`):
    the checks of the points, tracks and poses, and the block's construction.

    Raises
    ------
    FileFormatError
        Repeated point ids, NaN or infinite coordinates, tracks naming missing images or
        out-of-range 2D points, tracks that disagree with the images' 2D points, tracks
        that name an image twice, quaternions
        whose norm is not 1, malformed camera group lines, poses that contradict the
        frames (:func:`check_frames`).
    """
    mdl = model
    pc, pi, pp = mdl.files
    cams, free, groups = mdl.cams, mdl.free, mdl.groups
    image_id, cam_id, names, pose = mdl.image_id, mdl.cam_id, mdl.names, mdl.pose
    p2d, p3d, n2d = mdl.p2d, mdl.p3d, mdl.n2d
    pid, track, owner = mdl.pid, mdl.track, mdl.owner
    u, c = np.unique(pid, return_counts=True)
    if np.any(c > 1):
        raise FileFormatError(f"{pp}: POINT3D_ID {int(u[c > 1][0])} appears twice")
    nf = ~np.all(np.isfinite(mdl.xyz), axis=1)
    if np.any(nf):
        i = int(np.flatnonzero(nf)[0])
        raise FileFormatError(f"{pp}, {mdl.point_at(i)}: point {pid[i]} holds NaN or infinity")
    # track -> observations
    t_img, t_idx = track[:, 0], track[:, 1]
    order = np.argsort(image_id, kind="stable")
    pos = np.searchsorted(image_id[order], t_img)
    pos = np.clip(pos, 0, max(image_id.size - 1, 0))
    found = (image_id[order][pos] == t_img) if image_id.size else np.zeros(t_img.size, bool)
    if not np.all(found):
        k = int(np.flatnonzero(~found)[0])
        raise FileFormatError(
            f"{pp}, {mdl.point_at(owner[k])}: point {pid[owner[k]]} is observed in image "
            f"{t_img[k]:g}, which is not in {pi}"
        )
    row = order[pos]
    offset = np.concatenate([[0], np.cumsum(n2d)[:-1]]).astype(np.int64)
    badidx = (t_idx != np.round(t_idx)) | (t_idx < 0) | (t_idx >= n2d[row])
    if np.any(badidx):
        k = int(np.flatnonzero(badidx)[0])
        raise FileFormatError(
            f"{pp}, {mdl.point_at(owner[k])}: point {pid[owner[k]]}: POINT2D_IDX {t_idx[k]:g} is "
            f"out of range for image {int(image_id[row[k]])} ({int(n2d[row[k]])} 2D points)"
        )
    flat = offset[row] + t_idx.astype(np.int64)
    if np.any(p3d[flat] != pid[owner]):
        k = int(np.flatnonzero(p3d[flat] != pid[owner])[0])
        raise FileFormatError(
            f"{pp}, {mdl.point_at(owner[k])}: point {pid[owner[k]]} lists 2D point "
            f"{int(t_idx[k])} of image {int(image_id[row[k]])}, but {pi} gives that 2D point "
            f"POINT3D_ID {p3d[flat[k]]}: the two files disagree"
        )
    # observations in the order of images.txt: image by image, 2D point by 2D point
    by_2d = np.argsort(flat, kind="stable")
    flat, row, owner = flat[by_2d], row[by_2d], owner[by_2d]
    linked = int(np.sum(p3d != -1))
    repeated = int(np.sum(flat[1:] == flat[:-1]))
    if linked != flat.size or repeated:
        raise FileFormatError(
            f"{pi} links {linked} 2D points to 3D points but the tracks of {pp} hold "
            f"{flat.size} (with {repeated} repeated): the two files disagree"
        )
    _refuse_image_twice_in_a_track(mdl, flat, row, owner, offset)
    uv = p2d[flat] - 0.5
    nf = ~np.all(np.isfinite(uv), axis=1)
    if np.any(nf):
        k = int(np.flatnonzero(nf)[0])
        raise FileFormatError(f"{pi}: image {int(image_id[row[k]])} has NaN or infinite 2D points")
    # poses
    qn = np.linalg.norm(pose[:, :4], axis=1)
    if np.any(np.abs(qn - 1.0) > 1e-6):
        i = int(np.flatnonzero(np.abs(qn - 1.0) > 1e-6)[0])
        raise FileFormatError(
            f"{pi}, {mdl.image_at(i)}: the quaternion of image {int(image_id[i])} has norm "
            f"{qn[i]:.9g}, not 1"
        )
    check_frames(pi, image_id, names, pose)
    q = pose[:, [1, 2, 3, 0]]  # scipy: scalar last
    R = Rotation.from_quat(q).as_matrix().reshape(-1, 3, 3)
    X0 = -np.einsum("nji,nj->ni", R, pose[:, 4:7])
    M = _FLIP @ R
    exterior = np.column_stack([X0, opk_from_rotations(M)])
    m = image_id.size
    ids = names if image_key == "name" else image_id
    offset, variant = None, None
    if groups:  # cameras written one per image for a group with image-variant f, cx, cy
        cams, free, cam_id, offset, variant = _regroup(cams, free, cam_id, groups, str(pc))
    block = Block.from_arrays(
        cameras=cams,
        image_ids=ids,
        image_camera=cam_id,
        calibration_offset=offset,
        image_variant=variant,
        exterior=exterior.reshape(m, 6),
        point_ids=pid,
        xyz=mdl.xyz,
        obs_image_ids=ids[row],
        obs_point_ids=pid[owner],
        uv=uv,
        sigma=sigma,
        free=free,
    )
    # the other one of IMAGE_ID and NAME, for the writer (database keys and file names)
    return block.replace(colmap_images=ColmapImages(block.image_ids, image_id, names))




def _refuse_image_twice_in_a_track(
    mdl: ModelArrays, flat: np.ndarray, row: np.ndarray, owner: np.ndarray, offset: np.ndarray
) -> None:
    """Refuse a track that names one image twice (two 2D points of an image linked to one 3D
    point): COLMAP keeps both, a block holds one observation of a point per image.

    ``flat``, ``row``, ``owner``: per track element, its 2D point (index into all images' 2D
    points), its image and its point; ``offset``: each image's first 2D point. Names the
    first such point of the points file, its image and both POINT2D_IDX. Vectorised: one
    stable sort of (point, image) codes."""
    if flat.size < 2:
        return
    m = max(mdl.image_id.size, 1)
    key = owner.astype(np.int64) * m + row
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    if not same.size:
        return
    j = same[int(np.argmin(owner[order[same]]))]  # the first such point of the points file
    a, b = int(order[j]), int(order[j + 1])
    i, k = int(row[a]), int(owner[a])
    idx = sorted((int(flat[a] - offset[i]), int(flat[b] - offset[i])))
    pi, pp = mdl.files[1], mdl.files[2]
    where = mdl.points2d_at(i) if mdl.points2d_at is not None else mdl.image_at(i)
    raise FileFormatError(
        f"{pp}, {mdl.point_at(k)}: the track of point {mdl.pid[k]} names image "
        f"{int(mdl.image_id[i])} ({mdl.names[i]}) twice, POINT2D_IDX {idx[0]} and {idx[1]} "
        f"({pi}, {where}: both 2D points linked to point {mdl.pid[k]}); an image observes a "
        "point once "
        "(two 2D points of one image matched to one 3D point are a matching error), which a "
        "block cannot hold: remove one of the two from the track and set that 2D point's "
        "POINT3D_ID to -1"
    )


# --- writing ---------------------------------------------------------------------------------


def _int_ids(ids: np.ndarray, limit: int) -> np.ndarray | None:
    """The ids themselves when they are integers in 0..limit - 1, else None."""
    if ids.dtype.kind in "iu" and (ids.size == 0 or (ids.min() >= 0 and ids.max() < limit)):
        return ids.astype(np.int64)
    return None


def _join_lines(tokens: list[str], counts: np.ndarray) -> str:
    """Join a flat token list into lines of ``counts`` tokens (one string operation)."""
    total = len(tokens)
    seps = np.full(total, " ", dtype=object)
    ends = np.cumsum(counts) - 1
    seps[ends[counts > 0]] = "\n"
    out = np.empty(2 * total, dtype=object)
    out[0::2] = tokens
    out[1::2] = seps
    return "".join(out.tolist())


@dataclass(frozen=True)
class ColmapModel:
    """The numbers of a block written as a COLMAP model, text or binary.

    ``cameras``: ``(CAMERA_ID, MODEL, calibration)`` each; ``group_lines``: the
    ``# photogeom camera group:`` lines of image-variant groups (text only); per image
    ``image_id``, ``names``, ``image_camera`` (its ``CAMERA_ID``), ``pose`` (m, 7: QW QX QY
    QZ TX TY TZ) and ``per_image`` (its number of 2D points); per 2D point, image by image,
    ``uv`` (k, 2) px (COLMAP's corner origin) and ``point3d`` its ``POINT3D_ID``; per point
    ``point_id``, ``xyz`` (p, 3) and ``per_point`` (its track length); per track element,
    point by point, ``track`` (k, 2: IMAGE_ID, POINT2D_IDX).
    """

    cameras: list
    group_lines: list
    image_id: np.ndarray
    names: np.ndarray
    image_camera: np.ndarray
    pose: np.ndarray
    per_image: np.ndarray
    uv: np.ndarray
    point3d: np.ndarray
    point_id: np.ndarray
    xyz: np.ndarray
    per_point: np.ndarray
    track: np.ndarray


def colmap_model(
    block: Block,
    *,
    model: str | Mapping[object, str] | None = None,
    drop_extras: bool = False,
    what: str = "a COLMAP text model",
) -> ColmapModel:
    """The numbers of ``block`` written as a COLMAP model (see :func:`write_colmap`);
    ``what`` names the model in the refusal of extras."""
    if not drop_extras:
        refuse_extras(block, what)
    g = len(block.calibrations)
    gid = block.camera_ids.tolist()
    models = {}
    for k, (cid, c) in enumerate(zip(gid, block.calibrations)):
        want = model.get(cid) if isinstance(model, Mapping) else model
        try:
            auto = colmap_model_for(c, block.free.get(cid, ()))
        except InputError as exc:
            raise InputError(f"camera {cid!r}: {exc}") from None
        if want is None:
            models[k] = auto
            continue
        want = str(want).upper()
        if want not in COLMAP_MODELS:
            raise InputError(
                f"camera {cid!r}: COLMAP model {want!r} is not one photogeom writes; choose "
                f"from {', '.join(COLMAP_MODELS)}"
            )
        extra = _nonzero(c) - set(MODEL_FREE[want])
        if extra:
            raise InputError(
                f"camera {cid!r}: model {want} cannot hold {', '.join(sorted(extra))} "
                f"(non-zero); the smallest model that can is {auto}"
            )
        models[k] = want
    # cameras: one per group, or one per image for groups with image-variant offsets
    variant = np.zeros(g, dtype=bool)
    offs = np.any(block.calibration_offset != 0, axis=1)
    variant[np.unique(block.image_camera[offs])] = True
    keep_ids = _int_ids(block.camera_ids, _UINT32_MAX) if not np.any(variant) else None
    cam_lines = []
    group_lines = []  # the group of image-variant cameras, for read_colmap (COLMAP skips it)
    img_cam = np.empty(block.n_images, dtype=np.int64)
    next_id = 1
    for k in range(g):
        rows = np.flatnonzero(block.image_camera == k)
        first = len(cam_lines)
        if variant[k]:
            for i in rows.tolist():
                c = block.image_calibration(i)
                cam_lines.append((next_id, models[k], c))
                img_cam[i] = next_id
                next_id += 1
        else:
            cid = int(keep_ids[k]) if keep_ids is not None else next_id
            next_id += 1
            cam_lines.append((cid, models[k], block.calibrations[k]))
            img_cam[rows] = cid
        iv = block.image_variant.get(gid[k], ())
        if variant[k] or iv:
            group_lines.append(
                group_comment(iv, block.calibrations[k], [t[0] for t in cam_lines[first:]])
            )
    # images
    m = block.n_images
    bad = unwritable_name(block.image_ids)  # as given: astype(str) drops trailing NULs
    if bad is not None:
        raise InputError(
            f"image id {bad[0]!r}: {what} cannot hold an image name that {bad[1]} (it would "
            "be read back as another name, or not at all); rename the images"
        )
    kept = None if block.colmap_images is None else block.colmap_images.lookup(block.image_ids)
    if kept is not None:  # read from COLMAP: its IMAGE_ID and NAME, whichever was the key
        iid, inames = kept[0].astype(np.int64), kept[1].astype(str)
        if iid.min() < 0 or iid.max() >= _UINT32_MAX or np.unique(iid).size != m:
            raise InputError(
                "block.colmap_images gives IMAGE_IDs that are repeated or not COLMAP ids "
                f"{_ID_RANGE}; pass block.replace(colmap_images=None) to number the images"
            )
    else:
        iid = _int_ids(block.image_ids, _UINT32_MAX)
        if iid is None:
            iid = np.arange(1, m + 1, dtype=np.int64)
        inames = block.image_ids.astype(str)
    R = _FLIP @ block.rotations()  # world -> COLMAP camera
    T = -np.einsum("nij,nj->ni", R, block.exterior[:, :3])
    q = Rotation.from_matrix(R).as_quat(canonical=True).reshape(m, 4) if m else np.zeros((0, 4))
    n = block.n_observations
    o_img, o_pt = block.obs_image, block.obs_point
    by_img = np.argsort(o_img, kind="stable")
    per_img = np.bincount(o_img, minlength=m)
    start = np.concatenate([[0], np.cumsum(per_img)[:-1]]).astype(np.int64)
    idx2d = np.empty(n, dtype=np.int64)
    idx2d[by_img] = np.arange(n) - np.repeat(start, per_img)
    pid = _int_ids(block.point_ids, 2**63)  # 0 .. 2^63 - 1: every id the reader gives
    if pid is None:
        pid = np.arange(1, block.n_points + 1, dtype=np.int64)
    by_pt = np.argsort(o_pt, kind="stable")
    return ColmapModel(
        cameras=cam_lines,
        group_lines=group_lines,
        image_id=iid,
        names=inames,
        image_camera=img_cam,
        pose=np.column_stack([q[:, [3, 0, 1, 2]], T]).reshape(m, 7),
        per_image=per_img,
        uv=block.observations.uv[by_img] + 0.5,
        point3d=pid[o_pt[by_img]],
        point_id=pid,
        xyz=block.xyz,
        per_point=np.bincount(o_pt, minlength=block.n_points),
        track=np.column_stack([iid[o_img[by_pt]], idx2d[by_pt]]).reshape(n, 2),
    )


def colmap_texts(
    block: Block,
    *,
    model: str | Mapping[object, str] | None = None,
    drop_extras: bool = False,
) -> dict[str, str]:
    """The texts of ``cameras.txt``, ``images.txt``, ``points3D.txt``, ``rigs.txt`` and
    ``frames.txt`` (see :func:`write_colmap`)."""
    mdl = colmap_model(block, model=model, drop_extras=drop_extras)
    cam_lines, iid, inames, img_cam = mdl.cameras, mdl.image_id, mdl.names, mdl.image_camera
    per_img, m, n = mdl.per_image, len(iid), len(mdl.point3d)
    cams_txt = [
        "# Camera list with one line of data per camera:",
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
        f"# Number of cameras: {len(cam_lines)}",
        *mdl.group_lines,
    ]
    cams_txt += [camera_line(cid, mdl_, c) for cid, mdl_, c in cam_lines]
    # a name is one token of its line: white space at its ends would be dropped on reading
    spaced = [s for s in inames.tolist() if s.split() != [s]]
    if spaced:
        raise InputError(
            f"image id {spaced[0]!r}: COLMAP's images.txt cannot hold names with white space "
            "(also at their ends, which its readers drop) or empty names; rename the images"
        )
    pose_tok = np.array(format_floats(mdl.pose)).reshape(m, 7)
    uvc = mdl.uv
    p_tok = np.empty((n, 3), dtype=object)
    p_tok[:, 0] = format_floats(uvc[:, 0])
    p_tok[:, 1] = format_floats(uvc[:, 1])
    p_tok[:, 2] = list(map(str, mdl.point3d.tolist()))
    head_tok = np.empty((m, 10), dtype=object)
    head_tok[:, 0] = list(map(str, iid.tolist()))
    head_tok[:, 1:8] = pose_tok
    head_tok[:, 8] = list(map(str, img_cam.tolist()))
    head_tok[:, 9] = inames.tolist()
    body = _images_lines(head_tok, p_tok, per_img)
    mean_obs = n / m if m else 0.0
    imgs_txt = (
        "# Image list with two lines of data per image:\n"
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
        "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
        f"# Number of images: {m}, mean observations per image: {mean_obs:.6g}\n" + body
    )
    # points3D: id X Y Z R G B ERROR track (IMAGE_ID, POINT2D_IDX)
    p, per_pt = len(mdl.point_id), mdl.per_point
    ph = np.empty((p, 8), dtype=object)
    ph[:, 0] = list(map(str, mdl.point_id.tolist()))
    ph[:, 1:4] = np.array(format_floats(mdl.xyz), dtype=object).reshape(p, 3)
    ph[:, 4:7] = "0"
    ph[:, 7] = "-1"
    tt = np.array(list(map(str, mdl.track.ravel().tolist())), dtype=object).reshape(n, 2)
    counts = 8 + 2 * per_pt
    pstart = (np.cumsum(counts) - counts).astype(np.int64)  # (0,) for a block without points
    tstart = (np.cumsum(per_pt) - per_pt).astype(np.int64)
    ptok = np.empty(int(counts.sum()), dtype=object)
    ptok[(pstart[:, None] + np.arange(8)).ravel()] = ph.ravel()
    tpos = np.repeat(pstart + 8, 2 * per_pt) + (
        np.arange(2 * n) - np.repeat(2 * tstart, 2 * per_pt)
    )
    ptok[tpos] = tt.ravel()
    mean_track = n / p if p else 0.0
    pts_txt = (
        "# 3D point list with one line of data per point:\n"
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
        f"# Number of points: {p}, mean track length: {mean_track:.6g}\n"
        + _join_lines(ptok.tolist(), counts)
    )
    # rigs.txt, frames.txt (COLMAP 3.12 and later take the poses from the frames): one
    # trivial rig per camera (rig id = camera id), one frame per image (frame id = image id)
    rig_txt = (
        "# Rig calib list with one line of data per calib:\n"
        "#   RIG_ID, NUM_SENSORS, REF_SENSOR_TYPE, REF_SENSOR_ID, SENSORS[] as (SENSOR_TYPE, "
        "SENSOR_ID, HAS_POSE, [QW, QX, QY, QZ, TX, TY, TZ])\n"
        f"# Number of rigs: {len(cam_lines)}\n"
        + "".join(f"{cid} 1 CAMERA {cid}\n" for cid, _, _ in cam_lines)
    )
    frame_tok = np.empty((m, 12), dtype=object)
    frame_tok[:, 0] = head_tok[:, 0]
    frame_tok[:, 1] = head_tok[:, 8]
    frame_tok[:, 2:9] = pose_tok
    frame_tok[:, 9] = "1"
    frame_tok[:, 10] = "CAMERA"
    frame_tok[:, 11] = head_tok[:, 8]
    frame_txt = (
        "# Frame list with one line of data per frame:\n"
        "#   FRAME_ID, RIG_ID, RIG_FROM_WORLD[QW, QX, QY, QZ, TX, TY, TZ], NUM_DATA_IDS, "
        "DATA_IDS[] as (SENSOR_TYPE, SENSOR_ID, DATA_ID)\n"
        f"# Number of frames: {m}\n"
        + _join_lines(
            np.column_stack([frame_tok, head_tok[:, 0]]).ravel().tolist(),
            np.full(m, 13, dtype=np.int64),
        )
    )
    return {
        "cameras.txt": "\n".join(cams_txt) + "\n",
        "images.txt": imgs_txt,
        "points3D.txt": pts_txt,
        "rigs.txt": rig_txt,
        "frames.txt": frame_txt,
    }


def _images_lines(head_tok, p_tok, per_img) -> str:
    out = []
    s = 0
    for i, k in enumerate(per_img.tolist()):  # one join per image (empty lines kept)
        out.append(" ".join(head_tok[i].tolist()))
        out.append(" ".join(p_tok[s : s + k].ravel().tolist()))
        s += k
    return "\n".join(out) + "\n"


def write_colmap(
    block: Block,
    directory: str | os.PathLike,
    *,
    model: str | Mapping[object, str] | None = None,
    drop_extras: bool = False,
    binary: bool = False,
) -> Path:
    """Write a block as a COLMAP text or binary model (five files, replaced atomically as
    one batch).

    Parameters
    ----------
    block : Block
    directory : path-like
        Target folder (created if missing). ``cameras.txt``, ``images.txt``,
        ``points3D.txt``, ``rigs.txt`` (one trivial rig per camera) and ``frames.txt`` (one
        frame per image: COLMAP 3.12 and later read the poses there) are all formatted
        before any is replaced.
    model : str or mapping group -> str, optional
        COLMAP camera model per group. Default: the smallest of SIMPLE_PINHOLE, PINHOLE,
        SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV that holds the calibration's non-zero terms
        and its free parameters (so a block read from COLMAP keeps its models).
    drop_extras : bool
        Write a block with control or check points, GNSS/IMU observations or unequal
        observation standard deviations anyway (COLMAP's model has none of them); with
        ``binary``, also a camera group with image-variant parameters (written as one
        camera per image, which read back are separate groups).
    binary : bool, default False
        Write COLMAP's binary model (``cameras.bin``, ``images.bin``, ``points3D.bin``,
        ``rigs.bin``, ``frames.bin``; :mod:`photogeom.bundle.io_colmap_bin`): the same
        numbers as doubles, the points in ascending ``POINT3D_ID`` order.

    Returns
    -------
    pathlib.Path
        The folder.

    Notes
    -----
    A group with image-variant offsets is written as one COLMAP camera per image, and a
    comment line that makes them one group again for :func:`read_colmap` (see the module
    docstring). Ids: see the module docstring. Writing over a model that COLMAP wrote
    replaces its ``rigs.txt`` and ``frames.txt`` too, so COLMAP reads the new poses, not its
    old frames.

    Raises
    ------
    InputError
        K4 or B2 non-zero (no COLMAP model has them), a ``model`` that cannot hold the
        calibration, image names with white space (text; binary: empty names or NUL), or
        extras without ``drop_extras``.
    OutputError
        ``directory`` is a file (or lies under one), or a file cannot be written; nothing
        is written then.
    """
    files = colmap_files(block, model=model, drop_extras=drop_extras, binary=binary)
    d = Path(directory)
    from .io_formats import check_block_target, write_files  # (io_formats imports this module)

    check_block_target(d, "colmap-bin" if binary else "colmap")
    write_files({d / k: v for k, v in files.items()}, folders=[d])
    return d


def colmap_files(
    block: Block,
    *,
    model: str | Mapping[object, str] | None = None,
    drop_extras: bool = False,
    binary: bool = False,
) -> dict[str, bytes]:
    """The files of :func:`write_colmap` (name -> content), nothing written."""
    if binary:
        from .io_colmap_bin import colmap_binaries

        return colmap_binaries(block, model=model, drop_extras=drop_extras)
    texts = colmap_texts(block, model=model, drop_extras=drop_extras)
    return {k: v.encode("utf-8") for k, v in texts.items()}
