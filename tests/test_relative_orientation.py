"""Relative orientation of an image pair: noise-free recovery for any attitude, both
parameterisations, agreement with OpenCV's recoverPose, statistics against Monte Carlo,
y-parallaxes, model coordinates with covariance, and the bad inputs."""

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.adjust import gauss_helmert
from photogeom.orientation.relative import _Coplanarity, _Geometry

IO = pg.InteriorOrientation(100.0, x0=0.01, y0=-0.02, unit="mm")


def simulate(
    seed=0,
    bh=0.5,
    convergence=0.0,
    n=30,
    noise=0.0,
    attitude=(0.0, 0.0, 0.0),
    base_azimuth=0.0,
    io=IO,
):
    """A pair over terrain at height ~100: image 1 near-vertical, image 2 at base ``bh *
    100`` along ``base_azimuth`` (image-1 frame), tilted towards each other by
    ``convergence`` (rad); then the whole scene rotated by ``attitude`` (any)."""
    rng = np.random.default_rng(seed)
    H = 100.0
    B = bh * H
    d = np.array([math.cos(base_azimuth), math.sin(base_azimuth), 0.0])
    O1 = np.array([0.0, 0.0, H])
    O2 = O1 + B * d
    u = rng.uniform(-35, 35 + B, n)
    v = rng.uniform(-35, 35, n)
    pts = np.column_stack([u * d[0] - v * d[1], u * d[1] + v * d[0], rng.uniform(-15, 15, n)])
    a1 = rng.normal(0, 0.03, 3)
    a2 = rng.normal(0, 0.03, 3)
    # convergence: both images tilted towards the middle of the base
    tilt = np.array([convergence * d[1], convergence * d[0], 0.0])
    e1 = pg.ExteriorOrientation(*O1, *(a1 + np.array([-tilt[0], tilt[1], 0.0])))
    e2 = pg.ExteriorOrientation(*O2, *(a2 + np.array([tilt[0], -tilt[1], 0.0])))
    Rw = pg.opk_matrix(*attitude)
    shift = np.array([1000.0, 2000.0, 300.0])

    def move(e):
        return pg.ExteriorOrientation.from_matrix(
            Rw @ e.position + shift, e.matrix @ Rw.T, on_gimbal_lock="omega-zero"
        )

    e1, e2 = move(e1), move(e2)
    pts = pts @ Rw.T + shift
    xy1 = pg.project(pts, io, e1) + rng.normal(0, noise, (n, 2))
    xy2 = pg.project(pts, io, e2) + rng.normal(0, noise, (n, 2))
    return e1, e2, pts, xy1, xy2


def truth(e1, e2):
    """Relative rotation M2 M1.T and the unit base in the camera-1 frame."""
    b = e1.matrix @ (e2.position - e1.position)
    return e2.matrix @ e1.matrix.T, b / np.linalg.norm(b)


# --- noise-free recovery ------------------------------------------------------------------------


@settings(max_examples=25)
@given(
    omega=st.floats(-3.1, 3.1),
    phi=st.floats(-1.4, 1.4),
    kappa=st.floats(-3.1, 3.1),
    bh=st.floats(0.1, 1.0),
    convergence=st.floats(0.0, 0.5),
    azimuth=st.floats(-0.6, 0.6) | st.floats(math.pi - 0.6, math.pi + 0.6),
    seed=st.integers(0, 1000),
)
def test_noise_free_pairs_recovered_both_methods(omega, phi, kappa, bh, convergence, azimuth, seed):
    e1, e2, _, xy1, xy2 = simulate(
        seed, bh, convergence, attitude=(omega, phi, kappa), base_azimuth=azimuth
    )
    R, b = truth(e1, e2)
    for method in ("dependent", "independent"):
        fit = pg.relative_orientation(xy1, xy2, IO, IO, method=method)
        assert np.abs(fit.pair.relative_rotation - R).max() < 1e-9
        assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-9
        assert not fit.flagged.any()
        assert np.abs(fit.parallax).max() < 1e-9
    # the dependent elements by definition: image 1 fixed, bx = +-1
    dep = pg.relative_orientation(xy1, xy2, IO, method="dependent")
    assert dep.exterior1.parameters == pytest.approx(np.zeros(6), abs=0)
    assert abs(dep.exterior2.X0) == 1.0
    assert dep.params["by"] == pytest.approx(b[1] / abs(b[0]), abs=1e-9)
    assert dep.params["bz"] == pytest.approx(b[2] / abs(b[0]), abs=1e-9)
    assert np.abs(dep.exterior2.matrix - R).max() < 1e-9


@settings(max_examples=10)
@given(azimuth=st.floats(-math.pi, math.pi), seed=st.integers(0, 1000))
def test_independent_any_base_direction(azimuth, seed):
    """The independent elements describe a base in any direction of the image plane."""
    e1, e2, _, xy1, xy2 = simulate(seed, 0.6, base_azimuth=azimuth)
    R, b = truth(e1, e2)
    fit = pg.relative_orientation(xy1, xy2, IO, method="independent")
    assert np.abs(fit.pair.relative_rotation - R).max() < 1e-9
    assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-9
    # definitions: base = model x axis, omega1 = 0
    assert fit.exterior1.omega == 0.0
    assert np.allclose(fit.exterior2.position, [1, 0, 0])


def test_dependent_refuses_base_along_y():
    e1, e2, _, xy1, xy2 = simulate(3, 0.6, base_azimuth=math.pi / 2)
    with pytest.raises(pg.DegenerateGeometryError, match="independent"):
        pg.relative_orientation(xy1, xy2, IO, method="dependent")
    fit = pg.relative_orientation(xy1, xy2, IO, method="independent")
    _R, b = truth(e1, e2)
    assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-9


def test_dependent_and_independent_give_one_model():
    """The model points of both parameterisations differ by the similarity of their
    definitions: rotation M1 (independent) and scale |b| (dependent, bx = 1)."""
    _, _, _, xy1, xy2 = simulate(5, 0.7, 0.2, noise=0.003, attitude=(0.3, -0.2, 2.0))
    dep = pg.relative_orientation(xy1, xy2, IO, method="dependent", sigma=0.003)
    ind = pg.relative_orientation(xy1, xy2, IO, method="independent", sigma=0.003)
    # one adjustment problem: same residuals, sigma0, y-parallaxes
    assert dep.sigma0 == pytest.approx(ind.sigma0, rel=1e-7)
    assert np.allclose(dep.residuals, ind.residuals, atol=1e-10)
    assert np.allclose(dep.parallax, ind.parallax, atol=1e-10)
    Xd = dep.model_points().points
    Xi = ind.model_points().points
    b = dep.pair.base
    M1 = ind.exterior1.matrix
    assert np.allclose(Xi, Xd @ M1 / np.linalg.norm(b), atol=1e-9)
    ao = pg.absolute_orientation(Xd, Xi, method="svd")
    assert ao.scale == pytest.approx(1 / np.linalg.norm(b), rel=1e-9)
    assert np.allclose(ao.rotation, M1.T, atol=1e-9)


# --- against OpenCV ------------------------------------------------------------------------------


def _opencv_pose(xy1, xy2, f, cx, cy, seed=1):
    """recoverPose on OpenCV pixels (col = cx + x, row = cy - y): photogrammetric relative
    rotation and unit base in the camera-1 frame."""
    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]])
    c1 = np.column_stack([cx + xy1[:, 0], cy - xy1[:, 1]])
    c2 = np.column_stack([cx + xy2[:, 0], cy - xy2[:, 1]])
    cv2.setRNGSeed(seed)
    E, mask = cv2.findEssentialMat(c1, c2, K, method=cv2.RANSAC, prob=0.999, threshold=1.0)
    _, Rcv, tcv, _ = cv2.recoverPose(E[:3], c1, c2, K, mask=mask)
    F = np.diag([1.0, -1.0, -1.0])
    b = -F @ Rcv.T @ tcv.reshape(3)
    return F @ Rcv @ F, b / np.linalg.norm(b)


def _start(fit):
    start = fit.extras["start"]["parameters"]
    R = pg.opk_matrix(start["omega2"], start["phi2"], start["kappa2"])
    b = np.array([fit.extras["bx"], start["by"], start["bz"]])
    return R, b / np.linalg.norm(b)


@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_start_and_adjusted_agree_with_opencv_recover_pose(noise):
    io = pg.InteriorOrientation.digital(1200.0, 640.0, 480.0, unit="px")
    e1, e2, _, xy1, xy2 = simulate(11, 0.4, 0.15, noise=noise, attitude=(0.4, 0.1, -1.0), io=io)
    R_cv, b_cv = _opencv_pose(xy1, xy2, 1200.0, 640.0, 480.0)
    fit = pg.relative_orientation(xy1, xy2, io, method="dependent", sigma=noise or None)
    R_true, b_true = truth(e1, e2)
    candidates = (_start(fit), (fit.pair.relative_rotation, fit.pair.base_in_camera1))
    if noise == 0:
        for R, b in (*candidates, (R_true, b_true)):
            assert np.abs(R - R_cv).max() < 1e-6
            assert np.abs(b - b_cv).max() < 1e-6
    else:
        for R, b in candidates:
            assert np.abs(R - R_cv).max() < 2e-2
            assert np.abs(b - b_cv).max() < 2e-2
        # and the adjusted base lies within 4 standard deviations of the truth
        s = fit.std_errors
        by, bz = b_true[1] / abs(b_true[0]), b_true[2] / abs(b_true[0])
        assert abs(fit.params["by"] - by) < 4 * s["by"]
        assert abs(fit.params["bz"] - bz) < 4 * s["bz"]


# --- statistics ---------------------------------------------------------------------------------


def test_normalised_residuals_match_the_dense_gauss_helmert_engine():
    """Per-point w-tests of the relative orientation equal the engine's dense-path ones."""
    _, _, _, xy1, xy2 = simulate(2, 0.6, noise=0.004, n=25)
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.004, robust=False)
    cop = _Coplanarity(_Geometry("dependent", fit.extras["bx"]), IO, IO)
    L = np.column_stack([xy1, xy2]).reshape(-1)
    adj = gauss_helmert(
        lambda x, ll: cop.evaluate(x, ll.reshape(-1, 4))[0],
        fit.parameters,
        L,
        jacobian_x=lambda x, ll: cop.evaluate(x, ll.reshape(-1, 4))[1],
        jacobian_l=lambda x, ll: _dense_b(cop.evaluate(x, ll.reshape(-1, 4))[2]),
        weights=np.full(L.size, 1 / 0.004**2),
    )
    assert np.allclose(adj.x, fit.parameters, atol=1e-12)
    w_engine = adj.normalized_residuals.reshape(-1, 4)
    ok = np.isfinite(w_engine)
    assert np.allclose(w_engine[ok], fit.normalized_residuals[ok], rtol=1e-8, atol=1e-9)
    assert np.allclose(adj.redundancy_numbers.reshape(-1, 4), fit.redundancy_numbers, atol=1e-9)
    assert fit.redundancy_numbers.sum() == pytest.approx(fit.redundancy, rel=1e-9)


def _dense_b(B):
    n = B.shape[0]
    out = np.zeros((n, 4 * n))
    for i in range(4):
        out[np.arange(n), 4 * np.arange(n) + i] = B[:, i]
    return out


@pytest.mark.slow
def test_std_errors_and_model_point_covariance_match_monte_carlo():
    """200 noisy trials; the spread of a standard deviation from 200 trials is itself ~5 %,
    so the bounds here are 15 % (benchmarks/relative_orientation.py runs 1000 trials of both
    parameterisations: within 5 %). Model-point std devs include the orientation part."""
    method = "dependent"
    sd = 0.004
    _e1, _e2, _pts, xy1, xy2 = simulate(7, 0.6, 0.1, n=30)
    ref = pg.relative_orientation(xy1, xy2, IO, method=method, sigma=sd)
    mp_ref = ref.model_points()
    rng = np.random.default_rng(3)
    params, points, s0 = [], [], []
    for _ in range(200):
        a = xy1 + rng.normal(0, sd, xy1.shape)
        b = xy2 + rng.normal(0, sd, xy2.shape)
        f = pg.relative_orientation(a, b, IO, method=method, sigma=sd, robust=False)
        params.append(f.parameters)
        points.append(f.model_points().points)
        s0.append(f.sigma0)
    spread = np.std(params, axis=0, ddof=1)
    predicted = np.array(list(ref.std_errors_prior.values()))
    assert np.all(np.abs(spread / predicted - 1) < 0.15), spread / predicted
    pspread = np.std(points, axis=0, ddof=1)
    ppred = np.sqrt(np.einsum("nii->ni", mp_ref.covariance_prior))
    assert np.all(np.abs(np.median(pspread / ppred, axis=0) - 1) < 0.15)
    # the orientation part matters: the conditional covariance alone is far too small
    pcond = np.sqrt(np.einsum("nii->ni", mp_ref.cofactor_conditional))
    assert np.median(pspread / pcond) > 1.3
    assert np.mean(s0) == pytest.approx(1.0, abs=0.05)


def test_y_parallax_of_the_normal_case_is_y1_minus_y2():
    """Vertical images, base along x, one principal distance: a point moved across the
    epipolar line by dy in image 2 is left out and shows py = y1 - y2 = -dy."""
    io = pg.InteriorOrientation(100.0, unit="mm")
    rng = np.random.default_rng(0)
    pts = np.column_stack(
        [rng.uniform(-30, 90, 30), rng.uniform(-40, 40, 30), rng.uniform(-10, 10, 30)]
    )
    e1 = pg.ExteriorOrientation(0, 0, 100)
    e2 = pg.ExteriorOrientation(60, 0, 100)
    xy1 = pg.project(pts, io, e1)
    xy2 = pg.project(pts, io, e2)
    xy2[4, 1] += 0.02
    fit = pg.relative_orientation(xy1, xy2, io, sigma=0.001)
    assert fit.flagged.tolist() == [i == 4 for i in range(30)]
    assert fit.parallax[4] == pytest.approx(-0.02, rel=1e-6)
    assert np.abs(np.delete(fit.parallax, 4)).max() < 1e-9
    rep = fit.parallax_report(worst=3)
    assert rep.worst[0] == 4 and rep.ids[4] == "5"
    assert "left out" in rep.text()
    assert rep.to_dict()["worst"][0] == "5"


# --- robustness and bad input ------------------------------------------------------------------


def test_forty_percent_wrong_matches_are_flagged():
    sd = 0.003
    e1, e2, _, xy1, xy2 = simulate(4, 0.6, 0.1, n=120, noise=sd, attitude=(0.2, 0.5, 1.0))
    rng = np.random.default_rng(9)
    wrong = rng.random(120) < 0.4
    xy2 = xy2.copy()
    xy2[wrong] += rng.uniform(-4, 4, (int(wrong.sum()), 2))
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=sd)
    # no good match is lost; a wrong one is kept only when it lands on its epipolar line
    assert not (fit.flagged & ~wrong).any()
    kept_wrong = wrong & ~fit.flagged
    assert np.all(np.abs(fit.parallax[kept_wrong]) < 4 * sd)
    assert fit.flagged.sum() >= 0.9 * wrong.sum()
    R, b = truth(e1, e2)
    assert np.abs(fit.pair.relative_rotation - R).max() < 1e-3
    assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-3
    assert fit.sigma0 == pytest.approx(1.0, abs=0.3)


def test_without_robust_estimation_the_statistics_show_the_blunder():
    _, _, _, xy1, xy2 = simulate(8, 0.5, n=30, noise=0.002)
    xy2 = xy2.copy()
    xy2[7, 1] += 0.05
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.002, robust=False)
    assert fit.inliers.all()
    assert int(np.nanargmax(np.abs(fit.statistic))) == 7
    assert fit.snooping().suspect // 4 == 7


def test_fewer_than_five_points():
    _, _, _, xy1, xy2 = simulate(0, n=4)
    with pytest.raises(pg.TooFewPointsError, match="at least 5"):
        pg.relative_orientation(xy1, xy2, IO)


def test_points_on_a_line():
    e1, e2, _, _, _ = simulate(0)
    t = np.linspace(0, 1, 12)[:, None]
    line = np.array([1000.0, 2000.0, 300.0]) + t * [50.0, 10.0, 5.0]
    with pytest.raises(pg.DegenerateGeometryError, match="line"):
        pg.relative_orientation(pg.project(line, IO, e1), pg.project(line, IO, e2), IO)


def test_points_on_the_critical_cylinder():
    """Points on a cylinder whose axis is parallel to the base and which contains both
    projection centres (the classical dangerous surface)."""
    e1 = pg.ExteriorOrientation(0, 0, 0)
    e2 = pg.ExteriorOrientation(40, 0, 0, 0.02, -0.01, 0.03)
    r = 80.0
    rng = np.random.default_rng(0)
    a = rng.uniform(np.radians(140), np.radians(220), 30)
    pts = np.column_stack([rng.uniform(-10, 50, 30), r * np.sin(a), -r + r * np.cos(a)])
    for method in ("dependent", "independent"):
        with pytest.raises(pg.DegenerateGeometryError, match="critical surface"):
            pg.relative_orientation(
                pg.project(pts, IO, e1), pg.project(pts, IO, e2), IO, method=method
            )


@pytest.mark.parametrize("noise", [0.0, 0.002])
def test_pure_rotation_has_no_base(noise):
    rng = np.random.default_rng(1)
    pts = np.column_stack(
        [rng.uniform(-40, 40, 30), rng.uniform(-40, 40, 30), rng.uniform(-120, -80, 30)]
    )
    e1 = pg.ExteriorOrientation(0, 0, 0)
    e2 = pg.ExteriorOrientation(0, 0, 0, 0.05, 0.1, 0.3)
    xy2 = pg.project(pts, IO, e2) + rng.normal(0, noise, (30, 2))
    with pytest.raises(pg.DegenerateGeometryError, match="no base"):
        pg.relative_orientation(pg.project(pts, IO, e1), xy2, IO, sigma=noise or None)


def test_five_points_exact_or_ambiguous_never_silent():
    rng = np.random.default_rng(2)
    e1 = pg.ExteriorOrientation(0, 0, 0)
    e2 = pg.ExteriorOrientation(40, 5, 2, 0.05, 0.1, 0.3)
    outcomes = set()
    for _ in range(6):
        pts = np.column_stack(
            [rng.uniform(-40, 80, 5), rng.uniform(-40, 40, 5), rng.uniform(-120, -80, 5)]
        )
        try:
            fit = pg.relative_orientation(pg.project(pts, IO, e1), pg.project(pts, IO, e2), IO)
        except pg.DegenerateGeometryError as exc:
            assert "initial=" in str(exc)
            outcomes.add("ambiguous")
            # start values resolve it
            fit = pg.relative_orientation(
                pg.project(pts, IO, e1), pg.project(pts, IO, e2), IO, initial=(e1, e2)
            )
        else:
            outcomes.add("unique")
        assert fit.redundancy == 0 and math.isnan(fit.sigma0)
        assert np.abs(fit.pair.relative_rotation - e2.matrix).max() < 1e-9
    assert "ambiguous" in outcomes


def test_bad_values_and_shapes():
    _, _, _, xy1, xy2 = simulate(0)
    bad = xy1.copy()
    bad[3, 0] = np.nan
    with pytest.raises(pg.InputError, match="xy1"):
        pg.relative_orientation(bad, xy2, IO)
    with pytest.raises(pg.InputError, match="shape"):
        pg.relative_orientation(xy1, xy2[:-1], IO)
    with pytest.raises(pg.InputError, match="method"):
        pg.relative_orientation(xy1, xy2, IO, method="normal")
    with pytest.raises(pg.InputError, match="units"):
        pg.relative_orientation(xy1, xy2, IO, pg.InteriorOrientation(1000.0, unit="px"))
    with pytest.raises(pg.InputError, match="sigma"):
        pg.relative_orientation(xy1, xy2, IO, sigma=[1.0, 2.0])


def test_distortion_is_removed_first():
    dist = pg.BrownDistortion(k1=-0.05, k2=0.01)
    io = pg.InteriorOrientation(100.0, unit="mm", distortion=dist)
    e1, e2, _, xy1, xy2 = simulate(6, 0.6, io=io)
    fit = pg.relative_orientation(xy1, xy2, io, method="independent")
    R, b = truth(e1, e2)
    assert np.abs(fit.pair.relative_rotation - R).max() < 1e-9
    assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-9


def test_fit_family_fields_and_json():
    _, _, _, xy1, xy2 = simulate(1, noise=0.003)
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.003, ids=[f"t{i}" for i in range(30)])
    assert isinstance(fit, pg.Fit)
    assert set(fit.std_errors) == {"by", "bz", "omega2", "phi2", "kappa2"}
    assert fit.parallax.shape == (30,)
    assert fit.residuals.shape == (fit.inliers.sum(), 4)
    assert fit.correlation.shape == (5, 5)
    d = fit.to_dict()
    assert d["parameters"]["by"]["unit"] == "1"
    assert d["model_parameters"]["exterior2"]["X0"] in (1.0, -1.0)
    assert "y-parallaxes" not in fit.summary()  # the Fit summary; the report has its own text
    ind = pg.relative_orientation(xy1, xy2, IO, method="independent", sigma=0.003)
    assert set(ind.std_errors) == {"phi1", "kappa1", "omega2", "phi2", "kappa2"}


def _look_at(position, target, kappa):
    """An image at ``position`` looking at ``target``, turned by ``kappa`` about its axis."""
    z = position - target
    z = z / np.linalg.norm(z)  # the camera's +z points away from the scene
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    M = pg.opk_matrix(0.0, 0.0, kappa) @ np.vstack([x, np.cross(z, x), z])
    return pg.ExteriorOrientation.from_matrix(position, M, on_gimbal_lock="omega-zero")


@settings(max_examples=15)
@given(
    base=st.floats(10.0, 100.0),
    tilt1=st.floats(-0.7, 0.7),
    tilt2=st.floats(-0.7, 0.7),
    kappa1=st.floats(-math.pi, math.pi),
    kappa2=st.floats(-math.pi, math.pi),
    seed=st.integers(0, 1000),
)
def test_oblique_convergent_pairs_any_kappa(base, tilt1, tilt2, kappa1, kappa2, seed):
    """Oblique images (up to 40 degrees off nadir) converging on the scene, each turned by any
    kappa about its axis (e.g. adjacent strips flown in opposite directions)."""
    rng = np.random.default_rng(seed)
    pts = np.column_stack(
        [rng.uniform(-40, 40 + base, 40), rng.uniform(-40, 40, 40), rng.uniform(-15, 15, 40)]
    )
    centre = np.array([base / 2, 0.0, 0.0])
    e1 = _look_at(np.array([0.0, 100 * math.tan(tilt1), 100.0]), centre, kappa1)
    e2 = _look_at(np.array([base, 100 * math.tan(tilt2), 100.0]), centre, kappa2)
    xy1, xy2 = pg.project(pts, IO, e1), pg.project(pts, IO, e2)
    R, b = truth(e1, e2)
    for method in ("independent", "dependent"):
        try:
            fit = pg.relative_orientation(xy1, xy2, IO, method=method)
        except pg.DegenerateGeometryError as exc:  # the base across image 1's x axis
            assert method == "dependent" and "independent" in str(exc)
            assert abs(b[0]) < 0.05
            continue
        assert np.abs(fit.pair.relative_rotation - R).max() < 1e-9
        assert np.abs(fit.pair.base_in_camera1 - b).max() < 1e-9


def test_without_sigma_the_tau_test_finds_wrong_matches():
    """No a-priori sigma: sigma0 estimates the image noise, Pope's tau-test flags."""
    _, _, _, xy1, xy2 = simulate(12, 0.5, n=60, noise=0.004)
    xy2 = xy2.copy()
    xy2[[3, 17, 40]] += [[0.5, 0.3], [-0.4, 0.6], [0.2, -0.7]]
    fit = pg.relative_orientation(xy1, xy2, IO)
    assert fit.extras["test"] == "tau"
    assert sorted(np.flatnonzero(fit.flagged).tolist()) == [3, 17, 40]
    assert fit.sigma0 == pytest.approx(0.004, rel=0.3)  # unit weights: sigma0 in mm
