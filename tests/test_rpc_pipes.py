"""RPC files from pipes: ``read_rpc`` checked ``is_file()`` first, false for a
pipe, so ``photogeom rpc info <(cat IMG_RPC.TXT)`` said "no such file". Text and XML RPCs
are now read once from a pipe; a raster from a pipe (GDAL reads it with seeks) and a device
are refused by name."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.errors import FileFormatError
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
