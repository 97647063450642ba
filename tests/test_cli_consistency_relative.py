"""`photogeom orient relative --seed` and `--alpha`: the library's RANSAC seed and
significance level of the point tests, now options of the command."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
import photogeom.orientation.relative as rel

IO = pg.InteriorOrientation(100.0, unit="mm")
E1 = pg.ExteriorOrientation(0.0, 0.0, 100.0, 0.02, -0.03, 0.01)
E2 = pg.ExteriorOrientation(60.0, 3.0, 101.0, -0.01, 0.02, 0.05)
IDS = [f"P{i}" for i in range(40)]


@pytest.fixture
def pair(tmp_path):
    """40 matches in mm, one wrong match (P5) and one moderately bad one (P7, |w| ~ 3)."""
    rng = np.random.default_rng(0)
    pts = np.column_stack(
        [rng.uniform(-30, 90, 40), rng.uniform(-40, 40, 40), rng.uniform(-10, 10, 40)]
    )
    xy1 = pg.project(pts, IO, E1) + rng.normal(0, 0.004, (40, 2))
    xy2 = pg.project(pts, IO, E2) + rng.normal(0, 0.004, (40, 2))
    xy2[5] += [0.8, -1.2]
    xy2[7] += [0.0, 0.013]
    path = tmp_path / "m.csv"
    rows = np.column_stack([xy1, xy2])
    path.write_text(
        "id,x1,y1,x2,y2\n"
        + "".join(f"{i}," + ",".join(repr(float(v)) for v in r) + "\n" for i, r in zip(IDS, rows))
    )
    return path, xy1, xy2


@pytest.fixture
def spy(monkeypatch):
    """Record the keywords the command passes to the library."""
    seen: dict = {}
    real = rel.relative_orientation

    def wrapped(*args, **kwargs):
        seen.update(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(rel, "relative_orientation", wrapped)
    return seen


def test_seed_reaches_the_library(cli, pair, spy):
    path, _, _ = pair
    code, _, err = cli("orient", "relative", path, "--f", "100", "--sigma", "0.004", "--json")
    assert code == 0, err
    assert spy["seed"] == 0  # the default: the library's, results as before
    code, out, err = cli(
        "orient", "relative", path, "--f", "100", "--sigma", "0.004", "--seed", "12345", "--json"
    )
    assert code == 0, err
    assert spy["seed"] == 12345
    assert json.loads(out)["flagged"] == ["P5"]


@pytest.mark.parametrize("value", ["-1", "2147483648"])
def test_seed_out_of_range_is_refused(cli, pair, value):
    path, _, _ = pair
    code, _, err = cli("orient", "relative", path, "--f", "100", "--seed", value)
    assert code == 2
    assert "--seed" in err and "Traceback" not in err


def test_library_refuses_a_seed_opencv_cannot_take(pair):
    _, xy1, xy2 = pair
    with pytest.raises(pg.InputError, match=r"seed must be an integer in 0\.\.2147483647"):
        pg.relative_orientation(xy1, xy2, IO, seed=2**31)  # was ValueError from OpenCV


def test_alpha_drives_snooping_and_the_tables(cli, pair, spy, tmp_path):
    path, _, _ = pair
    base = ("orient", "relative", path, "--f", "100", "--sigma", "0.004")
    code, out, err = cli(*base, "--json")
    assert code == 0, err
    assert spy["alpha"] == 0.001
    d = json.loads(out)
    assert d["flagged"] == ["P5"] and d["snooping"]["alpha"] == 0.001
    code, out, err = cli(*base, "--alpha", "0.01", "--json")
    assert code == 0, err
    assert spy["alpha"] == 0.01
    d = json.loads(out)
    # |w| 2.91 of P24 passes at 0.001 (3.29) and fails at 0.01 (2.58)
    assert d["flagged"] == ["P5", "P24"]
    assert d["snooping"]["alpha"] == 0.01
    assert d["snooping"]["w"]["critical_value"] == pytest.approx(2.5758, abs=1e-4)
    assert d["parallax"]["critical_value"] == pytest.approx(2.5758, abs=1e-4)
    rep = tmp_path / "ro.html"
    code, out, err = cli(*base, "--alpha", "0.01", "--report", rep)
    assert code == 0, err
    # the printed residual table tests at the level snooping used, not at 0.001
    assert "critical value 2.576 at alpha = 0.01" in out
    assert "alpha = 0.001" not in out
    assert "alpha = 0.01" in rep.read_text()


@pytest.mark.parametrize("value", ["0", "1", "nan", "-0.1"])
def test_alpha_outside_0_1_is_refused_by_its_name(cli, pair, value):
    path, _, _ = pair
    code, _, err = cli("orient", "relative", path, "--f", "100", "--alpha", value)
    assert code == 2
    assert "--alpha must be in (0, 1)" in err


def test_library_fit_records_its_alpha(pair):
    _, xy1, xy2 = pair
    fit = pg.relative_orientation(xy1, xy2, IO, sigma=0.004, alpha=0.01)
    assert fit.extras["alpha"] == 0.01
    assert fit.to_dict()["snooping"]["alpha"] == 0.01
