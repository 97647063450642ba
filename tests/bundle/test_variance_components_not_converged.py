"""Variance components that stop at their round limit without converging are named in the
notes (before: ``variance_components['converged']`` was False and nothing said so)."""

from __future__ import annotations

import photogeom as pg
from photogeom.bundle import variance


def test_a_variance_component_iteration_that_did_not_converge_is_noted(monkeypatch):
    block = pg.simulate.uav_block("FC300S", seed=2, strips=2, images_per_strip=3).block
    done = pg.bundle_adjust(block, variance_components=True, snooping=False)
    assert done.variance_components["converged"]
    assert not any("did not converge" in n for n in done.notes)
    monkeypatch.setattr(variance, "MAX_ROUNDS", 1)  # stopped after its first round
    cut = pg.bundle_adjust(block, variance_components=True, snooping=False)
    assert not cut.variance_components["converged"]
    note = next(n for n in cut.notes if "variance components did not converge" in n)
    assert "in 1 round(s)" in note and "hold it at its a-priori sigmas" in note
    assert note in cut.summary()
