"""``photogeom grid fit <(cat x.bal)``: a pipe, which has no ``.bal`` name, was
read as a residuals CSV, and the error (``its first line holds three integers (3 7 19), the
header of a BAL file ... give the BAL file itself``) asked for the file. The pipe is now read
once, recognised as BAL by its content (a first line of three integers, or bzip2's magic)
and read from the bytes kept: the grids equal those from the same BAL file by name. A
residuals CSV from a pipe is still a CSV.
"""

from __future__ import annotations

import bz2
import os
from pathlib import Path

import pytest

from photogeom import datasets

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"


def _fit(cli, source, out: Path) -> tuple[int, str]:
    code, _, err = cli("grid", "fit", source, "-o", out, "--image-size", "2000x1500",
                       "--spacing", "500", "--folds", "0")  # fmt: skip
    return code, err


@pytest.mark.parametrize("packed", [False, True])
def test_grid_fit_reads_a_bal_pipe_as_the_bal_file(cli, tmp_path: Path, fifo_read_once, packed):
    named = tmp_path / ("block.bz2" if packed else "block.bal")
    data = bz2.compress(BAL.read_bytes()) if packed else BAL.read_bytes()
    named.write_bytes(data)
    code, err = _fit(cli, named, tmp_path / "want.json")
    assert code == 0, err
    code, err = _fit(cli, fifo_read_once(data, "stream"), tmp_path / "got.json")
    assert code == 0, err
    assert "residuals CSV" not in err
    assert (tmp_path / "got.json").read_bytes() == (tmp_path / "want.json").read_bytes()


def test_grid_fit_still_reads_a_residuals_csv_pipe(cli, tmp_path: Path, fifo_read_once):
    text = "image_id,u,v,rx,ry\n" + "".join(
        f"1,{100 + 37 * k % 1800},{100 + 53 * k % 1300},0.1,-0.2\n" for k in range(60)
    )
    (tmp_path / "res.csv").write_text(text)
    code, err = _fit(cli, tmp_path / "res.csv", tmp_path / "want.json")
    assert code == 0, err
    code, err = _fit(cli, fifo_read_once(text.encode(), "stream"), tmp_path / "got.json")
    assert code == 0, err
    assert (tmp_path / "got.json").read_bytes() == (tmp_path / "want.json").read_bytes()
