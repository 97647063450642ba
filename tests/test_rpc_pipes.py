"""RPC files from pipes: ``read_rpc`` checked ``is_file()`` first, false for a
pipe, so ``photogeom rpc info <(cat IMG_RPC.TXT)`` said "no such file". Text and XML RPCs
are now read once from a pipe; a raster from a pipe (GDAL reads it with seeks) and a device
are refused by name."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.errors import FileFormatError
from photogeom.io import sources
from photogeom.rpc.readers import read_rpc

sys.path.insert(0, str(Path(__file__).parent))  # the tests' helper modules
from fifos import fifo_with

DATA = Path(datasets.__file__).parent / "data" / "rpc"

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


@pytest.mark.parametrize("name", ["rpc_IKONOS.txt", "rpc_WV2.xml", "rpc_PLEIADES.xml"])
def test_read_rpc_from_a_pipe_equals_the_file(tmp_path: Path, name: str):
    want = read_rpc(DATA / name)
    got = read_rpc(fifo_with(tmp_path, (DATA / name).read_bytes(), "rpc.pipe"))
    lon, lat, h = want.long_off, want.lat_off, want.height_off
    np.testing.assert_array_equal(got.project(lon, lat, h), want.project(lon, lat, h))


def test_rpc_info_reads_a_pipe(cli, tmp_path: Path):
    fifo = fifo_with(tmp_path, (DATA / "rpc_IKONOS.txt").read_bytes(), "rpc.pipe")
    code, out, err = cli("rpc", "info", fifo)
    assert code == 0, err
    assert "RPC00B" in out


def test_a_raster_from_a_pipe_is_refused(tmp_path: Path):
    fifo = fifo_with(tmp_path, b"II*\x00" + b"\x00" * 64, name="image.tif")
    with pytest.raises(FileFormatError, match="it is a pipe, and GDAL reads a GeoTIFF"):
        read_rpc(fifo)


def test_a_device_is_refused():
    if not Path("/dev/null").exists():
        pytest.skip("no /dev/null")
    with pytest.raises(FileFormatError, match="/dev/null: it is a device"):
        read_rpc("/dev/null")


def _serve_again(fifo: Path, data: bytes) -> threading.Thread:
    """A second writer of ``data`` to ``fifo``: it waits for the next reader to open it."""

    def feed() -> None:
        with open(fifo, "wb") as fh:
            fh.write(data)

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    return t


def _drain(fifo: Path, writer: threading.Thread) -> None:
    """Let a writer that nobody read from finish."""
    with open(fifo, "rb") as fh:
        fh.read()
    writer.join()


def _same_rpc(got, want) -> None:
    lon, lat, h = want.long_off, want.lat_off, want.height_off
    np.testing.assert_array_equal(got.project(lon, lat, h), want.project(lon, lat, h))


def test_an_rpc_pipe_read_twice_in_a_command_gives_the_same_rpc(tmp_path: Path):
    """In a command (a pipe_reads scope) read_rpc opened the pipe itself each time: a second
    read of the same pipe (by read_rpc again, or by another reader) waited for a new writer
    or read what one wrote next, another RPC. It reads the pipe once per scope, as every
    other reader (io.sources.pipe_bytes)."""
    ikonos, wv2 = (DATA / "rpc_IKONOS.txt").read_bytes(), (DATA / "rpc_WV2.xml").read_bytes()
    want = read_rpc(DATA / "rpc_IKONOS.txt")
    fifo = fifo_with(tmp_path, ikonos, "rpc.pipe")
    with sources.pipe_reads():
        _same_rpc(read_rpc(fifo), want)
        assert sources.kept_pipe_bytes(fifo) == ikonos  # kept for the other readers
        writer = _serve_again(fifo, wv2)  # a later writer: not what this command reads
        _same_rpc(read_rpc(fifo), want)
        assert sources.read_input_bytes(fifo, None) == ikonos
    _drain(fifo, writer)


def test_a_pipe_read_by_another_reader_first_is_the_same_rpc(tmp_path: Path):
    """The pipe read through the shared reader first (its format, say), then as an RPC in
    the same command: read_rpc opened it again and read the next writer's content (a
    WorldView-2 RPC in place of the IKONOS one), or waited for one."""
    ikonos, wv2 = (DATA / "rpc_IKONOS.txt").read_bytes(), (DATA / "rpc_WV2.xml").read_bytes()
    want = read_rpc(DATA / "rpc_IKONOS.txt")
    fifo = fifo_with(tmp_path, ikonos, "rpc.pipe")
    with sources.pipe_reads():
        assert sources.read_input_bytes(fifo, 4096)[:4096] == ikonos[:4096]
        writer = _serve_again(fifo, wv2)
        _same_rpc(read_rpc(fifo), want)
    _drain(fifo, writer)


def test_a_text_rpc_pipe_over_its_limit_is_refused(tmp_path: Path, monkeypatch):
    from photogeom.rpc import readers

    monkeypatch.setattr(readers, "MAX_TEXT_BYTES", 2000)
    data = (DATA / "rpc_IKONOS.txt").read_bytes()
    assert len(data) > 2000
    with pytest.raises(FileFormatError, match="more than 2000 bytes; wrong file"):
        read_rpc(fifo_with(tmp_path, data, "rpc.pipe"))
