"""Big-endian 16-bit colour TIFFs keep their metadata in ``grid correct-images``.

Before: OpenCV writes little-endian TIFFs and the tags of a big-endian original were not
grafted onto them: all metadata lost, with a note. Now the values are converted element by
element (SHORT pairs inside the entry, LONG, DOUBLE, RATIONAL resolution, text).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.calibration import GridLayout
from photogeom.calibration.images import _read, correct_image_file

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

tifffile = pytest.importorskip("tifffile")

W, H = 60, 40
TAGS = [  # (code, dtype, count, value): private tags of every layout the IFD stores
    (50001, "H", 2, (7, 9)),  # two SHORTs inside the entry
    (50002, "d", 1, 3.25),  # a DOUBLE at an offset
    (50003, "I", 1, 123456),  # a LONG inside the entry
    (50004, "H", 5, (1, 2, 3, 4, 65535)),  # SHORTs at an offset
]


@pytest.mark.parametrize("byteorder", [">", "<"])
def test_tags_of_either_byte_order_are_kept(tmp_path, byteorder):
    layout = GridLayout(W, H, 20)
    nodes = np.empty((*layout.shape, 2))
    nodes[...] = (2.0, -1.0)
    grid = grid_with_nodes(layout, nodes)
    pixels = np.random.default_rng(0).integers(0, 65535, (H, W, 3)).astype(np.uint16)
    src, dst = tmp_path / "a.tif", tmp_path / "b.tif"
    tifffile.imwrite(
        src, pixels, byteorder=byteorder, photometric="rgb", description="photogeom test",
        resolution=(300, 300), extratags=[(*t, True) for t in TAGS],
    )  # fmt: skip
    assert correct_image_file(src, dst, grid) is None  # before (">"): "metadata ... not kept"
    with tifffile.TiffFile(dst) as tif:
        page = tif.pages[0]
        for code, _, _, value in TAGS:
            got = page.tags[code].value
            assert (tuple(got) if isinstance(value, tuple) else got) == value, code
        assert page.tags["ImageDescription"].value == "photogeom test"
        assert page.tags["XResolution"].value == (300, 1)
    got, _ = _read(dst)  # BGR, as stored
    np.testing.assert_array_equal(got[: H - 1, 2:, ::-1], pixels[1:, : W - 2])


def _resolution(path) -> tuple:
    """The resolution tags (282, 283, 296) as stored, None where absent (tifffile)."""
    with tifffile.TiffFile(path) as tif:
        tags = tif.pages[0].tags
        return tuple(
            (tuple(tags[c].value) if c != 296 else int(tags[c].value)) if c in tags else None
            for c in (282, 283, 296)
        )


@pytest.mark.parametrize(
    "write",
    [
        {},  # no resolution: Pillow's dpi (1, 1) was written as 1 dpi
        {"resolution": (118, 118), "resolutionunit": 3},  # per cm: was turned into inches
        {"resolution": (2, 1), "resolutionunit": 1},  # no unit (an aspect ratio)
        {"resolution": (300, 300), "resolutionunit": 2},
    ],
)
@pytest.mark.parametrize("channels", [1, 3])
def test_resolution_tags_are_kept_as_stored(tmp_path, write, channels):
    """8-bit TIFFs (written by Pillow): the resolution of the original, tag for tag."""
    layout = GridLayout(W, H, 20)
    grid = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))
    pixels = np.random.default_rng(1).integers(0, 255, (H, W, channels)).astype(np.uint8)
    src, dst = tmp_path / "a.tif", tmp_path / "b.tif"
    if write:
        tifffile.imwrite(
            src, pixels.squeeze(), metadata=None, software=False, **write,
            photometric="rgb" if channels == 3 else "minisblack",
        )  # fmt: skip
    else:
        from PIL import Image

        Image.fromarray(pixels.squeeze()).save(src)  # no resolution tags
    assert (_resolution(src)[0] is None) == (not write)
    correct_image_file(src, dst, grid)
    assert _resolution(dst) == _resolution(src)
