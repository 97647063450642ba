"""``register_clouds`` (``cloud register``): sigma0 from the residuals, whatever the chunking.

Before: sigma0 came from ``v'v = s^2 a - 2 s trace(R H) + b`` of the moments, which loses
~1e-16 spread^2 / residual^2 of itself to cancellation: on 3e5 UTM points with 1 cm noise
it was 0.0100026972 (chunk 1e6), 0.0100026980 (chunk 5e4), 0.0100026976 (chunk 7777) where
the residuals give 0.0100026973270. Now a second pass sums the residuals of the solution.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import photogeom as pg
from photogeom.io.cloud import write_cloud

N = 3000


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    d = tmp_path_factory.mktemp("register")
    rng = np.random.default_rng(11)
    src = np.column_stack(
        [rng.uniform(0, 800, N), rng.uniform(0, 600, N), rng.uniform(0, 50, N)]
    ) + np.array([500000.0, 5400000.0, 300.0])
    R = pg.opk_matrix(0.001, -0.002, 0.03)
    tgt = 1.00002 * src @ R.T + np.array([12.0, -30.0, 5.0]) + rng.normal(0, 0.01, (N, 3))
    return (
        write_cloud(d / "src.las", src, crs="EPSG:25832"),
        write_cloud(d / "tgt.las", tgt, crs="EPSG:25832"),
    )


def _exact_ssr(fit, x, X) -> float:
    """sum |s R x + t - X|^2 of the fit's transformation, in exact rational arithmetic."""
    sR = [[Fraction(float(fit.scale)) * Fraction(float(r)) for r in row] for row in fit.rotation]
    t = [Fraction(float(v)) for v in fit.translation]
    total = Fraction(0)
    for p, q in zip(x.tolist(), X.tolist()):
        fp = [Fraction(v) for v in p]
        for k in range(3):
            v = sR[k][0] * fp[0] + sR[k][1] * fp[1] + sR[k][2] * fp[2] + t[k] - Fraction(q[k])
            total += v * v
    return float(total)


@pytest.mark.parametrize("check_every", [0, 7])
def test_sigma0_is_that_of_the_residuals_whatever_the_chunk_size(clouds, check_every):
    from photogeom.io.cloud import read_cloud_xyz

    src, tgt = clouds
    regs = [
        pg.distributed.register_clouds(
            src, tgt, chunk_size=c, check_every=check_every, scheduler="sync"
        )
        for c in (N, 1000, 337)
    ]
    x, X = read_cloud_xyz(src), read_cloud_xyz(tgt)
    control = np.ones(N, dtype=bool)
    if check_every:
        control[::check_every] = False
    for reg in regs:
        fit = reg.fit
        ssr = _exact_ssr(fit, x[control], X[control])
        assert fit.extras["sum_squared_residuals"] == pytest.approx(ssr, rel=1e-12, abs=0)
        assert fit.sigma0 == pytest.approx(np.sqrt(ssr / fit.redundancy), rel=1e-12, abs=0)
        assert reg.control_rmse == pytest.approx(np.sqrt(ssr / reg.n_control), rel=1e-12, abs=0)
        # the covariance is sigma0^2 times the cofactor of the moments
        np.testing.assert_allclose(fit.covariance, fit.sigma0**2 * fit.cofactor, rtol=1e-12)
    s0 = [r.fit.sigma0 for r in regs]
    assert max(s0) - min(s0) <= 1e-12 * s0[0]
    if check_every:
        assert regs[0].n_check == len(range(0, N, check_every))
        np.testing.assert_allclose(regs[1].check_rms, regs[0].check_rms, rtol=1e-9)
