"""Block text files (BAL, plain or bzip2; COLMAP text; CSV blocks) from pipes within one
command (a :func:`photogeom.io.sources.pipe_reads` scope): ``read_text`` used the bytes of a
pipe only when another reader had kept them; reading a pipe first, it streamed it and kept
nothing, so a later read of the same pipe in the command (the BAL reader again, or any
other reader) waited for a new writer, or read what that writer wrote (another block). The
pipe is now streamed once and its bytes kept for the command, as every other reader does."""

from __future__ import annotations

import bz2
import dataclasses
import os
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.bundle import read_bal, write_bal
from photogeom.errors import FileFormatError
from photogeom.io import sources

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

BAL = Path(datasets.__file__).parent / "data" / "bundle" / "dubrovnik-3-7-pre.txt"

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def _serve_again(fifo: Path, data: bytes) -> threading.Thread:
    """A second writer of ``data`` to ``fifo``: it waits for the next reader to open it."""

    def feed() -> None:
        try:
            with open(fifo, "wb") as fh:
                fh.write(data)
        except BrokenPipeError:
            pass

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    return t


def _drain(fifo: Path, writer: threading.Thread) -> None:
    """Let a second writer end: read what it writes if nobody did (a reader that opens the
    pipe without blocking wakes a writer waiting in open, or finds the pipe done)."""
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        while writer.is_alive():
            try:
                os.read(fd, 1 << 16)
            except BlockingIOError:
                pass
            writer.join(0.01)
    finally:
        os.close(fd)


def _other_bal(tmp_path: Path) -> bytes:
    """Another BAL problem: the bundled one with its points moved 1 m."""
    block = read_bal(BAL)
    write_bal(dataclasses.replace(block, xyz=block.xyz + 1.0), tmp_path / "other.bal")
    return (tmp_path / "other.bal").read_bytes()


def _same_block(got, want) -> None:
    np.testing.assert_array_equal(got.xyz, want.xyz)
    np.testing.assert_array_equal(got.observations.uv, want.observations.uv)


@pytest.mark.parametrize("packed", [False, True], ids=["plain", "bzip2"])
def test_a_bal_pipe_read_first_is_kept_for_the_command(tmp_path: Path, packed: bool):
    raw = BAL.read_bytes()
    data = bz2.compress(raw) if packed else raw
    want = read_bal(BAL)
    other = _other_bal(tmp_path)
    fifo = fifo_with(tmp_path, data, "problem.pipe")
    with sources.pipe_reads():
        _same_block(read_bal(fifo), want)
        assert sources.kept_pipe_bytes(fifo) == data  # kept, as read (compressed or not)
        writer = _serve_again(fifo, other)  # a later writer: not what this command reads
        try:
            _same_block(read_bal(fifo), want)
            assert sources.read_input_bytes(fifo, None) == data
            assert sources.pipe_bytes(fifo, len(data)) == data
        finally:
            _drain(fifo, writer)


def test_outside_a_command_each_read_reads_the_stream(tmp_path: Path):
    want, other = read_bal(BAL), _other_bal(tmp_path)
    fifo = fifo_with(tmp_path, BAL.read_bytes(), "problem.pipe")
    _same_block(read_bal(fifo), want)
    assert sources.kept_pipes() is None
    writer = _serve_again(fifo, other)
    np.testing.assert_array_equal(read_bal(fifo).xyz, want.xyz + 1.0)  # the new writer's
    writer.join()


def test_a_pipe_read_in_part_by_another_reader_is_refused_not_read_again(tmp_path: Path):
    """Another reader read only the first 100 bytes of the pipe: the BAL reader opened it
    again and read the next writer's problem (points 1 m off) as if it were this one."""
    fifo = fifo_with(tmp_path, BAL.read_bytes(), "problem.pipe")
    with sources.pipe_reads():
        assert len(sources.pipe_bytes(fifo, 100)) == 101
        writer = _serve_again(fifo, _other_bal(tmp_path))
        try:
            with pytest.raises(FileFormatError, match="read once to 100 bytes and holds more"):
                read_bal(fifo)
        finally:
            _drain(fifo, writer)


def test_a_pipe_refused_before_its_end_is_not_read_again(tmp_path: Path):
    """The BAL reader refused a stream longer than its header allows before its end; a
    later read in the command reads no other writer's content."""
    long = b"1 1 1\n" + b"0 0 1.5 2.5\n" * 50_000  # 600 kB for a header of 16 values
    fifo = fifo_with(tmp_path, long, "problem.pipe")
    with sources.pipe_reads():
        with pytest.raises(FileFormatError, match="1 cameras, 1 points, 1 observations"):
            read_bal(fifo)
        writer = _serve_again(fifo, BAL.read_bytes())
        try:
            with pytest.raises(FileFormatError, match="holds more"):
                read_bal(fifo)
        finally:
            _drain(fifo, writer)
