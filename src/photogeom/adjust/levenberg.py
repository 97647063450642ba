"""The Levenberg-Marquardt loop shared by the sparse adjustments (bundle, grids in it).

The loop owns the damping rule, the acceptance test and the stopping rules; the problem
owns everything about its unknowns (:class:`DampedProblem`): the damped solve at its current
linearisation, the trial evaluation, the step-size test and the re-linearisation after an
accepted step.

* A step is accepted when the trial is valid (e.g. every point in front of its cameras),
  its cost finite and lower. The damping then falls with the gain ratio
  ``rho = actual / predicted decrease``: ``lam * max(1/10, 1 - (2 rho - 1)^3)`` (at least
  1e-15), Nielsen's rule with the fall per step bounded by :data:`MIN_DAMPING_FACTOR`
  (1/10) instead of his 1/3; a rejected step multiplies it by ``nu`` (2, doubling on each
  rejection in a row). With 1/3, a damping that starts high (1e-4 of the diagonal) needs
  several steps that the model predicts well (``rho`` near 1) to stop holding back the
  weakly determined directions (the calibration): 11 instead of 8 iterations on a
  simulated 250-image block, 14 instead of 9 from a poorer start, to the same minimum.
  Steps the model predicts less well (``rho`` below about 0.9) lower the damping as in
  Nielsen's rule.
* A problem may refine an accepted trial without a step of the damped system (``refine``,
  e.g. the bundle's tie points whose own step raised their cost, moved by point-only steps);
  the damping follows the step's own gain ratio, the cost and the convergence test the
  refined trial.
* A problem may offer the geodesic acceleration of a rejected step (``accelerate``, e.g.
  the bundle's: the step bent by the residuals' second derivative along it): a valid trial
  that raises the cost is retried once with it, in the same iteration (unless the loop
  converged: below); accepted, the damping follows the first step's gain ratio (its
  predicted decrease). A minimum along a
  curved valley (a camera per image: focal length against flying height) is then reached
  in fewer iterations: a simulated 1000-image BAL block in 35 instead of 67.
* Converged: an accepted step lowering the cost by at most ``ftol`` times the cost, an
  accepted step below ``xtol`` (the problem's test), a rejected finite trial whose step is
  below ``xtol``, a rejected valid trial whose predicted decrease is at most ``ftol`` times
  the cost (the cost is at its minimum to rounding: raising the damping would only shorten
  the step until it is below ``xtol``, nine more factorisations on a test block), or a cost
  of zero to rounding (``exact_cost``). Stopped: the damping grew
  past 1e16, or ``max_iterations`` iterations, or a step below ``xtol`` (rejected or
  accepted) after a trial rejected as invalid since the last accepted step
  (:data:`STOPPED_AT_INVALID`): the damping the invalid trials raised shortened the steps
  against states the problem refuses, not a minimum (a curve fit whose minimum lies
  beyond such a bound was reported converged at the bound, in 9 of 9 runs).
* A singular damped system raises the damping; past 1e10 the problem's
  :class:`~photogeom.errors.DegenerateGeometryError` propagates.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..errors import DegenerateGeometryError

__all__ = ["MIN_DAMPING_FACTOR", "DampedProblem", "LoopResult", "levenberg_marquardt_loop"]

#: The damping falls after an accepted step by at most this factor (Nielsen: 1/3).
MIN_DAMPING_FACTOR = 0.1


#: The loop's message where its steps shrink below ``xtol`` short of a state the problem
#: refuses (a trial rejected as invalid since the last accepted step): the steps were cut by
#: the damping that the invalid trials raised, not by a minimum.
STOPPED_AT_INVALID = (
    "not converged: the steps shrank below xtol short of a state the adjustment refuses "
    "(a trial with a point behind its camera): the cost still falls towards it, so this "
    "is no minimum"
)


class DampedProblem(Protocol):
    """What :func:`levenberg_marquardt_loop` asks of a problem."""

    def solve(self, damping: float) -> tuple[object, float]:
        """The step of the normal equations at the current linearisation with Marquardt
        ``damping`` and its predicted cost decrease; raises DegenerateGeometryError when
        the damped system is singular."""

    def evaluate(self, state, step) -> tuple[object, float, bool]:
        """``(trial state, its cost, valid)`` for ``step`` from ``state``."""

    def small(self, state, step) -> bool:
        """Whether ``step`` from ``state`` is below the step tolerance."""

    def accept(self, state) -> None:
        """Re-linearise at the accepted ``state`` (the last evaluated trial)."""

    # optional: ``refine(state, trial, cost) -> (trial, cost)``, an accepted trial improved
    # without a step of the damped system (a lower cost or the same), before ``accept``;
    # ``accelerate(state, step, damping) -> step or None``, a rejected step corrected by
    # its geodesic acceleration (or None: not offered), evaluated before the damping rises


@dataclass
class LoopResult:
    """Outcome of :func:`levenberg_marquardt_loop`."""

    state: object
    cost: float
    iterations: int
    converged: bool
    message: str
    history: list = field(default_factory=list)


def levenberg_marquardt_loop(
    problem: DampedProblem,
    state,
    cost: float,
    options,
    *,
    exact_cost: float = 0.0,
    progress=None,
) -> LoopResult:
    """Minimise from ``state`` (already linearised by ``problem``, cost ``cost``).

    Parameters
    ----------
    problem : DampedProblem
    state : object
        The problem's starting state.
    cost : float
        Its cost.
    options
        ``initial_damping``, ``max_iterations``, ``ftol``, ``xtol`` (e.g. ``BundleOptions``;
        ``xtol`` is used by the problem's ``small``).
    exact_cost : float
        A cost at or below this is an exact fit (converged without a step).
    progress : callable, optional
        ``progress(iteration, cost, damping)`` after each accepted step.
    """
    history = [cost]
    refine = getattr(problem, "refine", None)
    accelerate = getattr(problem, "accelerate", None)
    lam = options.initial_damping
    nu = 2.0
    converged = False
    invalid = False  # a trial rejected as invalid since the last accepted step
    message = f"not converged: {options.max_iterations} iterations reached"
    it = 0
    while it < options.max_iterations:
        if cost <= exact_cost:
            converged, message = True, "converged: the cost is zero to rounding (exact fit)"
            break
        it += 1
        try:
            step, pred = problem.solve(lam)
        except DegenerateGeometryError:
            if lam > 1e10:
                raise
            lam *= nu
            nu *= 2.0
            continue
        trial, new_cost, valid = problem.evaluate(state, step)
        better = valid and np.isfinite(new_cost) and new_cost < cost
        if not better and np.isfinite(new_cost) and problem.small(state, step):
            if valid and not invalid:
                converged = True
                message = "converged: no further decrease (step below xtol)"
            else:
                message = STOPPED_AT_INVALID
            break
        if not better and valid and np.isfinite(new_cost) and pred <= options.ftol * cost:
            converged = True
            message = "converged: no further decrease (predicted decrease below ftol)"
            break
        if not better and valid and np.isfinite(new_cost) and accelerate is not None:
            fast = accelerate(state, step, lam)
            if fast is not None:
                t2, c2, v2 = problem.evaluate(state, fast)
                if v2 and np.isfinite(c2) and c2 < cost:
                    trial, new_cost, step, better = t2, c2, fast, True
        if better:
            rho = (cost - new_cost) / pred if pred > 0 else 1.0
            small = problem.small(state, step)
            stopped = small and invalid  # short of an invalid trial's state: no minimum
            if refine is not None:
                trial, new_cost = refine(state, trial, new_cost)
            decrease = cost - new_cost
            state, cost = trial, new_cost
            history.append(cost)
            lam = max(lam * max(MIN_DAMPING_FACTOR, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-15)
            nu = 2.0
            problem.accept(state)
            if progress is not None:
                progress(it, cost, lam)
            if stopped:
                message = STOPPED_AT_INVALID
                break
            if decrease <= options.ftol * cost:
                converged, message = True, "converged: relative cost decrease below ftol"
                break
            if small:
                converged, message = True, "converged: step below xtol"
                break
            invalid = False
        else:
            invalid = invalid or not valid
            lam *= nu
            nu *= 2.0
            if lam > 1e16:
                message = "stopped: the damping grew without a decrease of the cost"
                break
    return LoopResult(state, cost, it, converged, message, history)
