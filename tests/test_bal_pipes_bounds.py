"""BAL files from pipes, and bounded reading.

* ``photogeom bundle adjust|convert <(cat f.bal)`` and a named pipe: the format was found
  with ``is_file()``, false for a pipe, so the command said "not a block folder"; a pipe is
  now read once as a BAL file.
* A device (``/dev/zero``) was read until memory ran out, and a bzip2 file was decompressed
  whole whatever its size (a bomb): the header's counts now bound what is read.
"""

from __future__ import annotations

import bz2
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.bundle import read_bal, read_block
from photogeom.errors import FileFormatError

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


@needs_fifo
def test_read_block_detects_a_bal_pipe(tmp_path: Path):
    block = read_block(fifo_with(tmp_path, bz2.compress(BAL.read_bytes()), "problem.pipe"))
    want = read_bal(BAL)
    np.testing.assert_array_equal(block.observations.uv, want.observations.uv)
    np.testing.assert_array_equal(block.xyz, want.xyz)


@needs_fifo
def test_bundle_convert_reads_a_bal_pipe(cli, tmp_path: Path):
    out = tmp_path / "out"
    fifo = fifo_with(tmp_path, BAL.read_bytes(), "problem.pipe")
    code, _, err = cli("bundle", "convert", fifo, out, "--to", "csv")
    assert code == 0, err
    assert (out / "observations.csv").is_file()


def test_a_device_is_refused(tmp_path: Path):
    if not Path("/dev/null").exists():
        pytest.skip("no /dev/null")
    with pytest.raises(FileFormatError, match="/dev/null: it is a device"):
        read_bal("/dev/null")


def test_a_bzip2_bomb_is_refused_by_the_header_counts(tmp_path: Path):
    raw = BAL.read_bytes()  # 3 cameras, 7 points, 19 observations: 127 values
    bomb = tmp_path / "bomb.bz2"
    bomb.write_bytes(bz2.compress(raw + b" 0" * (8 << 20)))  # 16 MB of extra values
    assert bomb.stat().st_size < 100_000
    with pytest.raises(FileFormatError, match=r"more than the 127 values its header announces"):
        read_bal(bomb)


def test_a_file_far_longer_than_its_header_says_is_refused(tmp_path: Path):
    long = tmp_path / "long.bal"
    long.write_bytes(b"1 1 1\n" + b"0 0 1.5 2.5\n" * 50_000)
    with pytest.raises(FileFormatError, match=r"1 cameras, 1 points, 1 observations"):
        read_bal(long)


def test_no_header_in_a_long_head_is_refused(tmp_path: Path):
    blank = tmp_path / "blank.bal"
    blank.write_bytes(b" " * (1 << 20))
    with pytest.raises(FileFormatError, match="no header"):
        read_bal(blank)


def test_compressed_files_still_read(tmp_path: Path):
    raw = BAL.read_bytes()
    multi = tmp_path / "multi.bz2"  # two bzip2 streams, as pbzip2 writes
    multi.write_bytes(bz2.compress(raw[:100]) + bz2.compress(raw[100:]))
    np.testing.assert_array_equal(read_bal(multi).xyz, read_bal(BAL).xyz)
    cut = tmp_path / "cut.bz2"
    cut.write_bytes(bz2.compress(raw)[:-10])
    with pytest.raises(FileFormatError, match="damaged or truncated"):
        read_bal(cut)


@needs_fifo
def test_a_stream_of_empty_bzip2_streams_is_refused_early(tmp_path: Path):
    """bzip2 streams that decompress to nothing (14 bytes each) were read on and on: the
    header's bound applies to decompressed bytes, and none came, so a stream of them that
    never ends was read for ever (and, kept for the command, held in memory). Compressed
    bytes beyond twice the decompressed ones plus 64 KiB are refused: 1 MB of empty
    streams is refused after 64 KiB, and a legitimate file (even incompressible text) is
    read as before."""
    empty = bz2.compress(b"")
    assert len(empty) == 14
    fifo = fifo_with(tmp_path, empty * (1_000_000 // 14), "problem.pipe")
    with pytest.raises(FileFormatError, match=r"decompress to 0 bytes: empty bzip2 streams"):
        read_bal(fifo)
    # random digits compress about 2.3 times only; a header announcing them all: the 3 MB
    # (1.3 MB compressed, two 1 MiB reads) are read whole, to the index check
    rng = np.random.default_rng(1)
    digits = " ".join(map(str, rng.integers(0, 10**9, 300_000))).encode()
    noisy = tmp_path / "noisy.bz2"
    noisy.write_bytes(bz2.compress(b"1 1 74997\n" + digits))
    assert noisy.stat().st_size > (1 << 20)
    with pytest.raises(FileFormatError, match="refers to camera") as info:
        read_bal(noisy)
    assert "empty bzip2" not in str(info.value)
