"""The presets' true calibration and a simulation's options are read-only.

Before: ``CameraPreset.true_calibration`` was a plain dict and every simulation of a camera
held the one shared preset (``sim.preset is PRESETS["FC300S"]``): ``sim.preset.
true_calibration["k1"] = 0.0`` turned the true k1 of every later ``uav_block("FC300S")`` in
the process from -0.11 into 0.0. ``sim.options`` (read by ``sim.summary()``) was a plain dict
too.
"""

from __future__ import annotations

import copy
import pickle

import pytest

import photogeom as pg
from photogeom.simulate import PRESETS, CameraPreset


def _sim():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)


def test_the_truth_of_later_simulations_cannot_be_changed():
    sim = _sim()
    k1 = sim.camera.k1
    assert k1 == PRESETS["FC300S"].true_calibration["k1"] == -0.11
    with pytest.raises(TypeError):
        sim.preset.true_calibration["k1"] = 0.0
    assert _sim().camera.k1 == k1
    assert pg.simulate.preset("FC300S").true_camera().k1 == k1


def test_options_are_read_only_and_the_summary_keeps_them():
    sim = _sim()
    summary = sim.summary()
    with pytest.raises(TypeError):
        sim.options["sigma"] = 99.0
    assert sim.summary() == summary
    for twin in (copy.deepcopy(sim), pickle.loads(pickle.dumps(sim))):
        with pytest.raises(TypeError):
            twin.options["sigma"] = 99.0
        assert twin.summary() == summary


def test_a_preset_of_ones_own_copies_the_mapping_given():
    truth = {"f_scale": 1.01, "k1": -0.05}
    p = CameraPreset("mine", 4000, 3000, 0.004, 12.0, 0.03, (5, 5), 0.7, 0.4,
                     true_calibration=truth)  # fmt: skip
    truth["k1"] = 0.0
    assert p.true_camera().k1 == -0.05 and p.true_calibration == {"f_scale": 1.01, "k1": -0.05}
    assert pickle.loads(pickle.dumps(p)) == p
