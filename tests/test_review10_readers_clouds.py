"""LAS/LAZ readers under damaged headers and data (review 10): named refusals, never a
traceback, an abort or gigabytes allocated before failing."""

from __future__ import annotations

import struct
import subprocess
import sys

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError

pytest.importorskip("laspy")
pytest.importorskip("lazrs")


def _cloud(tmp_path, suffix: str, n: int = 3000):
    x = np.random.default_rng(5).uniform(0, 100, (n, 3))
    path = tmp_path / f"c{suffix}"
    pg.io.write_cloud(path, x, point_format=1, version="1.2")
    return path


def _patch(path, offset: int, fmt: str, *values) -> None:
    data = bytearray(path.read_bytes())
    struct.pack_into(fmt, data, offset, *values)
    path.write_bytes(bytes(data))


def _laszip_record(path) -> int:
    """Byte offset of the LASzip VLR's record data."""
    data = path.read_bytes()
    return data.index(b"laszip encoded") - 2 + 54


def _read_in_a_child(path) -> subprocess.CompletedProcess:
    """read_cloud_xyz in another process: before the fix, lazrs aborted the process."""
    code = (
        "import sys, photogeom as pg\n"
        "try:\n"
        f"    pg.io.read_cloud_xyz({str(path)!r})\n"
        "except pg.errors.FileFormatError as exc:\n"
        "    print('FileFormatError:', exc)\n"
    )
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_damaged_version_is_named(tmp_path, suffix):
    """Version 1.255: laspy read the fields of a later version past the header and ended in
    struct.error ('unpack requires a buffer of 8 bytes')."""
    path = _cloud(tmp_path, suffix)
    _patch(path, 24, "<BB", 1, 255)
    for read in (pg.io.cloud_info, pg.io.read_cloud_xyz):
        with pytest.raises(FileFormatError, match=r"LAS version 1\.255"):
            read(path)


def test_damaged_creation_date_is_named(tmp_path):
    """Day 65535 of year 9999 ended in laspy's OverflowError ('date value out of range')."""
    path = _cloud(tmp_path, ".las")
    _patch(path, 90, "<HH", 65535, 9999)
    with pytest.raises(FileFormatError, match="OverflowError"):
        pg.io.cloud_info(path)


def test_vlr_count_beyond_the_file_is_named(tmp_path):
    """A damaged offset of the point data (4 GB) let a damaged VLR count through; laspy then
    read millions of empty VLRs (8 million: 57 s) before failing."""
    path = _cloud(tmp_path, ".las")
    _patch(path, 96, "<II", 0xFFFFFFFF, 100_000)
    with pytest.raises(FileFormatError, match=r"announces 100000 VLRs .* but the file has"):
        pg.io.cloud_info(path)


def test_lazrs_panic_is_a_named_error(tmp_path, monkeypatch):
    """lazrs turns some damaged data into a Rust panic, raised as pyo3's PanicException,
    a BaseException: it went past 'except Exception' to the user as a traceback."""
    import laspy

    class PanicException(BaseException):
        pass

    def panic(self, n):
        raise PanicException("attempt to calculate the remainder with a divisor of zero")

    path = _cloud(tmp_path, ".laz")
    monkeypatch.setattr(laspy.LasReader, "read_points", panic)
    with pytest.raises(FileFormatError, match="PanicException: attempt to calculate"):
        pg.io.read_cloud_xyz(path)
    with pytest.raises(FileFormatError, match="PanicException"):
        list(pg.io.iter_cloud_xyz(path, chunk_size=1000))


def test_interrupt_still_stops_a_read(tmp_path, monkeypatch):
    import laspy

    def interrupt(self, n):
        raise KeyboardInterrupt

    path = _cloud(tmp_path, ".laz")
    monkeypatch.setattr(laspy.LasReader, "read_points", interrupt)
    with pytest.raises(KeyboardInterrupt):
        pg.io.read_cloud_xyz(path)


def test_laz_still_reads_whole_and_in_slices(tmp_path):
    path = _cloud(tmp_path, ".laz", n=2500)
    x = np.random.default_rng(5).uniform(0, 100, (2500, 3))
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path), x, atol=0.01)
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path, 100, 300), x[100:300], atol=0.01)
    assert pg.io.read_cloud_xyz(path, 7, 7).shape == (0, 3)
