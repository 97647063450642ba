"""COLMAP binary models (``cameras.bin``, ``images.bin``, ``points3D.bin``): read and write.

The binary model is what COLMAP writes by default (``sparse/0/``); it holds the numbers of
the text model (:mod:`photogeom.bundle.io_colmap`, whose conventions apply unchanged) as
little-endian binary records, doubles to the last bit:

* ``cameras.bin``: ``uint64`` count; per camera ``uint32 CAMERA_ID``, ``int32`` model id
  (0 SIMPLE_PINHOLE, 1 PINHOLE, 2 SIMPLE_RADIAL, 3 RADIAL, 4 OPENCV, 6 FULL_OPENCV; the
  others are refused by name), ``uint64 WIDTH, HEIGHT``, the model's ``float64`` parameters.
* ``images.bin``: ``uint64`` count; per image ``uint32 IMAGE_ID``, ``float64 QW QX QY QZ TX
  TY TZ``, ``uint32 CAMERA_ID``, the ``NAME`` as UTF-8 ending in a NUL byte, ``uint64``
  number of 2D points, and per 2D point ``float64 X, Y``, ``uint64 POINT3D_ID`` (2^64 - 1:
  none).
* ``points3D.bin``: ``uint64`` count; per point ``uint64 POINT3D_ID``, ``float64 X Y Z``,
  ``uint8 R G B``, ``float64 ERROR``, ``uint64`` track length, and per track element
  ``uint32 IMAGE_ID, POINT2D_IDX``.

COLMAP 3.12 and later (pycolmap 4) also write ``rigs.bin`` and ``frames.bin``; ``images.bin``
keeps its layout and each image's pose (camera from world, composed from its frame and rig),
which is what is read; rigs and frames are read only to refuse poses that contradict them
and to warn of a rig of several cameras (as ``rigs.txt``, ``frames.txt`` of the text model:
:func:`photogeom.bundle.io_colmap.check_frames`). The writer writes one trivial rig per
camera and one frame per image, as the text writer does, so COLMAP reads the written poses.

Reading is linear in the files: the fixed-size parts are read with numpy at their byte
offsets, with one pass over the images for their variable-length names; the points are
found where the images' 2D points say they are (COLMAP writes them in ascending id order,
each with the track ``images.bin`` implies) and checked there, and only a file in another
order is walked point by point. Every count is checked against the file's size before
anything is allocated, and every error names the file and the byte offset.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from ._textio import read_binary
from .block import Block
from .io_colmap import (
    BINARY_FILES,
    COLMAP_MODELS,
    ModelArrays,
    _colmap_from_calibration,
    block_from_model,
    cameras_from_records,
    check_images,
    colmap_model,
)

#: COLMAP's camera model ids (``CameraModelId``) and names.
MODEL_IDS: dict[int, str] = {
    0: "SIMPLE_PINHOLE",
    1: "PINHOLE",
    2: "SIMPLE_RADIAL",
    3: "RADIAL",
    4: "OPENCV",
    5: "OPENCV_FISHEYE",
    6: "FULL_OPENCV",
    7: "FOV",
    8: "SIMPLE_RADIAL_FISHEYE",
    9: "RADIAL_FISHEYE",
    10: "THIN_PRISM_FISHEYE",
    11: "RAD_TAN_THIN_PRISM_FISHEYE",
    12: "SIMPLE_DIVISION",
    13: "DIVISION",
    14: "SIMPLE_FISHEYE",
    15: "FISHEYE",
    16: "EUCM",
    17: "EQUIRECTANGULAR",
}
_MODEL_ID = {name: k for k, name in MODEL_IDS.items()}
_NO_POINT = np.uint64(2**64 - 1)  # COLMAP's kInvalidPoint3DId

#: Fixed-size records (packed, little-endian).
_CAMERA_HEAD = struct.Struct("<IiQQ")  # 24 bytes
_IMAGE_HEAD = np.dtype([("id", "<u4"), ("pose", "<f8", (7,)), ("camera", "<u4")])  # 64 bytes
_POINT2D = np.dtype([("xy", "<f8", (2,)), ("point", "<u8")])  # 24 bytes
_POINT_HEAD = np.dtype(
    [("id", "<u8"), ("xyz", "<f8", (3,)), ("rgb", "u1", (3,)), ("error", "<f8"), ("n", "<u8")]
)  # 51 bytes
_TRACK = np.dtype([("image", "<u4"), ("index", "<u4")])  # 8 bytes
_U64 = struct.Struct("<Q")


def _count(data: bytes, path: Path, smallest: int, what: str) -> int:
    """The leading ``uint64`` count of a file, refused when ``count`` records of at least
    ``smallest`` bytes cannot fit in it (a corrupt count must not allocate)."""
    if len(data) < 8:
        raise FileFormatError(
            f"{path}, byte 0: expected the uint64 number of {what}, the file has "
            f"{len(data)} bytes"
        )
    n = _U64.unpack_from(data, 0)[0]
    if n * smallest > len(data) - 8:
        raise FileFormatError(
            f"{path}, byte 0: the file says {n} {what}, but {len(data)} bytes hold at most "
            f"{(len(data) - 8) // smallest} (truncated or not a COLMAP binary model)"
        )
    return n


def _truncated(path: Path, at: int, expected: str, size: int) -> FileFormatError:
    return FileFormatError(
        f"{path}, byte {at}: expected {expected}, the file ends at byte {size} (truncated)"
    )


def _trailing(path: Path, end: int, size: int, n: int, what: str) -> None:
    if end != size:
        raise FileFormatError(
            f"{path}, byte {end}: {size - end} bytes after the last of its {n} {what} "
            "(a wrong count, or not a COLMAP binary model)"
        )


def _gather(u8: np.ndarray, starts: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Records of ``dtype`` at byte offsets ``starts`` of ``u8`` (one numpy take of the
    rows of a sliding-window view, never a loop over the records)."""
    if starts.size == 0:
        return np.zeros(0, dtype=dtype)
    rows = np.lib.stride_tricks.sliding_window_view(u8, dtype.itemsize)[starts]
    return np.ascontiguousarray(rows).view(dtype).reshape(starts.size)


def _read_cameras(path: Path, refine_pp: bool):
    data = read_binary(path, "COLMAP cameras file")
    n = _count(data, path, _CAMERA_HEAD.size, "cameras")
    records = []
    pos = 8
    for _ in range(n):  # a handful of cameras
        at = pos
        if pos + _CAMERA_HEAD.size > len(data):
            raise _truncated(path, pos, "a camera (CAMERA_ID, MODEL_ID, WIDTH, HEIGHT)", len(data))
        cid, model_id, w, h = _CAMERA_HEAD.unpack_from(data, pos)
        pos += _CAMERA_HEAD.size
        model = MODEL_IDS.get(model_id)
        if model is None:
            raise FileFormatError(
                f"{path}, byte {at}: camera {cid} has camera model id {model_id}, which is not "
                f"a COLMAP model (ids 0 to {max(MODEL_IDS)}); the file is damaged or newer than "
                "photogeom knows"
            )
        if model not in COLMAP_MODELS:  # refused by name in cameras_from_records
            records.append((f"{path}, byte {at}", cid, model, w, h, []))
            break
        k = len(COLMAP_MODELS[model])
        if pos + 8 * k > len(data):
            raise _truncated(path, pos, f"the {k} parameters of camera {cid} ({model})", len(data))
        q = np.frombuffer(data, "<f8", count=k, offset=pos).tolist()
        pos += 8 * k
        records.append((f"{path}, byte {at}", cid, model, w, h, q))
    cams, free = cameras_from_records(records, str(path), refine_pp)
    _trailing(path, pos, len(data), n, "cameras")
    return cams, free


def _read_images(path: Path):
    data = read_binary(path, "COLMAP images file")
    size = len(data)
    head_size = _IMAGE_HEAD.itemsize
    m = _count(data, path, head_size + 1 + 8, "images")
    if m == 0:
        raise FileFormatError(f"{path}: no images")
    starts = np.empty(m, dtype=np.int64)
    name_end = np.empty(m, dtype=np.int64)
    n2d = np.empty(m, dtype=np.int64)
    pos = 8
    for i in range(m):  # one pass over the images: names and 2D point counts
        starts[i] = pos
        if pos + head_size + 1 > size:
            raise _truncated(path, pos, f"image record {i + 1} of {m}", size)
        nul = data.find(b"\0", pos + head_size)
        if nul < 0:
            raise _truncated(
                path, pos + head_size, f"the NUL-terminated NAME of image record {i + 1}", size
            )
        if nul + 9 > size:
            raise _truncated(
                path, nul + 1, f"the number of 2D points of image record {i + 1}", size
            )
        k = _U64.unpack_from(data, nul + 1)[0]
        if k > (size - nul - 9) // _POINT2D.itemsize:
            raise FileFormatError(
                f"{path}, byte {nul + 1}: image record {i + 1} says {k} 2D points, but the "
                f"{size - nul - 9} bytes left hold at most {(size - nul - 9) // 24} (truncated "
                "or not a COLMAP binary model)"
            )
        name_end[i], n2d[i] = nul, k
        pos = nul + 9 + k * _POINT2D.itemsize
    _trailing(path, pos, size, m, "images")
    u8 = np.frombuffer(data, dtype=np.uint8)
    head = _gather(u8, starts, _IMAGE_HEAD)
    names = []
    for i, (a, b) in enumerate(zip((starts + head_size).tolist(), name_end.tolist())):
        try:
            names.append(data[a:b].decode("utf-8"))
        except UnicodeDecodeError:
            raise FileFormatError(
                f"{path}, byte {a}: the NAME of image {int(head['id'][i])} is not UTF-8 text"
            ) from None
    first = name_end + 9
    total = int(n2d.sum())
    within = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(n2d) - n2d, n2d)
    pts = _gather(u8, np.repeat(first, n2d) + _POINT2D.itemsize * within, _POINT2D)
    p3d_raw = pts["point"]
    big = (p3d_raw >= np.uint64(2**63)) & (p3d_raw != _NO_POINT)
    if np.any(big):
        k = int(np.flatnonzero(big)[0])
        i = int(np.searchsorted(np.cumsum(n2d), k, side="right"))
        raise FileFormatError(
            f"{path}, byte {int(first[i]) + 24 * (k - int(np.sum(n2d[:i]))) + 16}: image "
            f"{int(head['id'][i])}: POINT3D_ID {int(p3d_raw[k])} is beyond the 64-bit signed "
            "range photogeom reads (ids < 2^63)"
        )
    p3d = np.where(p3d_raw == _NO_POINT, -1, p3d_raw.astype(np.int64))
    pose = head["pose"].astype(np.float64)
    nf = ~np.all(np.isfinite(pose), axis=1)
    if np.any(nf):
        i = int(np.flatnonzero(nf)[0])
        raise FileFormatError(f"{path}, byte {starts[i]}: the pose holds NaN or infinity")
    return (
        head["id"].astype(np.int64),
        head["camera"].astype(np.int64),
        np.array(names, dtype=str),
        pose,
        pts["xy"].astype(np.float64),
        p3d,
        n2d,
        starts,
    )


def _point_starts(data: bytes, path: Path, n: int, p3d: np.ndarray) -> np.ndarray:
    """Byte offsets of the ``n`` point records of ``points3D.bin``.

    COLMAP writes the points in ascending id order, each with as many track elements as
    ``images.bin`` links 2D points to it: the offsets are computed from the images and
    checked (the id and the track length at each); a file in another order (or with
    points that no image observes) is walked record by record.
    """
    size = len(data)
    head = _POINT_HEAD.itemsize
    ids, counts = np.unique(p3d[p3d >= 0], return_counts=True)
    if ids.size == n and 8 + head * n + 8 * int(counts.sum()) == size:
        lengths = head + 8 * counts.astype(np.int64)
        starts = 8 + np.cumsum(lengths) - lengths
        u8 = np.frombuffer(data, dtype=np.uint8)
        got = _gather(u8, starts, _POINT_HEAD)
        if np.array_equal(got["id"], ids.astype(np.uint64)) and np.array_equal(
            got["n"], counts.astype(np.uint64)
        ):
            return starts
    starts = np.empty(n, dtype=np.int64)
    pos = 8
    for k in range(n):  # a file COLMAP did not write in its order
        if pos + head > size:
            raise _truncated(path, pos, f"point record {k + 1} of {n}", size)
        t = _U64.unpack_from(data, pos + head - 8)[0]
        if t > (size - pos - head) // 8:
            raise FileFormatError(
                f"{path}, byte {pos + head - 8}: point record {k + 1} says {t} track elements, "
                f"but the {size - pos - head} bytes left hold at most {(size - pos - head) // 8} "
                "(truncated or not a COLMAP binary model)"
            )
        starts[k] = pos
        pos += head + 8 * t
    _trailing(path, pos, size, n, "points")
    return starts


def _read_points(path: Path, p3d: np.ndarray):
    data = read_binary(path, "COLMAP points3D file")
    n = _count(data, path, _POINT_HEAD.itemsize, "points")
    starts = _point_starts(data, path, n, p3d)
    u8 = np.frombuffer(data, dtype=np.uint8)
    head = _gather(u8, starts, _POINT_HEAD)
    big = head["id"] >= np.uint64(2**63)
    if np.any(big):
        k = int(np.flatnonzero(big)[0])
        raise FileFormatError(
            f"{path}, byte {starts[k]}: POINT3D_ID {int(head['id'][k])} is beyond the 64-bit "
            "signed range photogeom reads (ids < 2^63)"
        )
    tlen = head["n"].astype(np.int64)
    total = int(tlen.sum())
    within = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(tlen) - tlen, tlen)
    track = _gather(
        u8, np.repeat(starts + _POINT_HEAD.itemsize, tlen) + _TRACK.itemsize * within, _TRACK
    )
    owner = np.repeat(np.arange(n, dtype=np.int64), tlen)
    t = np.column_stack([track["image"], track["index"]]).astype(np.float64)
    return head["id"].astype(np.int64), head["xyz"].astype(np.float64), t, owner, starts


def read_colmap_binary(
    directory: str | os.PathLike,
    *,
    image_key: str = "name",
    refine_principal_point: bool = False,
    sigma: float = 1.0,
) -> Block:
    """Read a COLMAP binary model; :func:`photogeom.bundle.read_colmap` with ``binary=True``
    (the same options, checks and block as from the text model)."""
    d = Path(directory)
    pc, pi, pp = (d / f for f in BINARY_FILES)
    cams, free = _read_cameras(pc, refine_principal_point)
    image_id, cam_id, names, pose, p2d, p3d, n2d, img_at = _read_images(pi)
    check_images(cams, pc, pi, image_id, cam_id, names, image_key, lambda i: f"byte {img_at[i]}")
    pid, xyz, track, owner, pt_at = _read_points(pp, p3d)
    return block_from_model(
        ModelArrays(
            cams=cams,
            free=free,
            groups=[],
            files=(pc, pi, pp),
            image_id=image_id,
            cam_id=cam_id,
            names=names,
            pose=pose,
            p2d=p2d,
            p3d=p3d,
            n2d=n2d,
            image_at=lambda i: f"byte {img_at[i]}",
            pid=pid,
            xyz=xyz,
            track=track,
            owner=owner,
            point_at=lambda k: f"byte {pt_at[k]}",
        ),
        image_key,
        sigma,
    )


# --- writing ---------------------------------------------------------------------------------

_RIG = np.dtype([("id", "<u4"), ("sensors", "<u4"), ("type", "<i4"), ("sensor", "<u4")])
_FRAME = np.dtype(
    [
        ("id", "<u4"),
        ("rig", "<u4"),
        ("pose", "<f8", (7,)),
        ("n", "<u4"),
        ("type", "<i4"),
        ("sensor", "<u4"),
        ("data", "<u8"),
    ]
)


def _scatter(buf: np.ndarray, starts: np.ndarray, records: np.ndarray) -> None:
    """Put ``records`` (a structured array) at byte offsets ``starts`` of ``buf`` (one
    numpy assignment per byte of the record, never a loop over the records)."""
    raw = records.view(np.uint8).reshape(records.size, records.dtype.itemsize)
    for j in range(records.dtype.itemsize):
        buf[starts + j] = raw[:, j]


def _counted(n: int, records: np.ndarray) -> bytes:
    return _U64.pack(n) + records.tobytes()


def colmap_binaries(
    block: Block,
    *,
    model: str | Mapping[object, str] | None = None,
    drop_extras: bool = False,
) -> dict[str, bytes]:
    """The contents of ``cameras.bin``, ``images.bin``, ``points3D.bin``, ``rigs.bin`` and
    ``frames.bin`` (see :func:`photogeom.bundle.write_colmap` with ``binary=True``).

    The numbers are those of the text model (:func:`photogeom.bundle.io_colmap.colmap_texts`),
    as doubles; the points are written in ascending ``POINT3D_ID`` order, as COLMAP writes
    them.

    Raises
    ------
    InputError
        As the text model (image names that are empty or hold a NUL character or a line
        break, checked by :func:`photogeom.bundle.io_colmap.colmap_model`); a camera
        group with image-variant parameters (the binary model has no place for the
        ``# photogeom camera group:`` line that joins its cameras again) without
        ``drop_extras``.
    """
    mdl = colmap_model(block, model=model, drop_extras=drop_extras, what="a COLMAP binary model")
    if mdl.group_lines and not drop_extras:
        offs = np.any(block.calibration_offset != 0, axis=1)
        ids = block.camera_ids.tolist()
        named = [g for g in ids if block.image_variant.get(g)]
        gid = named[0] if named else ids[int(block.image_camera[offs][0])]
        raise InputError(
            f"camera group {gid!r} has image-variant parameters: a COLMAP binary model "
            "writes its images as separate cameras and cannot say that they are one group "
            "(the text model keeps that in a comment line); write the text model, or pass "
            "drop_extras=True to write the cameras as separate groups"
        )
    # cameras.bin
    cams = [_U64.pack(len(mdl.cameras))]
    for cid, name, c in mdl.cameras:
        cams.append(_CAMERA_HEAD.pack(cid, _MODEL_ID[name], c.width, c.height))
        cams.append(np.asarray(_colmap_from_calibration(name, c), dtype="<f8").tobytes())
    # images.bin
    m = len(mdl.image_id)
    head = np.zeros(m, dtype=_IMAGE_HEAD)
    head["id"], head["pose"], head["camera"] = mdl.image_id, mdl.pose, mdl.image_camera
    pts = np.zeros(len(mdl.point3d), dtype=_POINT2D)
    pts["xy"], pts["point"] = mdl.uv, mdl.point3d
    ends = np.cumsum(mdl.per_image)
    parts = [_U64.pack(m)]
    for i, name in enumerate(mdl.names.tolist()):  # one pass over the images
        k = int(mdl.per_image[i])
        parts += [head[i : i + 1].tobytes(), name.encode("utf-8") + b"\0", _U64.pack(k)]
        parts.append(pts[ends[i] - k : ends[i]].tobytes())
    # points3D.bin, in ascending POINT3D_ID order
    order = np.argsort(mdl.point_id, kind="stable")
    tlen = mdl.per_point[order].astype(np.int64)
    tstart = (np.cumsum(mdl.per_point) - mdl.per_point).astype(np.int64)[order]
    within = np.arange(int(tlen.sum()), dtype=np.int64) - np.repeat(np.cumsum(tlen) - tlen, tlen)
    rows = np.repeat(tstart, tlen) + within
    track = np.zeros(rows.size, dtype=_TRACK)
    track["image"], track["index"] = mdl.track[rows, 0], mdl.track[rows, 1]
    ph = np.zeros(order.size, dtype=_POINT_HEAD)
    ph["id"], ph["xyz"], ph["error"], ph["n"] = mdl.point_id[order], mdl.xyz[order], -1.0, tlen
    length = _POINT_HEAD.itemsize + _TRACK.itemsize * tlen
    pstart = 8 + np.cumsum(length) - length
    buf = np.zeros(8 + int(length.sum()), dtype=np.uint8)
    buf[:8] = np.frombuffer(_U64.pack(order.size), dtype=np.uint8)
    _scatter(buf, pstart, ph)
    _scatter(buf, np.repeat(pstart + _POINT_HEAD.itemsize, tlen) + _TRACK.itemsize * within, track)
    # rigs.bin, frames.bin: one trivial rig per camera, one frame per image (as the text model)
    cids = np.array([t[0] for t in mdl.cameras], dtype=np.int64)
    rigs = np.zeros(cids.size, dtype=_RIG)
    rigs["id"], rigs["sensors"], rigs["type"], rigs["sensor"] = cids, 1, 0, cids
    frames = np.zeros(m, dtype=_FRAME)
    frames["id"], frames["rig"], frames["pose"] = mdl.image_id, mdl.image_camera, mdl.pose
    frames["n"], frames["type"], frames["sensor"] = 1, 0, mdl.image_camera
    frames["data"] = mdl.image_id
    return {
        "cameras.bin": b"".join(cams),
        "images.bin": b"".join(parts),
        "points3D.bin": buf.tobytes(),
        "rigs.bin": _counted(cids.size, rigs),
        "frames.bin": _counted(m, frames),
    }
