"""Point CSVs from a pipe (`<(cat f.csv)`, `cat f.csv | photogeom ... /dev/stdin`): the
input can be read once, and the reader opens it for the header, the blocks and the
diagnostics; it used to report the pipe as empty."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.io import read_points

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

FIDUCIALS = datasets.path("lecture_fiducials")

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def test_read_points_from_a_named_pipe_equals_the_file(tmp_path: Path):
    data = Path(FIDUCIALS).read_bytes()
    from_file = read_points(FIDUCIALS, "x,y")
    from_pipe = read_points(fifo_with(tmp_path, data, "points.pipe"), "x,y")
    np.testing.assert_array_equal(from_pipe.coords, from_file.coords)
    assert list(from_pipe.ids) == list(from_file.ids)


def test_transform_apply_reads_points_from_a_pipe(cli, tmp_path: Path):
    params = tmp_path / "s.json"
    code, _, err = cli("transform", "estimate", "similarity2d", FIDUCIALS,
                       "--output-params", params)
    assert code == 0, err
    code, from_file, err = cli("transform", "apply", params, FIDUCIALS)
    assert code == 0, err
    fifo = fifo_with(tmp_path, Path(FIDUCIALS).read_bytes(), "points.pipe")
    code, from_pipe, err = cli("transform", "apply", params, fifo)
    assert code == 0, err
    def rows(text: str) -> list[str]:  # the comment line names the input path
        return [line for line in text.splitlines() if not line.startswith("#")]

    assert rows(from_pipe) == rows(from_file) and len(rows(from_file)) > 8


def test_an_empty_pipe_is_still_named_empty(tmp_path: Path):
    from photogeom.errors import FileFormatError

    with pytest.raises(FileFormatError, match="no header line and no data"):
        read_points(fifo_with(tmp_path, b"", "points.pipe"), "x,y")
