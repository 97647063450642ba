"""A LAZ file whose LASzip VLR lists no compressed items: lazrs divided by zero
when decoding the first points, a Rust panic, which printed Rust's panic message (and with
RUST_BACKTRACE=1 a backtrace of some 30 frames) on standard error before it became the
named FileFormatError. Rust's panic hook writes to file descriptor 2 itself, which Python
cannot intercept safely, so the damage is now refused from the header, before lazrs runs."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")
pytest.importorskip("lazrs")

from photogeom.errors import FileFormatError  # noqa: E402
from photogeom.io import cloud_info, read_cloud_xyz  # noqa: E402


def _laz_without_items(tmp_path: Path) -> Path:
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [0.001] * 3
    header.offsets = [0.0] * 3
    las = laspy.LasData(header)
    rng = np.random.default_rng(0)
    las.x, las.y, las.z = rng.uniform(0, 100, (3, 500))
    path = tmp_path / "scan.laz"
    las.write(path)
    data = bytearray(path.read_bytes())
    at = data.find(b"laszip encoded")  # user id; the record starts 54 bytes after the VLR
    assert at > 0
    (items,) = struct.unpack_from("<H", data, at - 2 + 54 + 32)
    assert items >= 1
    struct.pack_into("<H", data, at - 2 + 54 + 32, 0)  # the item count
    path.write_bytes(bytes(data))
    return path


def test_no_items_is_refused_before_lazrs_panics(tmp_path: Path, capfd):
    path = _laz_without_items(tmp_path)
    with pytest.raises(FileFormatError, match="LASzip VLR announces 0 compressed item"):
        read_cloud_xyz(path)
    err = capfd.readouterr().err
    assert "panicked" not in err and "backtrace" not in err


def test_cloud_info_with_check_size_false_still_reads_the_header(tmp_path: Path):
    info = cloud_info(_laz_without_items(tmp_path), check_size=False)
    assert info.point_count == 500


def test_cloud_transform_names_the_damage(cli, tmp_path: Path):
    path = _laz_without_items(tmp_path)
    code, _, err = cli("cloud", "transform", path, tmp_path / "out.las", "--to-crs",
                       "EPSG:32633", "--from-crs", "EPSG:32632")
    assert code == 2
    assert "LASzip VLR announces 0" in err
