"""An encoder of COLMAP binary models written out from COLMAP's documented layout, record by
record with ``struct`` (independent of photogeom's writer): turns a COLMAP text model, also
an inconsistent one, into the binary files COLMAP would write for it."""

from __future__ import annotations

import struct
from pathlib import Path

#: COLMAP's camera model ids (colmap/sensor/models.h).
MODEL_ID = {
    "SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4,
    "OPENCV_FISHEYE": 5, "FULL_OPENCV": 6, "FOV": 7,
}  # fmt: skip
NO_POINT = 2**64 - 1


def _data(path: Path) -> list[str]:
    return [s for s in path.read_text().splitlines() if not s.startswith("#")]


def cameras_bin(text_dir: Path) -> bytes:
    lines = [s.split() for s in _data(text_dir / "cameras.txt") if s.strip()]
    out = struct.pack("<Q", len(lines))
    for t in lines:
        out += struct.pack("<IiQQ", int(t[0]), MODEL_ID[t[1]], int(t[2]), int(t[3]))
        out += b"".join(struct.pack("<d", float(v)) for v in t[4:])
    return out


def images_bin(text_dir: Path) -> bytes:
    lines = _data(text_dir / "images.txt")
    heads = [(lines[k].split(), lines[k + 1].split() if k + 1 < len(lines) else [])
             for k in range(0, len(lines), 2) if lines[k].strip()]  # fmt: skip
    out = struct.pack("<Q", len(heads))
    for t, p in heads:
        out += struct.pack("<I", int(t[0]))
        out += struct.pack("<7d", *(float(v) for v in t[1:8]))
        out += struct.pack("<I", int(t[8])) + t[9].encode() + b"\0"
        out += struct.pack("<Q", len(p) // 3)
        for k in range(0, len(p), 3):
            pid = int(p[k + 2])
            out += struct.pack("<ddQ", float(p[k]), float(p[k + 1]), NO_POINT if pid < 0 else pid)
    return out


def points_bin(text_dir: Path) -> bytes:
    lines = [s.split() for s in _data(text_dir / "points3D.txt") if s.strip()]
    out = struct.pack("<Q", len(lines))
    for t in lines:
        out += struct.pack("<Q3d3Bd", int(t[0]), *(float(v) for v in t[1:4]),
                           *(int(v) for v in t[4:7]), float(t[7]))  # fmt: skip
        track = t[8:]
        out += struct.pack("<Q", len(track) // 2)
        for k in range(0, len(track), 2):
            out += struct.pack("<II", int(track[k]), int(track[k + 1]))
    return out


def text_to_binary(text_dir: Path, bin_dir: Path) -> Path:
    """Write the binary model of the text model in ``text_dir`` to ``bin_dir``."""
    bin_dir.mkdir(parents=True, exist_ok=True)
    (bin_dir / "cameras.bin").write_bytes(cameras_bin(text_dir))
    (bin_dir / "images.bin").write_bytes(images_bin(text_dir))
    (bin_dir / "points3D.bin").write_bytes(points_bin(text_dir))
    return bin_dir
