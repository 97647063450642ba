"""Bounded mutation fuzzing of every reader (a few seconds each): any exception other than
photogeom's own is a failure. The long run is ``run_mutations.py`` (by hand)."""

from __future__ import annotations

import random
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parent))
from harness import TARGETS, mutate, run_one

EXAMPLES = 60

_SEEDS: dict[str, list[bytes]] = {}


def _seeds(name: str) -> list[bytes]:
    if name not in _SEEDS:
        _SEEDS[name] = TARGETS[name].seeds()
    return _SEEDS[name]


PARAMS = list(TARGETS)  # the point CSV targets (CSV_TARGETS) included


@pytest.mark.parametrize("name", list(TARGETS))
def test_seeds_are_read(name):
    """The unmutated seeds are valid files: the fuzzing starts from accepted inputs."""
    with tempfile.TemporaryDirectory() as tmp:
        for data in _seeds(name):
            out = run_one(TARGETS[name], data, Path(tmp))
            assert out.ok and out.error is None, out.error


@pytest.mark.parametrize("name", PARAMS)
@settings(max_examples=EXAMPLES, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_mutated_inputs_raise_only_photogeom_errors(name, seed):
    rng = random.Random(seed)
    data = mutate(rng.choice(_seeds(name)), rng)
    with tempfile.TemporaryDirectory() as tmp:
        out = run_one(TARGETS[name], data, Path(tmp))
    assert out.ok, f"{type(out.error).__name__}: {out.error}"


def test_the_readers_of_every_calibration_format_and_of_bal_are_fuzzed():
    # the README says the fuzzing feeds every reader; the calibration files of other tools
    # (OpenCV YAML/XML, COLMAP cameras.txt) and BAL had no target
    from photogeom.camera.calibration_files import CALIBRATION_SUFFIXES

    by_format = {"metashape": "metashape-xml", "json": "camera-json", "colmap": "colmap-cameras"}
    wanted = {by_format.get(f, "opencv-yaml") for f in CALIBRATION_SUFFIXES.values()}
    assert wanted | {"opencv-xml", "bal"} <= set(TARGETS)


def test_the_files_of_a_colmap_binary_model_are_fuzzed():
    # the binary model (cameras.bin, images.bin, points3D.bin) is read since read_colmap
    # reads it: each of its files is a target
    assert {"colmap-bin-cameras", "colmap-bin-images", "colmap-bin-points3D"} <= set(TARGETS)
