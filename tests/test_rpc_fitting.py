"""Fitting RPCs: to a physical frame camera (terrain-independent) and to control points."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, InputError, TooFewPointsError
from photogeom.rpc import RPC, fit_rpc, fit_rpc_to_points

# WGS84
A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
LON0, LAT0 = 11.0, 48.0


def ecef(lon, lat, h):
    lo, la = np.radians(lon), np.radians(lat)
    n = A / np.sqrt(1 - E2 * np.sin(la) ** 2)
    return np.stack(
        [(n + h) * np.cos(la) * np.cos(lo), (n + h) * np.cos(la) * np.sin(lo),
         (n * (1 - E2) + h) * np.sin(la)], axis=-1,
    )  # fmt: skip


def enu(ground: np.ndarray) -> np.ndarray:
    """Local east-north-up coordinates (m) of lon/lat/h points, origin (LON0, LAT0, 0)."""
    d = ecef(ground[:, 0], ground[:, 1], ground[:, 2]) - ecef(LON0, LAT0, 0.0)
    lo, la = np.radians(LON0), np.radians(LAT0)
    R = np.array([
        [-np.sin(lo), np.cos(lo), 0.0],
        [-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)],
        [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)],
    ])  # fmt: skip
    return d @ R.T


IO = pg.InteriorOrientation(
    f=10000.0, unit="px", origin_px=(3999.5, 2999.5), image_size=(8000, 6000)
)
EO = pg.ExteriorOrientation(
    120.0, -80.0, 3000.0, np.radians(2.0), np.radians(-3.0), np.radians(30.0)
)


def frame_camera(ground: np.ndarray) -> np.ndarray:
    """A tilted aerial frame camera 3000 m above the ground, as a lon/lat/h -> pixel map."""
    return pg.project(enu(ground), IO, EO, system="pixel", behind="nan")


DLON = 1400 / (111320 * np.cos(np.radians(LAT0)))
DLAT = 1400 / 111130
BOUNDS = [[LON0 - DLON, LON0 + DLON], [LAT0 - DLAT, LAT0 + DLAT], [0.0, 600.0]]


@pytest.fixture(scope="module")
def frame_fit():
    return fit_rpc(frame_camera, BOUNDS, grid=(9, 9, 5), image_size=(8000, 6000))


def test_rpc_fitted_to_a_frame_camera_reproduces_it_on_check_points(frame_fit):
    fit = frame_fit
    assert fit.check_residuals is not None and fit.check_residuals.shape[0] == 8 * 8 * 4
    assert fit.extras["check_max_px"] < 0.01
    assert np.max(np.abs(fit.residuals)) < 0.01
    # independent random check points, projected by both models
    rng = np.random.default_rng(11)
    n = 2000
    G = np.column_stack([
        rng.uniform(*BOUNDS[0], n), rng.uniform(*BOUNDS[1], n), rng.uniform(*BOUNDS[2], n)
    ])  # fmt: skip
    c, r = fit.model.project(*G.T)
    ref = frame_camera(G)
    assert np.nanmax(np.abs(np.column_stack([c, r]) - ref)) < 0.01
    assert fit.model.image_size == (8000, 6000)
    assert fit.residual_unit == "px" and fit.residual_labels == ("col", "row")
    assert len(fit.parameter_names) == 78 and fit.redundancy == 2 * 9 * 9 * 5 - 78


def test_fitted_rpc_localises_like_the_camera(frame_fit):
    rpc = frame_fit.model
    # the camera's ray through a pixel meets the height h where the RPC localises it
    lon, lat = rpc.localize([1000.0, 7000.0, 4000.0], [500.0, 5500.0, 3000.0], 250.0)
    back = frame_camera(np.column_stack([lon, lat, np.full(3, 250.0)]))
    np.testing.assert_allclose(
        back, [[1000.0, 500.0], [7000.0, 5500.0], [4000.0, 3000.0]], atol=0.01
    )


def test_fitted_rpc_survives_a_write_read_round_trip(frame_fit, tmp_path):
    p = frame_fit.model.write(tmp_path / "frame_RPC.TXT")
    assert RPC.from_file(p).same_as(frame_fit.model)


def test_regularisation_keeps_the_fit_and_shrinks_the_coefficients():
    fits = {
        lam: fit_rpc(frame_camera, BOUNDS, grid=(7, 7, 4), regularization=lam)
        for lam in (1e-7, 1e-3)
    }
    n_small = np.linalg.norm(fits[1e-7].parameters)
    n_large = np.linalg.norm(fits[1e-3].parameters)
    assert n_large <= n_small
    assert fits[1e-7].extras["check_max_px"] < 0.01
    with pytest.raises(InputError, match="regularization"):
        fit_rpc(frame_camera, BOUNDS, regularization=-1.0)


def _footprint_bounds(rpc: RPC) -> list:
    """[[lon min, max], [lat min, max], [h min, max]] of an RPC's footprint (deg, m)."""
    fp = rpc.footprint()
    return [
        [fp[:, 0].min(), fp[:, 0].max()],
        [fp[:, 1].min(), fp[:, 1].max()],
        list(rpc.height_range),
    ]


def test_refit_of_a_vendor_rpc_reproduces_it():
    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    b = _footprint_bounds(vendor)
    fit = fit_rpc(vendor, b, grid=(7, 7, 4))
    assert fit.extras["check_max_px"] < 0.01


def test_refit_of_a_bias_corrected_rpc_with_cross_terms():
    vendor = RPC.from_file(pg.datasets.path("worldview2"))
    corrected = vendor.with_correction([[1e-4, -2e-4, 5.0], [3e-4, 1e-4, -3.0]])
    b = _footprint_bounds(vendor)
    fit = fit_rpc(corrected, b, grid=(7, 7, 4))
    assert fit.model.correction is None
    assert fit.extras["check_max_px"] < 0.01


def test_terrain_dependent_fit_from_control_points():
    # control points measured in a vendor image: terrain-dependent RPCs of each order
    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    rng = np.random.default_rng(5)
    n = 60
    c0, c1, r0, r1 = vendor.image_bounds
    cols, rows = rng.uniform(c0, c1, n), rng.uniform(r0, r1, n)
    h = rng.uniform(*vendor.height_range, n)
    lon, lat = vendor.localize(cols, rows, h)
    G = np.column_stack([lon, lat, h])
    image = np.column_stack([cols, rows])
    fit = fit_rpc_to_points(
        G[:45], image[:45], order=3, check_ground=G[45:], check_image=image[45:]
    )
    assert fit.rmse < 1e-3 and fit.check_rmse < 0.05
    for order, need in ((1, 7), (2, 19)):
        f = fit_rpc_to_points(G, image, order=order)
        assert f.parameters.size == 2 * need
        # the polynomial terms of higher degree are zero
        assert np.all(f.model.samp_num[poly_terms(order) :] == 0)
    # noisy measurements: sigma0 estimates the noise level
    noisy = image + rng.normal(0, 0.5, image.shape)
    f = fit_rpc_to_points(G, noisy, order=1, sigma=0.5)
    assert 0.6 < f.sigma0 < 1.5


def poly_terms(order: int) -> int:
    return {1: 4, 2: 10, 3: 20}[order]


def test_terrain_dependent_fit_needs_enough_points_in_3d():
    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    rng = np.random.default_rng(6)
    cols, rows = rng.uniform(0, 12000, 30), rng.uniform(0, 10000, 30)
    h = rng.uniform(0, 100, 30)
    lon, lat = vendor.localize(cols, rows, h)
    G = np.column_stack([lon, lat, h])
    im = np.column_stack([cols, rows])
    with pytest.raises(TooFewPointsError, match=r"30 point\(s\) given, at least 39 needed") as e:
        fit_rpc_to_points(G, im, order=3)
    assert "order 2 needs 19" in str(e.value)
    flat = G.copy()
    flat[:, 2] = 50.0
    with pytest.raises(DegenerateGeometryError, match="same height"):
        fit_rpc_to_points(flat, im, order=1)
    with pytest.raises(InputError, match="order"):
        fit_rpc_to_points(G, im, order=4)


def test_bad_cameras_and_bounds():
    with pytest.raises(InputError, match="callable"):
        fit_rpc(42, BOUNDS)
    with pytest.raises(DegenerateGeometryError, match="height range is empty"):
        fit_rpc(frame_camera, [BOUNDS[0], BOUNDS[1], [100.0, 100.0]])
    with pytest.raises(InputError, match="shape"):
        fit_rpc(lambda g: g[:, :1], BOUNDS, grid=(4, 4, 3))
