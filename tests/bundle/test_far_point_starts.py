"""Tie points seen in two images whose start lies hundreds of metres along their rays (as
nearly parallel rays of a GNSS/IMU start triangulate them: up to 330 m on the 250-image
ILCE-7RM2 block with 3000 tie points per image) do not hold back the adjustment: it
reaches the minimum of the block with good point starts, in as many iterations."""

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle.adjustment import Problem
from photogeom.bundle.options import BundleOptions

sys.path.insert(0, str(Path(__file__).parent))
from blocks import far_point_block


@pytest.fixture(scope="module")
def blocks():
    """The simulated block, its adjustment, and the block with 20 of its two-ray tie points
    moved to 1.6 times their distance from their first image's centre (170-220 m along
    their first ray)."""
    b, far, moved = far_point_block()
    assert np.linalg.norm(far.xyz[moved] - b.xyz[moved], axis=1).min() > 150.0
    return b, pg.bundle_adjust(b), far, moved


def test_far_two_ray_points_reach_the_same_minimum_as_fast(blocks):
    _, ref, far, _ = blocks
    fit = pg.bundle_adjust(far, max_iterations=30)
    assert ref.converged and fit.converged, fit.message
    # before: 16 iterations, most of them steps rejected for the far points
    assert fit.iterations <= ref.iterations + 1
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-8)
    np.testing.assert_allclose(fit.block.xyz, ref.block.xyz, atol=1e-5)
    np.testing.assert_allclose(fit.block.exterior, ref.block.exterior, atol=1e-7)


def test_point_steps_keep_each_point_at_its_lower_cost(blocks):
    """Each tie point of a trial ends at a cost no higher than at its trial position and at
    its start position (both with the trial's cameras), and in front of its cameras."""
    far = blocks[2]
    opts = BundleOptions().validate()
    problem = Problem(far, opts)
    s = problem.initial_state()
    rng = np.random.default_rng(0)
    nc = problem.m * problem.b + problem.ng * 11
    trial = problem.update(s, 1e-4 * rng.standard_normal(nc), np.zeros_like(s.X))
    trial.X[:] = s.X + 50.0 * rng.standard_normal(s.X.shape)  # many points made worse
    at_trial = problem.cost(trial)
    start = trial.copy()
    start.X[:] = s.X
    at_start = problem.cost(start)
    out, e2, depth, changed = problem.guard_point_steps(
        s, trial.copy(), at_trial[1].copy(), at_trial[2].copy()
    )
    assert changed
    tie = np.ones(problem.p, dtype=bool)
    tie[problem.control] = False  # held by their surveyed coordinates: not moved
    cost_out = np.bincount(problem.obs_j, weights=e2, minlength=problem.p)
    for _, e, _ in (at_trial, at_start):
        bound = np.bincount(problem.obs_j, weights=e, minlength=problem.p)
        assert np.all(cost_out[tie] <= bound[tie] * (1 + 1e-12) + 1e-9)
    np.testing.assert_array_equal(out.X[~tie], trial.X[~tie])
    assert np.all(depth > 0)
    # what the method reports is what the state gives
    _, e2_again, _ = problem.cost(out)
    np.testing.assert_allclose(e2_again, e2, rtol=1e-9, atol=1e-9)
