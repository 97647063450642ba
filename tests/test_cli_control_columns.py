"""`orient resection` / camera dlt estimate with --image-cols x (one name) or
--ground-cols X,Y said "ground columns must be three names and image columns two", naming
neither option nor which of the two was wrong."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.mark.parametrize(("command", "option", "value", "expected"), [
    (("orient", "resection"), "--image-cols", "x", "--image-cols x: give 2 column names"),
    (("camera", "dlt", "estimate"), "--ground-cols", "X,Y", "--ground-cols X,Y: give 3 column"),
])
def test_wrong_count_names_the_option(cli, tmp_path: Path, command, option, value, expected):
    pts = tmp_path / "p.csv"
    pts.write_text("id,X,Y,Z,x,y\nA,1,2,3,0.1,0.2\n")
    extra = ["--f", "152"] if command[0] == "orient" else []
    code, _, err = cli(*command, pts, *extra, option, value)
    assert code == 2 and err.startswith(f"error: {expected}"), err
