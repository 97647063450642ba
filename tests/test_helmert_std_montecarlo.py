"""Standard deviations of the Helmert parameters in both EPSG conventions against the spread
of Monte-Carlo trials, at a large and at a small rotation.

The coordinate-frame rotations are the angles of ``R.T``: their standard deviations must be
propagated through that conversion (equal to the position-vector ones only to first order in
the rotation)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.orientation.absolute_stats import transpose_angles
from photogeom.rotation import rotation_from_angles

TRIALS = 800
SEC = 180.0 / np.pi * 3600.0


def test_transpose_angle_jacobian_against_central_differences():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.uniform([-3.0, -1.4, -3.0], [3.0, 1.4, 3.0])
        b, J = transpose_angles(*a)
        np.testing.assert_allclose(pg.opk_matrix(*b), pg.opk_matrix(*a).T, atol=1e-12)
        h = 1e-6
        Jn = np.column_stack(
            [
                (transpose_angles(*(a + h * e))[0] - transpose_angles(*(a - h * e))[0]) / (2 * h)
                for e in np.eye(3)
            ]
        )
        np.testing.assert_allclose(J, Jn, atol=1e-8)


@pytest.mark.parametrize(
    "angles",
    [(0.9, -0.6, 1.2), (2e-5, -1e-5, 3e-5)],  # tens of degrees; arc-seconds (datum shifts)
    ids=["large", "small"],
)
def test_helmert_std_in_both_conventions_match_monte_carlo(angles):
    rng = np.random.default_rng(11)
    n, sigma = 12, 0.02
    R = rotation_from_angles(*angles)  # transposed convention = position vector
    s, t = 1.0 + 3e-6, np.array([120.0, -80.0, 45.0])
    x = rng.uniform(-500, 500, (n, 3))
    X0 = s * x @ R.T + t
    Xt = X0[None] + rng.normal(scale=sigma, size=(TRIALS, n, 3))
    est = pg.absolute_orientation_batch(np.broadcast_to(x, Xt.shape), Xt, "svd")
    assert est.valid.all()
    fit = pg.estimate_transform("similarity3d", x, Xt[0], sigma0_prior=1.0)
    helmert = fit.extras["helmert"]
    k = sigma / fit.sigma0  # reported std scaled to the true sigma
    for conv in ("position_vector", "coordinate_frame"):
        Rc = est.rotation if conv == "position_vector" else np.swapaxes(est.rotation, 1, 2)
        ang = np.array([pg.angles_from_rotation(r, "transposed") for r in Rc]) * SEC
        spread = ang.std(axis=0, ddof=1)
        reported = np.array([helmert[conv][key][1] for key in ("rx", "ry", "rz")]) * k
        np.testing.assert_allclose(spread / reported, 1.0, atol=0.10, err_msg=conv)
    ds = (est.scale - 1.0) * 1e6
    assert ds.std(ddof=1) / (helmert["coordinate_frame"]["ds"][1] * k) == pytest.approx(
        1.0, abs=0.10
    )
