"""`grid correct-images` on a folder holding a few images of a large block.

A user who corrects six images of the study's 250-image block got one stderr line per image
without a file, 244 lines of "failed N: no image file named N", among which the failure of
a file that was there and damaged was one line more. The images without a file are now
named up to ``MISSING_SHOWN`` and counted beyond that, after the files that failed; the
exit code (1) and ``--json`` (every failure, and ``missing``) are unchanged.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from photogeom.calibration import GridLayout, save_grids
from photogeom.cli.grid import MISSING_SHOWN

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 60, 40
N = 40  # images with a grid


def _folder(tmp_path):
    layout = GridLayout(W, H, 20)
    g = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))
    grids = save_grids(tmp_path / "grids.npz", {f"IMG_{i}": g for i in range(N)}, std=False)
    src = tmp_path / "in"
    src.mkdir()
    Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(src / "IMG_0.png")
    (src / f"IMG_{N - 1}.png").write_bytes(b"\x89PNG\r\n\x1a\n damaged")  # found, fails
    return grids, src


def test_images_without_a_file_are_counted_not_listed(cli, tmp_path):
    grids, src = _folder(tmp_path)
    code, out, err = cli("grid", "correct-images", grids, src, tmp_path / "out")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 + MISSING_SHOWN + 1 + 1  # damaged, named, counted, error
    assert lines[0].startswith(f"failed IMG_{N - 1}: ")  # the file that failed comes first
    assert "no image file named" not in lines[0]
    assert [ln.split(":")[0] for ln in lines[1 : 1 + MISSING_SHOWN]] == [
        f"failed IMG_{i}" for i in range(1, 1 + MISSING_SHOWN)
    ]
    rest = N - 2 - MISSING_SHOWN
    assert lines[-2] == (
        f"failed: {rest} more image(s) with a grid and no image file of their name in {src} "
        "(--json gives the reason for each)"
    )
    assert lines[-1].startswith(f"error: {N - 1} of {N} image(s) failed")
    assert "corrected 1 image(s)" in out


def test_json_keeps_every_failure(cli, tmp_path):
    grids, src = _folder(tmp_path)
    code, out, _ = cli("grid", "correct-images", grids, src, tmp_path / "out", "--json")
    assert code == 1
    d = json.loads(out)
    assert len(d["failures"]) == N - 1
    assert d["missing"] == [f"IMG_{i}" for i in range(1, N - 1)]


def test_a_few_missing_images_are_all_named(cli, tmp_path):
    layout = GridLayout(W, H, 20)
    g = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))
    grids = save_grids(tmp_path / "grids.npz", {"A": g, "B": g, "C": g}, std=False)
    src = tmp_path / "in"
    src.mkdir()
    Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(src / "A.png")
    code, _, err = cli("grid", "correct-images", grids, src, tmp_path / "out")
    assert code == 1
    assert "failed B: no image file named B" in err and "failed C: no image file named C" in err
    assert "more image(s)" not in err
