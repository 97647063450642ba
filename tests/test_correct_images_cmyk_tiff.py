"""A CMYK TIFF in ``grid correct-images``.

Before: OpenCV decodes it as RGB plus an opaque alpha channel; that was written as RGBA
under the original's CMYK tags (PhotometricInterpretation 5, InkSet), a file Pillow could
not open and OpenCV read as other pixels (up to 255 off with a zero grid). Now the RGB
pixels are written as an RGB TIFF, the other tags (resolution) kept, with a note.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from photogeom.calibration import GridLayout
from photogeom.calibration.images import correct_image_file

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 60, 40


def test_a_cmyk_tiff_is_written_as_a_readable_rgb_tiff(tmp_path):
    layout = GridLayout(W, H, 20)
    grid = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))  # no correction
    cmyk = (np.random.default_rng(0).random((H, W, 4)) * 255).astype(np.uint8)
    src, dst = tmp_path / "a.tif", tmp_path / "out.tif"
    Image.fromarray(cmyk, "CMYK").save(src, dpi=(300, 300))
    note = correct_image_file(src, dst, grid)
    assert note is not None and note.startswith("CMYK TIFF written as RGB")
    with Image.open(dst) as out:
        assert out.mode == "RGB" and out.size == (W, H)
        assert out.info.get("dpi") == (300, 300)
        got = np.asarray(out)
    # a zero grid writes the pixels as decoded (lossless TIFF) ...
    decoded = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)[..., 2::-1]
    np.testing.assert_array_equal(got, decoded)
    # ... and they are the colours of the CMYK original (Pillow's conversion, to rounding)
    with Image.open(src) as im:
        want = np.asarray(im.convert("RGB")).astype(int)
    assert np.abs(got.astype(int) - want).max() <= 2
