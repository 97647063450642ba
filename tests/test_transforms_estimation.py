"""Estimation of the transformation models: lecture examples 4-5, independent methods,
noise-free recovery, weights, check points, handedness, large coordinates."""

from __future__ import annotations

import json
from decimal import ROUND_HALF_UP, Decimal

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom import datasets
from photogeom.estimation import transforms as est


def agree(value: float, printed: str) -> bool:
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    return abs(value - float(printed)) <= 0.5 * 10.0**-decimals + 1e-12


def assert_printed(values, printed):
    values = np.asarray(values, dtype=float).reshape(-1)
    printed = [str(p) for p in np.asarray(printed, dtype=object).reshape(-1)]
    bad = [(float(v), p) for v, p in zip(values, printed) if not agree(v, p)]
    assert not bad, f"values differ from the printed digits: {bad}"


def fiducials():
    t = datasets.load("lecture_fiducials")
    return t, np.c_[t["x"], t["y"]], np.c_[t["X"], t["Y"]]


def two_images():
    t = datasets.load("lecture_two_images")
    return t, np.c_[t["x2"], t["y2"]], np.c_[t["x1"], t["y1"]]


# --- lecture example 4: interior orientation from fiducial marks ------------------------------


def test_example_4_interior_orientation():
    t, src, dst = fiducials()
    fit = pg.estimate_transform("similarity2d", src, dst, check=t["role"] == "check",
                                ids=t["id"], unit="mm")
    assert_printed(fit.parameters, ["1.0000354", "-0.0000022", "130.00875", "130.009"])
    assert fit.ids == ("1", "2", "3", "4") and fit.check_ids == ("5", "6", "7", "8")
    assert_printed(fit.residuals, [["-0.00225", "0.00425"], ["-0.00025", "-0.00225"],
                                   ["0.0045", "0.0"], ["-0.002", "-0.002"]])
    assert_printed(fit.check_residuals, [["0.0045", "0.00725"], ["-0.001", "0.00075"],
                                         ["-0.0085", "0.00575"], ["-0.001", "0.00225"]])
    assert fit.redundancy == 4 and fit.n_observations == 8
    # residual sign: computed minus observed
    np.testing.assert_allclose(fit.residuals, fit.model.apply(src[:4]) - dst[:4], atol=1e-12)
    assert fit.residual_unit == "mm" and fit.parameter_units["c"] == "mm"
    text = fit.summary()
    assert "check" in text and "computed - observed" in text
    json.dumps(fit.to_dict())


# --- lecture example 5: six tie points on two images ------------------------------------------


def test_example_5_similarity_affine_projective():
    _, src, dst = two_images()
    sim = pg.estimate_transform("similarity2d", src, dst)
    assert_printed(sim.parameters, ["1.86", "0.48", "-62.16", "89.33"])
    aff = pg.estimate_transform("affine2d", src, dst)
    assert_printed(aff.parameters, ["2.62", "1.72", "-298.19", "0.31", "2.88", "-127.03"])
    proj = pg.estimate_transform("projective2d", src, dst)
    lin = proj.extras["linearised"]
    p = [lin["parameters"][n] for n in ("a1", "a2", "a3", "b1", "b2", "b3", "c1", "c2")]
    # the printed projective parameters are the linearised (lecture) solution
    printed = ["0.975", "-0.029", "5.445", "-0.015", "0.97", "3.91", "-0.001", "-0.003"]
    assert_printed(np.delete(p, 3), np.delete(np.array(printed, dtype=object), 3))
    # b1 = -0.014469 is printed -0.015: rounded twice (-0.0145 -> -0.015)
    twice = Decimal(f"{p[3]:.4f}").quantize(Decimal("0.001"), rounding=ROUND_HALF_UP)
    assert str(twice) == "-0.015"
    # the nonlinear (rational-form) estimate is a different, better-founded estimate
    assert proj.method.startswith("Gauss-Markov") and proj.converged
    assert abs(proj.parameters[2] - p[2]) > 0.5
    assert any("linearised" in n for n in proj.notes)

    # which published figure is which: the printed "RMSE" 41.2096, 18.6572, 0.21 all are
    # sqrt(v.T v / 8) of the linear least-squares solutions
    def rms8(v):
        return float(np.sqrt(np.sum(np.square(v)) / 8))

    assert_printed([rms8(sim.residuals), rms8(aff.residuals), np.sqrt(lin["vtv"] / 8)],
                   ["41.2096", "18.6572", "0.21"])
    # similarity: redundancy 8, so the figure is our sigma0
    assert sim.redundancy == 8 and agree(sim.sigma0, "41.2096")
    # affine: redundancy 6, so sigma0 (and the per-point RMSE) is sqrt(v.T v / 6), not the figure
    assert aff.redundancy == 6 and aff.sigma0 == pytest.approx(rms8(aff.residuals) * np.sqrt(8 / 6))
    assert aff.rmse == pytest.approx(np.sqrt(np.sum(aff.residuals**2) / 6))
    # projective: the figure is of algebraic residuals of the linearised equations, not of our
    # (coordinate) residuals of the rational form
    assert lin["redundancy"] == 4
    assert not agree(rms8(proj.residuals), "0.21")


# --- independent methods -----------------------------------------------------------------------


def raw_design(model, src):
    n = src.shape[0]
    x, y = src[:, 0], src[:, 1]
    one, zero = np.ones(n), np.zeros(n)
    if model == "similarity2d":
        rows = [np.c_[x, y, one, zero], np.c_[y, -x, zero, one]]
    else:
        rows = [np.c_[x, y, one, zero, zero, zero], np.c_[zero, zero, zero, x, y, one]]
    A = np.empty((2 * n, rows[0].shape[1]))
    A[0::2], A[1::2] = rows
    return A


@pytest.mark.parametrize("model", ["similarity2d", "affine2d"])
@pytest.mark.parametrize("weighted", [False, True])
def test_linear_models_against_lstsq_on_raw_design(model, weighted):
    _, src, dst = two_images()
    w = np.array([1.0, 2.0, 0.5, 4.0, 1.5, 3.0]) if weighted else None
    fit = pg.estimate_transform(model, src, dst, weights=w)
    A, L = raw_design(model, src), dst.reshape(-1)
    sw = np.ones(2 * len(src)) if w is None else np.sqrt(np.repeat(w, 2))
    x, *_ = np.linalg.lstsq(A * sw[:, None], L * sw, rcond=None)
    np.testing.assert_allclose(fit.parameters, x, rtol=1e-10, atol=1e-10)
    v = A @ x - L
    r = A.shape[0] - A.shape[1]
    s0 = np.sqrt(np.sum(sw**2 * v**2) / r)
    C = s0**2 * np.linalg.inv((A * sw[:, None] ** 2).T @ A)
    np.testing.assert_allclose(fit.covariance, C, rtol=1e-8, atol=1e-12 * np.abs(C).max())
    np.testing.assert_allclose(fit.residuals.reshape(-1), v, atol=1e-9)
    assert fit.sigma0 == pytest.approx(s0, rel=1e-10)
    # redundancy numbers diag(Qvv P) against the hat matrix
    Aw = A * sw[:, None]
    hat = Aw @ np.linalg.solve(Aw.T @ Aw, Aw.T)
    np.testing.assert_allclose(fit.redundancy_numbers.reshape(-1), 1 - np.diag(hat), atol=1e-10)


def test_polynomial_against_lstsq_and_textbook_std():
    rng = np.random.default_rng(11)
    src = rng.uniform(-50, 50, (40, 2)) + np.array([1000.0, -300.0])
    dst = src * 0.9 + 0.002 * src**2 / 100 + rng.normal(0, 0.05, src.shape)
    fit = pg.estimate_transform("polynomial2d", src, dst, order=2)
    # plain coefficients by lstsq on the plain (raw) monomials
    A = np.column_stack([src[:, 0] ** i * src[:, 1] ** j for i, j in
                         pg.transforms.polynomial_exponents(2, 2)])
    cx, *_ = np.linalg.lstsq(A, dst[:, 0], rcond=None)
    cy, *_ = np.linalg.lstsq(A, dst[:, 1], rcond=None)
    tb = fit.extras["textbook"]
    np.testing.assert_allclose([tb[n][0] for n in fit.parameter_names],
                               np.r_[cx, cy], rtol=1e-7, atol=1e-9)
    # standard deviations of the plain coefficients: sigma0^2 (A.T A)^-1
    v = np.r_[A @ cx - dst[:, 0], A @ cy - dst[:, 1]]
    s0 = np.sqrt(v @ v / (2 * len(src) - 12))
    sd = s0 * np.sqrt(np.diag(np.linalg.inv(A.T @ A)))
    np.testing.assert_allclose([tb[n][1] for n in fit.parameter_names], np.r_[sd, sd], rtol=1e-5)
    np.testing.assert_allclose(fit.model.apply(src) - dst, fit.residuals, atol=1e-10)


def rational(p, u):
    """x = (a1 x' + a2 y' + a3) / (c1 x' + c2 y' + 1), same for y, with d/dp and d/du."""
    a, b, c = p[0:3], p[3:6], np.r_[p[6:8], 1.0]
    uh = np.c_[u, np.ones(len(u))]
    w = uh @ c
    x, y = uh @ a / w, uh @ b / w
    dp = np.zeros((len(u), 2, 8))
    dp[:, 0, 0:3] = uh / w[:, None]
    dp[:, 1, 3:6] = uh / w[:, None]
    dp[:, 0, 6:8] = -x[:, None] * u / w[:, None]
    dp[:, 1, 6:8] = -y[:, None] * u / w[:, None]
    du = np.zeros((len(u), 2, 2))
    du[:, 0] = (a[None, :2] - x[:, None] * c[None, :2]) / w[:, None]
    du[:, 1] = (b[None, :2] - y[:, None] * c[None, :2]) / w[:, None]
    return np.c_[x, y], dp, du


def test_projective_nonlinear_against_scipy_least_squares():
    _, src, dst = two_images()
    fit = pg.estimate_transform("projective2d", src, dst)
    sd = np.sqrt(np.diag(fit.covariance))

    def resid(z):  # parameters in units of their standard deviations
        return (rational(fit.parameters + sd * z, src)[0] - dst).reshape(-1)

    def jac(z):
        return rational(fit.parameters + sd * z, src)[1].reshape(-1, 8) * sd

    # scipy starts from the linearised solution, like the library
    start = [fit.extras["linearised"]["parameters"][n] for n in fit.parameter_names]
    ref = scipy.optimize.least_squares(resid, (np.array(start) - fit.parameters) / sd, jac=jac,
                                       method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(ref.x, 0.0, atol=1e-7)  # in standard deviations
    J = ref.jac / sd
    r = J.shape[0] - J.shape[1]
    C = (ref.fun @ ref.fun / r) * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(fit.covariance, C, rtol=1e-7)
    np.testing.assert_allclose(fit.residuals.reshape(-1), ref.fun, atol=1e-9)


def test_projective_gauss_helmert_against_total_least_squares():
    _, src, dst = two_images()
    fit = pg.estimate_transform("projective2d", src, dst, errors_in="both")
    assert fit.method.startswith("Gauss-Helmert") and fit.redundancy == 4
    n = len(src)
    sd = np.sqrt(np.diag(fit.covariance))

    def resid(z):  # (parameters in std units, adjusted source points)
        u = z[8:].reshape(n, 2)
        return np.r_[(u - src).reshape(-1),
                     (rational(fit.parameters + sd * z[:8], u)[0] - dst).reshape(-1)]

    def jac(z):
        u = z[8:].reshape(n, 2)
        _, dp, du = rational(fit.parameters + sd * z[:8], u)
        J = np.zeros((4 * n, 8 + 2 * n))
        J[: 2 * n, 8:] = np.eye(2 * n)
        J[2 * n:, :8] = dp.reshape(-1, 8) * sd
        J[2 * n:, 8:] = scipy.linalg.block_diag(*du)
        return J

    ref = scipy.optimize.least_squares(resid, np.r_[np.full(8, 0.3), src.reshape(-1)], jac=jac,
                                       method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    # MINPACK's LM stops with a gradient of ~3e-8 here; polish the reference with a few plain
    # Gauss-Newton steps (numpy lstsq) so that it is converged to the precision we test.
    for _ in range(3):
        ref.x = ref.x + np.linalg.lstsq(jac(ref.x), -resid(ref.x), rcond=None)[0]
    np.testing.assert_allclose(ref.x[:8], 0.0, atol=1e-7)
    u = ref.x[8:].reshape(n, 2)
    np.testing.assert_allclose(fit.extras["source_residuals"], u - src, atol=1e-9)
    p = fit.parameters + sd * ref.x[:8]
    np.testing.assert_allclose(fit.residuals, rational(p, u)[0] - dst, atol=1e-9)
    assert fit.sigma0 == pytest.approx(np.sqrt(ref.fun @ ref.fun / 4), rel=1e-10)


def test_shared_design_separate_solution_has_identical_statistics(monkeypatch):
    rng = np.random.default_rng(3)
    src = rng.uniform(-100, 100, (60, 3))
    dst = src @ rng.normal(size=(3, 3)) + rng.normal(0, 0.1, (60, 3))
    w = rng.uniform(0.5, 2.0, (60, 3))
    check = np.zeros(60, bool)
    check[::7] = True
    fits = []
    for limit in (10**9, 0):
        monkeypatch.setattr(est, "SEPARABLE_FROM", limit)
        fits.append(pg.estimate_transform("affine3d", src, dst, weights=w, check=check))
    joint, sep = fits
    assert "separately" in sep.message and "separately" not in joint.message
    for attr in ("parameters", "covariance", "residuals", "normalized_residuals",
                 "redundancy_numbers", "check_residuals"):
        np.testing.assert_allclose(getattr(sep, attr), getattr(joint, attr), rtol=1e-9,
                                   atol=1e-12, err_msg=attr)
    assert sep.sigma0 == pytest.approx(joint.sigma0, rel=1e-12)
    assert sep.redundancy == joint.redundancy == 3 * 51 - 12


def test_weights_and_covariance_forms_agree():
    _, src, dst = two_images()
    w = np.array([1.0, 2.0, 0.5, 4.0, 1.5, 3.0])
    a = pg.estimate_transform("affine2d", src, dst, weights=w)
    blocks = np.array([np.eye(2) / wi for wi in w])
    b = pg.estimate_transform("affine2d", src, dst, covariance=blocks)
    c = pg.estimate_transform("affine2d", src, dst, covariance=np.diag(np.repeat(1 / w, 2)))
    for f in (b, c):
        np.testing.assert_allclose(f.parameters, a.parameters, rtol=1e-10)
        np.testing.assert_allclose(f.covariance, a.covariance, rtol=1e-9,
                                   atol=1e-12 * np.abs(a.covariance).max())
    # x/y correlations that differ from point to point change the estimate (joint solution;
    # the same correlation everywhere would not, designs being equal)
    corr = blocks.copy()
    corr[:, 0, 1] = corr[:, 1, 0] = np.array([0.5, -0.3, 0.1, 0.7, -0.6, 0.0]) / w
    d = pg.estimate_transform("affine2d", src, dst, covariance=corr)
    assert not np.allclose(d.parameters, a.parameters)


def test_check_points_do_not_enter_the_estimate():
    t, src, dst = fiducials()
    chk = t["role"] == "check"
    with_checks = pg.estimate_transform("affine2d", src, dst, check=chk)
    control_only = pg.estimate_transform("affine2d", src[~chk], dst[~chk])
    np.testing.assert_allclose(with_checks.parameters, control_only.parameters)
    np.testing.assert_allclose(with_checks.check_residuals,
                               control_only.model.apply(src[chk]) - dst[chk], atol=1e-12)
    assert with_checks.check_rmse == pytest.approx(
        np.sqrt(np.sum(with_checks.check_residuals**2) / 4))


def test_handedness_pixel_to_image():
    # a true similarity from right-handed (col, -row) to image mm
    rng = np.random.default_rng(8)
    px = rng.uniform(0, 4000, (12, 2))
    true = pg.Similarity2D.from_textbook(0.012, 0.003, -24.0, 18.0)
    mm = true.apply(pg.imagecoords.flip_y(px)) + rng.normal(0, 1e-4, (12, 2))
    fit = pg.estimate_transform("similarity2d", px, mm, source_system="pixel",
                                target_system="image", unit="mm")
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=1e-3, atol=1e-3)
    assert fit.sigma0 < 1e-3 and fit.extras["handedness"]["source_flip_y"]
    assert any("left-handed" in note for note in fit.notes)
    # not told the systems: a similarity cannot fit a reflection
    naive = pg.estimate_transform("similarity2d", px, mm)
    assert naive.sigma0 > 1.0
    # the other way round (image -> pixel): target flipped, residuals in pixels as given
    back = pg.estimate_transform("similarity2d", mm, px, source_system="image",
                                 target_system="pixel")
    pred = pg.imagecoords.flip_y(back.model.apply(mm))
    np.testing.assert_allclose(back.residuals, pred - px, atol=1e-9)
    # same handedness: nothing flipped
    same = pg.estimate_transform("affine2d", px, px * 2, source_system="pixel",
                                 target_system="pixel")
    assert not same.notes and not same.extras["handedness"]["source_flip_y"]


def test_large_coordinates_recovered_to_1e9():
    rng = np.random.default_rng(21)
    local = rng.uniform(-500, 500, (50, 2))
    true = pg.Affine2D.from_textbook(1.0003, 0.9998, 0.7, 0.001, 512_345.678, 4_012_345.678)
    fit = pg.estimate_transform("affine2d", local, true.apply(local))
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=1e-9, atol=1e-9)
    local3 = rng.uniform(-1, 1, (50, 3))
    true3 = pg.Affine3D.from_textbook([2.0, 2.1, 1.9], [0.01, 0.0, -0.02], 0.3, -0.2, 2.5,
                                      [512_345.678, 4_012_345.678, 250.5])
    fit3 = pg.estimate_transform("affine3d", local3, true3.apply(local3))
    np.testing.assert_allclose(fit3.parameters, true3.parameters, rtol=1e-9, atol=1e-9)
    # and the other way round: UTM-sized source (conditioning by reduction)
    fit_inv = pg.estimate_transform("affine2d", true.apply(local), local)
    np.testing.assert_allclose(fit_inv.parameters, true.inverse().parameters, rtol=1e-9,
                               atol=1e-8)
    proj = pg.estimate_transform("projective2d", true.apply(local), local)
    np.testing.assert_allclose(proj.model.apply(true.apply(local)), local, atol=1e-7)


# --- noise-free recovery, angles over their full range ------------------------------------------

angles = st.floats(-np.pi + 1e-9, np.pi)


def pts(dim, seed, n=20, spread=100.0):
    return np.random.default_rng(seed).uniform(-spread, spread, (n, dim))


@settings(max_examples=25, deadline=None)
@given(s=st.floats(0.01, 100), t=angles, x0=st.floats(-1e5, 1e5), y0=st.floats(-1e5, 1e5),
       seed=st.integers(0, 2**31))
def test_recover_similarity2d(s, t, x0, y0, seed):
    true = pg.Similarity2D.from_textbook(s, t, x0, y0)
    src = pts(2, seed)
    fit = pg.estimate_transform("similarity2d", src, true.apply(src))
    scale = max(1.0, abs(x0), abs(y0))
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=0, atol=1e-9 * scale)
    tb = fit.extras["textbook"]
    assert np.angle(np.exp(1j * (tb["theta"][0] - t))) == pytest.approx(0, abs=1e-10)


@settings(max_examples=25, deadline=None)
@given(sx=st.floats(0.1, 10), sy=st.floats(0.1, 10), t=angles, e=st.floats(-1.3, 1.3),
       seed=st.integers(0, 2**31))
def test_recover_affine2d(sx, sy, t, e, seed):
    true = pg.Affine2D.from_textbook(sx, sy, t, e, 1234.5, -678.9)
    src = pts(2, seed)
    fit = pg.estimate_transform("affine2d", src, true.apply(src))
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=0, atol=1e-9 * 1e3)
    tb = fit.extras["textbook"]
    np.testing.assert_allclose([tb["sx"][0], tb["sy"][0], tb["e"][0]], [sx, sy, e], rtol=1e-8,
                               atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(t=angles, seed=st.integers(0, 2**31), both=st.booleans())
def test_recover_projective2d(t, seed, both):
    rng = np.random.default_rng(seed)
    H = np.eye(3)
    H[:2, :2] = rng.uniform(0.5, 2) * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    H[:2, :2] += rng.normal(scale=0.1, size=(2, 2))
    H[:2, 2] = rng.uniform(-100, 100, 2)
    H[2, :2] = rng.uniform(-2e-3, 2e-3, 2)
    true = pg.Projective2D(H)
    src = pts(2, seed, 12)
    fit = pg.estimate_transform("projective2d", src, true.apply(src),
                                errors_in="both" if both else "target")
    np.testing.assert_allclose(fit.model.matrix, true.matrix, rtol=1e-7, atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(w=angles, p=st.floats(-1.5, 1.5), k=angles, seed=st.integers(0, 2**31))
def test_recover_affine3d_and_projective3d(w, p, k, seed):
    rng = np.random.default_rng(seed)
    true = pg.Affine3D.from_textbook(rng.uniform(0.2, 5, 3), rng.uniform(-0.3, 0.3, 3), w, p, k,
                                     rng.uniform(-1e4, 1e4, 3))
    src = pts(3, seed, 15)
    fit = pg.estimate_transform("affine3d", src, true.apply(src))
    np.testing.assert_allclose(fit.parameters, true.parameters, rtol=0, atol=1e-8 * 1e4)
    tb = fit.extras["textbook"]
    got = pg.rotation_from_angles(tb["omega"][0], tb["phi"][0], tb["kappa"][0])
    np.testing.assert_allclose(got, true.decompose().rotation, atol=1e-8)
    H = true.matrix.copy()
    H[3, :3] = rng.uniform(-1e-3, 1e-3, 3)
    ptrue = pg.Projective3D(H)
    pfit = pg.estimate_transform("projective3d", src, ptrue.apply(src))
    np.testing.assert_allclose(pfit.model.matrix, ptrue.matrix, rtol=1e-7, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(order=st.integers(1, 3), dim=st.sampled_from([2, 3]), seed=st.integers(0, 2**31))
def test_recover_polynomial(order, dim, seed):
    rng = np.random.default_rng(seed)
    cls = pg.Polynomial2D if dim == 2 else pg.Polynomial3D
    centre = rng.uniform(-1e4, 1e4, dim)
    C = rng.normal(size=(dim, pg.transforms.polynomial_term_count(order, dim)))
    true = cls(order, C, centre, 50.0)
    src = centre + rng.uniform(-100, 100, (60, dim))
    fit = pg.estimate_transform(f"polynomial{dim}d", src, true.apply(src), order=order)
    np.testing.assert_allclose(fit.model.apply(src), true.apply(src), rtol=0, atol=1e-8)
    # the same mapping in the fit's own reduction
    same = true.with_reduction(fit.model.centre, fit.model.scale)
    np.testing.assert_allclose(fit.model.coefficients, same.coefficients, rtol=1e-6, atol=1e-8)


def test_gauss_helmert_sparse_path_and_handedness(monkeypatch):
    import importlib

    gh = importlib.import_module("photogeom.adjust.gauss_helmert")
    rng = np.random.default_rng(31)
    px = rng.uniform(0, 3000, (40, 2))
    H = np.array([[0.01, 0.001, -15.0], [0.0005, 0.0102, -12.0], [1e-6, -2e-6, 1.0]])
    true = pg.Projective2D(H)
    mm = true.apply(pg.imagecoords.flip_y(px)) + rng.normal(0, 0.002, (40, 2))
    px_obs = px + rng.normal(0, 0.2, (40, 2))
    w = np.tile([25.0, 25.0, 1e6 / 4, 1e6 / 4], (40, 1))  # px: 0.2, mm: 0.002
    kw = dict(errors_in="both", weights=w, source_system="pixel", target_system="image")
    dense = pg.estimate_transform("projective2d", px_obs, mm, **kw)
    monkeypatch.setattr(est, "SPARSE_FROM", 0)
    monkeypatch.setattr(gh, "DENSE_LIMIT", 0)
    sparse = pg.estimate_transform("projective2d", px_obs, mm, **kw)
    np.testing.assert_allclose(sparse.parameters, dense.parameters, rtol=1e-9)
    np.testing.assert_allclose(sparse.residuals, dense.residuals, atol=1e-12)
    assert sparse.sigma0 == pytest.approx(dense.sigma0, rel=1e-9)
    # the adjusted observations (observed + corrections, in the systems as given) satisfy
    # the model on the flipped pixel coordinates
    adj_src = px_obs + dense.extras["source_residuals"]
    adj_dst = mm + dense.residuals
    np.testing.assert_allclose(dense.model.apply(pg.imagecoords.flip_y(adj_src)), adj_dst,
                               atol=1e-9)
    np.testing.assert_allclose(dense.model.matrix, true.matrix, rtol=0.05, atol=1e-4)


def test_projective_minimal_point_sets_are_exact():
    true2 = pg.Projective2D.from_parameters([1.1, 0.1, 2.0, 0.05, 0.9, 3.0, 0.01, -0.02])
    src2 = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    fit2 = pg.estimate_transform("projective2d", src2, true2.apply(src2))
    np.testing.assert_allclose(fit2.parameters, true2.parameters, atol=1e-13)
    assert fit2.redundancy == 0 and np.isnan(fit2.sigma0)
    H = np.vstack([np.c_[2 * np.eye(3), [1.0, 2.0, 3.0]], [0.01, 0.02, -0.01, 1.0]])
    true3 = pg.Projective3D(H)
    src3 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.0]])
    fit3 = pg.estimate_transform("projective3d", src3, true3.apply(src3))
    np.testing.assert_allclose(fit3.model.matrix, H, atol=1e-12)


def test_summary_parameter_header_sits_over_its_columns_and_rms_has_its_unit():
    """Fit.summary(): the right edges of 'value', 'std. dev.' and 'unit' in the header are
    those of the numbers below them, and the RMS per axis carries the residual unit."""
    from photogeom.io import read_point_pairs

    pairs = read_point_pairs(pg.datasets.path("lecture_fiducials"))
    fit = pg.estimate_transform(
        "similarity2d", pairs.source, pairs.target, check=pairs.check_mask, unit="mm"
    )
    lines = fit.summary().splitlines()
    k = next(i for i, x in enumerate(lines) if x.split()[:1] == ["parameter"])
    head = lines[k]
    ends = [head.index(w) + len(w) for w in ("value", "std. dev.", "unit")]
    for row in lines[k + 1 : k + 5]:
        name, value, std, unit = row.split()
        assert [row.index(value) + len(value), row.index(std) + len(std), len(row)] == ends
        assert float(value) == pytest.approx(fit.params[name], rel=1e-9)
        assert unit == ("mm" if name in ("c", "d") else "1"), row
    rms = next(x for x in lines if "RMS per axis" in x)
    assert rms.endswith(" mm"), rms
