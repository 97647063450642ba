"""The shared Levenberg-Marquardt loop on small problems with known answers."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import least_squares

from photogeom.adjust.levenberg import MIN_DAMPING_FACTOR, levenberg_marquardt_loop
from photogeom.errors import DegenerateGeometryError

OPTIONS = SimpleNamespace(initial_damping=1e-4, max_iterations=100, ftol=1e-14, xtol=1e-14)


class Curve:
    """Least squares of ``y = a exp(b t) + c`` through the loop's protocol."""

    def __init__(self, t, y, x0, singular_solves=0):
        self.t, self.y, self.singular_solves = t, y, singular_solves
        self.accept(np.asarray(x0, float))

    def residuals(self, x):
        return x[0] * np.exp(x[1] * self.t) + x[2] - self.y

    def cost(self, x):
        r = self.residuals(x)
        return float(r @ r)

    def accept(self, x):
        e = np.exp(x[1] * self.t)
        J = np.column_stack([e, x[0] * self.t * e, np.ones_like(self.t)])
        self.N, self.g = J.T @ J, J.T @ self.residuals(x)

    def solve(self, damping):
        if self.singular_solves > 0:
            self.singular_solves -= 1
            raise DegenerateGeometryError("singular")
        d = np.diag(self.N)
        dx = -np.linalg.solve(self.N + damping * np.diag(d), self.g)
        return dx, float(-(self.g @ dx) - 0.5 * dx @ (self.N @ dx)) * 2.0

    def evaluate(self, x, dx):
        return x + dx, self.cost(x + dx), True

    def small(self, x, dx):
        return bool(np.all(np.abs(dx) <= OPTIONS.xtol * np.maximum(np.abs(x), 1.0)))


def _data(seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0, 40)
    return t, 2.5 * np.exp(-1.3 * t) + 0.4 + rng.normal(0.0, 0.01, t.size)


def test_the_minimum_of_a_curve_fit_is_scipys():
    t, y = _data()
    x0 = np.array([1.0, -0.5, 0.0])
    p = Curve(t, y, x0)
    run = levenberg_marquardt_loop(p, x0, p.cost(x0), OPTIONS)
    ref = least_squares(lambda x: p.residuals(x), x0, method="lm", xtol=1e-15, ftol=1e-15)
    assert run.converged and run.message.startswith("converged")
    np.testing.assert_allclose(run.state, ref.x, rtol=1e-7)
    assert run.cost == pytest.approx(2 * ref.cost, rel=1e-9)
    assert all(a > b for a, b in zip(run.history, run.history[1:]))  # accepted steps only


def test_an_exact_fit_stops_at_once_and_a_singular_system_raises_the_damping():
    t = np.linspace(0.0, 2.0, 10)
    x = np.array([2.0, -1.0, 0.5])
    p = Curve(t, x[0] * np.exp(x[1] * t) + x[2], x)
    run = levenberg_marquardt_loop(p, x, p.cost(x), OPTIONS, exact_cost=1e-20)
    assert run.converged and run.iterations == 0 and "exact fit" in run.message
    t, y = _data(1)
    x0 = np.array([1.0, -0.5, 0.0])
    seen = []
    p = Curve(t, y, x0, singular_solves=3)  # damping 1e-4 * 2 * 4 * 8 before a solve
    run = levenberg_marquardt_loop(
        p, x0, p.cost(x0), OPTIONS, progress=lambda it, c, lam: seen.append((it, lam))
    )
    assert run.converged and seen[0][0] == 4  # three iterations went to raising it
    assert 6.4e-3 * MIN_DAMPING_FACTOR <= seen[0][1] <= 6.4e-3
    p = Curve(t, y, x0, singular_solves=10**6)
    with pytest.raises(DegenerateGeometryError):
        levenberg_marquardt_loop(p, x0, p.cost(x0), OPTIONS)


def test_the_iteration_limit_is_reported():
    t, y = _data(2)
    x0 = np.array([1.0, -0.5, 0.0])
    p = Curve(t, y, x0)
    opts = SimpleNamespace(**{**vars(OPTIONS), "max_iterations": 2})
    run = levenberg_marquardt_loop(p, x0, p.cost(x0), opts)
    assert not run.converged and run.iterations == 2 and "2 iterations reached" in run.message


class Valley:
    """Rosenbrock's valley ``r = (10 (y - x^2), 1 - x)``, curved about its minimum (1, 1);
    with ``accelerated`` the problem offers the geodesic acceleration of a step."""

    def __init__(self, x0, accelerated):
        self.evaluated = []
        self.accept(np.asarray(x0, float))
        if accelerated:
            self.accelerate = self._accelerate

    @staticmethod
    def residuals(x):
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def cost(self, x):
        r = self.residuals(x)
        return float(r @ r)

    def accept(self, x):
        self.J = np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])
        self.N, self.g = self.J.T @ self.J, self.J.T @ self.residuals(x)

    def _damped(self, damping):
        return self.N + damping * np.diag(np.diag(self.N))

    def solve(self, damping):
        dx = -np.linalg.solve(self._damped(damping), self.g)
        return dx, float(-2.0 * (self.g @ dx) - dx @ self.N @ dx)

    def _accelerate(self, x, dx, damping):
        rvv = np.array([-20.0 * dx[0] ** 2, 0.0])  # second derivative along dx
        a = -np.linalg.solve(self._damped(damping), self.J.T @ rvv)
        d = np.diag(self.N)
        if 2.0 * np.sqrt(d @ a**2) > 0.75 * np.sqrt(d @ dx**2):
            return None
        return dx + 0.5 * a

    def evaluate(self, x, dx):
        self.evaluated.append(dx)
        return x + dx, self.cost(x + dx), True

    def small(self, x, dx):
        return bool(np.all(np.abs(dx) <= 1e-12))


def test_a_rejected_step_is_retried_with_its_acceleration():
    x0 = np.array([-1.2, 1.0])
    opts = SimpleNamespace(**{**vars(OPTIONS), "ftol": 1e-12})
    plain = Valley(x0, accelerated=False)
    ref = levenberg_marquardt_loop(plain, x0, plain.cost(x0), opts)
    fast = Valley(x0, accelerated=True)
    run = levenberg_marquardt_loop(fast, x0, fast.cost(x0), opts)
    assert ref.converged and run.converged
    np.testing.assert_allclose(run.state, [1.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(ref.state, [1.0, 1.0], atol=1e-6)
    # one evaluation more per accelerated retry, counted in the same iteration
    assert len(fast.evaluated) > run.iterations
    assert run.iterations < ref.iterations
    assert all(a > b for a, b in zip(run.history, run.history[1:]))


class Bounded(Curve):
    """:class:`Curve` whose trials with ``c`` at or above ``bound`` are invalid (as a point
    behind its camera is to the bundle), with its own step tolerance."""

    def __init__(self, t, y, x0, bound, xtol):
        self.bound, self.xtol = bound, xtol
        super().__init__(t, y, x0)

    def evaluate(self, x, dx):
        return x + dx, self.cost(x + dx), bool(x[2] + dx[2] < self.bound)

    def small(self, x, dx):
        return bool(np.all(np.abs(dx) <= self.xtol * np.maximum(np.abs(x), 1.0)))


@pytest.mark.parametrize("xtol", [1e-14, 1e-10, 1e-8])
@pytest.mark.parametrize("x0", [(1.0, -0.5, 0.0), (2.0, -1.0, 0.05), (3.0, -2.0, -0.5)])
def test_steps_shrinking_against_invalid_trials_are_not_convergence(xtol, x0):
    # the minimum (scipy's, c = 0.41) lies where the trials are invalid (c >= 0.35): the
    # steps shrink below xtol against that bound because the invalid trials raise the
    # damping, and the cost still falls beyond it. Before, the loop reported "converged"
    # there (a rejected invalid trial with a step below xtol, or an accepted step below
    # xtol after invalid ones), in each of these 9 runs
    t, y = _data()
    free_min = least_squares(lambda x: Curve(t, y, x).residuals(x), [1.0, -0.5, 0.0]).x
    assert free_min[2] > 0.35
    p = Bounded(t, y, x0, 0.35, xtol)
    opts = SimpleNamespace(initial_damping=1e-4, max_iterations=300, ftol=1e-14, xtol=xtol)
    x0 = np.asarray(x0)
    r = levenberg_marquardt_loop(p, x0, p.cost(x0), opts)
    assert not r.converged
    assert r.message.startswith("not converged: the steps shrank below xtol short of a state")
    assert r.state[2] < 0.35 and r.cost > p.cost(free_min)


def test_a_bound_beyond_the_minimum_leaves_the_convergence():
    t, y = _data()
    free_min = least_squares(lambda x: Curve(t, y, x).residuals(x), [1.0, -0.5, 0.0]).x
    x0 = np.array([1.0, -0.5, 0.0])
    p = Bounded(t, y, x0, 1.0, 1e-14)
    r = levenberg_marquardt_loop(p, x0, p.cost(x0), OPTIONS)
    assert r.converged
    np.testing.assert_allclose(r.state, free_min, rtol=1e-6)
