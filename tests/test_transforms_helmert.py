"""Geodetic 7-parameter Helmert (EPSG position vector / coordinate frame) against PROJ."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.errors import InputError

pyproj = pytest.importorskip("pyproj")

# ECEF points around Europe (metres)
POINTS = np.array([
    [4_027_894.006, 307_045.600, 4_919_474.910],
    [3_874_938.0, 116_218.0, 5_047_168.0],
    [4_510_731.0, 1_207_000.0, 4_341_000.0],
    [6_378_137.0, 0.0, 0.0],
])

# a published position-vector parameter set (ED50 -> WGS84 style magnitudes):
# tx, ty, tz (m), rx, ry, rz (arc-seconds), ds (ppm)
PARAMS = (-446.448, 125.157, -542.060, -0.1502, -0.2470, -0.8421, 20.4894)


def proj_helmert(params, convention, exact, points):
    tx, ty, tz, rx, ry, rz, ds = params
    pipe = (f"+proj=helmert +x={tx!r} +y={ty!r} +z={tz!r} +rx={rx!r} +ry={ry!r} +rz={rz!r} "
            f"+s={ds!r} +convention={convention}" + (" +exact" if exact else ""))
    t = pyproj.Transformer.from_pipeline(pipe)
    return np.column_stack(t.transform(points[:, 0], points[:, 1], points[:, 2]))


@pytest.mark.parametrize("convention", ["position_vector", "coordinate_frame"])
@pytest.mark.parametrize("rotation", ["exact", "small-angle"])
def test_published_parameters_against_proj(convention, rotation):
    sim = pg.Similarity3D.from_helmert(*PARAMS, convention=convention, rotation=rotation)
    ours = sim.apply(POINTS)
    ref = proj_helmert(PARAMS, convention, rotation == "exact", POINTS)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-6)  # metres
    # the accessor gives the published values back
    hp = sim.helmert_parameters(convention, rotation)
    np.testing.assert_allclose([hp[k] for k in ("tx", "ty", "tz", "rx", "ry", "rz", "ds")],
                               PARAMS, rtol=1e-9, atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(
    r=st.lists(st.floats(-2e5, 2e5), min_size=3, max_size=3),  # up to ~55 degrees
    ds=st.floats(-1e3, 1e3),
    convention=st.sampled_from(["position_vector", "coordinate_frame"]),
)
def test_large_rotations_exact_against_proj(r, ds, convention):
    params = (120.0, -33.5, 810.25, *r, ds)
    sim = pg.Similarity3D.from_helmert(*params, convention=convention)
    np.testing.assert_allclose(sim.apply(POINTS), proj_helmert(params, convention, True, POINTS),
                               rtol=0, atol=2e-6)
    # the PROJ string of the object reproduces it too
    t = pyproj.Transformer.from_pipeline(sim.to_proj_string(convention))
    out = np.column_stack(t.transform(POINTS[:, 0], POINTS[:, 1], POINTS[:, 2]))
    np.testing.assert_allclose(out, sim.apply(POINTS), rtol=0, atol=2e-6)


def test_conventions_differ_by_the_sign_of_the_rotations():
    pv = pg.Similarity3D.from_helmert(*PARAMS, convention="9606")
    cf = pg.Similarity3D.from_helmert(*PARAMS[:3], *(-v for v in PARAMS[3:6]), PARAMS[6],
                                      convention="1032")
    # equal to first order in the (small) angles
    np.testing.assert_allclose(pv.rotation, cf.rotation, atol=1e-11)
    # EPSG codes and names are accepted, and the exact position-vector R is the
    # "transposed" convention of the library (R = M(rx, ry, rz).T)
    r = np.radians(np.array(PARAMS[3:6]) / 3600)
    np.testing.assert_allclose(pv.rotation, pg.rotation_from_angles(*r, convention="transposed"),
                               atol=1e-15)
    cf2 = pg.Similarity3D.from_helmert(*PARAMS, convention="coordinate_frame")
    np.testing.assert_allclose(cf2.rotation, pg.rotation_from_angles(*r, convention="direct"),
                               atol=1e-15)
    assert pv.scale == pytest.approx(1 + 20.4894e-6, rel=1e-15)


def test_geodetic_inverse_against_proj():
    sim = pg.Similarity3D.from_helmert(*PARAMS, convention="position_vector")
    fwd = sim.apply(POINTS)
    pipe = (f"+proj=helmert +x={PARAMS[0]} +y={PARAMS[1]} +z={PARAMS[2]} +rx={PARAMS[3]} "
            f"+ry={PARAMS[4]} +rz={PARAMS[5]} +s={PARAMS[6]} +convention=position_vector +exact")
    t = pyproj.Transformer.from_pipeline(pipe)
    inv = np.column_stack(t.transform(fwd[:, 0], fwd[:, 1], fwd[:, 2],
                                      direction=pyproj.enums.TransformDirection.INVERSE))
    np.testing.assert_allclose(sim.inverse().apply(fwd), inv, rtol=0, atol=1e-6)
    np.testing.assert_allclose(inv, POINTS, rtol=0, atol=1e-6)


def test_bad_convention():
    with pytest.raises(InputError, match="position_vector"):
        pg.Similarity3D.from_helmert(*PARAMS, convention="bursa")
    with pytest.raises(InputError, match="small-angle"):
        pg.Similarity3D.from_helmert(*PARAMS, convention="pv", rotation="approx")
    lin = pg.Similarity3D.from_helmert(0, 0, 0, 3600.0, 0, 0, 0, convention="pv",
                                       rotation="small-angle")
    with pytest.raises(InputError, match="small-angle"):
        lin.helmert_parameters("pv", "exact")
