"""The adjustment with residual grids moves tie points started far along their rays by
point-only steps, as the bundle adjustment does: from two-ray tie points started 170-220 m
off it reaches the minimum of the good start in about as many iterations."""

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom.calibration import adjust_with_grids

sys.path.insert(0, str(Path(__file__).parent / "bundle"))
from blocks import far_point_block


@pytest.fixture(scope="module")
def blocks():
    """The simulated block and the block with 20 of its two-ray tie points moved to 1.6
    times their distance from their first image's centre (as in the bundle's test)."""
    b, far, moved = far_point_block()
    assert np.linalg.norm(far.xyz[moved] - b.xyz[moved], axis=1).min() > 150.0
    return b, far


def test_far_two_ray_points_reach_the_same_minimum_as_fast(blocks):
    good, far = blocks
    kw = dict(sigma_amplitude=0.5, std=False, max_iterations=30)
    ref = adjust_with_grids(good, 1000.0, **kw)
    fit = adjust_with_grids(far, 1000.0, **kw)
    assert ref.converged and fit.converged, fit.message
    # before: 13 iterations (5 from the good start), most of them steps rejected for the
    # far points, which the first accepted step had moved the wrong way
    assert fit.iterations <= ref.iterations + 1
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    np.testing.assert_allclose(fit.block.xyz, ref.block.xyz, atol=1e-5)
    np.testing.assert_allclose(fit.block.exterior, ref.block.exterior, atol=1e-7)
    key = good.image_ids[0]
    np.testing.assert_allclose(fit.grids[key].nodes, ref.grids[key].nodes, atol=1e-6)


def test_point_steps_compare_with_the_observations_corrected_by_the_grids(blocks):
    """The refinement of an accepted trial never raises its cost, and the cost it reports
    is the joint cost of the state it returns (grids' corrections and pseudo-observations
    included)."""
    from photogeom.bundle.options import BundleOptions
    from photogeom.calibration.in_adjustment import _GridProblem, _GridSteps

    far = blocks[1]
    opts = BundleOptions(initial_damping=1e-8).validate()
    gp = _GridProblem(far, opts, 1000.0, "image", "similarity", 1.0, None, 0.5, "mean")
    s = gp.bp.initial_state()
    rng = np.random.default_rng(0)
    z = 0.3 * rng.standard_normal(gp.n_grid)  # grids far from zero: their correction counts
    steps = _GridSteps(gp, (s, z), opts)
    nc = gp.bp.m * gp.bp.b + gp.bp.ng * 11
    dcg = np.zeros(gp.off_g)
    dcg[:nc] = 1e-5 * rng.standard_normal(nc)
    dp = 30.0 * rng.standard_normal(s.X.shape)  # many points made worse
    trial, cost, _ = steps.evaluate((s, z), (dcg, np.zeros_like(z), dp))
    (ts, tz), refined = steps.refine((s, z), trial, cost)
    assert refined < 0.5 * cost
    assert refined == pytest.approx(gp.cost(ts, tz)[0], rel=1e-10)
    assert np.all(gp.cost(ts, tz)[1] > 0)
