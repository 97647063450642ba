"""What a corrected JPEG keeps of the original's header segments, read from the bytes.

A JPEG with a multi-picture index (APP2 "MPF", a camera's preview after the main image)
opens in Pillow as "MPO"; it was written by OpenCV, its EXIF, XMP, ICC profile and
quantisation tables lost.
"""

from __future__ import annotations

import io
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageCms

from photogeom.calibration import GridLayout
from photogeom.calibration.images import correct_image_file

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 160, 120


@pytest.fixture(scope="module")
def grid():
    layout = GridLayout(W, H, 40)
    nodes = np.zeros((*layout.shape, 2))
    nodes[..., 0] = 1.0
    return grid_with_nodes(layout, nodes)


def header_segments(data: bytes) -> list[tuple[int, bytes]]:
    """``(marker, payload)`` of every segment before the first scan (SOS)."""
    out, i = [], 2
    assert data[:2] == b"\xff\xd8"
    while data[i + 1] != 0xDA:
        assert data[i] == 0xFF
        n = struct.unpack(">H", data[i + 2 : i + 4])[0]
        out.append((data[i + 1], data[i + 4 : i + 2 + n]))
        i += 2 + n
    return out


def _picture(value: int = 0) -> Image.Image:
    yy, xx = np.mgrid[0:H, 0:W]
    img = (np.sin(xx / 3.0) * np.cos(yy / 4.0) * 100 + 128 + value).clip(0, 255)
    img = img.astype(np.uint8)
    return Image.fromarray(np.dstack([img, 255 - img, img // 2]))


def _exif(make: str) -> Image.Exif:
    ex = Image.Exif()
    ex[0x010F] = make  # Make
    return ex


def test_a_jpeg_with_a_preview_keeps_its_metadata_and_quality(tmp_path, grid):
    src = tmp_path / "DSC0001.jpg"
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    buf = io.BytesIO()
    _picture().save(buf, "MPO", save_all=True, append_images=[_picture(40)],
                    exif=_exif("SONY"), icc_profile=icc, quality=80)  # fmt: skip
    src.write_bytes(buf.getvalue())
    with Image.open(src) as im:
        assert im.format == "MPO" and im.n_frames == 2  # the premise
        qtables = im.quantization
    note = correct_image_file(src, tmp_path / "out.jpg", grid)
    assert note is not None and "1 preview image(s)" in note and "MPF" in note
    assert "not kept: MPO" not in note  # it was written by OpenCV, metadata lost
    out = (tmp_path / "out.jpg").read_bytes()
    with Image.open(io.BytesIO(out)) as im:
        assert im.format == "JPEG"
        assert im.getexif()[0x010F] == "SONY"
        assert im.info["icc_profile"] == icc
        assert im.quantization == qtables  # quality 80 kept (OpenCV wrote 95)
    assert not any(m == 0xE2 and p.startswith(b"MPF\0") for m, p in header_segments(out))
