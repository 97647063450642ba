"""RPC localisation: round trips over the image, status per point, failures never silent."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import ConvergenceError, InputError
from photogeom.rpc import RPC, LocalizationStatus, LocalizationWarning, approximate_inverse

NAMES = ("quickbird", "ikonos", "skysat", "pleiades", "worldview2")


@pytest.fixture(scope="module", params=NAMES)
def rpc(request) -> RPC:
    return RPC.from_file(pg.datasets.path(request.param))


def image_grid(rpc: RPC, n: int = 25) -> tuple[np.ndarray, np.ndarray]:
    c0, c1, r0, r1 = rpc.image_bounds
    C, R = np.meshgrid(np.linspace(c0, c1, n), np.linspace(r0, r1, n))
    return C.ravel(), R.ravel()


def three_heights(rpc: RPC) -> list[float]:
    lo, hi = rpc.height_range
    return [lo, rpc.height_off, hi]


def test_localize_then_project_reproduces_the_image_points(rpc):
    C, R = image_grid(rpc)
    for h in three_heights(rpc):
        res = rpc.localize(C, R, h, full_output=True)
        assert res.all_converged, res.counts()
        assert np.all(res.residual <= 1e-6)
        c, r = rpc.project(res.lon, res.lat, h)
        assert np.max(np.abs(c - C)) < 1e-6 and np.max(np.abs(r - R)) < 1e-6


def test_project_then_localize_returns_the_input_to_1e9_degrees(rpc):
    # ground points over the whole image at three heights
    C, R = image_grid(rpc, 21)
    for h in three_heights(rpc):
        lon0, lat0 = rpc.localize(C, R, h)
        # perturb off the grid, then project and localise again
        rng = np.random.default_rng(7)
        gsd = np.ptp(lon0) / np.sqrt(C.size) * 1e-2
        lon = lon0 + rng.uniform(-gsd, gsd, lon0.shape)
        lat = lat0 + rng.uniform(-gsd, gsd, lat0.shape)
        c, r = rpc.project(lon, lat, h)
        lo, la = rpc.localize(c, r, h)
        assert np.max(np.abs(lo - lon)) < 1e-9
        assert np.max(np.abs(la - lat)) < 1e-9


def test_the_approximate_inverse_is_close_and_cached(rpc):
    inv = approximate_inverse(rpc)
    assert inv is approximate_inverse(rpc)
    assert inv.n_points >= 400
    # a start within a few pixels: Newton then converges in one or two iterations
    assert inv.max_error_px < 5.0
    C, R = image_grid(rpc, 15)
    res = rpc.localize(C, R, rpc.height_off, full_output=True)
    assert res.iterations.max() <= 3


def test_skysat_corners_at_low_heights_converge():
    # the SkySat model is strongly non-linear over its normalised domain (LAT/LONG_SCALE = 1
    # degree for a 2.5 km image); corners at low heights defeat simple iteration schemes
    rpc = RPC.from_file(pg.datasets.path("skysat"))
    c0, c1, r0, r1 = rpc.image_bounds
    C = np.array([c0, c1, c0, c1, c0, c1])
    R = np.array([r0, r0, r1, r1, r0, r1])
    for h in (-6000.0, -1000.0, -100.0, 0.0, 200.0):
        res = rpc.localize(C, R, h, full_output=True)
        assert res.all_converged
        c, r = rpc.project(res.lon, res.lat, h)
        assert np.max(np.abs(c - C)) < 1e-6 and np.max(np.abs(r - R)) < 1e-6
        lo, la = rpc.localize(*rpc.project(res.lon, res.lat, h), h)
        assert np.max(np.abs(lo - res.lon)) < 1e-9 and np.max(np.abs(la - res.lat)) < 1e-9


def test_skysat_naive_identity_iteration_fails_where_ours_converges():
    # the "simple scheme": step by the normalised image residual as if the normalised image
    # and ground axes coincided (what a unit Jacobian in normalised units assumes)
    rpc = RPC.from_file(pg.datasets.path("skysat"))
    c0, c1, r0, r1 = rpc.image_bounds
    C, R, h = np.array([c0, c1]), np.array([r0, r1]), -100.0
    sn, ln = rpc.normalize_image(C, R)
    L = np.zeros(2)
    P = np.zeros(2)
    with np.errstate(all="ignore"):
        for _ in range(100):
            lon = L * rpc.long_scale + rpc.long_off
            lat = P * rpc.lat_scale + rpc.lat_off
            c, r = rpc.project(lon, lat, h, domain_limit=None)
            s_, l_ = rpc.normalize_image(c, r)
            L, P = L - (s_ - sn), P - (l_ - ln)
    naive_ok = np.isfinite(c) & (np.abs(c - C) < 1e-3) & (np.abs(r - R) < 1e-3)
    assert not naive_ok.any()
    res = rpc.localize(C, R, h, full_output=True)
    assert res.all_converged


def test_status_per_point_and_nan_for_failures():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    cols = np.array([rpc.samp_off, 1e6, rpc.samp_off + 0.5 * rpc.samp_scale])
    rows = np.array([rpc.line_off, 0.0, rpc.line_off])
    with pytest.warns(LocalizationWarning, match="1 of 3 point"):
        lon, lat = rpc.localize(cols, rows, 28.0, domain_limit=None)
    assert np.isfinite(lon[[0, 2]]).all() and np.isnan(lon[1]) and np.isnan(lat[1])
    res = rpc.localize(cols, rows, 28.0, domain_limit=None, full_output=True)
    assert list(res.status) == [
        LocalizationStatus.CONVERGED,
        LocalizationStatus.DIVERGED,
        LocalizationStatus.CONVERGED,
    ]
    assert res.counts() == {"converged": 2, "limit_reached": 0, "diverged": 1}
    with pytest.raises(ConvergenceError, match="did not converge") as e:
        rpc.localize(cols, rows, 28.0, domain_limit=None, on_failure="raise")
    assert e.value.result.status[1] == LocalizationStatus.DIVERGED


def test_tolerance_and_iteration_limit_are_honoured():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    c, r = rpc.samp_off + 0.7 * rpc.samp_scale, rpc.line_off
    res = rpc.localize(c, r, 28.0, tol=1e-3, full_output=True)
    assert res.status == LocalizationStatus.CONVERGED and res.residual <= 1e-3
    # a tolerance below the rounding level of the projection cannot be reached
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LocalizationWarning)
        res = rpc.localize(c, r, 28.0, tol=1e-15, max_iter=5, full_output=True)
    assert res.status == LocalizationStatus.LIMIT_REACHED
    assert np.isnan(res.lon) and np.isnan(res.lat)
    with pytest.raises(InputError, match="tol"):
        rpc.localize(c, r, 28.0, tol=0.0)
    with pytest.raises(InputError, match="max_iter"):
        rpc.localize(c, r, 28.0, max_iter=0)
    with pytest.raises(InputError, match="on_failure"):
        rpc.localize(c, r, 28.0, on_failure="ignore")


def test_localize_at_per_point_heights_vectorised():
    rpc = RPC.from_file(pg.datasets.path("pleiades"))
    rng = np.random.default_rng(3)
    n = 5000
    c0, c1, r0, r1 = rpc.image_bounds
    C, R = rng.uniform(c0, c1, n), rng.uniform(r0, r1, n)
    H = rng.uniform(*rpc.height_range, n)
    lon, lat = rpc.localize(C, R, H)
    c, r = rpc.project(lon, lat, H)
    assert np.max(np.abs(c - C)) < 1e-6 and np.max(np.abs(r - R)) < 1e-6
