"""Truncated LAS/LAZ files: named errors with the file and the counts, never fewer points
than the header promises without a word."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError

pytest.importorskip("laspy")
pytest.importorskip("dask")


def _cut(path, out, keep_fraction):
    data = path.read_bytes()
    out.write_bytes(data[: int(len(data) * keep_fraction)])
    return out


@pytest.fixture
def pair(tmp_path):
    x = np.random.default_rng(1).uniform(0, 100, (5000, 3))
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    pg.io.write_cloud(a, x)
    pg.io.write_cloud(b, x + np.array([1.0, 2.0, 3.0]))
    return a, b


@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_cloud_info_names_truncated_file(tmp_path, suffix):
    x = np.random.default_rng(2).uniform(0, 100, (5000, 3))
    full = tmp_path / f"full.{suffix}"
    pg.io.write_cloud(full, x)
    cut = _cut(full, tmp_path / f"cut.{suffix}", 2 / 3)
    with pytest.raises(FileFormatError) as info:
        pg.io.cloud_info(cut)
    msg = str(info.value)
    assert str(cut) in msg and "is truncated" in msg and "copy it again" in msg
    assert "5000 points" in msg
    # the header can still be read on purpose
    assert pg.io.cloud_info(cut, check_size=False).point_count == 5000
    assert pg.io.cloud_info(full).point_count == 5000


def test_truncated_las_counts_in_message(pair, tmp_path):
    _, b = pair
    cut = _cut(b, tmp_path / "bt.las", 2 / 3)
    size = cut.stat().st_size
    with pytest.raises(FileFormatError) as info:
        pg.io.read_cloud_xyz(cut)
    msg = str(info.value)
    assert f"{size} bytes" in msg and "points of 30 bytes" in msg
    assert f"{(size - 375) // 30} whole point(s)" in msg


@pytest.mark.parametrize("where", ["mid-record", "record boundary"])
def test_short_read_is_an_error_even_past_the_header_check(pair, tmp_path, monkeypatch, where):
    """The file may be cut after it was opened (or the size check skipped): the count read
    is checked against the range asked for."""
    _, b = pair
    cut = tmp_path / "bt.las"
    keep = 375 + 30 * 3000 + (17 if where == "mid-record" else 0)  # header 375, records 30
    cut.write_bytes(b.read_bytes()[:keep])
    monkeypatch.setattr(pg.io.cloud, "_truncation", lambda path, header: None)
    with pytest.raises(FileFormatError, match=r"bt\.las") as info:
        pg.io.read_cloud_xyz(cut, 1000, 5000)
    msg = str(info.value)
    assert "5000 points" in msg and "copy it again" in msg
    if where == "record boundary":
        assert "the file ends after point 3000 but its header promises 5000 points" in msg
    with pytest.raises(FileFormatError, match=r"bt\.las"):
        list(pg.io.iter_cloud_xyz(cut, chunk_size=1000))
    # a range inside the present points still reads
    assert pg.io.read_cloud_xyz(cut, 0, 1000).shape == (1000, 3)


def test_register_truncated_target_names_file(pair, tmp_path):
    a, b = pair
    cut = _cut(b, tmp_path / "bt.las", 2 / 3)
    with pytest.raises(FileFormatError, match=r"bt\.las is truncated"):
        pg.distributed.register_clouds(a, cut, check_every=10, chunk_size=1000, scheduler="sync")


def test_register_worker_error_names_both_files(pair, tmp_path, monkeypatch):
    a, b = pair
    cut = _cut(b, tmp_path / "bt.las", 2 / 3)
    monkeypatch.setattr(pg.io.cloud, "_truncation", lambda path, header: None)
    with pytest.raises(FileFormatError) as info:
        pg.distributed.register_clouds(a, cut, check_every=10, chunk_size=1000, scheduler="sync")
    msg = str(info.value)
    # the block that fails first (the one cut mid-record or one past the end) depends on the
    # order the scheduler runs them in; either names both files, the block and the count
    assert f"registering {a} to {cut}, pairs " in msg and "5000 points" in msg
    assert "copy it again" in msg


def test_cli_register_truncated(cli, pair, tmp_path):
    a, b = pair
    cut = _cut(b, tmp_path / "bt.las", 2 / 3)
    code, out, err = cli("cloud", "register", a, cut, "--check-every", "10", "--chunk-size", "1000")
    assert code == 2 and out == ""
    assert err.startswith(f"error: {cut} is truncated") and "Traceback" not in err


def test_cli_info_truncated_laz(cli, tmp_path):
    x = np.random.default_rng(3).uniform(0, 100, (5000, 3))
    full = tmp_path / "full.laz"
    pg.io.write_cloud(full, x)
    cut = _cut(full, tmp_path / "cut.laz", 0.6)
    code, _out, err = cli("cloud", "info", cut)
    assert code == 2
    assert err.startswith(f"error: {cut} is truncated: its LAZ chunk table")


def test_transform_truncated_writes_nothing(pair, tmp_path, monkeypatch):
    _, b = pair
    cut = _cut(b, tmp_path / "bt.las", 2 / 3)
    monkeypatch.setattr(pg.io.cloud, "_truncation", lambda path, header: None)
    out = tmp_path / "out.las"
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [1.0, 2.0, 3.0])
    with pytest.raises(FileFormatError, match=r"bt\.las"):
        pg.io.transform_cloud(cut, out, T, chunk_size=1000)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.las", "b.las", "bt.las"]
