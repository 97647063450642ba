"""The single-solve timing of ``benchmarks/absolute_orientation.py``: interleaved rounds.

On a shared machine the speed drifts within seconds; timing each method in its own block
then reports the drift as a difference between methods. The benchmark times a block of
calls of every contender in turn, rotating the order, and keeps each one's fastest block.
"""

from __future__ import annotations

import importlib.util
import types
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "absolute_orientation.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_absolute_orientation", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class Clock:
    """A clock that only the timed functions advance (no real time involved)."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


def test_rounds_interleave_and_rotate(bench, monkeypatch):
    clock = Clock()
    monkeypatch.setattr(bench, "time", types.SimpleNamespace(perf_counter=clock.perf_counter))
    calls: list[str] = []

    def make(name: str, cost: float):
        def f():
            calls.append(name)
            clock.now += cost

        return f

    # 1 ms per call: blocks of 2 calls at the default 2 ms per block
    fns = {name: make(name, 1e-3) for name in ("a", "b", "c")}
    bench.interleaved_fastest(fns, rounds=3)
    timed = calls[6:]  # after two warm-up calls each
    rounds = [timed[i : i + 6] for i in range(0, len(timed), 6)]
    assert len(rounds) == 3
    # each round: a block of every contender, the first one rotating
    assert [r[::2] for r in rounds] == [["a", "b", "c"], ["b", "c", "a"], ["c", "a", "b"]]
    assert all(r[0::2] == r[1::2] for r in rounds)


def test_fastest_block_per_call(bench, monkeypatch):
    clock = Clock()
    monkeypatch.setattr(bench, "time", types.SimpleNamespace(perf_counter=clock.perf_counter))

    def load() -> float:
        """The machine is three times slower from 10 ms to 40 ms (another job runs)."""
        return 3.0 if 0.01 <= clock.now < 0.04 else 1.0

    def f():
        clock.now += 1e-4 * load()

    def g():
        clock.now += 2e-4 * load()

    best = bench.interleaved_fastest({"f": f, "g": g}, rounds=20)
    # g costs twice f at any machine state; the fastest blocks of both are outside the slow
    # spell, so the ratio is exact (f timed in one stretch, then g, would put all of f's
    # calls in the slow spell and report g 2/3 as slow as f)
    assert best["f"] == pytest.approx(1e-4, rel=1e-9)
    assert best["g"] / best["f"] == pytest.approx(2.0, rel=1e-9)
