"""Transformation models: lecture examples 1-3 and 8-10, parameter forms, inverses, JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom import transforms as tr
from photogeom.errors import ConvergenceError, DegenerateGeometryError, InputError


def agree(value: float, printed: str) -> bool:
    """``value`` rounds to the printed number (half a unit of its last digit)."""
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    return abs(value - float(printed)) <= 0.5 * 10.0**-decimals + 1e-12


def assert_printed(values, printed):
    values = np.asarray(values, dtype=float).reshape(-1)
    printed = [str(p) for p in np.asarray(printed, dtype=object).reshape(-1)]
    bad = [(v, p) for v, p in zip(values, printed) if not agree(v, p)]
    assert not bad, f"values differ from the printed digits: {bad}"


LECTURE_POINTS = np.array([(113.02, 0.002), (-112.99, 112.99), (113.01, -113.01)])


# --- lecture examples ------------------------------------------------------------------------


def test_example_1_similarity_parameters():
    sim = pg.Similarity2D.from_textbook(1.0, 5.0, 125.0, 130.0, unit="deg")
    assert_printed([sim.a, sim.b, sim.c, sim.d], ["0.9962", "-0.0872", "125", "130"])
    tb = sim.textbook()
    assert tb["scale"] == pytest.approx(1.0, abs=1e-15)
    assert np.degrees(tb["theta"]) == pytest.approx(5.0, abs=1e-12)


def test_example_2_affine_parameters():
    aff = pg.Affine2D.from_textbook(0.95, 1.03, 5.0, 0.5, 125.0, 130.0, unit="deg")
    assert_printed([aff.a1, aff.a2, aff.b1, aff.b2, aff.a3, aff.b3],
                   ["0.9472", "-0.0738", "0.0898", "1.0260", "125", "130"])
    # the textbook form equals [[1, sin e], [0, cos e]] diag(sx, sy) R(theta), written out
    e, t = np.radians(0.5), np.radians(5.0)
    A = np.array([[1, np.sin(e)], [0, np.cos(e)]]) @ np.diag([0.95, 1.03]) @ np.array(
        [[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    np.testing.assert_allclose(aff.linear, A, atol=1e-15)
    tb = aff.textbook()
    np.testing.assert_allclose([tb["sx"], tb["sy"], np.degrees(tb["theta"]), np.degrees(tb["e"])],
                               [0.95, 1.03, 5.0, 0.5], rtol=1e-12)


def test_example_3_apply_similarity_affine_projective():
    sim = pg.Similarity2D(1.0, -0.2, 130.1, 130.0)
    assert_printed(sim.apply(LECTURE_POINTS),
                   [["243.1196", "152.6060"], ["-5.488", "220.3920"], ["265.712", "39.5920"]])
    aff = pg.Affine2D(0.94, -0.01, 126.0, 0.05, 1.054, 128.1)
    assert_printed(aff.apply(LECTURE_POINTS),
                   [["232.2388", "133.7531"], ["18.6595", "241.5420"], ["233.3595", "14.6380"]])
    proj = pg.Projective2D.from_parameters([0.94, -0.01, 126.0, 0.05, 1.054, 128.1, 0.003, -0.045])
    assert_printed(proj.apply(LECTURE_POINTS),
                   [["173.4458", "99.8925"], ["-4.2182", "-54.6040"], ["36.3235", "2.2785"]])
    # one point at a time gives the same as the batch
    np.testing.assert_allclose(proj.apply(LECTURE_POINTS[1]), proj.apply(LECTURE_POINTS)[1])


def test_example_8_similarity3d():
    M = pg.opk_matrix(*np.radians([10.0, 15.0, 50.0]))
    # m32 = -0.16773126 is printed truncated (-0.1677312), every other element rounded
    assert np.trunc(M[2, 1] * 1e7) / 1e7 == pytest.approx(-0.1677312, abs=1e-12)
    M_rounded = M.copy()
    M_rounded[2, 1] = -0.1677312
    assert_printed(M_rounded, [["0.620885", "0.7832956", "-0.030816"],
                               ["-0.739942", "0.5985935", "0.306874"],
                               ["0.258819", "-0.1677312", "0.951251"]])
    sim = pg.Similarity3D.from_angles(1.0, 10.0, 15.0, 50.0, [-200, 136, 189], unit="deg")
    np.testing.assert_allclose(sim.rotation, M.T, atol=1e-15)
    assert_printed(sim.apply([1354, 547, 135]), ["270.8707", "1501.3692", "443.5540"])
    rig = pg.Rigid3D.from_angles(10.0, 15.0, 50.0, [-200, 136, 189], unit="deg")
    np.testing.assert_allclose(rig.apply([1354, 547, 135]), sim.apply([1354, 547, 135]))


ROWS_3D = [[0.6, -0.7, 0.3, -200], [0.8, 0.6, 0.2, 136], [-0.1, 0.3, 0.9, 189]]


def test_example_9_affine3d():
    aff = pg.Affine3D.from_matrix(ROWS_3D)
    assert_printed(aff.apply([1354, 547, 135]), ["270", "1574.4", "339.2"])


def test_example_10_projective3d():
    H = np.vstack([ROWS_3D, [0.01, 0.02, 0.0, 1.0]])
    proj = pg.Projective3D(H)
    assert_printed(proj.apply_homogeneous([1354, 547, 135]), ["270", "1574.4", "339.2", "25.48"])
    assert_printed(proj.apply([1354, 547, 135]), ["10.5965", "61.7896", "13.3124"])
    assert proj.parameter_names[-3:] == ("h41", "h42", "h43") and len(proj.parameters) == 15


# --- parameter forms --------------------------------------------------------------------------


def test_similarity2d_forms_written_out():
    s, t = 2.5, np.radians(-130.0)
    sim = pg.Similarity2D.from_textbook(s, t, 3.0, -4.0)
    # x = a x' + b y' + c, y = -b x' + a y' + d with a = s cos, b = -s sin
    assert sim.a == pytest.approx(s * np.cos(t)) and sim.b == pytest.approx(-s * np.sin(t))
    p = np.array([[1.5, -2.0]])
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    np.testing.assert_allclose(sim.apply(p), s * p @ R.T + [3.0, -4.0], atol=1e-14)
    assert sim.textbook()["theta"] == pytest.approx(t)


def test_affine2d_reflection_and_det():
    aff = pg.Affine2D(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # mirror x
    assert aff.det == pytest.approx(-1.0)
    tb = aff.textbook()
    assert tb["sx"] < 0 and tb["sy"] > 0
    again = pg.Affine2D.from_textbook(tb["sx"], tb["sy"], tb["theta"], tb["e"], 0, 0)
    np.testing.assert_allclose(again.parameters, aff.parameters, atol=1e-15)


def test_affine3d_decomposition_and_similarity_deviation():
    aff = pg.Affine3D.from_matrix(ROWS_3D)
    dec = aff.decompose()
    np.testing.assert_allclose(dec.compose(), aff.linear, atol=1e-14)
    assert pg.rotation.is_rotation(dec.rotation)
    assert dec.det == pytest.approx(np.linalg.det(np.array(ROWS_3D)[:, :3]))
    assert np.prod(dec.scales) == pytest.approx(dec.det)
    # textbook round trip
    tb = aff.textbook()
    back = pg.Affine3D.from_textbook(
        [tb["sx"], tb["sy"], tb["sz"]], [tb["shear_xy"], tb["shear_xz"], tb["shear_yz"]],
        tb["omega"], tb["phi"], tb["kappa"], [tb["tx"], tb["ty"], tb["tz"]])
    np.testing.assert_allclose(back.parameters, aff.parameters, atol=1e-13)
    dev = aff.similarity_deviation()
    assert dev["anisotropy"] > 0.1 and dev["relative_deviation"] > 0.05
    # a similarity has no deviation and its decomposition is s, s, s without shear
    sim = pg.Similarity3D.from_angles(1.7, 0.3, -1.2, 2.9, [1, 2, 3])
    aff_s = pg.Affine3D(sim.scale * sim.rotation, sim.translation)
    dev = aff_s.similarity_deviation()
    assert dev["anisotropy"] == pytest.approx(0.0, abs=1e-12)
    assert dev["relative_deviation"] == pytest.approx(0.0, abs=1e-14)
    assert dev["nearest_similarity"].scale == pytest.approx(1.7)
    d = aff_s.decompose()
    np.testing.assert_allclose(d.scales, [1.7, 1.7, 1.7], rtol=1e-12)
    np.testing.assert_allclose(d.shears, 0.0, atol=1e-12)
    np.testing.assert_allclose(d.rotation, sim.rotation, atol=1e-12)
    # a reflection puts its sign into sz
    refl = pg.Affine3D(np.diag([1.0, 2.0, -3.0]), [0, 0, 0]).decompose()
    np.testing.assert_allclose(refl.scales, [1, 2, -3], atol=1e-14)


def test_polynomial_structure_and_reduction():
    assert tr.polynomial_term_count(3, 2) == 10 and tr.polynomial_term_count(2, 3) == 10
    np.testing.assert_array_equal(tr.polynomial_exponents(2, 2),
                                  [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]])
    rng = np.random.default_rng(5)
    poly = pg.Polynomial2D(3, rng.normal(size=(2, 10)), centre=[5e5, 4e6], scale=250.0)
    assert poly.parameter_names[:3] == ("a00", "a10", "a01")
    assert poly.parameter_names[10:13] == ("b00", "b10", "b01")
    pts = rng.normal(size=(6, 2)) * 300 + [5e5, 4e6]
    u = (pts - [5e5, 4e6]) / 250.0
    # x = sum a_ij u^i v^j written out
    expect_x = sum(c * u[:, 0] ** i * u[:, 1] ** j
                   for c, (i, j) in zip(poly.coefficients[0], tr.polynomial_exponents(3, 2)))
    np.testing.assert_allclose(poly.apply(pts)[:, 0], expect_x, rtol=1e-12)
    # another reduction of the same mapping (moderate: exact algebra, few digits lost)
    other = poly.with_reduction([5e5 + 10, 4e6 - 20], 100.0)
    np.testing.assert_allclose(other.apply(pts), poly.apply(pts), rtol=1e-10, atol=1e-9)
    small = pg.Polynomial2D(2, rng.normal(size=(2, 6)), centre=[1.0, 2.0], scale=3.0)
    plain = small.to_plain()
    assert plain.scale == 1.0 and np.all(plain.centre == 0)
    np.testing.assert_allclose(plain.apply(pts[:, :] * 1e-5), small.apply(pts * 1e-5), rtol=1e-11)
    tb = small.textbook()
    assert list(tb) == list(small.parameter_names)
    # Jacobian of the mapping against central differences
    x0 = np.array([[0.3, -0.7]])
    J = small.jacobian(x0)[0]
    h = 1e-6
    num = np.column_stack([(small.apply(x0 + h * e) - small.apply(x0 - h * e))[0] / (2 * h)
                           for e in np.eye(2)])
    np.testing.assert_allclose(J, num, rtol=1e-7, atol=1e-8)


def test_polynomial_inverse_status_and_error():
    poly = pg.Polynomial2D(2, [[0, 1, 0, 0.4, 0, 0], [0, 0, 1, 0, 0, 0]])  # x' + 0.4 x'^2
    inv = poly.inverse(tol=1e-12)
    # x = u + 0.4 u^2 has no real preimage for x < -1/1.6
    res = inv.apply_with_status([[0.5, 0.2], [-5.0, 0.0]])
    assert res.converged.tolist() == [True, False]
    np.testing.assert_allclose(poly.apply(res.points[0]), [0.5, 0.2], atol=1e-12)
    with pytest.raises(ConvergenceError, match="did not converge") as err:
        inv.apply([[0.5, 0.2], [-5.0, 0.0]])
    assert err.value.result.converged.tolist() == [True, False]
    assert inv.inverse() is poly


# --- properties -------------------------------------------------------------------------------

angles = st.floats(-np.pi, np.pi)
scales = st.floats(0.01, 100.0)
shifts = st.floats(-1e5, 1e5)


def _points(dim, seed, n=30, spread=100.0):
    return np.random.default_rng(seed).uniform(-spread, spread, (n, dim))


def _roundtrip(model, pts, rtol=1e-9):
    back = model.inverse().apply(model.apply(pts))
    scale = max(np.max(np.abs(pts)), 1.0)
    np.testing.assert_allclose(back, pts, rtol=0, atol=rtol * scale)


@settings(max_examples=40, deadline=None)
@given(s=scales, t=angles, x0=shifts, y0=shifts, seed=st.integers(0, 2**31))
def test_similarity2d_inverse(s, t, x0, y0, seed):
    m = pg.Similarity2D.from_textbook(s, t, x0, y0)
    _roundtrip(m, _points(2, seed), 1e-9 * max(1, abs(x0) + abs(y0)) / s)
    tb = m.textbook()
    assert tb["scale"] == pytest.approx(s, rel=1e-12)
    assert np.angle(np.exp(1j * (tb["theta"] - t))) == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(sx=st.floats(0.1, 10), sy=st.floats(0.1, 10), t=angles, e=st.floats(-1.4, 1.4),
       x0=shifts, y0=shifts, seed=st.integers(0, 2**31))
def test_affine2d_inverse_and_textbook(sx, sy, t, e, x0, y0, seed):
    m = pg.Affine2D.from_textbook(sx, sy, t, e, x0, y0)
    _roundtrip(m, _points(2, seed), 1e-8 * max(1, abs(x0) + abs(y0)) / min(sx, sy * np.cos(e)))
    tb = m.textbook()
    np.testing.assert_allclose([tb["sx"], tb["sy"], tb["e"]], [sx, sy, e], rtol=1e-8, atol=1e-10)
    assert np.angle(np.exp(1j * (tb["theta"] - t))) == pytest.approx(0.0, abs=1e-9)


def _random_projective(dim, seed, persp=0.002):
    rng = np.random.default_rng(seed)
    H = np.eye(dim + 1)
    H[:dim, :dim] = pg.rotation.matrix_from_axis_angle(rng.normal(size=3), rng.uniform(-3, 3))[
        :dim, :dim] * rng.uniform(0.5, 2) if dim == 3 else np.array(
        [[np.cos(a := rng.uniform(-np.pi, np.pi)), -np.sin(a)], [np.sin(a), np.cos(a)]]
    ) * rng.uniform(0.5, 2)
    H[:dim, :dim] += rng.normal(scale=0.1, size=(dim, dim))
    H[:dim, dim] = rng.uniform(-100, 100, dim)
    H[dim, :dim] = rng.uniform(-persp, persp, dim)
    return H


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), dim=st.sampled_from([2, 3]))
def test_projective_inverse(seed, dim):
    cls = pg.Projective2D if dim == 2 else pg.Projective3D
    m = cls(_random_projective(dim, seed))
    _roundtrip(m, _points(dim, seed), 1e-8)
    assert cls.from_parameters(m.parameters).matrix.tolist() == m.matrix.tolist()


@settings(max_examples=30, deadline=None)
@given(w=angles, p=st.floats(-1.55, 1.55), k=angles, s=scales, seed=st.integers(0, 2**31))
def test_3d_rigid_similarity_affine_inverse(w, p, k, s, seed):
    t = np.random.default_rng(seed).uniform(-1e4, 1e4, 3)
    pts = _points(3, seed)
    rig = pg.Rigid3D.from_angles(w, p, k, t)
    _roundtrip(rig, pts, 1e-10 * 1e4)
    sim = pg.Similarity3D.from_angles(s, w, p, k, t)
    _roundtrip(sim, pts, 1e-10 * 1e4 / s)
    rng = np.random.default_rng(seed + 1)
    aff = pg.Affine3D.from_textbook(rng.uniform(0.2, 5, 3), rng.uniform(-0.5, 0.5, 3), w, p, k, t)
    _roundtrip(aff, pts, 1e-9 * 1e4)
    tb = aff.textbook()
    back = pg.Affine3D.from_textbook(
        [tb["sx"], tb["sy"], tb["sz"]], [tb["shear_xy"], tb["shear_xz"], tb["shear_yz"]],
        tb["omega"], tb["phi"], tb["kappa"], t)
    np.testing.assert_allclose(back.linear, aff.linear, atol=1e-10 * np.max(np.abs(aff.linear)))
    rw, rp, rk = rig.angles()
    np.testing.assert_allclose(pg.rotation.rotation_from_angles(rw, rp, rk), rig.rotation,
                               atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(order=st.integers(1, 4), dim=st.sampled_from([2, 3]), seed=st.integers(0, 2**31))
def test_polynomial_inverse_round_trip(order, dim, seed):
    rng = np.random.default_rng(seed)
    cls = pg.Polynomial2D if dim == 2 else pg.Polynomial3D
    centre = rng.uniform(-1e5, 1e5, dim)
    ident = cls.identity(order, centre, 500.0)
    C = ident.coefficients.copy()
    C[:, 1:] += rng.normal(scale=5.0, size=(dim, C.shape[1] - 1)) / np.arange(1, C.shape[1])
    m = cls(order, C, centre, 500.0)
    pts = centre + rng.uniform(-400, 400, (25, dim))
    back = m.inverse(tol=1e-9).apply(m.apply(pts))
    # the inverse meets its tolerance on the forward residual (target units)
    np.testing.assert_allclose(m.apply(back), m.apply(pts), rtol=0, atol=1e-9 + 1e-15 * 1e5 * 16)


MODELS_FOR_JSON = [
    pg.Similarity2D(1.1, -0.2, 3, 4),
    pg.Affine2D(1, 0.1, 2, -0.2, 0.9, 3),
    pg.Projective2D.from_parameters([1, 0.1, 2, -0.2, 0.9, 3, 1e-3, -2e-3]),
    pg.Polynomial2D(2, np.arange(12.0).reshape(2, 6), [1.0, 2.0], 3.0),
    pg.Rigid3D.from_angles(0.1, 0.2, 0.3, [1, 2, 3]),
    pg.Similarity3D.from_angles(2.0, 0.1, 0.2, 0.3, [1, 2, 3]),
    pg.Affine3D.from_matrix(ROWS_3D),
    pg.Projective3D(np.vstack([ROWS_3D, [0.01, 0.02, 0.0, 1.0]])),
    pg.Polynomial3D(1, np.arange(12.0).reshape(3, 4) + 1),
]


@pytest.mark.parametrize("model", MODELS_FOR_JSON, ids=lambda m: m.name)
def test_json_round_trip_and_repr(model):
    data = json.loads(json.dumps(model.to_dict()))
    again = tr.from_dict(data)
    assert type(again) is type(model)
    pts = _points(model.dim, 3, n=5)
    np.testing.assert_allclose(again.apply(pts), model.apply(pts), rtol=1e-14, atol=1e-12)
    text = repr(model)
    assert type(model).__name__ in text and len(text) < 600
    if hasattr(model, "parameters") and not isinstance(model, pg.Similarity3D):
        np.testing.assert_allclose(model.with_parameters(model.parameters).apply(pts),
                                   model.apply(pts))


def test_polynomial_inverse_json():
    m = pg.Polynomial2D(2, [[0, 1, 0, 0.01, 0, 0], [0, 0, 1, 0, 0.02, 0]])
    inv = tr.from_dict(json.loads(json.dumps(m.inverse().to_dict())))
    assert isinstance(inv, tr.Polynomial2DInverse)
    np.testing.assert_allclose(m.apply(inv.apply([[1.0, 2.0]])), [[1.0, 2.0]], atol=1e-9)


def test_textbook_jacobian_similarity2d_analytic():
    # d(s, theta)/d(a, b) written out: s = hypot(a, b), theta = atan2(-b, a)
    m = pg.Similarity2D(0.7, -1.3, 10.0, 20.0)
    a, b, s2 = 0.7, -1.3, 0.7**2 + 1.3**2
    expect = np.array([
        [a / np.sqrt(s2), b / np.sqrt(s2), 0, 0],
        [b / s2, -a / s2, 0, 0],
        [0, 0, 1, 0],
        [0, 0, 0, 1],
    ])
    np.testing.assert_allclose(m.textbook_jacobian(), expect, rtol=1e-8, atol=1e-10)


def test_model_bad_input():
    with pytest.raises(InputError, match="finite"):
        pg.Similarity2D(np.nan, 0, 0, 0)
    with pytest.raises(InputError, match="proper rotation"):
        pg.Rigid3D(np.diag([1.0, 1.0, -1.0]), [0, 0, 0])
    with pytest.raises(DegenerateGeometryError, match="inverse"):
        pg.Affine2D(1, 2, 0, 2, 4, 0).inverse()
    with pytest.raises(DegenerateGeometryError, match="no inverse"):
        pg.Similarity2D(0, 0, 1, 1).inverse()
    with pytest.raises(InputError, match="vanishing"):
        pg.Projective2D.from_parameters([1, 0, 0, 0, 1, 0, 1.0, 0]).apply([[-1.0, 5.0]])
    with pytest.raises(DegenerateGeometryError, match="last element"):
        pg.Projective2D(np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 0]]))
    with pytest.raises(InputError, match="shape"):
        pg.Polynomial2D(2, np.zeros((2, 5)))
    with pytest.raises(InputError, match="order"):
        pg.Polynomial2D(0, np.zeros((2, 1)))
    with pytest.raises(InputError, match="shape"):
        pg.Affine2D(1, 0, 0, 0, 1, 0).apply([[1.0, 2.0, 3.0]])
    with pytest.raises(InputError, match="unknown transformation model"):
        tr.from_dict({"model": "helmert9"})


@pytest.mark.parametrize("model", [
    pg.Affine2D.from_textbook(0.95, 1.03, 2.9, 0.3, 125.0, 130.0),
    pg.Affine2D.from_textbook(-2.0, 0.4, -1.0, -1.2, 1e5, -3.0),
    pg.Similarity2D.from_textbook(0.012, -3.1, 5e5, 4e6),
], ids=["affine", "affine-reflection", "similarity"])
def test_closed_form_textbook_jacobians_against_differences(model):
    np.testing.assert_allclose(model.textbook_jacobian(), model.numeric_textbook_jacobian(),
                               rtol=1e-6, atol=1e-8 * np.abs(model.textbook_jacobian()).max())
