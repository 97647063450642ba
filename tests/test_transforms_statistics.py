"""The transformation and absolute-orientation statistics: regressions of defects
found by measurement (Monte Carlo against reported standard deviations, stochastic models)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg


def _problem(n: int = 10, scale: float = 1.5, seed: int = 6):
    rng = np.random.default_rng(seed)
    src = rng.uniform(-50.0, 50.0, (n, 3))
    R = pg.opk_matrix(0.7, -0.4, 2.2).T
    tgt = scale * src @ R.T + np.array([1000.0, 2000.0, 300.0])
    return rng, src, tgt


def _blocks(rng, n: int) -> np.ndarray:
    L = rng.normal(size=(n, 3, 3)) * 0.02 + np.eye(3) * 0.03
    return L @ L.transpose(0, 2, 1)


# --- estimate_transform("similarity3d" / "rigid3d") with per-coordinate precision -----------


@pytest.mark.parametrize("model", ["similarity3d", "rigid3d"])
@pytest.mark.parametrize("kind", ["weights", "covariance", "full"])
def test_absolute_models_take_per_coordinate_precision(model, kind):
    # estimate_transform documents weights per coordinate (n, d) and covariances (n, d, d) /
    # (n d, n d) for every model; the 3D similarity and rigid models refused them with an
    # error naming method='gauss-markov', an argument estimate_transform does not have
    rng, src, tgt = _problem(scale=1.5 if model == "similarity3d" else 1.0)
    n = src.shape[0]
    if kind == "weights":
        sa = rng.uniform(0.01, 0.1, (n, 3))
        opts = {"weights": 1.0 / sa**2}
        ref_opts = {"weights": 1.0 / sa**2}
        X = tgt + rng.normal(size=(n, 3)) * sa
    else:
        C = _blocks(rng, n)
        X = tgt + np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.normal(size=(n, 3)))
        if kind == "full":
            full = np.zeros((3 * n, 3 * n))
            for i in range(n):
                full[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = C[i]
            C = full
        opts = {"covariance": C, "sigma0_prior": 2.0}
        ref_opts = {"covariance_target": C, "sigma0_prior": 2.0}
    fit = pg.estimate_transform(model, src, X, **opts)
    ref = pg.absolute_orientation(
        src, X, "gauss-markov", with_scale=model == "similarity3d", **ref_opts
    )
    np.testing.assert_allclose(fit.parameters, ref.parameters, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-7, atol=1e-18)
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    assert fit.redundancy == ref.redundancy


def test_similarity3d_covariance_std_matches_monte_carlo():
    # 400 trials: the relative sampling error of a standard deviation is 1/sqrt(2 * 400) =
    # 3.5 %; 0.85-1.15 is over 4 of those for each of the 7 parameters
    rng, src, tgt = _problem(seed=16)
    n = src.shape[0]
    C = _blocks(rng, n)
    Lc = np.linalg.cholesky(C)
    est = []
    for _ in range(400):
        X = tgt + np.einsum("nij,nj->ni", Lc, rng.normal(size=(n, 3)))
        est.append(pg.estimate_transform("similarity3d", src, X, covariance=C).parameters)
    fit = pg.estimate_transform("similarity3d", src, tgt, covariance=C)
    reported = np.array(list(fit.std_errors_prior.values()))
    ratio = np.std(est, axis=0) / reported
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio


# --- absolute_orientation("gauss-helmert", weights=..., sigma0_prior=...) ---------------------


def test_gauss_helmert_point_weights_are_p_itself():
    # weights are the diagonal of P for every method (docs: "weights are the diagonal of P;
    # sigma_* and covariance_* give P = sigma0_prior^2 C^-1"). The Gauss-Helmert method turned
    # weights into sigmas 1/sqrt(w) and then applied sigma0_prior^2 again: sigma0 grew with
    # sigma0_prior (0.748 -> 1.496 for sigma0_prior 1 -> 2) and std_errors_prior did not
    rng, src, tgt = _problem(seed=7)
    n = src.shape[0]
    sp = rng.uniform(0.01, 0.05, n)
    x = src + rng.normal(size=(n, 3)) * sp[:, None]
    X = tgt + rng.normal(size=(n, 3)) * sp[:, None]
    w = 1.0 / sp**2
    one = pg.absolute_orientation(x, X, "gauss-helmert", weights=w)
    two = pg.absolute_orientation(x, X, "gauss-helmert", weights=w, sigma0_prior=2.0)
    # the same P: the same estimate and a-posteriori statistics
    np.testing.assert_allclose(two.parameters, one.parameters, rtol=0, atol=1e-10)
    assert two.sigma0 == pytest.approx(one.sigma0, rel=1e-9)
    np.testing.assert_allclose(two.covariance, one.covariance, rtol=1e-8)
    # the a-priori covariance scales with sigma0_prior^2, the w-test with 1 / sigma0_prior
    np.testing.assert_allclose(two.covariance_prior, 4.0 * one.covariance_prior, rtol=1e-8)
    np.testing.assert_allclose(
        two.snooping().statistic, one.snooping().statistic / 2.0, rtol=1e-8
    )
    # and the same P as the sigmas sigma0_prior / sqrt(w) in both systems
    sig = 2.0 / np.sqrt(w)
    ref = pg.absolute_orientation(
        x, X, "gauss-helmert", sigma_source=sig, sigma_target=sig, sigma0_prior=2.0
    )
    assert two.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    np.testing.assert_allclose(two.covariance, ref.covariance, rtol=1e-8)


# --- per-coordinate weights (3n,) in RANSAC and iterated data snooping ------------------------


def _blunder_problem():
    rng, src, tgt = _problem(n=12, seed=5)
    sa = rng.uniform(0.01, 0.05, (12, 3))
    X = tgt + rng.normal(size=(12, 3)) * sa
    X[4] += [0.5, 0.0, 0.0]
    return src, X, 1.0 / sa**2


def test_snooping_takes_flat_per_coordinate_weights():
    # absolute_orientation takes per-coordinate weights as (n, 3) or (3n,); iterated snooping
    # subset (n, 3) but passed (3n,) on unchanged once a point was removed: InputError
    # "expected shape (11,) ... got (36,)" instead of the result
    src, X, w = _blunder_problem()
    a = pg.snooping_absolute_orientation(src, X, "gauss-markov", weights=w, sigma="prior")
    b = pg.snooping_absolute_orientation(
        src, X, "gauss-markov", weights=w.reshape(-1), sigma="prior"
    )
    assert a.extras["removed"] == b.extras["removed"] == [4]
    np.testing.assert_allclose(b.parameters, a.parameters, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-10)


def test_ransac_takes_flat_per_coordinate_weights():
    # the refinement indexed (3n,) weights with the (n,) inlier mask: IndexError
    src, X, w = _blunder_problem()
    a = pg.ransac_absolute_orientation(src, X, 0.2, method="gauss-markov", weights=w, rng=1)
    b = pg.ransac_absolute_orientation(
        src, X, 0.2, method="gauss-markov", weights=w.reshape(-1), rng=1
    )
    assert not a.inliers[4] and a.inliers.sum() == 11
    np.testing.assert_array_equal(b.inliers, a.inliers)
    np.testing.assert_allclose(b.parameters, a.parameters, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-10)


def test_ransac_refuses_weights_of_the_wrong_shape_by_name():
    src, X, _ = _blunder_problem()
    with pytest.raises(pg.InputError, match=r"weights: expected shape \(12,\)"):
        pg.ransac_absolute_orientation(src, X, 0.2, weights=np.ones(13), rng=1)


# --- Gauss-Helmert with the precision of one system only --------------------------------------


@pytest.mark.parametrize(
    "given, missing",
    [
        ({"sigma_target": 0.02}, "source"),
        ({"sigma_target": np.full(10, 0.02)}, "source"),
        ({"sigma_source": 0.02}, "target"),
    ],
)
def test_gauss_helmert_says_what_it_assumed_for_the_other_system(given, missing):
    # with sigma_target=0.02 alone the source was silently taken with sigma 1 (weight 1):
    # sigma0 0.026 on data whose target noise is exactly 0.02 and whose source noise is 0.02,
    # and nothing said so (the note only gave a prescale factor of 0.02)
    rng, src, tgt = _problem(seed=3)
    x = src + rng.normal(size=src.shape) * 0.02
    X = tgt + rng.normal(size=tgt.shape) * 0.02
    fit = pg.absolute_orientation(x, X, "gauss-helmert", **given)
    text = " ".join(fit.notes)
    assert f"no precision given for the {missing} coordinates" in text
    assert "sigma0_prior = 1" in text
    both = pg.absolute_orientation(x, X, "gauss-helmert", sigma_source=0.02, sigma_target=0.02)
    none = pg.absolute_orientation(x, X, "gauss-helmert")
    for f in (both, none):
        assert not any("no precision given" in note for note in f.notes)


# --- orient absolute --convention direct: standard deviations of the direct angles ------------


def test_direct_angle_std_matches_monte_carlo():
    # the parameters (and their std) are the transposed-convention angles; the direct angles
    # (R = M(b)) printed with --convention direct had no standard deviation. Their covariance
    # is J C J.T of the exact conversion; at a large rotation it differs from the transposed
    # one (here by 1.24x in omega), so copying the transposed std would be wrong. 500 trials:
    # 3.2 % sampling error of a std; 0.87-1.13 is 4 of those
    from photogeom.cli.orient_absolute import _angle_std

    rng = np.random.default_rng(61)
    n = 10
    src = rng.uniform(-50.0, 50.0, (n, 3))
    R = pg.opk_matrix(0.9, 1.1, 2.5).T
    tgt = 1.2 * src @ R.T + np.array([10.0, 20.0, 30.0])
    sig = 0.05
    direct = []
    for _ in range(500):
        f = pg.absolute_orientation(src, tgt + rng.normal(size=(n, 3)) * sig, sigma_target=sig)
        direct.append(f.angles("direct", "deg"))
    # the helper gives a-posteriori std; divided by sigma0 they are the a-priori ones
    one = pg.absolute_orientation(src, tgt + rng.normal(size=(n, 3)) * sig, sigma_target=sig)
    reported = np.array(_angle_std(one, "direct", "deg")) / one.sigma0
    ratio = np.std(direct, axis=0) / reported
    assert np.all((ratio > 0.87) & (ratio < 1.13)), ratio
    transposed = np.array(_angle_std(one, "transposed", "deg")) / one.sigma0
    assert np.max(reported / transposed) > 1.15


def test_cli_prints_the_std_of_the_angles_in_the_chosen_convention(cli):
    import json

    from photogeom import datasets
    from photogeom.cli.orient_absolute import _angle_std

    lidar = str(datasets.path("lidar_wang2014"))
    t = datasets.load("lidar_wang2014")
    fit = pg.absolute_orientation(np.c_[t["x"], t["y"], t["z"]], np.c_[t["X"], t["Y"], t["Z"]])
    for conv in ("transposed", "direct"):
        code, out, err = cli("orient", "absolute", lidar, "--json", "--convention", conv,
                             "--angle-unit", "gon")
        assert code == 0, err
        std = json.loads(out)["angles"]["std"]
        expect = _angle_std(fit, conv, "gon")
        assert [std[a] for a in ("omega", "phi", "kappa")] == pytest.approx(expect, rel=1e-9)
        code, out, err = cli("orient", "absolute", lidar, "--convention", conv,
                             "--angle-unit", "gon")
        assert code == 0, err
        assert f"std. dev. of these angles (a posteriori): omega {expect[0]:.3g} gon" in out
    # the transposed std are those of the parameter table, in gon
    tr = _angle_std(fit, "transposed", "gon")
    assert tr[0] == pytest.approx(fit.std_errors["omega"] * 200.0 / np.pi, rel=1e-12)
    # the raw closed form's direct reading is not a function of the rotation angles: no std
    cf = pg.absolute_orientation(np.c_[t["x"], t["y"], t["z"]], np.c_[t["X"], t["Y"], t["Z"]],
                                 "closed-form")
    assert _angle_std(cf, "direct", "gon") is None
    assert _angle_std(cf, "transposed", "gon") is not None
