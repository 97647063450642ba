"""The covariance of a robust bundle adjustment is the M-estimator's sandwich.

Before, the covariance with a robust loss was ``sigma0^2`` times the inverse of the
IRLS-weighted normal matrix: over 400 Monte-Carlo redraws of every observation of a
simulated 8-image block the spread of the calibration was 0.91-0.96 times the reported
standard deviations with Cauchy's loss (calibration and exterior orientation 0.954 on
average; a linear M-estimator below: 0.89-0.93). The normal matrix now weights each image
point by ``slope^2 / spread`` of its score (``photogeom.bundle.robust.covariance_weights``):
0.973 on that block (the rest is sigma0, 3 % high with Cauchy's loss), 0.97-1.02 for the
linear M-estimator."""

import numpy as np
import pytest
from scipy import integrate

import photogeom as pg
from photogeom.bundle.robust import covariance_weights, influence_factors

SCALES = {"huber": 1.345, "cauchy": 2.385}


def _by_quadrature(loss, c, a):
    """(E[w + w' q], E[w^2 q] / (2 a)) for ``q = a x``, ``x`` chi-square(2), numerically."""
    if loss == "huber":
        w = lambda q: 1.0 if q <= c * c else c / np.sqrt(q)  # noqa: E731
        dw = lambda q: 0.0 if q <= c * c else -0.5 * c * q**-1.5  # noqa: E731
    else:
        w = lambda q: 1.0 / (1.0 + q / c**2)  # noqa: E731
        dw = lambda q: -1.0 / c**2 / (1.0 + q / c**2) ** 2  # noqa: E731

    def mean(g):
        f = lambda x: g(a * x) * 0.5 * np.exp(-0.5 * x)  # noqa: E731
        t = c * c / a
        if t > 200:
            return integrate.quad(f, 0, 200, limit=400)[0]
        return integrate.quad(f, 0, t, limit=400)[0] + integrate.quad(f, t, np.inf, limit=400)[0]

    return mean(lambda q: w(q) + dw(q) * q), mean(lambda q: w(q) ** 2 * q) / (2 * a)


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
@pytest.mark.parametrize("c", [0.7, 1.345, 2.385, 4.0])
def test_closed_forms_agree_with_quadrature(loss, c):
    a = np.array([1e-3, 0.01, 0.1, 0.3, 1.0, 2.0, 5.0, 20.0, 100.0])
    slope, spread = influence_factors(loss, c, a)
    ref = np.array([_by_quadrature(loss, c, x) for x in a])
    np.testing.assert_allclose(slope, ref[:, 0], rtol=1e-8)
    np.testing.assert_allclose(spread, ref[:, 1], rtol=1e-8)


def test_limits():
    assert influence_factors("squared", 1.0, 2.0) == (1.0, 1.0)
    np.testing.assert_array_equal(covariance_weights([0.2, 0.9], "squared", 1.0), 1.0)
    # the 2-D Huber estimator tends to the spatial median: efficiency pi / 4
    s, b = influence_factors("huber", 1.345, 1e8)
    assert s * s / b == pytest.approx(np.pi / 4, rel=1e-3)
    # both sides of the switch to the asymptotic series (Cauchy, x = c^2 / (2 a) = 50)
    s, b = influence_factors("cauchy", 1.0, 0.01 * np.array([1 - 1e-9, 1 + 1e-9]))
    assert abs(s[0] / s[1] - 1) < 1e-8 and abs(b[0] / b[1] - 1) < 1e-8
    for loss, c in SCALES.items():  # efficiencies of the default scales in 2-D
        s, b = influence_factors(loss, c, 1.0)
        assert 0.93 < s * s / b < 0.95


def _irls(J, E, loss, c, iterations=40):
    """Robust estimates (T, p) of ``theta`` in ``y = J theta + e`` (truth 0) for ``T``
    redraws ``E`` (T, n, 2) of 2-D errors, by IRLS on the points' squared norms; the final
    weights (T, n)."""
    theta = np.zeros((E.shape[0], J.shape[2]))
    for _ in range(iterations):
        e = E - np.einsum("nip,tp->tni", J, theta)
        q = np.einsum("tni,tni->tn", e, e)
        if loss == "huber":
            w = np.minimum(1.0, c / np.sqrt(np.maximum(q, 1e-300)))
        else:
            w = 1.0 / (1.0 + q / c**2)
        N = np.einsum("tn,nip,niq->tpq", w, J, J)
        g = np.einsum("tn,nip,tni->tp", w, J, E)
        theta = np.linalg.solve(N, g[..., None])[..., 0]
    return theta, w


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_sandwich_weights_match_a_monte_carlo_m_estimator(loss):
    """A linear model with 2-D observations, robust estimates over 2000 seeded redraws of
    normal errors (sampling error of a standard deviation 1.6 %): their spread equals the
    standard deviations from the sandwich weights within 5 %; the inverse of the IRLS-
    weighted normal matrix (the covariance before) is 8-10 % too large with Cauchy's."""
    c = SCALES[loss]
    rng = np.random.default_rng(12)
    n, p = 40, 3
    J = rng.normal(size=(n, 2, p))
    theta, w = _irls(J, rng.normal(size=(2000, n, 2)), loss, c)
    spread = theta.std(axis=0, ddof=1)
    N1 = np.einsum("nip,niq->pq", J, J)
    h = np.einsum("nip,pq,niq->n", J, np.linalg.inv(N1), J) / 2  # leverage per point
    D = covariance_weights(h, loss, c)
    new = np.sqrt(np.diag(np.linalg.inv(np.einsum("n,nip,niq->pq", D, J, J))))
    assert np.all(np.abs(spread / new - 1) < 0.05), spread / new
    old = np.mean(
        [np.sqrt(np.diag(np.linalg.inv(np.einsum("n,nip,niq->pq", x, J, J)))) for x in w],
        axis=0,
    )
    if loss == "cauchy":
        assert np.all(spread / old < 0.95), spread / old


@pytest.fixture(scope="module")
def small_block():
    sim = pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=3, tie_points_per_image=50, local_field=0.0
    )
    t = sim.truth
    ctrl = sim.block.role == "control"
    # start at the truth: fewer iterations per redraw
    start = sim.block.replace(
        exterior=t.exterior,
        xyz=np.where(ctrl[:, None], sim.block.xyz, t.xyz),
        calibrations=t.calibrations,
    )
    return sim, start


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_bundle_standard_deviations_match_the_monte_carlo_spread(small_block, loss):
    """200 seeded redraws of every observation (image points, GNSS, IMU, control) of a
    6-image block: the spread of the calibration and the projection centres against the
    mean reported standard deviation, and sigma0^2 (a few per cent high with Cauchy's loss,
    see docs/bundle-adjustment.md)."""
    sim, b = small_block
    t = sim.truth
    ctrl = b.role == "control"
    sig = b.observations.sigma[:, None]
    rng = np.random.default_rng(31)
    est, std, s02 = [], [], []
    for _ in range(200):
        uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * sig
        gnss = t.exterior[:, :3] + rng.normal(0, 1, b.gnss.shape) * b.gnss_sigma
        imu = t.exterior[:, 3:] + rng.normal(0, 1, b.imu.shape) * b.imu_sigma
        xyz = b.xyz.copy()
        xyz[ctrl] = t.xyz[ctrl] + rng.normal(0, 1, (int(ctrl.sum()), 3)) * b.point_sigma[ctrl]
        redrawn = b.with_observations(uv=uv).replace(gnss=gnss, imu=imu, xyz=xyz)
        fit = pg.bundle_adjust(redrawn, loss=loss, snooping=False, ftol=1e-6, xtol=1e-6)
        (cam,) = fit.calibration
        names = [n for n, v in fit.calibration_std[cam].items() if np.isfinite(v)]
        est.append([fit.calibration[cam][n] for n in names] + [*fit.block.exterior[:, :3].flat])
        std.append([fit.calibration_std[cam][n] for n in names] + [*fit.exterior_std[:, :3].flat])
        s02.append(fit.sigma0**2)
    ratio = np.std(est, axis=0, ddof=1) / np.mean(std, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    assert abs(np.mean(ratio) - 1) < 0.05, ratio
    assert np.mean(s02) == pytest.approx(1.0, abs=0.08)
