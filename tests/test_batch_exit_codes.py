"""Exit codes of batch commands: a batch that ran every item and some failed
exits 1 with one ``error:`` line (docs/cli.md); before, ``examples run`` exited 2 (as bad
input) where ``grid correct-images`` exited 1, and ``grid correct-images`` ended without
an ``error:`` line."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from photogeom import datasets
from photogeom.calibration import GridLayout, save_grids

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 60, 40


@pytest.fixture
def data(tmp_path, monkeypatch):
    copy = tmp_path / "data"
    shutil.copytree(datasets._data_dir(), copy)
    monkeypatch.setattr(datasets, "_data_dir", lambda: copy)
    return copy


def test_examples_run_with_a_failed_example_exits_1(cli, data):
    (data / "lidar_wang2014.csv").write_text("id,a,b\n1,2,3\n")
    code, out, err = cli("examples", "run", "fiducials", "absolute-lidar")
    assert code == 1
    assert err.startswith("error: example absolute-lidar failed: ")
    assert "(the other 1 ran)" in err and "FAILED" in out


def test_examples_run_bad_input_stays_exit_2(cli):
    code, _, err = cli("examples", "run", "no-such-example")
    assert code == 2 and err.startswith("error: ")
    code, _, err = cli("examples", "run", "fiducials", "--all")
    assert code == 2 and "not both" in err


def test_correct_images_ends_with_one_error_line(cli, tmp_path):
    layout = GridLayout(W, H, 20)
    g = grid_with_nodes(layout, np.zeros((*layout.shape, 2)))
    grids = save_grids(tmp_path / "grids.npz", {"IMG_1": g, "IMG_2": g}, std=False)
    src = tmp_path / "in"
    src.mkdir()
    Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(src / "IMG_1.png")
    code, _, err = cli("grid", "correct-images", grids, src, tmp_path / "out")
    assert code == 1
    assert "failed IMG_2: no image file named IMG_2" in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("error: 1 of 2 image(s) failed") and "other 1 corrected" in last
