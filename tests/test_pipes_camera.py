"""Calibration files from pipes: ``cat cam.yml | photogeom camera project p.csv
--camera /dev/stdin ...`` stopped with ``/dev/stdin: not valid JSON``: ``--camera`` told a
calibration of another tool (OpenCV YAML/XML, COLMAP ``cameras.txt``, Metashape XML) from a
camera JSON by reading the head of a *regular* file only, so a pipe went to the JSON
reader. A pipe is now read once, its bytes kept, the format told by content and the
calibration parsed from those bytes, for ``--camera``, ``--camera2`` and ``--calibration``.

An OpenCV ``cv2.FileStorage`` JSON was read by ``--calibration`` but refused by ``--camera``
even from a regular file (``no camera found (expected 'interior'/'exterior' entries ...)``);
it is now read as the calibration it is there too.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")

CAL = pg.MetashapeCalibration(1280, 960, 1000.0, cx=3.0, cy=-2.0, k1=0.1, p1=1e-3)

OPENCV_XML = b"""<?xml version="1.0"?>
<opencv_storage>
<image_width>1280</image_width>
<image_height>960</image_height>
<camera_matrix type_id="opencv-matrix"><rows>3</rows><cols>3</cols><dt>d</dt>
<data>1000. 0. 642.5 0. 1000. 477.5 0. 0. 1.</data></camera_matrix>
<distortion_coefficients type_id="opencv-matrix"><rows>5</rows><cols>1</cols><dt>d</dt>
<data>0.1 0. 0. 0.001 0.</data></distortion_coefficients>
</opencv_storage>
"""

OPENCV_JSON = b"""{"image_width": 1280, "image_height": 960,
"camera_matrix": {"type_id": "opencv-matrix", "rows": 3, "cols": 3, "dt": "d",
 "data": [1000.0, 0.0, 642.5, 0.0, 1000.0, 477.5, 0.0, 0.0, 1.0]},
"distortion_coefficients": {"type_id": "opencv-matrix", "rows": 5, "cols": 1, "dt": "d",
 "data": [0.1, 0.0, 0.0, 0.001, 0.0]}}
"""


def _calibration_files(tmp_path: Path) -> dict[str, bytes]:
    files = {}
    for suffix in ("yml", "xml", "txt", "json"):  # OpenCV YAML, Metashape, COLMAP, camera JSON
        path = tmp_path / f"cal.{suffix}"
        pg.write_calibration(CAL, path)
        files[suffix] = path.read_bytes()
    files["opencv.xml"] = OPENCV_XML
    files["opencv.json"] = OPENCV_JSON
    return files


@pytest.mark.parametrize("option", ["--camera", "--calibration"])
def test_camera_project_reads_every_calibration_format_from_a_pipe(
    cli, tmp_path: Path, fifo_read_once, option
):
    pts = tmp_path / "p.csv"
    pts.write_text("id,X,Y,Z\na,10,20,0\nb,-30,5,3\n")
    args = ("--eo", "0,0,100,1,2,3", "--pixel")
    for name, data in _calibration_files(tmp_path).items():
        regular = tmp_path / f"regular.{name}"
        regular.write_bytes(data)
        code, want, err = cli("camera", "project", pts, option, regular, *args)
        assert code == 0, (name, err)
        pipe = fifo_read_once(data, f"{option[2:]}.{name}.pipe")
        code, got, err = cli("camera", "project", pts, option, pipe, *args)
        assert code == 0, (name, err)
        assert got == want, name


def test_orient_relative_reads_both_cameras_from_pipes(cli, tmp_path: Path, fifo_read_once):
    files = _calibration_files(tmp_path)
    (tmp_path / "a.yml").write_bytes(files["yml"])
    (tmp_path / "b.txt").write_bytes(files["txt"])
    R1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.0, 0.0, 0.0)
    R2 = pg.ExteriorOrientation(30.0, 1.0, 101.0, 0.01, -0.02, 0.03)
    rng = np.random.default_rng(3)
    ground = rng.uniform([-40, -30, -5], [70, 30, 5], (12, 3))
    io = CAL.interior_orientation()
    cam1, cam2 = pg.FrameCamera(io, R1), pg.FrameCamera(io, R2)
    xy1, xy2 = cam1.project(ground), cam2.project(ground)
    rows = ["id,x,y"] + [f"p{i},{float(a[0])!r},{float(a[1])!r}" for i, a in enumerate(xy1)]
    rows2 = ["id,x,y"] + [f"p{i},{float(a[0])!r},{float(a[1])!r}" for i, a in enumerate(xy2)]
    (tmp_path / "i1.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "i2.csv").write_text("\n".join(rows2) + "\n")
    base = ("orient", "relative", tmp_path / "i1.csv", tmp_path / "i2.csv")
    code, want, err = cli(*base, "--camera", tmp_path / "a.yml", "--camera2", tmp_path / "b.txt")
    assert code == 0, err
    code, got, err = cli(
        *base,
        "--camera", fifo_read_once(files["yml"], "a.pipe"),
        "--camera2", fifo_read_once(files["txt"], "b.pipe"),
    )  # fmt: skip
    assert code == 0, err

    def untimed(text: str) -> list[str]:  # the report gives the run time
        return [line for line in text.splitlines() if not line.rstrip().endswith(" ms")]

    assert untimed(got) == untimed(want)


def test_orient_intersection_names_what_a_piped_calibration_lacks(
    cli, tmp_path: Path, fifo_read_once
):
    pts = tmp_path / "i.csv"
    pts.write_text("id,x,y\na,1,2\n")
    data = _calibration_files(tmp_path)["yml"]
    (tmp_path / "cam.yml").write_bytes(data)
    code, _, want = cli("orient", "intersection", pts, pts, "--camera", tmp_path / "cam.yml",
                        "--camera", tmp_path / "cam.yml")  # fmt: skip
    assert code == 2, want
    pipe = fifo_read_once(data, "cam.pipe")
    code, _, err = cli("orient", "intersection", pts, pts, "--camera", pipe, "--camera", pipe)
    assert code == 2, err
    assert "not valid JSON" not in err
    assert err.replace(str(pipe), "X") == want.replace(str(tmp_path / "cam.yml"), "X")
