"""LAS/LAZ point clouds chunk by chunk: equal to the in-memory result, header kept."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError, InputError

laspy = pytest.importorskip("laspy")
pytest.importorskip("lazrs")


def _cloud(tmp_path, name="scan.laz", n=5000, crs="EPSG:32632", fmt=6, version="1.4"):
    rng = np.random.default_rng(0)
    xyz = rng.uniform([0, 0, 0], [300, 200, 40], (n, 3))
    extra = {
        "reflectance": rng.normal(size=n).astype(np.float32),
        "tile": rng.integers(0, 9, n).astype(np.uint16),
    }
    path = tmp_path / name
    pg.io.write_cloud(path, xyz, crs=crs, point_format=fmt, version=version, extra=extra)
    las = laspy.read(path)
    las.intensity = rng.integers(0, 60000, n).astype(np.uint16)
    las.classification = rng.integers(0, 10, n).astype(np.uint8)
    las.write(path)
    return path


def _expected(las, T, scales, offsets):
    out = T.apply(np.c_[las.x, las.y, las.z])
    return np.rint((out - offsets) / scales).astype(np.int64)


@pytest.mark.parametrize("suffix", [".laz", ".las"])
def test_transform_equals_in_memory_and_keeps_everything(tmp_path, suffix):
    src = _cloud(tmp_path, "scan" + suffix)
    T = pg.Similarity3D.from_angles(1.00003, 0.02, -0.01, 1.3, [512000.0, 5400000.0, 410.0])
    dst = tmp_path / ("utm" + suffix)
    res = pg.io.transform_cloud(src, dst, T, chunk_size=777)
    assert res.chunks == 7 and res.passes == 1 and res.point_count == 5000
    a, b = laspy.read(src), laspy.read(dst)
    assert b.header.point_format.id == a.header.point_format.id
    assert b.header.version == a.header.version
    np.testing.assert_array_equal(b.header.scales, a.header.scales)
    q = _expected(a, T, b.header.scales, b.header.offsets)
    np.testing.assert_array_equal(np.c_[b.X, b.Y, b.Z], q)
    for dim in ("reflectance", "tile", "intensity", "classification", "gps_time"):
        np.testing.assert_array_equal(np.asarray(b[dim]), np.asarray(a[dim]))
    assert b.header.parse_crs().to_epsg() == 32632
    # header bounds are those of the written points
    np.testing.assert_allclose(b.header.mins, [b.x.min(), b.y.min(), b.z.min()])
    np.testing.assert_allclose(b.header.maxs, [b.x.max(), b.y.max(), b.z.max()])
    # offsets moved to the new place: coordinates stored with small integers
    assert np.all(np.abs(np.c_[b.X, b.Y, b.Z]) < 1e6)
    assert (dst.suffix == ".laz") == pg.io.cloud_info(dst).compressed


def test_old_point_format_with_geotiff_crs(tmp_path):
    src = _cloud(tmp_path, "old.las", fmt=1, version="1.2", crs="EPSG:25832")
    T = pg.Rigid3D(np.eye(3), [10.0, 20.0, 0.5])
    dst = tmp_path / "old2.las"
    pg.io.transform_cloud(src, dst, T, chunk_size=1000)
    info = pg.io.cloud_info(dst)
    assert info.point_format == 1 and info.version == "1.2"
    assert info.crs_name.startswith("EPSG:25832")
    assert "GeoKeyDirectoryVlr" in info.vlrs


def test_nonlinear_transform_takes_a_bounds_pass_and_crs_from_proj(tmp_path):
    rng = np.random.default_rng(1)
    lon = 9.0 + rng.uniform(0, 0.01, 3000)
    lat = 48.0 + rng.uniform(0, 0.01, 3000)
    h = 300 + rng.uniform(0, 50, 3000)
    src = tmp_path / "geo.laz"
    pg.io.write_cloud(src, np.c_[lon, lat, h], scales=(1e-8, 1e-8, 1e-3), crs="EPSG:4979")
    op = pg.crs.ProjTransform("EPSG:4979", "EPSG:4978")
    dst = tmp_path / "ecef.laz"
    res = pg.io.transform_cloud(src, dst, op, chunk_size=1000, scales=(1e-3, 1e-3, 1e-3))
    assert res.passes == 2
    assert pg.io.cloud_info(dst).crs_name.startswith("EPSG:4978")
    a = laspy.read(src)
    X, Y, Z = pg.crs.geodetic_to_ecef(np.asarray(a.y), np.asarray(a.x), np.asarray(a.z))
    b = pg.io.read_cloud_xyz(dst)
    np.testing.assert_allclose(b, np.c_[X, Y, Z], atol=0.5e-3 + 1e-9)


def test_fit_and_function_transforms_and_chunks(tmp_path):
    src = _cloud(tmp_path)
    xyz = pg.io.read_cloud_xyz(src)
    parts = list(pg.io.iter_cloud_xyz(src, chunk_size=1200))
    assert [len(p) for p in parts] == [1200, 1200, 1200, 1200, 200]
    np.testing.assert_array_equal(np.concatenate(parts), xyz)
    np.testing.assert_array_equal(pg.io.read_cloud_xyz(src, 1000, 1010), xyz[1000:1010])
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.3, [5.0, 6.0, 7.0])
    fit = pg.absolute_orientation(xyz[:100], T.apply(xyz[:100]))
    pg.io.transform_cloud(src, tmp_path / "f.laz", fit)
    np.testing.assert_allclose(
        pg.io.read_cloud_xyz(tmp_path / "f.laz"), T.apply(xyz), atol=0.5e-3 + 1e-9
    )


def test_bad_input_and_atomic_output(tmp_path):
    src = _cloud(tmp_path)
    T = pg.Rigid3D(np.eye(3), [0.0, 0.0, 0.0])
    with pytest.raises(InputError, match="does not exist"):
        pg.io.transform_cloud(tmp_path / "none.laz", tmp_path / "o.laz", T)
    (tmp_path / "junk.las").write_bytes(b"not a las file at all")
    with pytest.raises(FileFormatError, match="not a readable LAS/LAZ"):
        pg.io.cloud_info(tmp_path / "junk.las")
    with pytest.raises(InputError, match="is the input file"):
        pg.io.transform_cloud(src, src, T)
    with pytest.raises(InputError, match="3D transformation"):
        pg.io.transform_cloud(src, tmp_path / "o.laz", pg.Similarity2D(1.0, 0.0, 0.0, 0.0))
    with pytest.raises(InputError, match="chunk_size"):
        pg.io.transform_cloud(src, tmp_path / "o.laz", T, chunk_size=0)
    huge = pg.Similarity3D(1e6, np.eye(3), [0.0, 0.0, 0.0])
    (tmp_path / "o.laz").write_bytes(b"old")
    with pytest.raises(InputError, match="larger scales"):
        pg.io.transform_cloud(src, tmp_path / "o.laz", huge)
    assert (tmp_path / "o.laz").read_bytes() == b"old"  # untouched
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


@pytest.mark.parametrize(("suffix", "scheduler"), [(".laz", "threads"), (".las", "sync")])
def test_pieces_as_dask_tasks_equal_the_sequential_output(tmp_path, suffix, scheduler):
    """Pieces written by separate tasks and joined (LAZ: chunk tables concatenated) give the
    sequential file's points and header; readers seek in the joined file."""
    pytest.importorskip("dask")
    rng = np.random.default_rng(4)
    n = 123_457
    xyz = rng.uniform([0, 0, 0], [900, 700, 60], (n, 3))
    src = tmp_path / ("big" + suffix)
    pg.io.write_cloud(src, xyz, crs="EPSG:32632", extra={"amp": rng.normal(size=n)})
    las = laspy.read(src)
    las.return_number = rng.integers(1, 4, n).astype(np.uint8)
    las.number_of_returns = np.full(n, 3, dtype=np.uint8)
    las.write(src)
    T = pg.Similarity3D.from_angles(0.9999, 0.03, 0.01, -0.4, [512000.0, 5400000.0, 410.0])
    seq, par = tmp_path / ("seq" + suffix), tmp_path / ("par" + suffix)
    pg.io.transform_cloud(src, seq, T, chunk_size=20_000)
    done = []
    res = pg.io.transform_cloud(
        src,
        par,
        T,
        chunk_size=20_000,
        scheduler=scheduler,
        progress=lambda d, t: done.append((d, t)),
    )
    assert res.chunks == 3 and done[-1] == (n, n)  # pieces of 50 000 points
    a, b = laspy.read(seq), laspy.read(par)
    np.testing.assert_array_equal(a.points.array, b.points.array)
    for field in ("point_count", "scales", "offsets", "mins", "maxs"):
        np.testing.assert_array_equal(getattr(a.header, field), getattr(b.header, field))
    np.testing.assert_array_equal(
        a.header.number_of_points_by_return, b.header.number_of_points_by_return
    )
    assert b.header.parse_crs().to_epsg() == 32632
    np.testing.assert_array_equal(
        pg.io.read_cloud_xyz(par, 99_990, 100_010), np.c_[a.x, a.y, a.z][99_990:100_010]
    )
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_output_file_policy(tmp_path):
    """Mode of a plain open(), read-only destinations refused, symbolic links followed."""
    import os
    import stat

    src = _cloud(tmp_path, n=500)
    T = pg.Rigid3D(np.eye(3), [1.0, 2.0, 3.0])
    out = tmp_path / "o.laz"
    pg.io.transform_cloud(src, out, T)
    umask = os.umask(0o022)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask
    out.chmod(0o444)
    with pytest.raises(pg.errors.OutputError, match="read-only"):
        pg.io.transform_cloud(src, out, T)
    out.chmod(0o640)
    link = tmp_path / "link.laz"
    link.symlink_to(out)
    pg.io.transform_cloud(src, link, T)
    assert link.is_symlink() and stat.S_IMODE(out.stat().st_mode) == 0o640
    with pytest.raises(pg.errors.OutputError, match="does not exist"):
        pg.io.transform_cloud(src, tmp_path / "no" / "o.laz", T)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
