"""Workflow review 7: files written by one command read back by the next."""

from __future__ import annotations

import numpy as np

from photogeom.io import read_points, write_points


def test_ids_beginning_with_hash_survive_a_write_and_read(tmp_path):
    """An id such as '#12' written unquoted made its row a comment line: the point was
    silently lost by the next command (camera project -> orient resection)."""
    ids = ["# 1", "#2", " #3", "007", "P 3"]
    coords = np.arange(15, dtype=float).reshape(5, 3)
    path = tmp_path / "pts.csv"
    write_points(path, ids, coords, columns=("X", "Y", "Z"))
    back = read_points(path)
    assert list(back.ids) == ["# 1", "#2", "#3", "007", "P 3"]
    np.testing.assert_array_equal(back.coords, coords)
    assert '"#2"' in path.read_text()


def _run(args):
    from typer.testing import CliRunner

    from photogeom.cli.main import app

    return CliRunner().invoke(app, [str(a) for a in args])


def test_transform_apply_names_output_columns_as_the_estimate(tmp_path):
    """A pixel -> mm interior orientation (--source-cols col,row --target-cols x,y) applied to
    pixel points wrote mm coordinates as columns COL,ROW, which orient resection (x,y) could
    not read; the output now has the estimate's target columns (source ones with --inverse)."""
    fid = tmp_path / "fid.csv"
    fid.write_text(
        "id,col,row,x,y\n"
        "1,19018.3,9674.8,113.016,0.002\n2,185.6,9675.2,-112.977,-0.002\n"
        "3,9601.4,259.2,0.013,112.99\n4,9601.0,19092.3,0.008,-113.008\n"
    )
    params = tmp_path / "io.json"
    r = _run(["transform", "estimate", "similarity2d", fid, "--source-cols", "col,row",
              "--target-cols", "x,y", "--source-system", "pixel", "--target-system", "fiducial",
              "--unit", "mm", "--output-params", params])  # fmt: skip
    assert r.exit_code == 0, r.output
    pix = tmp_path / "pix.csv"
    pix.write_text("id,col,row\n007,100.5,200.25\n")
    out = tmp_path / "mm.csv"
    assert _run(["transform", "apply", params, pix, "-o", out]).exit_code == 0
    table = read_points(out)
    assert table.columns == ("x", "y") and table.ids == ("007",)
    back = tmp_path / "back.csv"
    assert _run(["transform", "apply", params, out, "--inverse", "-o", back]).exit_code == 0
    again = read_points(back)
    assert again.columns == ("col", "row")
    np.testing.assert_allclose(again.coords, [[100.5, 200.25]], atol=1e-9)
