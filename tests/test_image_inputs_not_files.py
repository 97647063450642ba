"""An image to correct that is not a regular file: ``correct_image_file`` checked
``is_file()`` and said "no such image file" for a pipe (``<(curl ...)``, a named pipe), a
device and a folder alike, though each exists. An image is decoded from memory, so a pipe is
read once, whole, and corrected as the file is; a device or a folder is refused by what it
is."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from photogeom.calibration import GridLayout, correct_image_file
from photogeom.errors import FileFormatError
from photogeom.io import sources

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with
from residual_grids import grid_with_nodes

W, H = 60, 40
SHIFT = (2.0, -1.0)  # px, at every node: whole pixels, so the correction is a known shift


def _grid():
    layout = GridLayout(W, H, 20)
    nodes = np.empty((*layout.shape, 2))
    nodes[...] = SHIFT
    return grid_with_nodes(layout, nodes)


def _image(tmp_path: Path) -> tuple[Path, np.ndarray]:
    img = np.random.default_rng(3).integers(0, 256, (H, W, 3), dtype=np.uint8)
    path = tmp_path / "a.png"
    assert cv2.imwrite(str(path), img)
    return path, img


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_an_image_from_a_pipe_is_corrected_as_the_file(tmp_path: Path):
    path, img = _image(tmp_path)
    fifo = fifo_with(tmp_path, path.read_bytes(), "image.png")
    with sources.pipe_reads():
        assert correct_image_file(fifo, tmp_path / "out.png", _grid()) is None
        assert sources.kept_pipe_bytes(fifo) == path.read_bytes()  # read once, kept
    got = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
    # the known shift: output pixel (u, v) takes input (u - 2, v + 1), border replicated
    vv, uu = np.mgrid[0:H, 0:W]
    want = img[np.clip(vv + 1, 0, H - 1), np.clip(uu - 2, 0, W - 1)]
    np.testing.assert_array_equal(got, want)
    correct_image_file(path, tmp_path / "from_file.png", _grid())
    assert (tmp_path / "out.png").read_bytes() == (tmp_path / "from_file.png").read_bytes()


def test_a_device_is_refused_as_a_device(tmp_path: Path):
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    with pytest.raises(FileFormatError, match="/dev/zero: it is a device"):
        correct_image_file("/dev/zero", tmp_path / "out.png", _grid())


def test_a_folder_and_a_missing_file_are_named(tmp_path: Path):
    with pytest.raises(FileFormatError, match="a folder, not an image file"):
        correct_image_file(tmp_path, tmp_path / "out.png", _grid())
    with pytest.raises(FileFormatError, match="no such image file"):
        correct_image_file(tmp_path / "none.png", tmp_path / "out.png", _grid())
    assert not (tmp_path / "out.png").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_pipe_or_a_folder_in_a_folder_of_images_is_named(tmp_path: Path):
    """In a folder, a named pipe or a folder with an image's name was "no image file named
    IMG_1 (or IMG_1.<ext>)", though it is there."""
    from photogeom.calibration import correct_folder

    src = tmp_path / "in"
    src.mkdir()
    path, _ = _image(tmp_path)
    os.replace(path, src / "IMG_0.png")
    os.mkfifo(src / "IMG_1.jpg")
    (src / "IMG_2.tif").mkdir()
    grid = _grid()
    res = correct_folder(src, tmp_path / "out", {f"IMG_{k}": grid for k in range(4)})
    assert list(res.written) == ["IMG_0"]
    assert res.failures["IMG_1"] == (
        f"IMG_1.jpg in {src} is a named pipe (FIFO) or socket, not an image file: the "
        "images of a folder are read as regular files (a named pipe would wait for a "
        "writer); write the image to a regular file of that name"
    )
    assert res.failures["IMG_2"].startswith(f"IMG_2.tif in {src} is a folder, not an image")
    assert res.failures["IMG_3"] == f"no image file named IMG_3 (or IMG_3.<ext>) in {src}"


@pytest.mark.parametrize(
    "args",
    [
        ("transform", "apply", "-", "points.csv"),
        ("grid", "fit", "-", "--image-size", "60x40", "-o", "g.npz"),
        ("bundle", "adjust", "-"),
        ("rpc", "info", "-"),
    ],
)
def test_a_dash_as_an_input_says_what_dash_means(cli, tmp_path, monkeypatch, args):
    """``-`` as an input file was "cannot read -: no such file" (or "-: no such file"):
    it now says that '-' is the standard output, for outputs only, and names /dev/stdin."""
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(*args)
    assert code == 2
    assert err.rstrip().endswith(
        "'-' stands for the standard output, and only where a command writes (-o -): to "
        "read the standard input, give /dev/stdin"
    ), err
    # not said for another missing input
    code, _, err = cli(*[a if a != "-" else "missing.csv" for a in args])
    assert code == 2 and "/dev/stdin" not in err
