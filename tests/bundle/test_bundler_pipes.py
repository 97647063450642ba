"""A Bundler file from a pipe (``... | photogeom bundle convert /dev/stdin ...``, ``<(cat
bundle.out)``) is found by its first line, as a regular file is: the pipe is read once,
whole, and its bytes kept for the reader (before: a pipe was always taken for BAL, whose
reader refused it asking for ``--format bundler``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom import MetashapeCalibration
from photogeom.bundle import read_block, read_bundler, write_block
from photogeom.io.sources import pipe_reads

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parent.parent))
from blocks import grid_block

from fifos import fifo_with

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
SIZE = (3000, 2000)
CAL = MetashapeCalibration(*SIZE, 2400.0, k1=-0.08, k2=0.03)


@pytest.fixture(scope="module", params=[120, 900], ids=["short", "beyond-64KiB"])
def bundler_file(request, tmp_path_factory):
    """A Bundler file (the short one under the 64 KiB the readers look at first)."""
    path = tmp_path_factory.mktemp("b") / "block.out"
    block = grid_block(2, rows=2, cols=3, n_points=request.param, noise=0.3, cal=CAL)
    write_block(block, path, "bundler", drop_extras=True)
    assert (path.stat().st_size > 64 << 10) == (request.param == 900)
    return path


def _same(a, b):
    np.testing.assert_array_equal(a.observations.uv, b.observations.uv)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_allclose(a.exterior, b.exterior, rtol=0, atol=1e-12)  # CSV: deg


@needs_fifo
def test_convert_finds_a_bundler_pipe(cli, tmp_path, bundler_file):
    fifo = fifo_with(tmp_path, bundler_file.read_bytes(), "stream")
    out = tmp_path / "csv"
    code, text, err = cli("bundle", "convert", fifo, out, "--to", "csv", "--image-size",
                          "3000x2000", "--json")  # fmt: skip
    assert code == 0, err
    assert '"source_format": "bundler"' in text
    _same(pg.bundle.read_csv_block(out), read_bundler(bundler_file, image_size=SIZE))


@needs_fifo
def test_read_block_finds_a_bundler_pipe_in_a_scope(tmp_path, bundler_file):
    fifo = fifo_with(tmp_path, bundler_file.read_bytes(), "stream")
    with pipe_reads():
        block = read_block(fifo, image_size=SIZE)
    _same(block, read_bundler(bundler_file, image_size=SIZE))


@needs_fifo
def test_a_bal_pipe_is_still_read_as_bal(cli, tmp_path, bundler_file):
    bal = tmp_path / "b.bal"
    write_block(read_bundler(bundler_file, image_size=SIZE), bal, "bal")
    fifo = fifo_with(tmp_path, bal.read_bytes(), "stream")
    code, text, err = cli("bundle", "convert", fifo, tmp_path / "csv", "--to", "csv",
                          "--image-size", "3000x2000", "--json")  # fmt: skip
    assert code == 0, err
    assert '"source_format": "bal"' in text
