"""``grid correct-images`` refuses a JPEG whose scan data is damaged.

OpenCV decodes such a file anyway (libjpeg warns "Corrupt JPEG data: ..." on stderr and
fills the damaged blocks with wrong pixels); the image was then "corrected" and written as
a good one. Now it is a named failure: nothing is written for it, the rest of the folder
is corrected.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from photogeom.calibration import GridLayout, correct_folder
from photogeom.calibration.images import correct_image_file
from photogeom.errors import FileFormatError

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import grid_with_nodes

W, H = 160, 120


@pytest.fixture(scope="module")
def grid():
    layout = GridLayout(W, H, 40)
    nodes = np.zeros((*layout.shape, 2))
    nodes[..., 0] = 1.0
    return grid_with_nodes(layout, nodes)


def _jpeg() -> bytes:
    yy, xx = np.mgrid[0:H, 0:W]
    img = (np.sin(xx / 3.0) * np.cos(yy / 4.0) * 100 + 128).astype(np.uint8)
    ok, enc = cv2.imencode(".jpg", np.dstack([img, 255 - img, img // 2]))
    assert ok
    return enc.tobytes()


def _damaged(good: bytes) -> bytes:
    """The scan data overwritten in its middle (the headers intact)."""
    d = bytearray(good)
    mid = len(d) // 2
    d[mid : mid + 120] = bytes([0xFF, 0x00] * 60)  # stuffed bytes: garbage Huffman codes
    return bytes(d)


def test_the_damaged_file_still_decodes_in_opencv_to_wrong_pixels():
    """The premise: OpenCV returns pixels for the damaged file, and they are wrong."""
    good = _jpeg()
    a = cv2.imdecode(np.frombuffer(good, np.uint8), cv2.IMREAD_UNCHANGED)
    b = cv2.imdecode(np.frombuffer(_damaged(good), np.uint8), cv2.IMREAD_UNCHANGED)
    assert b is not None and b.shape == a.shape
    assert np.abs(a.astype(int) - b).max() > 50


def test_a_damaged_jpeg_is_refused_by_name(tmp_path, grid, capfd):
    src = tmp_path / "a.jpg"
    src.write_bytes(_damaged(_jpeg()))
    with pytest.raises(FileFormatError, match=r"damaged JPEG data \(libjpeg: Corrupt JPEG data"):
        correct_image_file(src, tmp_path / "out.jpg", grid)
    assert not (tmp_path / "out.jpg").exists()
    assert list(tmp_path.iterdir()) == [src]  # no temporary file either
    assert "Corrupt JPEG data" not in capfd.readouterr().err  # said once, in the error


def test_a_folder_corrects_the_good_jpegs_and_lists_the_damaged(tmp_path, grid, capfd):
    src = tmp_path / "in"
    src.mkdir()
    good = _jpeg()
    (src / "good.jpg").write_bytes(good)
    (src / "bad.jpg").write_bytes(_damaged(good))
    capfd.readouterr()
    res = correct_folder(src, tmp_path / "out", {"good": grid, "bad": grid})
    assert set(res.written) == {"good"}
    assert set(res.failures) == {"bad"}
    assert str(src / "bad.jpg") in res.failures["bad"]
    assert "damaged JPEG data" in res.failures["bad"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["good.jpg"]
    assert capfd.readouterr().err == ""  # a good JPEG decodes without a word


def test_other_lines_on_stderr_are_kept(tmp_path, grid, capfd, monkeypatch):
    """Only libjpeg's damage warnings are taken from standard error; what else is printed
    there while a JPEG decodes reaches it."""
    from photogeom.calibration import images

    real = images._decode_quietly

    def chatty(cv2_module, data):
        os.write(2, b"a line of another library\n")
        return real(cv2_module, data)

    monkeypatch.setattr(images, "_decode_quietly", chatty)
    src = tmp_path / "a.jpg"
    src.write_bytes(_jpeg())
    capfd.readouterr()
    correct_image_file(src, tmp_path / "out.jpg", grid)
    assert capfd.readouterr().err == "a line of another library\n"


def test_a_process_without_standard_error_reads_and_refuses_as_well(tmp_path):
    """Standard error is read while a JPEG decodes; a process started without one (file
    descriptor 2 closed, as under some service managers) still corrects a good JPEG and
    refuses a damaged one, instead of failing on the missing descriptor."""
    import subprocess

    good = _jpeg()
    (tmp_path / "good.jpg").write_bytes(good)
    (tmp_path / "bad.jpg").write_bytes(_damaged(good))
    code = (
        "import os, sys\n"
        "os.close(2)\n"
        "sys.stderr = None\n"
        "from pathlib import Path\n"
        "from photogeom.calibration.images import _read\n"
        "from photogeom.errors import FileFormatError\n"
        f"print(_read(Path({str(tmp_path / 'good.jpg')!r}))[0].shape)\n"
        "try:\n"
        f"    _read(Path({str(tmp_path / 'bad.jpg')!r}))\n"
        "except FileFormatError as exc:\n"
        "    print('refused:', exc)\n"
    )
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = {**os.environ, "PYTHONPATH": src}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0] == f"({H}, {W}, 3)"
    assert lines[1].startswith("refused:") and "damaged JPEG data" in lines[1]


@pytest.mark.parametrize("icc", [False, True])
def test_a_cmyk_jpeg_is_written_as_rgb_and_the_note_says_so(tmp_path, grid, icc):
    # before: a CMYK JPEG without an ICC profile was written as RGB with no note (with a
    # CMYK profile only "ICC profile not kept" said it); the note now names the conversion
    from PIL import Image

    rng = np.random.default_rng(1)
    cmyk = Image.fromarray((rng.random((H, W, 4)) * 255).astype(np.uint8), "CMYK")
    src, dst = tmp_path / "a.jpg", tmp_path / "out.jpg"
    kw = {}
    if icc:  # a profile header naming the CMYK colour space (bytes 16-19)
        kw["icc_profile"] = bytes(16) + b"CMYK" + bytes(108)
    cmyk.save(src, quality=95, **kw)
    note = correct_image_file(src, dst, grid)
    with Image.open(dst) as out:
        assert out.mode == "RGB" and out.size == (W, H)
    assert note is not None and note.startswith("CMYK JPEG written as RGB")
    assert "colours are approximate" in note
    assert ("ICC profile not kept" in note) == icc
    # an RGB JPEG gets no such note
    rgb = tmp_path / "rgb.jpg"
    rgb.write_bytes(_jpeg())
    assert correct_image_file(rgb, tmp_path / "rgb_out.jpg", grid) is None
