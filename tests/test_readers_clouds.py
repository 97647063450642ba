"""LAS/LAZ readers under damaged headers and data: named refusals, never a
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


def test_huge_laz_chunk_size_is_refused_not_allocated(tmp_path):
    """A chunk size of 10^9 points in the LASzip VLR: lazrs allocated the chunk (28 GB) and
    the process aborted ('memory allocation of ... bytes failed')."""
    path = _cloud(tmp_path, ".laz")
    _patch(path, _laszip_record(path) + 12, "<I", 1_000_000_000)
    run = _read_in_a_child(path)
    assert run.returncode == 0, run.stderr[-500:]
    assert "LAZ chunks hold 1000000000 points each" in run.stdout
    with pytest.raises(FileFormatError, match="re-compress the file"):
        pg.io.cloud_info(path)


def test_damaged_laz_chunk_table_count_is_refused_not_allocated(tmp_path):
    """A chunk table announcing 3 x 10^9 chunks: lazrs allocated its entries (46 GB) and the
    process aborted."""
    path = _cloud(tmp_path, ".laz")
    data = path.read_bytes()
    start = struct.unpack_from("<I", data, 96)[0]
    (table,) = struct.unpack_from("<q", data, start)
    _patch(path, table, "<II", 0, 3_000_000_000)
    run = _read_in_a_child(path)
    assert run.returncode == 0, run.stderr[-500:]
    assert "says version 0 and 3000000000 chunks" in run.stdout


def test_laz_point_count_of_billions_fails_before_allocating(tmp_path):
    """A LAZ header promising 2.3 x 10^9 points (no chunk table to check it against):
    read_cloud_xyz allocated the (n, 3) result first and ended in MemoryError (52 GiB)."""
    path = _cloud(tmp_path, ".laz")
    data = path.read_bytes()
    start = struct.unpack_from("<I", data, 96)[0]
    _patch(path, 107, "<I", 2_348_815_240)  # legacy point count (LAS 1.2)
    _patch(path, start, "<q", -1)  # no chunk table
    with pytest.raises(FileFormatError, match="2348815240 points its header promises"):
        pg.io.read_cloud_xyz(path)


def test_laz_still_reads_whole_and_in_slices(tmp_path):
    path = _cloud(tmp_path, ".laz", n=2500)
    x = np.random.default_rng(5).uniform(0, 100, (2500, 3))
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path), x, atol=0.01)
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path, 100, 300), x[100:300], atol=0.01)
    assert pg.io.read_cloud_xyz(path, 7, 7).shape == (0, 3)


@pytest.mark.parametrize("scale", [0.0, float("nan"), float("inf"), 1e308])
def test_damaged_scales_are_refused_not_read_silently(tmp_path, scale):
    """An X scale of 0 read every X as the offset (50.0), NaN/inf/1e308 read NaN or
    infinite X: all without a word."""
    path = _cloud(tmp_path, ".las")
    _patch(path, 131, "<d", scale)  # the X scale factor
    with pytest.raises(FileFormatError, match=r"X scale .* cannot give coordinates"):
        pg.io.read_cloud_xyz(path)
    with pytest.raises(FileFormatError, match="header is damaged"):
        list(pg.io.iter_cloud_xyz(path))
    info = pg.io.cloud_info(path, check_size=False)  # the header can still be looked at
    assert info.scales[0] == scale or np.isnan(scale)


def test_damaged_offset_is_refused(tmp_path):
    path = _cloud(tmp_path, ".laz")
    _patch(path, 155 + 8, "<d", float("inf"))  # the Y offset
    with pytest.raises(FileFormatError, match=r"Y scale 0\.001 and offset inf"):
        pg.io.cloud_info(path)
