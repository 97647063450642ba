"""Every block writer either writes an image id that its reader gives back unchanged, or
refuses it by name and writes nothing. Before: a trailing NUL was dropped by the COLMAP
writers (``'img0\\x00'`` read back as ``'img0'``: numpy's str arrays drop trailing NULs),
white space at the ends of a name was dropped by the COLMAP text writer (``' img0'``,
``'img0\\t'`` read back as ``'img0'``), and a NUL or a line break (``\\x0b``, ``\\x85``,
``\\u2028``) in a COLMAP text name or a Bundler image list was written into a file its reader
then refused; a name ending in ' 0 NUMBER' (``'img0 0 1200'``) was written to a Bundler
image list, whose reader takes that for the focal length of Bundler's list format and gave
``'img0'`` back."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import MetashapeCalibration
from photogeom.bundle import read_block, write_block
from photogeom.errors import InputError, OutputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

CAL = MetashapeCalibration(3000, 2000, 2400.0, k1=-0.08, k2=0.03)
NAMES = ["img0\x00", "im\x00g0", "img0\t", " img0", "img0\r", "im\x0bg0", "im\x85g0",
         "im\u2028g0", "im\x1cg0", "img0\x1f", "img0\x01", "img0\x7f", "img 0",
         # a Bundler list line 'NAME 0 FOCAL': read back as 'img0' before (now refused)
         "img0 0 1200", "img0 0 -1.5e3", "img 0 0"]  # fmt: skip
KINDS = {"csv": "", "colmap": "", "colmap-bin": "", "bundler": ".out"}


@pytest.fixture(scope="module")
def block():
    return grid_block(2, rows=1, cols=3, n_points=40, cal=CAL)


@pytest.mark.parametrize("kind", list(KINDS))
@pytest.mark.parametrize("name", NAMES, ids=[repr(n) for n in NAMES])
def test_an_image_id_is_written_exactly_or_refused(tmp_path, block, kind, name):
    ids = block.image_ids.tolist()
    ids[1] = name
    renamed = block.replace(image_ids=np.array(ids, dtype=object))
    assert str(renamed.image_ids[1]) == name  # the block holds it as given
    out = tmp_path / ("b" + KINDS[kind])
    options = {} if kind == "csv" else {"drop_extras": True}
    try:
        write_block(renamed, out, kind, **options)
    except (InputError, OutputError) as exc:
        assert repr(name) in str(exc), str(exc)
        assert list(tmp_path.iterdir()) == []
        return
    size = {"image_size": (3000, 2000)} if kind == "bundler" else {}
    back = read_block(out, kind, **size)
    assert [str(k) for k in back.image_ids.tolist()] == [str(k) for k in ids]
