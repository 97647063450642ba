"""sigma0, the global test and variance components with a robust loss: consistent under
normal errors (photogeom.bundle.robust), checked against numerical integration and against
Monte-Carlo redraws of a simulated block's noise."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

import photogeom as pg
from photogeom.bundle.robust import (
    consistent_variance_factor,
    expected_weighted_squares,
    weighted_square_factor,
)

SCALES = {"huber": 1.345, "cauchy": 2.385}


def _kappa_by_quadrature(loss, c, a):
    """E[w(a q) q] / 2 for q ~ chi-square(2), integrated numerically."""

    def w(e2):
        if loss == "huber":
            return min(1.0, c / np.sqrt(e2)) if e2 > 0 else 1.0
        return 1.0 / (1.0 + e2 / c**2)

    f = lambda q: w(a * q) * q * 0.5 * np.exp(-0.5 * q)  # noqa: E731
    t = c * c / a
    return (integrate.quad(f, 0, t, limit=200)[0] + integrate.quad(f, t, np.inf, limit=200)[0]) / 2


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from(["huber", "cauchy"]),
    st.floats(0.5, 4.0),
    st.floats(1e-3, 400.0),
)
def test_closed_forms_agree_with_quadrature(loss, c, a):
    assert weighted_square_factor(loss, c, a) == pytest.approx(
        _kappa_by_quadrature(loss, c, a), rel=1e-7, abs=1e-12
    )


def test_kappa_limits():
    for loss, c in SCALES.items():
        assert weighted_square_factor(loss, c, 1e-9) == pytest.approx(1.0, abs=1e-6)
        k = [weighted_square_factor(loss, c, a) for a in (0.25, 1.0, 4.0)]
        assert 1.0 > k[0] > k[1] > k[2] > 0.0
    assert weighted_square_factor("squared", 1.0, 3.0) == 1.0


def test_squared_loss_is_the_textbook_estimate():
    h = np.array([0.2, 0.5, 0.9])
    np.testing.assert_allclose(expected_weighted_squares(h, "squared", 1.0), 2 * (1 - h))
    assert consistent_variance_factor(12.0, 6, None, None, "squared", 1.0) == (2.0, 1.0)


@settings(max_examples=30, deadline=None)
@given(st.sampled_from(["huber", "cauchy"]), st.floats(0.05, 20.0), st.integers(0, 10**6))
def test_the_fixed_point_solves_its_equation(loss, s2_true, seed):
    """v'PWv built from the model's own expectation gives back its variance factor."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(0.0, 0.8, 200)
    w = rng.uniform(0.3, 1.0, 200)
    red = 2.0 * float(np.sum(1 - w * h)) + 25.0  # 25 from prior observations
    other = red - 2.0 * float(np.sum(1 - w * h))
    expected = float(np.sum(expected_weighted_squares(h, loss, SCALES[loss], s2_true)))
    vtpv = s2_true * (expected + other)
    s2, k = consistent_variance_factor(vtpv, red, h, w, loss, SCALES[loss])
    assert s2 == pytest.approx(s2_true, rel=1e-6)
    assert 0 < k < 1


@pytest.fixture(scope="module")
def clean_block():
    sim = pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=120, local_field=0.0
    )
    return sim


def _redraws(sim, loss, n, factor=1.0, **options):
    """sigma0 over ``n`` redraws of normal image noise (``factor`` x the a-priori sigma)."""
    b = sim.block
    sig = b.observations.sigma
    rng = np.random.default_rng(11)
    out = []
    for _ in range(n):
        uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * sig[:, None] * factor
        out.append(pg.bundle_adjust(b.with_observations(uv=uv), loss=loss, **options))
    return out


@pytest.mark.parametrize(("loss", "low", "high"), [("huber", 0.97, 1.03), ("cauchy", 1.0, 1.08)])
def test_sigma0_is_consistent_on_clean_data(clean_block, loss, low, high):
    """Before: mean sigma0 0.90 (Huber) and 0.84 (Cauchy) on such a block; standard
    deviations 10-16 % too small and the global test failing clean data."""
    fits = _redraws(clean_block, loss, 6, snooping=False)
    s0 = np.mean([f.sigma0 for f in fits])
    assert low < s0 < high
    # the test statistic follows the sigma0: within its interval for most redraws
    assert sum(bool(f.chi2["passed"]) for f in fits) >= 3


def test_variance_component_of_the_images_with_huber(clean_block):
    """Image noise twice its a-priori sigma: the image group's factor comes out near 2
    (before: 1.8)."""
    fits = _redraws(clean_block, "huber", 3, factor=2.0, snooping=False, variance_components=True)
    f = np.mean([x.variance_components["factors"]["image_tie"] for x in fits])
    assert f == pytest.approx(2.0, rel=0.04)


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_global_test_is_the_least_squares_one(clean_block, loss):
    """Review 8: the global test of a robust fit used v'PWv / kappa, whose mean was 6.5 %
    above r with Cauchy's loss and whose spread was 1.24 times chi-square's (kappa taken at
    the estimated variance): 63 % (Cauchy) and 91 % (Huber) of 300 clean redraws passed at
    5 %. It now tests the least-squares v'Pv of the final linearisation: on clean data the
    statistic of the least-squares fit, 94.7 % and 95.3 % passing over 300 redraws."""
    sim = clean_block
    b = sim.block
    rng = np.random.default_rng(21)
    uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * b.observations.sigma[:, None]
    noisy = b.with_observations(uv=uv)
    robust = pg.bundle_adjust(noisy, loss=loss, snooping=False)
    ls = pg.bundle_adjust(noisy, snooping=False)
    assert robust.chi2["dof"] == ls.chi2["dof"]
    assert robust.chi2["statistic"] == pytest.approx(ls.chi2["statistic"], rel=1e-5)


def test_global_test_still_fails_on_a_muted_blunder(clean_block):
    """A 40 px blunder, down-weighted by Cauchy's loss (sigma0 stays near 1), still fails
    the global test, and the w-test names it."""
    sim = clean_block
    b = sim.block
    rng = np.random.default_rng(22)
    uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * b.observations.sigma[:, None]
    k = int(np.flatnonzero(b.role[b.obs_point] == "tie")[10])
    uv[k, 0] += 40.0
    fit = pg.bundle_adjust(b.with_observations(uv=uv), loss="cauchy")
    assert fit.sigma0 < 1.15
    assert not fit.chi2["passed"] and fit.chi2["statistic"] > fit.chi2["upper"]
    assert fit.snooping["flagged"][0][1] == b.observations.point_ids[k]


def test_results_name_the_loss_and_its_scale(clean_block):
    """summary(), to_dict() and the HTML report say which loss and scale the adjustment
    used (before: the summary named no loss, to_dict() and the report no scale)."""
    from photogeom.report.bundle import bundle_report

    b = clean_block.block
    fit = pg.bundle_adjust(b, loss="cauchy", loss_scale=3.0, snooping=False)
    d = fit.to_dict()
    assert d["solver"]["loss"] == "cauchy" and d["solver"]["loss_scale"] == 3.0
    assert "loss: cauchy, scale 3 a-priori sigmas" in fit.summary()
    assert "loss cauchy (scale 3 a-priori sigmas)" in bundle_report(fit).to_html()
    ls = pg.bundle_adjust(b, snooping=False)
    assert ls.to_dict()["solver"]["loss_scale"] is None
    assert "loss: squared (least squares)" in ls.summary()
