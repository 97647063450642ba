"""Camera JSON files from pipes: ``camera project --camera <(cat cam.json)``
waited for ever: the command read the camera file three times (``camera_from_json`` twice
itself, once for the interior and once for the exterior orientation) and a pipe gives its
content once. A pipe is now read once per command."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from photogeom.camera import ExteriorOrientation, InteriorOrientation

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def test_camera_project_reads_the_camera_from_a_pipe(cli, tmp_path: Path, fifo_read_once):
    cam = {
        "interior": InteriorOrientation(f=152.0).to_dict(),
        "exterior": ExteriorOrientation(0.0, 0.0, 1000.0, 0.01, -0.02, 0.3).to_dict(),
    }
    data = json.dumps(cam).encode()
    (tmp_path / "cam.json").write_bytes(data)
    pts = tmp_path / "ground.csv"
    pts.write_text("id,X,Y,Z\n1,10,20,0\n2,-30,5,1\n")
    code, want, err = cli("camera", "project", pts, "--camera", tmp_path / "cam.json")
    assert code == 0, err
    code, got, err = cli("camera", "project", pts, "--camera", fifo_read_once(data, "cam.pipe"))
    assert code == 0, err
    assert got == want
