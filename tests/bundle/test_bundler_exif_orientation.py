"""Image sizes of a Bundler file read from its images under an EXIF orientation that turns
them by 90 degrees (Orientation 5-8: a JPEG stored 2000 x 3000 px is shown 3000 x 2000 px).
Bundler itself and COLMAP use the pixels as stored (COLMAP does not apply the tag:
colmap/colmap#1406, #2104); a tool that applies the orientation writes coordinates of the
image as shown. The observations decide: before, the stored size was taken whatever they
showed, so a block whose coordinates refer to the shown image got the wrong pixel origin
(u off by (3000 - 2000) / 2 = 500 px) silently, and a file whose observations fit both was
read as stored without a word."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from photogeom import MetashapeCalibration
from photogeom.bundle import read_bundler, write_bundler
from photogeom.bundle.io_bundler import ExifOrientationWarning
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

PIL = pytest.importorskip("PIL.Image")
SIZE = (3000, 2000)
CAL = MetashapeCalibration(*SIZE, 2400.0, k1=-0.08, k2=0.03)


@pytest.fixture(scope="module")
def bundler(tmp_path_factory):
    """A Bundler file of 3000 x 2000 px images (observations reach |x| > 1000 px)."""
    d = tmp_path_factory.mktemp("b")
    write_bundler(grid_block(2, rows=1, cols=3, n_points=60, cal=CAL), d / "b.out",
                  drop_extras=True)  # fmt: skip
    return d / "b.out"


def _images(folder: Path, bundler: Path, size, orientation, kind: str = "JPEG") -> Path:
    """The Bundler file and its list in ``folder``, the listed images ``size`` px as stored,
    with EXIF ``orientation`` (None: no tag), in format ``kind``."""
    folder.mkdir()
    out = folder / "b.out"
    out.write_bytes(bundler.read_bytes())
    listing = bundler.with_name("b.out.list.txt").read_text()
    (folder / "b.out.list.txt").write_text(listing)
    for name in listing.split():
        exif = PIL.Exif()
        if orientation is not None:
            exif[274] = orientation
        PIL.new("L", size).save(folder / name, kind, exif=exif)
    return out


def _same(a, b):
    np.testing.assert_array_equal(a.image_sizes(), b.image_sizes())
    np.testing.assert_array_equal(a.observations.uv, b.observations.uv)


def test_coordinates_of_the_stored_image_keep_the_stored_size(tmp_path, bundler):
    out = _images(tmp_path / "s", bundler, SIZE, 6)  # stored landscape, shown portrait
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        block = read_bundler(out)
    _same(block, read_bundler(bundler, image_size=SIZE))


def test_coordinates_of_the_shown_image_take_the_shown_size(tmp_path, bundler):
    out = _images(tmp_path / "t", bundler, SIZE[::-1], 6)  # stored portrait, shown landscape
    with pytest.warns(ExifOrientationWarning, match=r"2000 x 3000 px as stored.*3000 x 2000"):
        block = read_bundler(out)
    _same(block, read_bundler(bundler, image_size=SIZE))


@pytest.mark.parametrize("orientation", [5, 8])
def test_observations_that_fit_both_are_refused_naming_the_fix(tmp_path, bundler, orientation):
    out = _images(tmp_path / "a", bundler, (3200, 3100), orientation)
    with pytest.raises(InputError, match=r"3200 x 3100 px as stored.*3100 x 3200 px.*image_size"):
        read_bundler(out)
    read_bundler(out, image_size=(3200, 3100))  # the size given: read


def test_without_the_tag_the_stored_size_is_taken(tmp_path, bundler):
    out = _images(tmp_path / "n", bundler, SIZE, None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _same(read_bundler(out), read_bundler(bundler, image_size=SIZE))


@pytest.mark.parametrize("orientation", [6, 8])
def test_a_tiffs_stored_size_is_read_as_stored(tmp_path, bundler, orientation):
    # Pillow gives a TIFF's size turned by its Orientation tag (a JPEG's as stored): a TIFF
    # stored 3000 x 2000 px with Orientation 6 was taken for one stored 2000 x 3000 px, and
    # its observations of the stored pixels were said to refer to the image as shown (an
    # ExifOrientationWarning that grid correct-images of the files would not match them)
    out = _images(tmp_path / "t", bundler, SIZE, orientation, "TIFF")
    name = out.with_name("b.out.list.txt").read_text().split()[0]
    with PIL.open(out.parent / name) as im:  # the premise: Pillow turns the TIFF's size
        assert im.size == SIZE[::-1] and (im.tag_v2[256], im.tag_v2[257]) == SIZE
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        block = read_bundler(out)
    _same(block, read_bundler(bundler, image_size=SIZE))


def test_a_tiff_whose_coordinates_refer_to_the_shown_image_says_so(tmp_path, bundler):
    out = _images(tmp_path / "t", bundler, SIZE[::-1], 6, "TIFF")  # shown 3000 x 2000
    with pytest.warns(ExifOrientationWarning, match=r"2000 x 3000 px as stored.*3000 x 2000"):
        block = read_bundler(out)
    _same(block, read_bundler(bundler, image_size=SIZE))
