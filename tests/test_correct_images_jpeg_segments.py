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


def _segment(marker: int, payload: bytes) -> bytes:
    return bytes([0xFF, marker]) + struct.pack(">H", len(payload) + 2) + payload


def _spliced(jpeg: bytes, segments: list[bytes]) -> bytes:
    """``segments`` inserted after the APPn segments of ``jpeg``, before its tables."""
    at = 2
    while jpeg[at + 1] in range(0xE0, 0xF0):
        at += 2 + struct.unpack(">H", jpeg[at + 2 : at + 4])[0]
    return jpeg[:at] + b"".join(segments) + jpeg[at:]


XMP = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF/></x:xmpmeta>'
GUID = b"0123456789ABCDEF0123456789ABCDEF"


def test_comments_extended_xmp_iptc_and_vendor_segments_are_kept(tmp_path, grid):
    """Built with real bytes: Pillow's JPEG with EXIF, XMP and ICC, then a comment (COM),
    the second part of an XMP packet over 64 KB (APP1 xmp/extension), a camera vendor's
    APP4, IPTC (APP13, Photoshop) spliced in; before, only JFIF, EXIF, XMP and ICC were
    written."""
    icc = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    buf = io.BytesIO()
    _picture().save(buf, "JPEG", exif=_exif("DJI"), icc_profile=icc, xmp=XMP, quality=85)
    extended = b"http://ns.adobe.com/xmp/extension/\0" + GUID + struct.pack(">II", 9, 0)
    extended += b"<ext>a</>"
    extra = [
        _segment(0xFE, b"Corrected by hand"),
        _segment(0xE1, extended),
        _segment(0xE4, b"DJI\0vendor block"),
        _segment(0xED, b"Photoshop 3.0\x008BIM\x04\x04\0\0\0\0\0\0"),
        _segment(0xEE, b"Adobe\0d\0\0\0\0\x01"),  # coding of the original: not copied
    ]
    src = tmp_path / "DJI_0001.JPG"
    src.write_bytes(_spliced(buf.getvalue(), extra))
    assert correct_image_file(src, tmp_path / "out.jpg", grid) is None
    out = (tmp_path / "out.jpg").read_bytes()
    segs = header_segments(out)
    n_app = next(k for k, (m, _) in enumerate(segs) if not (0xE0 <= m <= 0xEF or m == 0xFE))
    head = [_segment(m, p) for m, p in segs[:n_app]]
    # Pillow's JFIF, EXIF, XMP and ICC, then the others in their order, byte for byte,
    # before the tables
    assert [m for m, _ in segs[:4]] == [0xE0, 0xE1, 0xE1, 0xE2]
    assert head[4:] == extra[:4]
    assert not any(m == 0xEE for m, _ in segs)
    main = [k for k, (m, p) in enumerate(segs) if p.startswith(b"http://ns.adobe.com/xap/1.0/")]
    ext = [k for k, (m, p) in enumerate(segs) if p.startswith(b"http://ns.adobe.com/xmp/ext")]
    assert len(main) == 1 and len(ext) == 1 and main[0] < ext[0]
    assert sum(p.startswith(b"Exif\0\0") for _, p in segs) == 1
    with Image.open(io.BytesIO(out)) as im:
        assert im.info["comment"] == b"Corrected by hand"
        assert im.info["xmp"] == XMP and im.info["icc_profile"] == icc
        assert im.getexif()[0x010F] == "DJI"
        im.load()  # decodes
