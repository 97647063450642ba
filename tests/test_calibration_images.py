"""Image files with a TIFF Orientation tag: corrected in the stored pixel layout.

OpenCV and Pillow both turn TIFF pixels by the Orientation tag (274) on decoding; the
grid's pixel coordinates are those of the stored layout (the adjustment's), so the file
must be corrected as stored and written back as stored, the tag kept. The stored pixels
are read here with tifffile, which never turns them, and the correction is a whole-pixel
shift whose result is known without the library.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from photogeom.calibration import GridLayout, ResidualGrid, correct_folder, correct_image_file
from photogeom.errors import FileFormatError

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

tifffile = pytest.importorskip("tifffile")

W, H = 60, 40  # not square: a turned image does not fit its grid
SHIFT = (2.0, -1.0)  # modelled residual (px), the same at every node


def _shift_grid() -> ResidualGrid:
    layout = GridLayout(W, H, 20)
    nodes = np.empty((*layout.shape, 2))
    nodes[...] = SHIFT
    return grid_with_nodes(layout, nodes)


def _shifted(stored: np.ndarray) -> np.ndarray:
    """The known correction: output pixel (u, v) takes input (u - rx, v - ry), the border
    replicated (whole pixels, so bilinear resampling is exact)."""
    vv, uu = np.mgrid[0:H, 0:W]
    src_v = np.clip(vv - int(SHIFT[1]), 0, H - 1)
    src_u = np.clip(uu - int(SHIFT[0]), 0, W - 1)
    return stored[src_v, src_u]


def _pattern(channels: int) -> np.ndarray:
    rng = np.random.default_rng(channels)
    img = rng.integers(0, 256, (H, W, channels), dtype=np.uint8)
    img[:8, :15] = 255  # a bright block at the stored top left
    return img if channels > 1 else img[..., 0]


@pytest.mark.parametrize("orientation", [1, 3, 6, 8])
@pytest.mark.parametrize("channels", [1, 3])
def test_tiff_orientation_corrected_as_stored(tmp_path, orientation, channels):
    src, dst = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    stored = _pattern(channels)
    tags = Image.Exif()
    tags[274] = orientation
    tags[0x0110] = "ILCE-7RM2"
    Image.fromarray(stored).save(src / "IMG_1.tif", exif=tags, compression="tiff_adobe_deflate")
    res = correct_folder(src, dst, {"IMG_1": _shift_grid()}, progress=False)
    assert res.ok, res.failures
    if orientation == 1:
        assert res.notes == {}
    else:  # corrected as stored: said, as a grid of the image as shown would be wrong here
        assert list(res.notes) == ["IMG_1"]
        assert res.notes["IMG_1"].startswith(f"EXIF orientation {orientation} (shown ")
    out = tifffile.imread(dst / "IMG_1.tif")
    np.testing.assert_array_equal(out, _shifted(stored))
    with tifffile.TiffFile(dst / "IMG_1.tif") as tf:
        page = tf.pages[0]
        assert page.tags["Orientation"].value == orientation
        assert page.tags["Model"].value == "ILCE-7RM2"
        assert page.compression == 8  # Deflate kept


@pytest.mark.parametrize("bigtiff", [False, True])
def test_tiff_orientation_of_other_writers(tmp_path, bigtiff):
    """Classic and BigTIFF, the tag written by tifffile (a LONG-free SHORT entry)."""
    stored = _pattern(3)
    tifffile.imwrite(
        tmp_path / "a.tif", stored, photometric="rgb", bigtiff=bigtiff,
        extratags=[(274, 3, 1, 6, True)],
    )  # fmt: skip
    correct_image_file(tmp_path / "a.tif", tmp_path / "b.tif", _shift_grid())
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "b.tif"), _shifted(stored))


@pytest.mark.parametrize(("dtype", "value"), [(1, 1), (1, 6), (6, 6), (4, 6)])
def test_tiff_orientation_of_any_integer_type(tmp_path, dtype, value):
    """BYTE, SBYTE and LONG tags are one number too (BYTE and SBYTE were refused as 'not a
    single number', even Orientation 1)."""
    stored = _pattern(3)
    tifffile.imwrite(
        tmp_path / "a.tif", stored, photometric="rgb", extratags=[(274, dtype, 1, value, True)]
    )
    correct_image_file(tmp_path / "a.tif", tmp_path / "b.tif", _shift_grid())
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "b.tif"), _shifted(stored))


def test_tiff_orientation_that_is_not_one_number_is_refused(tmp_path):
    tifffile.imwrite(
        tmp_path / "a.tif", _pattern(3), photometric="rgb", extratags=[(274, 3, 2, (6, 6), True)]
    )
    with pytest.raises(FileFormatError, match="Orientation tag"):
        correct_image_file(tmp_path / "a.tif", tmp_path / "b.tif", _shift_grid())
    assert not (tmp_path / "b.tif").exists()


def test_no_metadata_note_for_a_tiff_without_metadata(tmp_path):
    """16-bit colour goes through OpenCV; a TIFF with only layout tags loses nothing."""
    img = np.random.default_rng(1).integers(0, 65535, (H, W, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "a.tif", img, photometric="rgb", metadata=None, software=False)
    assert correct_image_file(tmp_path / "a.tif", tmp_path / "b.tif", _shift_grid()) is None
    out = cv2.imread(str(tmp_path / "b.tif"), cv2.IMREAD_UNCHANGED)  # OpenCV's writer
    np.testing.assert_array_equal(out[..., ::-1], _shifted(img))
    # with a camera model it is metadata: grafted onto OpenCV's file (it was
    # lost, with a note)
    tifffile.imwrite(
        tmp_path / "c.tif", img, photometric="rgb", metadata=None, software=False,
        extratags=[(272, "s", 0, "ILCE-7RM2", True)],
    )  # fmt: skip
    note = correct_image_file(tmp_path / "c.tif", tmp_path / "d.tif", _shift_grid())
    assert note is None
    with tifffile.TiffFile(tmp_path / "d.tif") as t:
        assert t.pages[0].tags[272].value == "ILCE-7RM2"


def test_a_damaged_tiff_fails_by_name_without_libtiff_lines(tmp_path, capfd):
    """A cut TIFF is a named failure of photogeom; OpenCV's own "TIFF_Error ..." log lines
    (libtiff, printed on stderr by the C library) no longer appear beside it, and OpenCV's
    log level is restored afterwards."""
    good = tmp_path / "a.tif"
    cv2.imwrite(str(good), _pattern(3))
    bad = tmp_path / "b.tif"
    bad.write_bytes(good.read_bytes()[:3000])
    level = cv2.utils.logging.getLogLevel()
    capfd.readouterr()
    with pytest.raises(FileFormatError, match="not a readable image"):
        correct_image_file(bad, tmp_path / "out.tif", _shift_grid())
    err = capfd.readouterr().err
    assert "TIFF_Error" not in err and "ERROR" not in err, err
    assert cv2.utils.logging.getLogLevel() == level


def test_an_image_of_another_size_names_its_path_and_the_fix(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    cv2.imwrite(str(src / "a.png"), np.zeros((H + 2, W, 3), np.uint8))
    res = correct_folder(src, tmp_path / "out", {"a": _shift_grid()})
    msg = res.failures["a"]
    assert str(src / "a.png") in msg and f"{W} x {H + 2} px" in msg
    assert "resized or cropped" in msg
