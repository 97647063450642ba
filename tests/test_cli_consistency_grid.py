"""`photogeom grid fit` on a BAL file without a .bal/.bz2 name.

The bundled ``dubrovnik-3-7-pre.txt`` (a BAL file, a name ``bundle adjust`` reads as BAL)
was read by ``grid fit`` as a residuals CSV: ``no column 'image_id' (columns: 3 7 19) ...
replace the separators with commas``. A regular file is now recognised by its content (and,
and a pipe: read once, its bytes kept for the reader).
"""

from __future__ import annotations

import bz2
import os
import shutil
import sys
from pathlib import Path

import pytest

from photogeom import datasets

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"


def _grids(cli, source, tmp_path, name="g.json"):
    out = tmp_path / name
    code, text, err = cli("grid", "fit", source, "-o", out, "--image-size", "2000x1500",
                          "--spacing", "500", "--folds", "0", "--json")  # fmt: skip
    return code, text, err, out


def test_a_bal_file_named_txt_is_a_block(cli, tmp_path):
    code, _text, err, out = _grids(cli, BAL, tmp_path)
    assert code == 0, err
    assert out.is_file()
    # the same grids as from the file named .bal
    named = tmp_path / "same.bal"
    shutil.copy(BAL, named)
    code2, _text2, err2, out2 = _grids(cli, named, tmp_path, "g2.json")
    assert code2 == 0, err2
    assert out.read_bytes() == out2.read_bytes()


def test_a_bzip2_bal_of_any_name_is_a_block(cli, tmp_path):
    packed = tmp_path / "problem.dat"
    packed.write_bytes(bz2.compress(BAL.read_bytes()))
    code, _, err, _out = _grids(cli, packed, tmp_path)
    assert code == 0, err


def test_a_residuals_csv_is_still_a_csv(cli, tmp_path):
    csv = tmp_path / "res.txt"
    csv.write_text(
        "image_id,u,v,rx,ry\n"
        + "".join(f"1,{100 + 37 * k % 1800},{100 + 53 * k % 1300},0.1,-0.2\n" for k in range(60))
    )
    code, _, err, _out = _grids(cli, csv, tmp_path)
    assert code == 0, err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_bal_pipe_is_a_block(cli, tmp_path):
    # a pipe is now read once and recognised by content as well (before: the
    # error named the BAL header and asked for the file; test_pipes_grid.py)
    code, _, err, out = _grids(cli, fifo_with(tmp_path, BAL.read_bytes(), "stream"), tmp_path)
    assert code == 0, err
    code2, _, err2, out2 = _grids(cli, BAL, tmp_path, "g2.json")
    assert code2 == 0, err2
    assert out.read_bytes() == out2.read_bytes()
