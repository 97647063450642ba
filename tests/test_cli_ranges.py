"""Integer options out of range are refused by name, not by a traceback or silently
(a negative --seed crashed inside numpy; --worst -1, --folds -1 and --folds 1 listed or
validated nothing without a word)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets

LIDAR = str(datasets.path("lidar_wang2014"))


@pytest.mark.parametrize(
    "args",
    [
        ("orient", "absolute", LIDAR, "--ransac", "--threshold", "0.1", "--seed", "-1"),
        ("grid", "evaluate", "--preset", "FC300S", "--seed", "-1"),
        ("grid", "sweep", "--preset", "FC300S", "--seed", "-1"),
        ("bundle", "simulate", "{tmp}/block", "--seed", "-1"),
    ],
)
def test_negative_seed_is_a_usage_error(cli, tmp_path: Path, args):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    code, _, err = cli(*args)
    assert code == 2
    assert "--seed" in err and "Traceback" not in err
    assert not (tmp_path / "block").exists()


def test_negative_worst_is_a_usage_error(cli, tmp_path: Path):
    pts = tmp_path / "m.csv"
    pts.write_text("id,x1,y1,x2,y2\n1,0,0,1,0\n")
    code, _, err = cli("orient", "relative", pts, "--f", "100", "--worst", "-1")
    assert code == 2 and "--worst" in err


@pytest.mark.parametrize("folds", ["-1", "1"])
def test_folds_below_two_are_refused(cli, tmp_path: Path, folds):
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 400, 200), rng.uniform(0, 300, 200)
    res = tmp_path / "r.csv"
    res.write_text("image_id,u,v,rx,ry\n" + "".join(
        f"A,{a},{b},{0.1 * np.sin(a / 90)},{0.1 * np.cos(b / 70)}\n" for a, b in zip(u, v)))
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", res, "--image-size", "400x300", "--spacing", "100",
                       "-o", out, "--folds", folds)
    assert code == 2 and f"--folds {folds}" in err and "0 for no cross-validation" in err
    assert not out.exists()
    code, _, err = cli("grid", "fit", res, "--image-size", "400x300", "--spacing", "100",
                       "-o", out, "--folds", "0")
    assert code == 0, err
