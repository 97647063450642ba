"""The RPC statistics: defects found by measurement, each with its test."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.examples.rpc import simulated_control
from photogeom.io import write_points
from photogeom.rpc import refine_rpc

WV2 = str(pg.datasets.path("worldview2"))


def _control_file(path, column: str | None, values):
    """The 4 simulated control points of a WorldView-2 image, with an extra column."""
    _, ground, _, observed = simulated_control()
    coords = np.column_stack([ground[:4], observed[:4]])
    extra = {} if column is None else {column: [float(v) for v in values]}
    write_points(path, [f"P{i}" for i in range(4)], coords, ["lon", "lat", "h", "col", "row"],
                 extra=extra)  # fmt: skip
    return ground[:4], observed[:4]


@pytest.mark.parametrize("model", ["shift", "affine"])
def test_refine_weight_column_is_relative_to_sigma(cli, tmp_path, model):
    # a weight column is unitless (docs/cli.md): a point's standard deviation is
    # --sigma / sqrt(weight). It used to replace --sigma by 1 / sqrt(weight): with weights
    # 1 and --sigma 0.3 the CLI's sigma0 was 0.3 times the library's (sigma = 0.3)
    rpc = pg.RPC.from_file(WV2)
    w = np.array([1.0, 4.0, 1.0, 0.25])
    p = tmp_path / "weighted.csv"
    ground, image = _control_file(p, "weight", w)
    code, out, err = cli("rpc", "refine", WV2, p, "--model", model, "--sigma", "0.3", "--json")
    assert code == 0, err
    data = json.loads(out)
    lib = refine_rpc(rpc, ground, image, model=model, sigma=0.3 / np.sqrt(w))
    assert data["sigma0"] == pytest.approx(lib.sigma0, rel=1e-9)
    for name, std in lib.std_errors.items():
        assert data["parameters"][name]["std"] == pytest.approx(std, rel=1e-9)
    # equal weights of 1 are the same as no weight column
    p1 = tmp_path / "ones.csv"
    _control_file(p1, "weight", np.ones(4))
    p0 = tmp_path / "plain.csv"
    _control_file(p0, None, None)
    s0 = [json.loads(cli("rpc", "refine", WV2, f, "--model", model, "--sigma", "0.3",
                         "--json")[1])["sigma0"] for f in (p1, p0)]  # fmt: skip
    assert s0[0] == pytest.approx(s0[1], rel=1e-12)


def test_refine_sigma_column_is_in_pixels(cli, tmp_path):
    # a sigma column gives each point's standard deviation in px (unchanged behaviour)
    rpc = pg.RPC.from_file(WV2)
    s = np.array([0.2, 0.4, 0.3, 0.5])
    p = tmp_path / "sigmas.csv"
    ground, image = _control_file(p, "sigma", s)
    code, out, err = cli("rpc", "refine", WV2, p, "--model", "affine", "--json")
    assert code == 0, err
    lib = refine_rpc(rpc, ground, image, model="affine", sigma=s)
    assert json.loads(out)["sigma0"] == pytest.approx(lib.sigma0, rel=1e-9)


@pytest.mark.parametrize("model", ["shift", "affine"])
def test_written_refined_rpc_does_not_keep_the_vendor_bias_error(cli, tmp_path, model):
    # WorldView-2's file gives ERR_BIAS 26.68 m, ERR_RAND 0.14 m. A bias-compensated model
    # written by 'rpc refine -o' kept ERR_BIAS 26.68 m when the correction folded (shift) and
    # lost both when it was re-fitted (affine); now ERR_BIAS is dropped (it described the bias
    # the correction removes) and ERR_RAND kept in both cases
    vendor = pg.RPC.from_file(WV2)
    assert vendor.err_bias == 26.68 and vendor.err_rand == 0.14
    p = tmp_path / "control.csv"
    _control_file(p, None, None)
    out = tmp_path / f"{model}_RPC.TXT"
    code, _, err = cli("rpc", "refine", WV2, p, "--model", model, "-o", out)
    assert code == 0, err
    written = pg.RPC.from_file(out)
    assert written.err_bias is None
    assert written.err_rand == 0.14
    # the library's folding says what it dropped
    ground, image = simulated_control()[1][:4], simulated_control()[3][:4]
    folded = refine_rpc(vendor, ground, image, model="shift").model.with_correction_folded()
    assert folded.err_bias is None and folded.err_rand == 0.14
    assert any("ERR_BIAS" in note for note in folded.notes)


def test_regularised_fit_does_not_depend_on_sigma_and_its_cofactor_is_documented():
    # docs/rpc.md and the fitting module stated lambda^2 sum c^2 next to the image term
    # divided by sigma^2, and the cofactor (A^T P A + lambda^2 S^2 I)^-1: both mean that
    # sigma changes the estimate. The code weights the pseudo-observations (lambda S /
    # sigma)^2, so the estimate is the same for every sigma (now documented) and the cofactor
    # is (A^T P A + (lambda S / sigma)^2 I)^-1
    from photogeom.rpc import fit_rpc_to_points

    rpc = pg.RPC.from_file(WV2)
    rng = np.random.default_rng(1)
    c0, c1, r0, r1 = rpc.image_bounds
    h = rng.uniform(0.0, 500.0, 30)
    lon, lat = rpc.localize(rng.uniform(c0, c1, 30), rng.uniform(r0, r1, 30), h)
    ground = np.column_stack([lon, lat, h])
    image = np.column_stack(rpc.project(lon, lat, h)) + rng.normal(0.0, 0.5, (30, 2))
    lam = 0.1
    fits = [fit_rpc_to_points(ground, image, sigma=s, regularization=lam) for s in (1.0, 5.0)]
    np.testing.assert_allclose(fits[0].parameters, fits[1].parameters, rtol=0, atol=1e-14)
    assert fits[0].sigma0 == pytest.approx(5.0 * fits[1].sigma0, rel=1e-12)
    # the cofactor Q (A^T P A) Q (the sandwich of the regularised estimate, checked
    # against finite differences in test_montecarlo_rpc.py) scales with sigma^2: with
    # a regularisation term that did not scale with 1/sigma^2 it would not
    np.testing.assert_allclose(fits[1].cofactor, 25.0 * fits[0].cofactor, rtol=1e-6,
                               atol=1e-9 * np.abs(fits[1].cofactor).max())  # fmt: skip


def test_intersection_with_parallel_rays_is_a_named_failure_not_a_result():
    # the same image twice: the rays coincide and the height is not determined. It used to
    # "converge" for some points (h = 28.87 m for a true 20 m, std of h 3.8e8 m, lon 231 deg)
    # and report "did not converge in 20 iterations" for others; now such points are NaN,
    # flagged degenerate, with a warning naming the cause (DegenerateGeometryError with
    # on_failure="raise"); points seen by a real stereo pair are unaffected
    import warnings

    from photogeom.errors import DegenerateGeometryError
    from photogeom.rpc import LocalizationWarning, intersect_rpc

    a = pg.RPC.from_file(pg.datasets.path("ikonos"))
    b = pg.RPC.from_file(pg.datasets.path("pleiades"))
    G = np.array([[-56.17, -34.90, 50.0], [-56.16, -34.91, 20.0], [-56.15, -34.89, 80.0]])
    obs = np.stack([np.column_stack(r.project(*G.T)) for r in (a, b, a)], axis=1)
    obs[:2, 2] += [0.3, -0.2]  # points 0, 1: seen twice in image a (and not in b)
    obs[:2, 1] = np.nan
    with pytest.warns(LocalizationWarning, match="parallel") as caught:
        res = intersect_rpc([a, b, a], obs)
    assert not any("did not converge" in str(w.message) for w in caught)
    assert res.degenerate.tolist() == [True, True, False]
    assert res.converged.tolist() == [False, False, True]
    assert np.all(np.isnan(res.ground[:2])) and np.all(np.isnan(res.std_prior[:2]))
    np.testing.assert_allclose(res.ground[2, :2], G[2, :2], rtol=0, atol=1e-10)
    assert res.to_dict()["degenerate"] == [True, True, False]
    with pytest.raises(DegenerateGeometryError, match="parallel"):
        intersect_rpc([a, b, a], obs, on_failure="raise")
    # a real stereo pair: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = intersect_rpc([a, b], obs[2:, :2])
    assert not ok.degenerate.any()


def test_refine_reports_the_a_priori_std_also_at_redundancy_zero(cli, tmp_path):
    # a shift from one control point (the usual bias compensation) has redundancy 0: the
    # a-posteriori std is undefined, but the std from --sigma is known (0.5 px for a0, b0).
    # The CLI showed '-' and JSON null only; now JSON gives std_prior (as fit.std_errors_prior)
    # and the parameter table the a-priori std, marked
    rpc = pg.RPC.from_file(WV2)
    p = tmp_path / "one.csv"
    ground, image = _control_file(p, None, None)
    p.write_text("\n".join(p.read_text().splitlines()[:2]) + "\n")  # header + first point
    code, out, err = cli("rpc", "refine", WV2, p, "--model", "shift", "--sigma", "0.5", "--json")
    assert code == 0, err
    par = json.loads(out)["parameters"]
    lib = refine_rpc(rpc, ground[:1], image[:1], model="shift", sigma=0.5)
    for name in ("a0", "b0"):
        assert par[name]["std"] is None
        assert par[name]["std_prior"] == pytest.approx(lib.std_errors_prior[name], rel=1e-12)
        assert par[name]["std_prior"] == pytest.approx(0.5, rel=1e-12)
    code, out, _ = cli("rpc", "refine", WV2, p, "--model", "shift", "--sigma", "0.5")
    # the parameter table shows the a-priori std where the a-posteriori one is undefined
    rows = [line for line in out.splitlines() if line.strip().startswith(("a0", "b0"))]
    assert len(rows) == 2 and all("0.5 (a priori)" in r for r in rows), out
    # with redundancy, std_prior of the affine model equals the library's for every parameter
    p4 = tmp_path / "four.csv"
    ground, image = _control_file(p4, None, None)
    data = json.loads(cli("rpc", "refine", WV2, p4, "--sigma", "0.3", "--json")[1])
    lib = refine_rpc(rpc, ground, image, model="affine", sigma=0.3)
    for name, std in lib.std_errors_prior.items():
        assert data["parameters"][name]["std_prior"] == pytest.approx(std, rel=1e-9)


def test_intersection_sigma_table_may_be_nan_where_a_point_is_not_seen():
    # image_points mark "not seen" by NaN; a per-observation sigma table (n, K) built the same
    # way was refused ("sigma: standard deviations must be positive"), though those entries
    # are never used. Now only the sigmas of existing observations are checked
    from photogeom.errors import InputError
    from photogeom.rpc import intersect_rpc

    a = pg.RPC.from_file(pg.datasets.path("ikonos"))
    b = pg.RPC.from_file(pg.datasets.path("pleiades"))
    G = np.array([[-56.17, -34.90, 50.0], [-56.16, -34.91, 20.0]])
    obs = np.stack([np.column_stack(r.project(*G.T)) for r in (a, b, a)], axis=1)
    obs[0, 2] = np.nan
    sig = np.array([[0.5, 0.8, np.nan], [0.5, 0.8, 0.6]])
    res = intersect_rpc([a, b, a], obs, sigma=sig)
    ref = intersect_rpc([a, b], obs[:1, :2], sigma=[0.5, 0.8])
    np.testing.assert_allclose(res.cofactor[0], ref.cofactor[0], rtol=1e-10)
    sig[1, 2] = np.nan  # an existing observation without a sigma is still refused
    with pytest.raises(InputError, match="point 1, image 2"):
        intersect_rpc([a, b, a], obs, sigma=sig)


def test_refine_ground_sigma_matches_monte_carlo_with_noisy_control_coordinates():
    # control points surveyed to 0.5 m (east, north) and 1 m (up) move their WorldView-2
    # image positions by about 1 px, more than the 0.3 px of image measurement: with the
    # ground taken as exact, the reported std of the affine correction was 4.9-6.1 times
    # too small (sigma0 6.7). ground_sigma propagates them through the RPC's Jacobian.
    # 400 trials: the std of an estimated std is 1/sqrt(2 * 399) = 3.5 %, so 12 % is 3.4 of
    # it; mean sigma0^2 has std sqrt(2 / 10 / 400) = 0.022 (redundancy 10), 0.1 is 4.5 of it
    rpc = pg.RPC.from_file(WV2)
    rng = np.random.default_rng(9)
    c0, c1, r0, r1 = rpc.image_bounds
    n = 8
    h = rng.uniform(0.0, 300.0, n)
    lon, lat = rpc.localize(rng.uniform(c0, c1, n), rng.uniform(r0, r1, n), h)
    G = np.column_stack([lon, lat, h])
    c, r = rpc.project(lon, lat, h)
    true = np.column_stack([c + 10.0, r - 7.0])
    gs = np.array([0.5, 0.5, 1.0])  # m east, north, up
    m_per_deg = np.radians(6378137.0)
    g_deg = np.column_stack([np.full(n, gs[0] / (m_per_deg * np.cos(np.radians(lat[0])))),
                             np.full(n, gs[1] / m_per_deg), np.full(n, gs[2])])  # fmt: skip
    P, S = [], []
    for _ in range(400):
        obs = true + rng.normal(0.0, 0.3, true.shape)
        noisy = G + rng.normal(0.0, 1.0, G.shape) * g_deg
        fit = refine_rpc(rpc, noisy, obs, model="affine", sigma=0.3, ground_sigma=gs)
        P.append(fit.parameters)
        S.append(fit.sigma0**2)
    ratio = np.std(P, axis=0, ddof=1) / np.array(list(fit.std_errors_prior.values()))
    np.testing.assert_allclose(ratio, 1.0, atol=0.12)
    assert np.mean(S) == pytest.approx(1.0, abs=0.1)
    # without ground errors the result is the same as before (weights 1 / sigma^2)
    exact = refine_rpc(rpc, G, true, model="affine", sigma=0.3)
    zero = refine_rpc(rpc, G, true, model="affine", sigma=0.3, ground_sigma=0.0)
    np.testing.assert_allclose(zero.parameters, exact.parameters, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        zero.cofactor, exact.cofactor, rtol=1e-9, atol=1e-9 * np.abs(exact.cofactor).max()
    )
    np.testing.assert_allclose(zero.residuals, exact.residuals, atol=1e-9)


def test_refine_cli_ground_sigma(cli, tmp_path):
    rpc = pg.RPC.from_file(WV2)
    p = tmp_path / "control.csv"
    ground, image = _control_file(p, None, None)
    args = ("rpc", "refine", WV2, p, "--model", "affine", "--sigma", "0.3", "--json")
    data = json.loads(cli(*args, "--ground-sigma", "0.5,0.5,1")[1])
    lib = refine_rpc(rpc, ground, image, model="affine", sigma=0.3, ground_sigma=[0.5, 0.5, 1])
    assert data["sigma0"] == pytest.approx(lib.sigma0, rel=1e-9)
    for name, std in lib.std_errors_prior.items():
        assert data["parameters"][name]["std_prior"] == pytest.approx(std, rel=1e-9)
    one = json.loads(cli(*args, "--ground-sigma", "0.5")[1])
    lib1 = refine_rpc(rpc, ground, image, model="affine", sigma=0.3, ground_sigma=0.5)
    assert one["sigma0"] == pytest.approx(lib1.sigma0, rel=1e-9)
    code, _, err = cli(*args, "--ground-sigma", "0.5,1")
    assert code == 2 and "--ground-sigma" in err


def test_metres_per_degree_against_pyproj_geodesics():
    """The WGS84 metres per degree (used for metric standard deviations and ground sigmas)
    against geodesic distances of small steps (pyproj.Geod) at h = 0."""
    import pyproj

    from photogeom.rpc.geodesy import metres_per_degree

    geod = pyproj.Geod(ellps="WGS84")
    lat = np.array([-80.0, -33.3, 0.0, 12.5, 47.0, 89.0])
    d = 1e-5
    _, _, de = geod.inv(np.zeros_like(lat), lat, np.full_like(lat, d), lat)
    _, _, dn = geod.inv(np.zeros_like(lat), lat - d / 2, np.zeros_like(lat), lat + d / 2)
    east, north = metres_per_degree(lat, np.zeros_like(lat))
    np.testing.assert_allclose(east, de / d, rtol=1e-7)
    np.testing.assert_allclose(north, dn / d, rtol=1e-7)
    # a height h scales both by (R + h) / R
    e2, n2 = metres_per_degree(lat, np.full_like(lat, 5000.0))
    assert np.all(e2[:-1] > east[:-1]) and np.all(n2 > north)
