"""``correct_folder(workers=N)`` on local processes: one OpenCV thread per process.

Each process ran OpenCV with its default thread count (the machine's cores): N processes
ran N x cores OpenCV threads. The parent's count is the same after the call.
"""

from __future__ import annotations

import multiprocessing
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from photogeom.calibration import GridLayout, correct_folder
from photogeom.calibration import images as images_module

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 64, 48

pytestmark = pytest.mark.skipif(
    multiprocessing.get_start_method(allow_none=False) != "fork",
    reason="the processes see the test's stand-in only when forked",
)


def _threads_seen(src, dst, grid, **kwargs):
    """Stand-in for the file correction in the processes: the image corrected as usual,
    the process's OpenCV thread count returned as the note."""
    images_module.correct_image_file_original(src, dst, grid, **kwargs)
    return f"opencv threads {cv2.getNumThreads()}"


@pytest.fixture
def folder(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    rng = np.random.default_rng(0)
    for k in range(4):
        cv2.imwrite(str(src / f"IMG_{k}.png"), rng.integers(0, 255, (H, W, 3), np.uint8))
    layout = GridLayout(W, H, 16)
    grid = grid_with_nodes(layout, np.full((*layout.shape, 2), 0.5))
    return src, {f"IMG_{k}": grid for k in range(4)}


@pytest.mark.parametrize("warm", [False, True])
def test_processes_run_one_opencv_thread_and_the_parent_keeps_its_count(
    tmp_path, folder, monkeypatch, warm
):
    src, grids = folder
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)  # a parent with more than one thread (the machine may have one core)
    try:
        if warm:  # OpenCV's threads started in the parent before the processes fork
            a = np.zeros((512, 512), np.float32)
            cv2.remap(a, a, a, cv2.INTER_LINEAR)
        monkeypatch.setattr(
            images_module, "correct_image_file_original", images_module.correct_image_file,
            raising=False,
        )  # fmt: skip
        monkeypatch.setattr(images_module, "correct_image_file", _threads_seen)
        res = correct_folder(src, tmp_path / "out", grids, workers=2)
        assert sorted(res.written) == sorted(grids)
        assert set(res.notes.values()) == {"opencv threads 1"}, res.notes
        assert cv2.getNumThreads() == 2  # the parent's count restored
    finally:
        cv2.setNumThreads(before)
