"""`bundle simulate --tie-points-per-image -5` (or nan, inf) ended in numpy's
traceback 'ValueError: lam < 0 or lam is NaN' (exit 1); --local-field nan simulated a block
without a field (exit 0); --blunder-size inf stopped with 'uv: row 915 holds NaN or
infinity'. uav_block now refuses them by name, the command by its options."""

from __future__ import annotations

from pathlib import Path

import pytest

import photogeom as pg
from photogeom.errors import InputError


@pytest.mark.parametrize(("kw", "value", "match"), [
    ("tie_points_per_image", -5.0, "tie_points_per_image must be > 0"),
    ("tie_points_per_image", float("nan"), "tie_points_per_image must be > 0"),
    ("tie_points_per_image", float("inf"), "tie_points_per_image must be > 0"),
    ("local_field", float("nan"), "local_field must be >= 0"),
    ("blunder_size", float("inf"), "blunder_size must be >= 0"),
    ("blunders", -1, "blunders must be >= 0"),
])
def test_uav_block_refuses_by_name(kw, value, match):
    with pytest.raises(InputError, match=match):
        pg.simulate.uav_block("FC300S", strips=1, images_per_strip=3, **{kw: value})


@pytest.mark.parametrize(("option", "value"), [
    ("--tie-points-per-image", "-5"), ("--tie-points-per-image", "nan"),
    ("--local-field", "nan"), ("--blunder-size", "inf"),
])
def test_bundle_simulate_names_the_option(cli, tmp_path: Path, option, value):
    out = tmp_path / "b"
    code, _, err = cli("bundle", "simulate", out, "--strips", "1", "--images-per-strip", "3",
                       "--blunders", "2", option, value)
    assert code == 2, err
    assert err.startswith((f"error: {option} must be >= 0", f"error: {option} must be > 0")), err
    assert not out.exists()
