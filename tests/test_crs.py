"""Geodetic, geocentric and topocentric conversions: published example, PROJ, properties."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.errors import InputError

pyproj = pytest.importorskip("pyproj")


def test_epsg_guidance_note_geocentric_example():
    # IOGP Guidance Note 7-2, geographic/geocentric conversion (EPSG 9602), WGS 84:
    # 53 deg 48' 33.820" N, 2 deg 07' 46.380" E, h = 73.0 m
    lat = 53 + 48 / 60 + 33.820 / 3600
    lon = 2 + 7 / 60 + 46.380 / 3600
    X, Y, Z = pg.crs.geodetic_to_ecef(lat, lon, 73.0)
    assert (round(X, 3), round(Y, 3), round(Z, 3)) == (3771793.968, 140253.342, 5124304.349)
    la, lo, h = pg.crs.ecef_to_geodetic(3771793.968, 140253.342, 5124304.349)
    assert abs(la - lat) < 1e-8 and abs(lo - lon) < 1e-8 and abs(h - 73.0) < 1e-3


def test_axes_and_poles():
    a, b = 6378137.0, pg.crs.get_ellipsoid("WGS84").b
    np.testing.assert_allclose(pg.crs.geodetic_to_ecef(0, 0, 0), (a, 0, 0), atol=1e-9)
    np.testing.assert_allclose(pg.crs.geodetic_to_ecef(0, 90, 10), (0, a + 10, 0), atol=1e-9)
    np.testing.assert_allclose(pg.crs.geodetic_to_ecef(90, 0, 0), (0, 0, b), atol=1e-9)
    lat, _, h = pg.crs.ecef_to_geodetic(0.0, 0.0, -b - 5.0)
    assert lat == -90.0 and abs(h - 5.0) < 1e-9


def _random_geodetic(rng, n, hmin=-1e3, hmax=1e4):
    return rng.uniform(-90, 90, n), rng.uniform(-180, 180, n), rng.uniform(hmin, hmax, n)


@pytest.mark.parametrize("ellps", ["WGS84", "GRS80", "bessel", "intl"])
def test_equal_to_proj(ellps):
    rng = np.random.default_rng(3)
    lat, lon, h = _random_geodetic(rng, 20000, -1e4, 1e5)
    proj_ell = {"WGS84": "WGS84", "GRS80": "GRS80", "bessel": "bessel", "intl": "intl"}[ellps]
    t = pyproj.Transformer.from_pipeline(f"+proj=cart +ellps={proj_ell}")
    Xp, Yp, Zp = t.transform(lon, lat, h)
    X, Y, Z = pg.crs.geodetic_to_ecef(lat, lon, h, ellipsoid=ellps)
    np.testing.assert_allclose(np.c_[X, Y, Z], np.c_[Xp, Yp, Zp], rtol=0, atol=2e-9)
    # inverse: PROJ's cart inverse is itself exact to ~1e-11 deg / 1e-6 m within 10 km
    near = np.abs(h) < 1e4
    lo2, la2, h2 = t.transform(X[near], Y[near], Z[near], direction="INVERSE")
    la, lo, hh = pg.crs.ecef_to_geodetic(X[near], Y[near], Z[near], ellipsoid=ellps)
    np.testing.assert_allclose(la, la2, atol=1e-10)
    np.testing.assert_allclose(lo, lo2, atol=1e-10)
    np.testing.assert_allclose(hh, h2, atol=2e-6)


def test_round_trips_at_rounding_level():
    rng = np.random.default_rng(7)
    lat, lon, h = _random_geodetic(rng, 200000)
    X, Y, Z = pg.crs.geodetic_to_ecef(lat, lon, h)
    la, lo, hh = pg.crs.ecef_to_geodetic(X, Y, Z)
    assert np.max(np.abs(la - lat)) < 1e-12
    assert np.max(np.abs(lo - lon)) < 1e-12
    # the spacing of doubles at 6.4e6 m is 9.3e-10 m: the round trip is at that level
    dh = hh - h
    assert np.sqrt(np.mean(dh**2)) < 1e-9 and np.max(np.abs(dh)) < 4e-9
    X2, Y2, Z2 = pg.crs.geodetic_to_ecef(la, lo, hh)
    d = np.sqrt((X2 - X) ** 2 + (Y2 - Y) ** 2 + (Z2 - Z) ** 2)
    assert np.sqrt(np.mean(d**2)) < 1e-9 and np.max(d) < 4e-9


def test_far_points_and_satellites():
    rng = np.random.default_rng(11)
    lat, lon, h = _random_geodetic(rng, 20000, 1e5, 4.2e7)
    la, _, hh = pg.crs.ecef_to_geodetic(*pg.crs.geodetic_to_ecef(lat, lon, h))
    assert np.max(np.abs(la - lat)) < 1e-12
    np.testing.assert_allclose(hh, h, rtol=1e-15, atol=3e-8)


@settings(max_examples=60, deadline=None)
@given(
    lat0=st.floats(-89.9, 89.9),
    lon0=st.floats(-180, 180),
    h0=st.floats(-400, 9000),
    e=st.floats(-5e4, 5e4),
    n=st.floats(-5e4, 5e4),
    u=st.floats(-1e3, 1e4),
)
def test_enu_round_trip_and_proj(lat0, lon0, h0, e, n, u):
    enu = np.array([e, n, u])
    xyz = pg.crs.enu_to_ecef(enu, lat0, lon0, h0)
    np.testing.assert_allclose(pg.crs.ecef_to_enu(xyz, lat0, lon0, h0), enu, rtol=0, atol=3e-9)
    t = pyproj.Transformer.from_pipeline(
        f"+proj=topocentric +ellps=WGS84 +lat_0={lat0!r} +lon_0={lon0!r} +h_0={h0!r}"
    )
    np.testing.assert_allclose(t.transform(*xyz), enu, rtol=0, atol=1e-8)


def test_enu_is_a_rigid_motion_and_up_is_the_normal():
    R = pg.crs.enu_rotation(47.3, 8.5)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert abs(np.linalg.det(R) - 1) < 1e-15
    # a point straight above the origin is pure up
    X = np.array(pg.crs.geodetic_to_ecef(47.3, 8.5, 1234.5))
    np.testing.assert_allclose(pg.crs.ecef_to_enu(X, 47.3, 8.5, 1000.0), [0, 0, 234.5], atol=1e-8)


def test_curvature_drop_matches_enu_of_ellipsoid_points():
    # walk 1 km / 10 km north on the ellipsoid: U is minus the drop, to the d^4 term
    for d, expected in ((1000.0, 0.0785), (10000.0, 7.85)):
        lat0 = 45.0
        M = 6335439.327 / (1 - 0.00669437999014 * 0.5) ** 1.5  # meridian radius at 45 deg
        lat = lat0 + np.degrees(d / M)
        enu = pg.crs.LocalFrame(lat0, 0.0, 0.0).from_geodetic(lat, 0.0, 0.0)[0]
        drop = pg.crs.curvature_drop(np.hypot(enu[0], enu[1]), lat0=lat0)
        # mean radius sqrt(M N) against the meridian radius M: 0.17 % apart at 45 deg
        assert abs(drop + enu[2]) < 4e-3 * drop
        assert abs(drop - expected) < 0.01 * expected


def test_local_frame_for_gnss_positions():
    rng = np.random.default_rng(5)
    lat = 46.5 + rng.uniform(-0.01, 0.01, 50)
    lon = 7.4 + rng.uniform(-0.01, 0.01, 50)
    h = 600 + rng.uniform(100, 140, 50)
    frame = pg.crs.LocalFrame.at_centroid(lat, lon, h)
    enu = frame.from_geodetic(lat, lon, h)
    assert np.all(np.abs(enu.mean(axis=0)[:2]) < 1e-6)
    la, lo, hh = frame.to_geodetic(enu)
    np.testing.assert_allclose(la, lat, atol=1e-12)
    np.testing.assert_allclose(lo, lon, atol=1e-12)
    np.testing.assert_allclose(hh, h, atol=1e-8)
    cov = np.diag([1.0, 2.0, 3.0])
    c2 = frame.covariance_from_ecef(cov)
    assert abs(np.trace(c2) - 6.0) < 1e-12
    assert frame.to_dict()["ellipsoid"] == "WGS84"


def test_any_crs_through_proj_and_helmert_pipeline():
    lon, lat = np.array([9.1, 9.2]), np.array([48.7, 48.8])
    utm = pg.crs.transform_points(np.c_[lon, lat, [300.0, 310.0]], "EPSG:4979", "EPSG:32632")
    ref = pyproj.Transformer.from_crs(4326, 32632, always_xy=True).transform(lon, lat)
    np.testing.assert_allclose(utm[:, :2], np.c_[ref], atol=1e-9)
    # an estimated Helmert as a PROJ pipeline step gives the same points (both conventions)
    rng = np.random.default_rng(2)
    x = rng.normal(size=(30, 3)) * 1000 + [4.1e6, 6e5, 4.8e6]
    T = pg.Similarity3D.from_helmert(
        -87.0, -98.0, -121.0, 0.5, -0.3, 0.8, 2.5, convention="coordinate_frame"
    )
    fit = pg.absolute_orientation(x, T.apply(x), method="svd")
    for conv in ("position_vector", "coordinate_frame"):
        p = pyproj.Transformer.from_pipeline(fit.transform.to_proj_string(conv))
        np.testing.assert_allclose(np.c_[p.transform(*x.T)], T.apply(x), atol=1e-6)
    op = pg.crs.ProjTransform("EPSG:4979", "EPSG:4978")
    X = op.apply(np.c_[lon, lat, [300.0, 310.0]])
    np.testing.assert_allclose(X[:, 0], pg.crs.geodetic_to_ecef(lat, lon, [300, 310])[0], atol=1e-8)


def test_bad_input_names_the_problem():
    with pytest.raises(InputError, match="lat must be within"):
        pg.crs.geodetic_to_ecef(91.0, 0.0, 0.0)
    with pytest.raises(InputError, match="NaN"):
        pg.crs.geodetic_to_ecef(np.nan, 0.0, 0.0)
    with pytest.raises(InputError, match="centre"):
        pg.crs.ecef_to_geodetic(1.0, 2.0, 3.0)
    with pytest.raises(InputError, match="unknown ellipsoid"):
        pg.crs.get_ellipsoid("potato")
    with pytest.raises(InputError, match="shape"):
        pg.crs.ecef_to_enu(np.zeros((4, 2)), 0, 0, 0)
    with pytest.raises(InputError, match="not a coordinate reference system"):
        pg.crs.parse_crs("EPSG:999999")
    assert pg.crs.get_ellipsoid((6378137.0, 298.257223563)).a == 6378137.0


def test_optional_libraries_are_imported_only_when_used():
    import subprocess
    import sys

    code = (
        "import sys, photogeom, photogeom.cli.main\n"
        "print(sorted(m for m in ('laspy', 'lazrs', 'dask', 'distributed', 'pyproj') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("convention", ["position_vector", "coordinate_frame"])
def test_helmert_estimate_recovers_a_proj_datum_step(convention):
    """Points moved by PROJ's +proj=helmert (published-size parameters): the absolute
    orientation gives PROJ's parameters back in the same EPSG convention."""
    p = {"x": 584.8, "y": 67.0, "z": 400.3, "rx": 0.105, "ry": 0.013, "rz": -2.378, "s": 10.29}
    step = " ".join(f"+{k}={v}" for k, v in p.items())
    op = pyproj.Transformer.from_pipeline(f"+proj=helmert {step} +convention={convention} +exact")
    lat, lon = np.meshgrid(np.linspace(45, 55, 6), np.linspace(5, 15, 6))
    src = np.column_stack(pg.crs.geodetic_to_ecef(lat.ravel(), lon.ravel(), 300.0))
    dst = np.column_stack(op.transform(*src.T))
    fit = pg.absolute_orientation(src, dst, method="svd")
    got = fit.transform.helmert_parameters(convention)
    for ours, theirs in (("tx", "x"), ("ty", "y"), ("tz", "z")):
        assert abs(got[ours] - p[theirs]) < 2e-5
    for key in ("rx", "ry", "rz"):
        assert abs(got[key] - p[key]) < 1e-6
    assert abs(got["ds"] - p["s"]) < 1e-6
    assert fit.rmse < 1e-8
