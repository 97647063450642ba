"""The camera options --f, --x0, --y0 given nan or inf were reported in the
library's words ('f is NaN or infinite', 'x0 is NaN or infinite'), by every command that
builds a camera from them (camera project, orient resection, orient relative, ...)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.mark.parametrize(("option", "value"), [
    ("--f", "nan"), ("--x0", "inf"), ("--y0", "-inf"), ("--pixel-size", "nan"),
])
def test_camera_options_non_finite(cli, tmp_path: Path, option, value):
    pts = tmp_path / "g.csv"
    pts.write_text("id,X,Y,Z\nA,1300,650,169\n")
    f = [] if option == "--f" else ["--f", "152"]
    px = ["--pixel"] if option == "--pixel-size" else []
    code, _, err = cli("camera", "project", pts, *f, option, value, *px,
                       "--eo", "1114,862,1600,2,3,10")
    assert code == 2
    assert err.startswith(f"error: {option} {value}: give a finite number"), err
