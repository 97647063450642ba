"""absolute_orientation(..., robust="ransac") refines on the inliers with every option of the
method: precisions of both systems, covariances, sigma0_prior, start values and the direct
methods' options. Checked against the same method run on the inliers alone, with the
per-pair values selected by hand."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError

N = 20
OUTLIERS = [0, 7, 13]


def _data():
    rng = np.random.default_rng(21)
    x = rng.uniform(-50.0, 50.0, (N, 3))
    R = pg.opk_matrix(*np.radians([10.0, 20.0, 175.0])).T
    X = 1.2 * x @ R.T + np.array([4.0e5, 5.1e6, 300.0]) + rng.normal(0.0, 0.01, (N, 3))
    x = x + rng.normal(0.0, 0.004, (N, 3))
    X[OUTLIERS] += [[5.0, 0.0, 0.0], [0.0, -4.0, 2.0], [0.0, 0.0, 6.0]]
    return rng, x, X


def _cases(rng):
    sig_s = rng.uniform(0.002, 0.006, N)
    cov = np.einsum("ni,ij->nij", rng.uniform(0.005, 0.02, (N, 3)) ** 2, np.eye(3))
    full = np.zeros((3 * N, 3 * N))
    for i in range(N):  # correlated within a point, observations point by point
        full[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = cov[i] + 2e-5 * (1 - np.eye(3))
    return {
        "gh-sigma0-prior": ("gauss-helmert", {"sigma0_prior": 0.01}),
        "gh-both-sigmas": ("gauss-helmert", {"sigma_source": 0.004, "sigma_target": 0.01}),
        "gh-per-point-source": ("gauss-helmert", {"sigma_source": sig_s, "sigma_target": 0.01}),
        "gh-source-covariance": ("gauss-helmert", {"covariance_source": cov * 0.1,
                                                   "sigma_target": 0.01}),
        "gm-covariance": ("gauss-markov", {"covariance_target": cov, "sigma0_prior": 0.5}),
        "gm-full-covariance": ("gauss-markov", {"covariance": full}),
        "gm-initial-one-step": ("gauss-markov", {  # the step depends on the start
            "initial": (4.0e5 + 0.5, 5.1e6, 300.0, 1.2, *np.radians([10.5, 20.0, 175.0])),
            "max_iter": 1, "raise_on_failure": False}),
        "gh-iterative-tol": ("gauss-helmert", {"sigma_source": sig_s, "sigma_target": 0.01,
                                               "tol": 1e-3}),
        "closed-form-nearest": ("closed-form", {"nearest_rotation": True}),
        "closed-form-coplanar": ("closed-form", {"coplanar_threshold": 0.0}),
        "svd-symmetric": ("svd", {"scale_method": "symmetric", "sigma0_prior": 0.02}),
    }  # fmt: skip


def _subset(name, value, mask):
    if name not in ("sigma_source", "covariance_source", "covariance_target", "covariance"):
        return value
    if np.ndim(value) == 0:
        return value
    a = np.asarray(value)
    if a.shape == (3 * N, 3 * N):
        idx = np.repeat(mask, 3)
        return a[np.ix_(idx, idx)]
    return a[mask]


@pytest.mark.parametrize("case", list(_cases(np.random.default_rng(0))))
def test_ransac_refines_with_the_options_given(case):
    rng, x, X = _data()
    method, options = _cases(rng)[case]
    fit = pg.absolute_orientation(x, X, method, robust="ransac", threshold=0.1, rng=1,
                                  **options)  # fmt: skip
    mask = fit.inliers
    assert np.flatnonzero(~mask).tolist() == OUTLIERS
    ref = pg.absolute_orientation(x[mask], X[mask], method,
                                  **{k: _subset(k, v, mask) for k, v in options.items()})
    np.testing.assert_allclose(fit.parameters, ref.parameters, rtol=1e-10, atol=1e-9)
    assert fit.sigma0_prior == ref.sigma0_prior
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-7, atol=1e-30)
    # the direct call of the RANSAC function takes them too
    direct = pg.ransac_absolute_orientation(x, X, 0.1, method=method, rng=1, **options)
    np.testing.assert_allclose(direct.parameters, ref.parameters, rtol=1e-10, atol=1e-9)


def test_unknown_or_misshapen_refinement_options_are_named():
    _, x, X = _data()
    with pytest.raises(InputError, match=r"unexpected keyword argument.*sigma_sauce"):
        pg.ransac_absolute_orientation(x, X, 0.1, method="gauss-helmert", sigma_sauce=0.1)
    with pytest.raises(InputError, match=rf"sigma_source.*\({N},\)"):
        pg.absolute_orientation(x, X, "gauss-helmert", robust="ransac", threshold=0.1,
                                sigma_source=np.ones(N - 1))  # fmt: skip
    with pytest.raises(InputError, match="covariance_target"):
        pg.absolute_orientation(x, X, "gauss-markov", robust="ransac", threshold=0.1,
                                covariance_target=np.ones((N, 3)))  # fmt: skip
