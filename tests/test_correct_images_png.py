"""``grid correct-images`` keeps a PNG's colour type.

Before: a palette PNG was written as RGB (RGBA with transparency), its colours blended
by the bilinear resampling; grey with alpha as RGBA (8 and 16 bits); the transparent
colour (tRNS) of a grey PNG was dropped. Now palette images are resampled by nearest
neighbour with their palette, bit depth and transparency kept (said in a note), grey with
alpha stays grey with alpha (8 and 16 bits, exact), and tRNS is kept.
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from photogeom.calibration import GridLayout, correct_folder, save_grids
from photogeom.calibration.correction import correct_image
from photogeom.calibration.images import correct_image_file

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 60, 40
SHIFT = (2.0, -1.0)  # px, whole pixels: output (u, v) takes input (u - 2, v + 1)


@pytest.fixture(scope="module")
def grid():
    layout = GridLayout(W, H, 20)
    nodes = np.empty((*layout.shape, 2))
    nodes[...] = SHIFT
    return grid_with_nodes(layout, nodes)


def _shifted_equal(out: np.ndarray, original: np.ndarray) -> bool:
    return np.array_equal(out[: H - 1, 2:], original[1:, : W - 2])


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png(depth: int, colour_type: int, rows: np.ndarray, extra: bytes = b"") -> bytes:
    """A PNG written by hand (filter None), independent of the code under test."""
    h = rows.shape[0]
    ihdr = struct.pack(">IIBBBBB", W, h, depth, colour_type, 0, 0, 0)
    raw = b"".join(b"\x00" + r.tobytes() for r in rows)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + extra
            + _chunk(b"IDAT", zlib.compress(raw)) + _chunk(b"IEND", b""))  # fmt: skip


def _samples16(png: bytes) -> np.ndarray:
    """The 16-bit grey and alpha samples of a PNG of colour type 4 (any filter but Paeth
    and Average: those of the writer under test are None and Up)."""
    i = png.index(b"IDAT")
    (n,) = struct.unpack(">I", png[i - 4 : i])
    body = np.frombuffer(zlib.decompress(png[i + 4 : i + 4 + n]), np.uint8).reshape(H, -1)
    assert set(body[:, 0].tolist()) <= {0, 2}
    rows = body[:, 1:].astype(np.int64)
    up = body[:, 0] == 2
    for r in range(1, H):  # rows in order: "Up" adds the row above (test code, 40 rows)
        if up[r]:
            rows[r] = (rows[r] + rows[r - 1]) % 256
    return rows.astype(np.uint8).view(">u2").reshape(H, W, 2)


@pytest.mark.parametrize("transparency", [None, 3])
def test_palette_png_keeps_its_palette(tmp_path, grid, transparency):
    rng = np.random.default_rng(0)
    index = rng.integers(0, 16, (H, W), dtype=np.uint8)
    im = Image.fromarray(index, "P")
    im.putpalette(rng.integers(0, 256, 48).tolist())
    kw = {} if transparency is None else {"transparency": transparency}
    im.save(tmp_path / "p.png", **kw)
    note = correct_image_file(tmp_path / "p.png", tmp_path / "o.png", grid)
    assert note.startswith("palette image: resampled by nearest neighbour")
    with Image.open(tmp_path / "o.png") as out:
        assert out.mode == "P" and out.getpalette() == im.getpalette()
        assert out.info.get("transparency") == transparency
        assert _shifted_equal(np.asarray(out), index)
    raw_in, raw_out = (tmp_path / "p.png").read_bytes(), (tmp_path / "o.png").read_bytes()
    assert raw_out[24:26] == raw_in[24:26] == bytes([4, 3])  # bit depth 4, palette


def test_grey_alpha_png_stays_grey_alpha(tmp_path, grid):
    rng = np.random.default_rng(1)
    la = rng.integers(0, 256, (H, W, 2), dtype=np.uint8)
    Image.fromarray(la, "LA").save(tmp_path / "la.png")
    assert correct_image_file(tmp_path / "la.png", tmp_path / "o.png", grid) is None
    with Image.open(tmp_path / "o.png") as out:
        assert out.mode == "LA"
        assert _shifted_equal(np.asarray(out), la)


def test_grey_alpha_16_bit_samples_exact(tmp_path, grid):
    la = np.random.default_rng(2).integers(0, 65536, (H, W, 2)).astype(">u2")
    (tmp_path / "la16.png").write_bytes(_png(16, 4, la.reshape(H, -1)))
    correct_image_file(tmp_path / "la16.png", tmp_path / "o.png", grid)
    out = (tmp_path / "o.png").read_bytes()
    assert out[24:26] == bytes([16, 4])
    assert _shifted_equal(_samples16(out), la)


def test_grey_transparent_colour_kept(tmp_path, grid):
    grey = np.random.default_rng(3).integers(0, 256, (H, W), dtype=np.uint8)
    (tmp_path / "g.png").write_bytes(_png(8, 0, grey, _chunk(b"tRNS", b"\x00\x07")))
    correct_image_file(tmp_path / "g.png", tmp_path / "o.png", grid)
    with Image.open(tmp_path / "o.png") as out:
        assert out.mode == "L" and out.info.get("transparency") == 7
        assert _shifted_equal(np.asarray(out), grey)


def test_folder_and_nearest_option(tmp_path, grid):
    src = tmp_path / "in"
    src.mkdir()
    index = np.random.default_rng(4).integers(0, 4, (H, W), dtype=np.uint8)
    im = Image.fromarray(index, "P")
    im.putpalette([0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 255])
    im.save(src / "IMG_1.png")
    grids = save_grids(tmp_path / "g.npz", {"IMG_1": grid}, std=False)
    from photogeom.calibration import load_grids

    res = correct_folder(src, tmp_path / "out", load_grids(grids), progress=False)
    assert "nearest neighbour" in res.notes["IMG_1"]
    # the library's nearest resampling on its own: values are never blended
    img = np.arange(W * H, dtype=np.float32).reshape(H, W)
    out = correct_image(img, grid, interpolation="nearest")
    assert np.array_equal(out[: H - 1, 2:], img[1:, : W - 2])


def _chunk_types(png: bytes) -> list[bytes]:
    """The chunk types of a PNG file in order (its chunk list walked)."""
    at, kinds = 8, []
    while at < len(png):
        (length,) = struct.unpack(">I", png[at : at + 4])
        kinds.append(png[at + 4 : at + 8])
        at += 12 + length
    return kinds


@pytest.mark.parametrize("channels", [3, 4])
def test_text_chunks_keep_their_side_of_the_image_data(tmp_path, grid, channels):
    """XMP before the image data stays there (the XMP specification encourages it at the
    beginning; Pillow's ``Image.open().info`` reads only what precedes the image data),
    a text chunk after the image data stays after it. Before, every text chunk was moved
    after the image data: the XMP of a camera's PNG was no longer in ``info``."""
    import cv2

    xmp = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF/></x:xmpmeta>'
    pixels = np.random.default_rng(3).integers(0, 255, (H, W, channels)).astype(np.uint8)
    png = cv2.imencode(".png", pixels)[1].tobytes()
    head, iend = 33, png.rindex(b"IEND") - 4  # after IHDR; the IEND chunk
    early = _chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x00\x00\x00\x00" + xmp)
    late = _chunk(b"tEXt", b"Comment\x00written last")
    src = tmp_path / "a.png"
    src.write_bytes(png[:head] + early + png[head:iend] + late + png[iend:])
    assert correct_image_file(src, tmp_path / "b.png", grid) is None
    kinds = _chunk_types((tmp_path / "b.png").read_bytes())
    assert kinds.index(b"iTXt") < kinds.index(b"IDAT") < kinds.index(b"tEXt")
    with Image.open(tmp_path / "b.png") as im:  # not decoded: what precedes the data
        assert im.info["XML:com.adobe.xmp"].encode() == xmp
        assert "Comment" not in im.info
        im.load()
        assert im.info["Comment"] == "written last"


def test_a_damaged_png_names_libpngs_reason_without_its_line(tmp_path, grid, capfd):
    """A PNG libpng refuses: the failure gives libpng's reason, and libpng's own
    "libpng error: ..." line (printed on stderr by the C library) no longer appears
    beside it, as for TIFF."""
    import cv2

    from photogeom.errors import FileFormatError

    pixels = np.random.default_rng(5).integers(0, 255, (H, W, 3)).astype(np.uint8)
    png = bytearray(cv2.imencode(".png", pixels)[1].tobytes())
    at = png.index(b"IDAT") + 4 + 40  # inside the compressed image data
    png[at : at + 20] = bytes(20)
    src = tmp_path / "a.png"
    src.write_bytes(bytes(png))
    capfd.readouterr()
    with pytest.raises(FileFormatError, match=r"not a readable image \(libpng: .+\)"):
        correct_image_file(src, tmp_path / "b.png", grid)
    assert "libpng" not in capfd.readouterr().err
    assert not (tmp_path / "b.png").exists()


def _crc_ok(png: bytes) -> bool:
    """Every chunk's CRC matches its type and data."""
    at = 8
    while at < len(png):
        (length,) = struct.unpack(">I", png[at : at + 4])
        end = at + 12 + length
        if zlib.crc32(png[at + 4 : end - 4]) != struct.unpack(">I", png[end - 4 : end])[0]:
            return False
        at = end
    return True


def test_a_metadata_chunk_with_a_wrong_crc_is_left_out_and_said(tmp_path, grid, capfd):
    """libpng warns "iTXt: CRC error" and ignores the chunk; it was copied with its wrong
    CRC, so the written file was damaged in turn (no note). Now it is left out, named in
    the image's note; the good chunks and the pixels are kept."""
    import cv2

    pixels = np.random.default_rng(4).integers(0, 255, (H, W, 3)).astype(np.uint8)
    png = cv2.imencode(".png", pixels)[1].tobytes()
    bad = bytearray(_chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x00\x00\x00\x00<x:xmpmeta/>"))
    bad[-1] ^= 0xFF  # the CRC
    good = _chunk(b"tEXt", b"Comment\x00kept")
    src = tmp_path / "a.png"
    src.write_bytes(png[:33] + bytes(bad) + good + png[33:])
    assert not _crc_ok(src.read_bytes())  # the premise
    capfd.readouterr()
    note = correct_image_file(src, tmp_path / "b.png", grid)
    assert note == (
        "PNG metadata chunk(s) 'iTXt' at byte 33 left out: their CRC is wrong (damaged in "
        "the original)"
    )
    assert "libpng" not in capfd.readouterr().err  # said in the note, with the file
    out = (tmp_path / "b.png").read_bytes()
    assert _crc_ok(out)
    assert b"iTXt" not in _chunk_types(out) and b"tEXt" in _chunk_types(out)
    decoded = cv2.imdecode(np.frombuffer(out, np.uint8), cv2.IMREAD_UNCHANGED)
    assert _shifted_equal(decoded, pixels)
