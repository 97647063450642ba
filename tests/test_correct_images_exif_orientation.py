"""``grid correct-images`` of image files whose EXIF orientation (2-8) shows them otherwise
than stored: the pixels are corrected as stored (COLMAP and Bundler coordinates refer to
them) and the tag is kept, which is wrong for grids of coordinates of the image as shown (a
tool that applied the orientation). Orientations 2-4 (mirrored, turned by 180 degrees) keep
the size, so no size check can tell; before, such a file was corrected without a word."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from photogeom.calibration import GridLayout, correct_folder
from photogeom.calibration.correction import correct_image
from photogeom.calibration.images import correct_image_file

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

PIL = pytest.importorskip("PIL.Image")
W, H = 96, 64


@pytest.fixture(scope="module")
def grid():
    layout = GridLayout(W, H, 32)
    nodes = np.zeros((*layout.shape, 2))
    nodes[..., 0] = 2.0  # every pixel 2 px in x: a mirrored layout would move it the other way
    return grid_with_nodes(layout, nodes)


def _pixels() -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    return (np.sin(xx / 4.0) * np.cos(yy / 5.0) * 90 + 128 + xx).astype(np.uint8)


def _jpeg(path: Path, orientation: int | None) -> None:
    exif = PIL.Exif()
    if orientation is not None:
        exif[274] = orientation
    PIL.fromarray(_pixels()).save(path, "JPEG", quality=95, exif=exif)


@pytest.mark.parametrize(
    "orientation, words",
    [(2, "mirrored left-right"), (3, "turned by 180 degrees"), (4, "mirrored top-bottom"),
     (6, "turned by 90 degrees clockwise")],
)  # fmt: skip
def test_an_image_shown_otherwise_than_stored_is_corrected_as_stored_with_a_note(
    tmp_path, grid, orientation, words
):
    src, dst = tmp_path / "a.jpg", tmp_path / "out.jpg"
    _jpeg(src, orientation)
    note = correct_image_file(src, dst, grid)
    assert note is not None and f"EXIF orientation {orientation} (shown {words})" in note
    assert "corrected as stored" in note and "as shown" in note
    with PIL.open(dst) as im:  # the tag kept, the stored layout kept
        assert im.getexif().get(274) == orientation and im.size == (W, H)
    got = cv2.imread(str(dst), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)
    stored = cv2.imread(str(src), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)
    want = correct_image(stored, grid).astype(float)
    assert np.mean(np.abs(got - want)) < 2.0  # JPEG's loss only


@pytest.mark.parametrize("orientation", [None, 1])
def test_an_image_shown_as_stored_has_no_note(tmp_path, grid, orientation):
    src = tmp_path / "a.jpg"
    _jpeg(src, orientation)
    assert correct_image_file(src, tmp_path / "out.jpg", grid) is None


def test_a_folder_names_the_images_shown_otherwise(tmp_path, grid):
    src = tmp_path / "in"
    src.mkdir()
    _jpeg(src / "plain.jpg", None)
    _jpeg(src / "upside.jpg", 3)
    res = correct_folder(src, tmp_path / "out", {"plain": grid, "upside": grid})
    assert set(res.written) == {"plain", "upside"}
    assert list(res.notes) == ["upside"] and "EXIF orientation 3" in res.notes["upside"]
