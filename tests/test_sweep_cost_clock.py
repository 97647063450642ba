"""The grid-size sweep's computing time: the clock it is read from and what it covers.

The closest-to-origin rule weighs the min-max normalised computing time of each spacing.
``sweep_spacings`` read it from the wall clock around the grid fit and the re-adjustment,
so the chosen spacing followed the load of the machine (other processes, a first call's
warm-up). It is now the process's CPU time of the grid fit and the correction, after an
untimed warm-up; the re-adjustment is timed apart. These tests read the times from a
substituted clock (no assertion on seconds).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.calibration import choose_spacing, study

SPACINGS = [300.0, 1000.0, 2000.0]
WARM_UP = 100.0  # clock units the first call of the fit costs (imports, caches)
CORRECT = 0.5  # clock units of one correction
ADJUST = 7.0  # clock units of one re-adjustment


@pytest.fixture(scope="module")
def adjusted():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    return pg.bundle_adjust(sim.block, snooping=False)


class _Clock:
    """A clock that advances only when the sweep's steps say so (``scale`` units each)."""

    def __init__(self, scale: float = 1.0):
        self.now = 0.0
        self.scale = scale
        self.fits: list[tuple[float, object]] = []

    def __call__(self) -> float:
        return self.now


def _substitute(monkeypatch, clock: _Clock) -> None:
    """Let the sweep's fit, correction and re-adjustment advance ``clock``, the fit by
    ``1000 / spacing`` units (plus ``WARM_UP`` on its first call in the process)."""
    fit, correct = study.fit_residual_grids, study.correct_block_observations
    adjust = getattr(study, "_adjust_corrected", None)

    def timed_fit(block, spacing, **options):
        first = not clock.fits
        clock.fits.append((float(spacing), options.get("images")))
        clock.now += clock.scale * ((WARM_UP if first else 0.0) + 1000.0 / spacing)
        return fit(block, spacing, **options)

    def timed_correct(block, grids, **options):
        clock.now += clock.scale * CORRECT
        return correct(block, grids, **options)

    def timed_adjust(corrected, **options):
        clock.now += clock.scale * ADJUST
        return adjust(corrected, **options)

    # raising=False: a sweep without these names fails on the times, not here
    monkeypatch.setattr(study, "_clock", clock, raising=False)
    monkeypatch.setattr(study, "fit_residual_grids", timed_fit)
    monkeypatch.setattr(study, "correct_block_observations", timed_correct)
    monkeypatch.setattr(study, "_adjust_corrected", timed_adjust, raising=False)


def test_the_documented_clock_is_the_process_cpu_time():
    assert study._clock is time.process_time


def test_times_come_from_the_clock_without_warm_up_or_readjustment(monkeypatch, adjusted):
    clock = _Clock()
    _substitute(monkeypatch, clock)
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0)
    # the cost: the fit and the correction of each spacing, read from the clock
    np.testing.assert_allclose(sw["time"], [1000.0 / g + CORRECT for g in SPACINGS], rtol=1e-12)
    # the re-adjustment timed apart, not in the cost
    np.testing.assert_allclose(sw["time_readjust"], [ADJUST] * len(SPACINGS), rtol=1e-12)
    # (1000/300 + 0.5, 1000/1000 + 0.5, 1000/2000 + 0.5) normalised: 1, 3/17, 0
    np.testing.assert_allclose(sw["choice"]["time_norm"][0], [1.0, 3.0 / 17.0, 0.0], atol=1e-12)
    # the warm-up fitted one image's grid at the first spacing before the timed fits
    first_image = adjusted.block.image_ids.tolist()[0]
    assert clock.fits[0] == (SPACINGS[0], [first_image])
    # then every spacing, once per timing (the minimum is the cost)
    assert [g for g, _ in clock.fits[1:]] == SPACINGS * sw["timings"]


def test_the_warm_up_keeps_to_the_images_of_the_sweep(monkeypatch, adjusted):
    clock = _Clock()
    _substitute(monkeypatch, clock)
    left = adjusted.block.image_ids.tolist()[0]
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS[1:], folds=0, exclude=[left])
    second = adjusted.block.image_ids.tolist()[1]
    assert clock.fits[0] == (SPACINGS[1], [second])
    np.testing.assert_allclose(
        sw["time"], [1000.0 / g + CORRECT for g in SPACINGS[1:]], rtol=1e-12
    )


def test_a_slower_clock_chooses_the_same_spacings(monkeypatch, adjusted):
    """Every time 3.7 times as long (a slower machine, a steady load): the same choice."""
    runs = []
    for scale in (1.0, 3.7):
        clock = _Clock(scale)
        _substitute(monkeypatch, clock)
        runs.append(pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0))
    np.testing.assert_allclose(runs[1]["time"], 3.7 * runs[0]["time"], rtol=1e-12)
    np.testing.assert_array_equal(runs[1]["choice"]["spacing"], runs[0]["choice"]["spacing"])
    assert runs[1]["spacing"] == runs[0]["spacing"]


@settings(max_examples=80, deadline=None)
@given(
    st.integers(2, 7),
    st.integers(1, 4),
    st.integers(0, 2**32 - 1),
    st.booleans(),
    st.floats(1e-3, 1e3),
    st.floats(0.0, 10.0),
)
def test_choose_spacing_ignores_the_unit_and_a_common_offset_of_time(
    n, models, seed, rounded, scale, offset
):
    """Min-max normalisation: times scaled by a constant, or all raised by one (a
    re-adjustment as long at every spacing), give the same choice."""
    rng = np.random.default_rng(seed)
    g = rng.choice(np.arange(100, 2100, 100), n, replace=False).astype(float)
    step = rng.uniform(0, 5, (models, n))
    t = rng.uniform(0, 5, (models, n))
    if rounded:  # many exact ties
        step, t = np.round(step), np.round(t)
    ref = choose_spacing(g, step, t)["spacing"]
    np.testing.assert_array_equal(choose_spacing(g, step, scale * t)["spacing"], ref)
    np.testing.assert_array_equal(choose_spacing(g, step, scale * (t + offset))["spacing"], ref)
