"""Check points of a free network: compared with their survey after the
similarity transformation onto it, their standard deviations in that datum (the cameras'
part included), against the spread of Monte-Carlo redraws after the same transformation."""

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle.result import similarity_residuals


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC6310", seed=1, strips=2, images_per_strip=4, tie_points_per_image=100, local_field=0.0
    )


def test_similarity_residuals_remove_a_similarity():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(6, 3)) * 50
    M = pg.opk_matrix(0.3, -0.2, 1.1)
    Y = 1.3 * X @ M.T + [10.0, -4.0, 2.0]
    np.testing.assert_allclose(similarity_residuals(X, Y), 0.0, atol=1e-9)
    assert np.isnan(similarity_residuals(X[:2], Y[:2])).all()
    line = np.outer(np.arange(4.0), [1.0, 2.0, 3.0])
    assert np.isnan(similarity_residuals(line, line)).all()


def test_free_network_check_std_follows_the_spread(sim):
    """Before: errors against the survey of about 1 m (the arbitrary datum of the start
    values, 56 GSD) and standard deviations of the triangulation alone; over 150 redraws
    the spread of the similarity residuals is now 0.97, 1.01, 1.02 times the reported
    standard deviations in X, Y, Z (30 redraws here: sampling error about 0.04)."""
    free = sim.block.without_datum_observations()
    chk = np.flatnonzero(free.role == "check")
    truth = sim.truth.xyz[chk]
    rng = np.random.default_rng(5)
    E, S = [], []
    for _ in range(30):
        uv = sim.ideal + rng.normal(0, 1, sim.ideal.shape) * free.observations.sigma[:, None]
        f = pg.bundle_adjust(
            free.with_observations(uv=uv), datum="free", snooping=False, point_covariance=True
        )
        E.append(similarity_residuals(f.block.xyz[chk], truth))
        S.append(f.point_std[chk])
    E, S = np.array(E), np.array(S)
    ratio = np.sqrt(np.mean(E**2, axis=(0, 1)) / np.mean(S**2, axis=(0, 1)))
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    # the errors the fit reports are those residuals against the survey: centimetres
    assert np.all(f.check["rmse"] < 0.05)
    assert "similarity" in f.check["convention"]
    assert any("similarity transformation" in n for n in f.notes)
    assert "after the similarity transformation onto the survey" in f.summary()
    from photogeom.report import bundle_report

    assert "7-parameter similarity" in bundle_report(f, "free").to_html()


def test_free_network_with_two_check_points_is_not_compared(sim):
    free = sim.block.without_datum_observations()
    chk = np.flatnonzero(free.role == "check")
    role = free.role.copy()
    role[chk[2:]] = "tie"
    f = pg.bundle_adjust(free.replace(role=role), datum="free", snooping=False,
                         point_covariance=True)  # fmt: skip
    assert np.isnan(f.check["errors"]).all()
    assert np.isnan(f.point_std[chk[:2]]).all()
    assert any("at least 3 check points" in n for n in f.notes)
