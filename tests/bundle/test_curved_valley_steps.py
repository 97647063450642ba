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


def test_a_retry_solves_with_the_rejected_steps_factor(bal_block, monkeypatch):
    """One factorisation per damping trial: the accelerated retry of a rejected step solves
    the same damped matrix for another right-hand side with that step's factor (before, a
    second reduction and factorisation per retry)."""
    import photogeom.adjust.schur as schur

    counts = {"factor": 0, "solve": 0, "retry": 0}
    real_factorize = schur.factorize
    real_solve = adjustment._BundleSteps.solve
    real_accelerate = adjustment._BundleSteps.accelerate

    def factorize(*a, **k):
        counts["factor"] += 1
        return real_factorize(*a, **k)

    def solve(self, damping):
        counts["solve"] += 1
        return real_solve(self, damping)

    def accelerate(self, state, step, damping):
        counts["retry"] += 1
        return real_accelerate(self, state, step, damping)

    monkeypatch.setattr(schur, "factorize", factorize)
    monkeypatch.setattr(adjustment._BundleSteps, "solve", solve)
    monkeypatch.setattr(adjustment._BundleSteps, "accelerate", accelerate)
    run = _run(bal_block)
    assert run.converged and run.iterations <= 10
    assert counts["retry"] >= 1  # a rejected step retried
    assert counts["factor"] == counts["solve"]


@pytest.mark.parametrize("kind", ["bal", "shared"])
def test_the_retry_step_equals_that_of_a_fresh_system(bal_block, kind, monkeypatch):
    """The acceleration solved with the kept factor equals the solve of a freshly formed
    damped system with the second derivative as its residuals (to 1e-12): a camera per
    image (its calibration folded into the images' unknowns) and one shared camera."""
    from photogeom.adjust import schur

    if kind == "bal":
        block, datum = bal_block, "free"
    else:  # GNSS, IMU and control: priors in the normal equations
        block = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=5).block
        datum = "weighted"
    opts = BundleOptions(datum=datum, snooping=False).validate()
    problem = adjustment.Problem(block, opts)
    assert (problem.sys.inner is not None) == (kind == "bal")
    state = problem.initial_state()
    steps = adjustment._BundleSteps(problem, state, problem.cost(state)[1], opts.xtol)
    lam = 1e-3
    step, _ = steps.solve(lam)
    seen = []
    real = problem.sys.gradient

    def record(lin, r):
        seen.append(np.array(r))
        return real(lin, r)

    monkeypatch.setattr(problem.sys, "gradient", record)
    monkeypatch.setattr(adjustment, "ACCELERATION_RATIO", np.inf)  # always returned
    fast = steps.accelerate(state, step, lam)
    (r_vv,) = seen
    lin = steps.lin
    curved = schur.Linearization(
        r_vv, lin.A, lin.G, lin.P, lin.local_info, np.zeros_like(lin.local_grad),
        lin.point_info, np.zeros_like(lin.point_grad), lin.global_info,
        np.zeros_like(lin.global_grad), 0.0,
    )  # fmt: skip
    ac, ap, _ = problem.sys.normal_equations(curved, damping=lam).solve()
    ref = np.r_[step[0] + 0.5 * ac, (step[1] + 0.5 * ap).ravel()]
    got = np.r_[fast[0], fast[1].ravel()]
    assert np.linalg.norm(got - ref) <= 1e-12 * np.linalg.norm(ref)
    assert np.linalg.norm(ac) > 1e-6 * np.linalg.norm(step[0])  # a real acceleration
