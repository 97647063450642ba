"""Steps along a curved valley of the cost: geodesic acceleration of rejected steps.

A block with a camera per image (BAL) trades each image's focal length with its distance to
the ground and its radial distortion with both; the cost's valley along these trades is
curved, and the damped Gauss-Newton step, straight, overshoots it: rejected, the damping
rises until the steps are short enough, and the loop creeps along the valley (a simulated
1000-image BAL block took 67 iterations, 2000 images did not converge in 100). The
rejected step's geodesic acceleration (the second derivative of the residuals along the
step) bends it into the valley.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle import adjustment
from photogeom.bundle.options import BundleOptions


@pytest.fixture(scope="module")
def bal_block(tmp_path_factory):
    """30 FC6310 images with a camera each (f, k1, k2 free), 5 m and 2 degrees off."""
    sim = pg.simulate.uav_block(
        "FC6310",
        seed=1,
        strips=3,
        images_per_strip=10,
        tie_points_per_image=120,
        gcps="none",
        checks=0,
        gnss_sigma=None,
        imu_sigma_deg=None,
        min_rays=3,
    )
    path = tmp_path_factory.mktemp("bal") / "b30.bal"
    pg.bundle.write_bal(sim.block, path, drop_extras=True)
    return pg.bundle.read_bal(path)


def _run(block):
    opts = BundleOptions(datum="free", snooping=False).validate()
    problem = adjustment.Problem(block, opts)
    return adjustment.levenberg_marquardt(problem, problem.initial_state(), opts)


def test_rejected_steps_are_bent_into_the_valley(bal_block, monkeypatch):
    run = _run(bal_block)
    assert run.converged
    assert run.iterations <= 10  # 14 with the damping alone
    assert all(a > b for a, b in zip(run.history, run.history[1:]))
    monkeypatch.delattr(adjustment._BundleSteps, "accelerate")
    ref = _run(bal_block)
    assert ref.converged and ref.iterations == 14
    # the same minimum (both stop at ftol 1e-10 of the cost)
    assert run.history[-1] == pytest.approx(ref.history[-1], rel=1e-9)
    np.testing.assert_allclose(run.state.cal[:, 0], ref.state.cal[:, 0], atol=1e-3)  # f, px
    np.testing.assert_allclose(run.state.X, ref.state.X, atol=1e-5)  # m


def test_a_robust_loss_takes_no_accelerated_step(bal_block, monkeypatch):
    """The acceleration's second derivative is that of the squared residuals."""
    opts = BundleOptions(datum="free", snooping=False, loss="huber").validate()
    problem = adjustment.Problem(bal_block, opts)
    state = problem.initial_state()
    steps = adjustment._BundleSteps(problem, state, problem.cost(state)[1], opts.xtol)
    step, _ = steps.solve(1e-3)
    assert steps.accelerate(state, step, 1e-3) is None
