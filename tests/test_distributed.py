"""Dask: per-item jobs with failures collected, dask-array transformation and orientation."""

import functools
import itertools

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, PhotogeomError
from photogeom.orientation.absolute_chunked import absolute_orientation_chunks

da = pytest.importorskip("dask.array")
pytest.importorskip("distributed")


def _square_or_fail(i, bad=(3,)):
    if i in bad:
        raise ValueError(f"item {i} is bad")
    return i * i


def _data(n=60000, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 3)) * [80.0, 60.0, 10.0] + [512000.0, 5400000.0, 400.0]
    T = pg.Similarity3D.from_angles(0.99997, 0.4, -2.2, 2.9, [-511000.0, -5399000.0, 20.0])
    X = T.apply(x) + rng.normal(size=(n, 3)) * 0.02
    return x, X, rng


@pytest.mark.parametrize("method", ["svd", "quaternion", "dual-quaternion", "gauss-helmert"])
def test_dask_orientation_equals_in_memory(method):
    x, X, rng = _data()
    w = rng.uniform(0.5, 2.0, x.shape[0])
    for weights in (None, w):
        ref = pg.absolute_orientation(x, X, method=method, weights=weights, statistics=False)
        fit = pg.distributed.absolute_orientation(
            da.from_array(x, chunks=(7000, 3)),
            da.from_array(X, chunks=(9000, 3)),
            method=method,
            weights=weights,
            scheduler="sync",
        )
        assert abs(fit.scale - ref.scale) < 1e-13
        np.testing.assert_allclose(fit.rotation, ref.rotation, rtol=0, atol=1e-13)
        # rounding at 5.4e6 m coordinates: 3e-7 m is 6e-14 relative
        np.testing.assert_allclose(fit.translation, ref.translation, rtol=0, atol=3e-7)
        for k in ("omega", "phi", "kappa", "tx"):
            assert abs(fit.params[k] - ref.params[k]) < 1e-7
    # sum of squared residuals from the moments equals the residuals' (noise >> rounding)
    full = pg.absolute_orientation(x, X, method="svd")
    fit = pg.distributed.absolute_orientation(x, X, scheduler="threads")
    vtv = float(np.sum(full.residuals**2))
    # relative accuracy ~1e-16 spread^2 / noise^2 = 1.6e-9 here
    assert abs(fit.extras["sum_squared_residuals"] - vtv) < 2e-8 * vtv


def test_chunked_moments_any_split_and_far_from_origin():
    x, X, _ = _data(5000, seed=4)
    ref = pg.absolute_orientation(x, X, method="svd", statistics=False)
    splits = [0, 1, 2, 3, 700, 701, 4999, 5000]  # empty and one-point chunks too
    fit = absolute_orientation_chunks((x[a:b], X[a:b]) for a, b in itertools.pairwise(splits))
    np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-13)
    np.testing.assert_allclose(fit.translation, ref.translation, atol=1e-7)


def test_dask_orientation_bad_input():
    x, X, _ = _data(100)
    X[5, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        pg.distributed.absolute_orientation(x, X, scheduler="sync")
    with pytest.raises(InputError, match="needs all points"):
        pg.distributed.absolute_orientation(x, X, method="gauss-markov")
    with pytest.raises(InputError, match="pairs"):
        pg.distributed.absolute_orientation(x, X[:50])
    line = np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)]
    with pytest.raises(pg.DegenerateGeometryError):
        pg.distributed.absolute_orientation(line, line + 1.0, scheduler="sync")


def test_transform_array_is_lazy_and_blockwise():
    x, _, _ = _data(10000)
    T = pg.Affine3D(np.array([[1.0, 0.01, 0], [0, 1.0, 0.02], [0, 0, 0.99]]), [1.0, 2.0, 3.0])
    y = pg.distributed.transform_array(T, da.from_array(x, chunks=(3000, 3)))
    assert isinstance(y, da.Array) and y.chunks[0] == (3000, 3000, 3000, 1000)
    np.testing.assert_array_equal(y.compute(scheduler="sync"), T.apply(x))


@pytest.mark.parametrize("scheduler", ["sync", "threads"])
def test_map_items_collects_failures_in_order(scheduler):
    seen = []
    res = pg.distributed.map_items(
        functools.partial(_square_or_fail, bad=(2, 5)),
        range(8),
        scheduler=scheduler,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert res.results == [0, 1, None, 9, 16, None, 36, 49]
    assert [f.index for f in res.failures] == [2, 5]
    assert res.failures[0].error == "ValueError: item 2 is bad"
    assert "Traceback" in res.failures[0].traceback
    assert seen[-1] == (8, 8) and len(seen) == 8
    with pytest.raises(PhotogeomError, match="2 of 8 item"):
        res.raise_failures()


def test_map_items_on_a_local_cluster_resections():
    """Space resection of several images as tasks on a 2-worker local cluster; equal to the
    in-process results; a bad image is reported, not fatal."""
    rng = np.random.default_rng(8)
    io = pg.InteriorOrientation(152.0, unit="mm")
    ground = rng.uniform([0, 0, 80], [1000, 1000, 160], (8, 3))
    items, truth = [], []
    for k in range(4):
        eo = pg.ExteriorOrientation(400 + 50 * k, 500, 1500, *np.radians([1.0, -2.0, 10 * k]))
        items.append((ground, pg.project(ground, io, eo), io))
        truth.append(eo)
    items.append((ground[:2], pg.project(ground[:2], io, truth[0]), io))  # too few points
    res = pg.distributed.resect_images(items, scheduler="local:2")
    assert [f.index for f in res.failures] == [4]
    assert "TooFewPointsError" in res.failures[0].error
    for eo, fit in zip(truth, res.results[:4]):
        got = fit.exterior
        np.testing.assert_allclose([got.X0, got.Y0, got.Z0], [eo.X0, eo.Y0, eo.Z0], atol=1e-6)


def test_scheduler_values():
    with pytest.raises(InputError, match="local:N"):
        pg.distributed.map_items(abs, [1], scheduler="local:0")
    with pytest.raises(InputError, match="scheduler address"):
        pg.distributed.map_items(abs, [1], scheduler="bogus")
    assert pg.distributed.map_items(abs, [], scheduler="local").results == []


def test_rpc_localisation_of_many_files():
    names = ["ikonos", "pleiades", "worldview2"]
    paths = [pg.datasets.path(n) for n in names]
    col, row, h = np.array([100.0, 2000.0]), np.array([50.0, 1500.0]), np.array([30.0, 30.0])
    res = pg.distributed.localize_files(
        [*paths, "missing_RPC.TXT"], (col, row, h), scheduler="threads"
    )
    assert [f.index for f in res.failures] == [3]
    for p, (lon, lat) in zip(paths, res.results[:3]):
        lon0, lat0 = pg.RPC.from_file(p).localize(col, row, h)
        np.testing.assert_array_equal(lon, lon0)
        np.testing.assert_array_equal(lat, lat0)
    with pytest.raises(InputError, match="point sets for"):
        pg.distributed.localize_files(paths, [(col, row, h)], scheduler="sync")


def test_cloud_as_dask_array(tmp_path):
    pytest.importorskip("laspy")
    x, X, _ = _data(7000)
    pg.io.write_cloud(tmp_path / "x.laz", x - [512000.0, 5400000.0, 0.0])
    pg.io.write_cloud(tmp_path / "X.laz", X)
    dx = pg.io.cloud_dask_xyz(tmp_path / "x.laz", chunk_size=3000)
    dX = pg.io.cloud_dask_xyz(tmp_path / "X.laz", chunk_size=2500)
    assert dx.chunks[0] == (3000, 3000, 1000)
    xs = pg.io.read_cloud_xyz(tmp_path / "x.laz")
    np.testing.assert_array_equal(dx.compute(scheduler="sync"), xs)
    fit = pg.distributed.absolute_orientation(dx, dX, scheduler="sync")
    ref = pg.absolute_orientation(xs, pg.io.read_cloud_xyz(tmp_path / "X.laz"), statistics=False)
    np.testing.assert_allclose(fit.rotation, ref.rotation, atol=1e-13)
    np.testing.assert_allclose(fit.translation, ref.translation, atol=1e-7)


@pytest.mark.parametrize("method", ["svd", "gauss-helmert"])
def test_out_of_core_statistics_equal_the_in_memory_fit(method):
    """sigma0 and the parameters' covariance from the merged moments are the in-memory
    fit's (v'Pv from the moments: 1e-8 relative here; gauss-helmert's cofactor at the
    observed instead of the corrected source points: residual / spread ~ 1e-4)."""
    x, X, rng = _data(20000, seed=5)
    w = rng.uniform(0.5, 2.0, x.shape[0])
    for weights in (None, w) if method == "svd" else (None,):
        ref = pg.absolute_orientation(x, X, method=method, weights=weights)
        fit = pg.distributed.absolute_orientation(
            da.from_array(x, chunks=(3000, 3)), X, method=method, weights=weights,
            scheduler="sync",
        )
        assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-7)
        assert fit.redundancy == ref.redundancy and fit.n_observations == ref.n_observations
        tol = 1e-9 if method == "svd" else 1e-3
        np.testing.assert_allclose(fit.cofactor, ref.cofactor, rtol=tol,
                                   atol=tol * np.abs(ref.cofactor).max())
        np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=max(tol, 3e-7),
                                   atol=max(tol, 3e-7) * np.abs(ref.covariance).max())
        assert fit.residuals.shape == (0, 3)
    splits = [0, 1, 2, 700, 701, 20000]  # empty and one-point chunks merge exactly
    chunked = absolute_orientation_chunks(
        (x[a:b], X[a:b]) for a, b in itertools.pairwise(splits)
    )
    ref = pg.absolute_orientation(x, X)
    np.testing.assert_allclose(np.sqrt(np.diag(chunked.covariance)),
                               np.sqrt(np.diag(ref.covariance)), rtol=1e-8)


def test_out_of_core_standard_deviations_against_monte_carlo():
    """The standard deviations from the moments against the spread of 300 redraws of the
    noise (sampling error of a std ratio over 300 redraws: ~4 %)."""
    rng = np.random.default_rng(11)
    x = rng.uniform(-50, 50, (60, 3)) + np.array([480000.0, 5300000.0, 200.0])
    T = pg.Similarity3D.from_angles(1.0002, 0.3, -0.5, 1.2, [10.0, -20.0, 5.0])
    X0 = T.apply(x)
    sigma = 0.05
    est, sds, s0 = [], [], []
    for _ in range(300):
        X = X0 + rng.normal(0, sigma, X0.shape)
        fit = absolute_orientation_chunks([(x[:25], X[:25]), (x[25:], X[25:])])
        est.append(fit.parameters)
        sds.append(np.sqrt(np.diag(fit.covariance)))
        s0.append(fit.sigma0)
    ratio = np.std(est, axis=0, ddof=1) / np.mean(sds, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    assert np.mean(np.square(s0)) == pytest.approx(sigma**2, rel=0.03)
