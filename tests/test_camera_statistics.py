"""Statistics of camera models and image orientation against Monte Carlo."""

from __future__ import annotations

import numpy as np

import photogeom as pg


def _three_images(k1: float):
    io_film = pg.InteriorOrientation(153.0, distortion=pg.BrownDistortion(k1=k1))
    io_digital = pg.InteriorOrientation.digital(4000.0, 2000.0, 1500.0)
    eos = [
        pg.ExteriorOrientation(0.0, 0.0, 1000.0, 0.02, -0.01, 0.1),
        pg.ExteriorOrientation(600.0, 0.0, 1000.0, -0.01, 0.03, -0.1),
        pg.ExteriorOrientation(300.0, 500.0, 1100.0, 0.01, 0.02, 1.0),
    ]
    return list(zip([io_film, io_digital, io_film], eos))


def test_intersection_std_with_distortion_matches_monte_carlo():
    # The measured (distorted) coordinates carry sigma; after undistortion a point at
    # normalised radius 0.31 with k1 = -0.3 has its noise scaled by about 1 / 0.8, which the
    # weights must carry (before: spread / reported std 1.05, 1.11, 1.13 for X, Y, Z).
    rng = np.random.default_rng(3)
    cams = _three_images(-0.3)
    sigma = np.array([0.006, 0.8, 0.002])  # mm, px, mm
    trials = 3000
    g = np.tile([350.0, 200.0, 100.0], (trials, 1))
    obs = np.stack([pg.project(g, io, eo) for io, eo in cams])
    obs = obs + rng.normal(size=obs.shape) * sigma[:, None, None]
    res = pg.space_intersection(obs, cams, sigma=sigma)
    # relative sampling error of a standard deviation from 3000 trials: 1 / sqrt(2 * 2999)
    # = 1.3 %; 5 % is about four of them
    ratio = res.points.std(axis=0, ddof=1) / res.std_prior.mean(axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.05)
    # E[sigma0^2] = 1; the mean of 3000 chi-square(3)/3 values has sampling error 1.5 %
    assert abs(np.mean(res.sigma0**2) - 1.0) < 0.06


def _pair(io: pg.InteriorOrientation, n: int):
    """A convergent pair at height 100 with base 60 and n points on rough terrain."""
    rng = np.random.default_rng(7)
    pts = np.column_stack(
        [rng.uniform(-35, 95, n), rng.uniform(-35, 35, n), rng.uniform(-15, 15, n)]
    )
    e1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.01, 0.1, -0.02)
    e2 = pg.ExteriorOrientation(60.0, 0.0, 100.0, -0.03, -0.1, 0.02)
    return pg.project(pts, io, e1), pg.project(pts, io, e2)


def test_relative_orientation_std_with_distortion_matches_monte_carlo():
    # sigma is that of the measured coordinates; the normalised radius reaches 1.1 here, where
    # k1 = -0.1 scales the noise of the undistorted coordinates by up to 1 / 0.6. Before, the
    # weights ignored that: spread / reported std of omega2 and phi2 1.16, 1.18, mean
    # sigma0^2 1.08; the same pair without distortion gives 1.06, 1.09, 0.98.
    io = pg.InteriorOrientation(
        100.0, x0=0.01, y0=-0.02, unit="mm", distortion=pg.BrownDistortion(k1=-0.1)
    )
    sd = 0.004
    xy1, xy2 = _pair(io, n=30)
    ref = pg.relative_orientation(xy1, xy2, io, sigma=sd)
    rng = np.random.default_rng(3)
    params, s02 = [], []
    for _ in range(300):
        a = xy1 + rng.normal(0, sd, xy1.shape)
        b = xy2 + rng.normal(0, sd, xy2.shape)
        f = pg.relative_orientation(a, b, io, sigma=sd, robust=False)
        params.append(f.parameters)
        s02.append(f.sigma0**2)
    ratio = np.std(params, axis=0, ddof=1) / np.array(list(ref.std_errors_prior.values()))
    # 300 trials: a standard deviation has sampling error 1 / sqrt(598) = 4.1 %; the mean
    # ratio over the five parameters (correlated) is bounded at 6 %, the worst at 14 %
    # (3.4 sampling errors); before the fix the mean was 1.08 and the worst 1.18
    assert abs(np.mean(ratio) - 1.0) < 0.06, ratio
    assert np.all(np.abs(ratio - 1.0) < 0.14), ratio
    # mean of 300 chi-square(25)/25 values: sampling error 1.6 %
    assert abs(np.mean(s02) - 1.0) < 0.05


def test_model_points_weight_the_two_images_as_the_orientation_does():
    # image 1 measured 8 times more precisely than image 2: the model points must be the
    # weighted intersection whose covariance model_points reports. Before, they were the
    # unweighted one: spread / reported std of Y 1.41 on average over the points (median
    # 1.07); now 0.98.
    io = pg.InteriorOrientation(100.0, x0=0.01, y0=-0.02, unit="mm")
    xy1, xy2 = _pair(io, n=30)
    s1, s2 = 0.001, 0.008
    sd = np.tile([s1, s1, s2, s2], (30, 1))
    ref = pg.relative_orientation(xy1, xy2, io, sigma=sd).model_points()
    rng = np.random.default_rng(4)
    points = []
    for _ in range(300):
        a = xy1 + rng.normal(size=xy1.shape) * s1
        b = xy2 + rng.normal(size=xy2.shape) * s2
        f = pg.relative_orientation(a, b, io, sigma=sd, robust=False)
        points.append(f.model_points().points)
    ratio = np.std(points, axis=0, ddof=1) / np.sqrt(np.einsum("nii->ni", ref.covariance_prior))
    # per point and axis the sampling error of a std from 300 trials is 4.1 %; the mean over
    # 30 (correlated) points is bounded at 8 %, every ratio at 20 % (4.9 sampling errors)
    assert np.all(np.abs(ratio.mean(axis=0) - 1.0) < 0.08), ratio.mean(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.2), ratio


def test_linear_dlt_statistics_are_those_of_the_image_coordinates():
    # close range, depth 2-12 m: the DLT denominator varies several-fold between points,
    # and the linear equations (image residual times denominator) must be weighted by it.
    # Before: mean sigma0^2 1.17 and spread / reported std up to 1.31 for correct sigma.
    rng = np.random.default_rng(11)
    eo = pg.ExteriorOrientation(1.0, -2.0, 3.0, 0.4, -0.6, 2.0)
    io = pg.InteriorOrientation.digital(4000.0, 3000.0, 2000.0)
    n = 15
    xn = rng.uniform(-0.7, 0.7, (n, 2))
    d = rng.uniform(2.0, 12.0, n)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * d[:, None]
    g = eo.position + pc @ eo.matrix
    xy = pg.project(g, io, eo)
    sig = rng.uniform(0.3, 1.5, (n, 2))
    ref = pg.estimate_dlt(g, xy, unit="px", sigma=sig, refine=False)
    params, s02 = [], []
    for _ in range(400):
        f = pg.estimate_dlt(
            g, xy + rng.normal(size=xy.shape) * sig, unit="px", sigma=sig, refine=False
        )
        params.append(f.parameters)
        s02.append(f.sigma0**2)
    ratio = np.std(params, axis=0, ddof=1) / np.array(list(ref.std_errors_prior.values()))
    # 400 trials: sampling error of one std 3.5 %; the mean of 11 correlated ratios within
    # 6 %, each within 14 % (4 sampling errors); E[sigma0^2] = 1 within 4 % (400 values of
    # chi-square(19)/19: sampling error 1.6 %)
    assert abs(ratio.mean() - 1.0) < 0.06, ratio
    assert np.all(np.abs(ratio - 1.0) < 0.14), ratio
    assert abs(np.mean(s02) - 1.0) < 0.05


def test_resection_cli_states_the_ground_unit_of_the_crs(tmp_path, cli):
    # control in a CRS in US survey feet: X0, Y0, Z0 and their standard deviations are in
    # US survey feet, which the output must say (it said "m")
    import json

    io = pg.InteriorOrientation(153.0, 0.01, -0.02)
    eo = pg.ExteriorOrientation(1000.0, 2000.0, 1500.0, 0.02, -0.03, 0.5)
    rng = np.random.default_rng(2)
    g = np.column_stack(
        [rng.uniform(600, 1400, 10), rng.uniform(1600, 2400, 10), rng.uniform(0, 200, 10)]
    )
    xy = pg.project(g, io, eo) + rng.normal(0, 0.004, (10, 2))
    path = tmp_path / "control.csv"
    rows = [f"p{i},{a[0]},{a[1]},{a[2]},{b[0]},{b[1]}" for i, (a, b) in enumerate(zip(g, xy))]
    path.write_text("id,X,Y,Z,x,y\n" + "\n".join(rows) + "\n")
    base = ("orient", "resection", path, "--f", "153", "--x0", "0.01", "--y0", "-0.02")
    code, out, err = cli(*base, "--sigma", "0.004", "--crs", "EPSG:2263", "--json")
    assert code == 0, err
    params = json.loads(out)["parameters"]
    assert [params[k]["unit"] for k in ("X0", "Y0", "Z0")] == ["ftUS"] * 3
    assert params["omega"]["unit"] == "rad"
    code, out, err = cli(*base, "--crs", "EPSG:25832", "--json")
    assert code == 0, err
    assert json.loads(out)["parameters"]["X0"]["unit"] == "m"


def test_dlt_cli_states_the_ground_unit_of_the_crs(tmp_path, cli):
    # L1..L3, L5..L7 are image units per ground unit and L9..L11 per ground unit: with a
    # CRS in US survey feet they were labelled px/m and 1/m
    import json

    io = pg.InteriorOrientation.digital(4000.0, 3000.0, 2000.0)
    eo = pg.ExteriorOrientation(1.0, -2.0, 3.0, 0.4, -0.6, 2.0)
    rng = np.random.default_rng(1)
    xn = rng.uniform(-0.7, 0.7, (12, 2))
    d = rng.uniform(2.0, 12.0, 12)
    g = (
        eo.position
        + (np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(12)]) * d[:, None]) @ eo.matrix
    )
    xy = pg.project(g, io, eo) + rng.normal(0, 0.5, (12, 2))
    path = tmp_path / "control.csv"
    rows = [f"p{i},{a[0]},{a[1]},{a[2]},{b[0]},{b[1]}" for i, (a, b) in enumerate(zip(g, xy))]
    path.write_text("id,X,Y,Z,x,y\n" + "\n".join(rows) + "\n")
    code, out, err = cli(
        "camera", "dlt", "estimate", path, "--unit", "px", "--crs", "EPSG:2263", "--json"
    )
    assert code == 0, err
    units = {k: v["unit"] for k, v in json.loads(out)["parameters"].items()}
    assert units["L1"] == "px/ftUS" and units["L11"] == "1/ftUS" and units["L4"] == "px"
    code, out, err = cli("camera", "dlt", "estimate", path, "--unit", "px", "--json")
    assert code == 0, err
    assert json.loads(out)["parameters"]["L1"]["unit"] == "px/m"
