"""The grid-size sweep times each spacing's fit and correction several times.

A spacing's CPU time is common to every stereo model, so one slow timing (a burst of load
on a shared machine: caches and memory shared with other processes) moved many models'
closest-to-origin choices at once, and the block's spacing with them. ``sweep_spacings``
now repeats the timing in passes over all spacings (interleaved) and keeps each spacing's
minimum; only the timing is repeated, the re-adjustment and the steps are made once, and
the repeated passes take at most the CPU time of the first pass. These tests read the
times from a scripted clock (no assertion on seconds).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import study
from photogeom.errors import InputError

SPACINGS = [300.0, 1000.0, 2000.0]
WARM_UP = 100.0  # clock units of the untimed warm-up fit
CORRECT = 0.5  # clock units of one correction


@pytest.fixture(scope="module")
def adjusted():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    return pg.bundle_adjust(sim.block, snooping=False)


class _Script:
    """A clock that advances only when the sweep's steps run: the k-th timed fit of a
    spacing ``g`` costs ``1000 / g`` units times ``slow.get((g, k), 1)`` (a burst of load);
    every re-adjustment ``adjust`` units."""

    def __init__(self, slow=None, adjust: float = 7.0):
        self.now = 0.0
        self.slow = dict(slow or {})
        self.adjust = adjust
        self.fits: list[float] = []  # spacings of the timed fits, in call order
        self.adjustments = 0

    def __call__(self) -> float:
        return self.now


def _substitute(monkeypatch, clock: _Script) -> None:
    fit, correct, adjust = (
        study.fit_residual_grids,
        study.correct_block_observations,
        study._adjust_corrected,
    )
    warm = {"done": False}

    def timed_fit(block, spacing, **options):
        if not warm["done"]:  # the warm-up (one image, untimed)
            warm["done"] = True
            clock.now += WARM_UP
        else:
            k = sum(1 for g in clock.fits if g == spacing)
            clock.fits.append(float(spacing))
            clock.now += 1000.0 / spacing * clock.slow.get((float(spacing), k), 1.0)
        return fit(block, spacing, **options)

    def timed_correct(block, grids, **options):
        clock.now += CORRECT
        return correct(block, grids, **options)

    def timed_adjust(corrected, **options):
        clock.now += clock.adjust
        clock.adjustments += 1
        return adjust(corrected, **options)

    monkeypatch.setattr(study, "_clock", clock)
    monkeypatch.setattr(study, "fit_residual_grids", timed_fit)
    monkeypatch.setattr(study, "correct_block_observations", timed_correct)
    monkeypatch.setattr(study, "_adjust_corrected", timed_adjust)


QUIET = [1000.0 / g + CORRECT for g in SPACINGS]


def test_the_minimum_over_interleaved_timings_is_the_cost(monkeypatch, adjusted):
    # a burst of load: the first timing of 1000 px three times as long, the second of
    # 2000 px twice as long, the last of 300 px 1.5 times
    slow = {(1000.0, 0): 3.0, (2000.0, 1): 2.0, (300.0, 2): 1.5}
    clock = _Script(slow)
    _substitute(monkeypatch, clock)
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=3)
    assert sw["timings"] == 3
    # every spacing once, then every spacing again: a burst meets one timing of several
    # spacings, not every timing of one
    assert clock.fits == SPACINGS * 3
    np.testing.assert_allclose(sw["time"], QUIET, rtol=1e-12)
    # the re-adjustment and the steps once per spacing: only the timing is repeated
    assert clock.adjustments == len(SPACINGS)
    np.testing.assert_allclose(sw["time_readjust"], [7.0] * len(SPACINGS), rtol=1e-12)


def test_a_burst_on_one_spacing_no_longer_moves_the_choice(monkeypatch, adjusted):
    """The same burst with one timing changes the cost; with three the choice is the one of
    a quiet machine (and so are the normalised times the models are ranked by)."""
    quiet_clock = _Script()
    _substitute(monkeypatch, quiet_clock)
    quiet = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=1)
    runs = {}
    for repeats in (1, 3):
        # 2000 px (the cheapest) as slow as 300 px: its normalised time was 0
        clock = _Script({(2000.0, 0): 6.0})
        _substitute(monkeypatch, clock)
        runs[repeats] = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=repeats)
    assert runs[1]["timings"] == 1 and runs[1]["time"][2] == pytest.approx(3.5)
    np.testing.assert_allclose(runs[3]["time"], quiet["time"], rtol=1e-12)
    np.testing.assert_allclose(
        runs[3]["choice"]["time_norm"], quiet["choice"]["time_norm"], atol=1e-12
    )
    np.testing.assert_array_equal(runs[3]["choice"]["spacing"], quiet["choice"]["spacing"])
    assert runs[3]["spacing"] == quiet["spacing"]
    # the steps do not depend on the timings
    np.testing.assert_array_equal(runs[3]["step"], quiet["step"])


def test_the_repeated_passes_take_at_most_the_first_pass(monkeypatch, adjusted):
    """With a short re-adjustment the first pass is mostly the fits and corrections: one
    repeated pass fits within it, a second would not."""
    clock = _Script(adjust=0.1)
    _substitute(monkeypatch, clock)
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=5)
    assert sw["timings"] == 2
    assert clock.fits == SPACINGS * 2
    # re-adjustments 1.1 times as long as the fits and corrections: two repeated passes
    # fit in the budget, a third would not
    clock = _Script(adjust=1.1 * sum(QUIET) / len(SPACINGS))
    _substitute(monkeypatch, clock)
    assert pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=5)["timings"] == 3


def test_the_default_is_the_documented_number_of_repeats(monkeypatch, adjusted):
    clock = _Script()
    _substitute(monkeypatch, clock)
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0)
    assert study.TIMING_REPEATS == 3 and sw["timings"] == 3
    from photogeom.cli import grid_block

    assert grid_block.TIMING_REPEATS == study.TIMING_REPEATS  # --repeats' default


@pytest.mark.parametrize("bad", [0, -1, True, 2.5, "3", None])
def test_repeats_must_be_a_whole_number_from_one(adjusted, bad):
    with pytest.raises(InputError, match=r"^sweep_spacings: repeats must be an integer >= 1"):
        pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=bad)


def test_the_command_line_takes_repeats_and_says_how_many_were_made(cli):
    args = ("grid", "sweep", "--preset", "FC300S", "--strips", "2", "--images-per-strip", "4")
    code, text, err = cli(*args, "--spacings", "500,2000", "--repeats", "1", "--json")
    assert code == 0, err
    d = json.loads(text)
    assert d["timings"] == 1 and len(d["time"]) == 2
    code, _, err = cli(*args, "--repeats", "0")
    assert code != 0 and "--repeats" in err


def test_the_report_figure_names_the_measure(monkeypatch, adjusted):
    from photogeom.report.grid_study import _fig_sweep

    clock = _Script()
    _substitute(monkeypatch, clock)
    sw = pg.calibration.sweep_spacings(adjusted, SPACINGS, folds=0, repeats=3)
    _, ax = _fig_sweep(sw).axes
    assert ax.get_xlabel() == "normalised CPU time (grid fit and correction, least of 3 timings)"
