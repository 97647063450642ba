"""--image-size of grid evaluate, sweep and report for a BAL or Bundler BLOCK, as grid fit
and bundle adjust have it. BAL holds no image size: without the option the reader takes the
smallest even size holding the observations, which sets the grids' extent and the pixel
origin; before, these commands had no --image-size and said nothing, so a BAL block was
evaluated at that guess (3768 x 2980 px for the 4000 x 3000 px images here) silently."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

SIZE = "4000x3000"


@pytest.fixture(scope="module")
def blocks(tmp_path_factory):
    """An adjusted FC300S block as a BAL file, and the same converted by the library with
    the images' size into a CSV block (the route the commands offered before)."""
    d = tmp_path_factory.mktemp("blocks")
    sim = pg.simulate.uav_block(
        "FC300S", seed=2, strips=1, images_per_strip=3, tie_points_per_image=60
    )
    bal = d / "adj.bal"
    pg.bundle.write_block(sim.block, bal, "bal", drop_extras=True)
    block = pg.bundle.read_bal(bal, image_size=(4000, 3000))
    fit = pg.bundle_adjust(block, datum="free", snooping=False)
    pg.bundle.write_block(fit.block, bal, "bal")
    folder = d / "csv"
    pg.bundle.write_csv_block(pg.bundle.read_bal(bal, image_size=(4000, 3000)), folder)
    return bal, folder


def _rms(out: str) -> tuple[float, float]:
    blk = json.loads(out)["residuals"]["block"]
    return blk["before"]["rms"], blk["after"]["rms"]


def test_evaluate_takes_the_image_size_of_a_bal_block(cli, blocks):
    bal, folder = blocks
    args = ("grid", "evaluate", "--spacing", "1000", "--json")
    code, want, err = cli(*args, folder)
    assert code == 0, err
    code, got, err = cli(*args, bal, "--image-size", SIZE)
    assert code == 0, err
    assert "warning" not in err
    np.testing.assert_allclose(_rms(got), _rms(want), rtol=1e-9)
    # without it: the reader's guess, said on stderr with the option that fixes it
    code, _, err = cli(*args, bal)
    assert code == 0, err
    text = " ".join(err.split())
    assert f"warning: {bal}: a BAL file holds no image size" in text
    assert "--image-size WIDTHxHEIGHT" in text
    w, h = pg.bundle.read_bal(bal).image_sizes()[0]
    assert f"fitted for {int(w)} x {int(h)} px" in text and (w, h) != (4000, 3000)


def test_sweep_takes_the_image_size_of_a_bal_block(cli, blocks):
    bal, folder = blocks
    args = ("grid", "sweep", "--spacings", "1000,2000", "--repeats", "1", "--json")
    code, want, err = cli(*args, folder)
    assert code == 0, err
    code, got, err = cli(*args, bal, "--image-size", SIZE)
    assert code == 0, err
    assert "warning" not in err
    a, b = json.loads(got), json.loads(want)
    np.testing.assert_allclose(a["step"], b["step"], rtol=1e-9)
    np.testing.assert_allclose(a["step_before"], b["step_before"], rtol=1e-9)


def test_report_has_the_option(cli):
    code, out, _ = cli("grid", "report", "--help")
    assert code == 0 and "--image-size" in out


@pytest.mark.parametrize("command", ["evaluate", "sweep"])
def test_image_size_is_refused_where_the_cameras_give_the_size(cli, blocks, command):
    _, folder = blocks
    code, _, err = cli("grid", command, folder, "--image-size", SIZE)
    assert code == 2
    assert "--image-size applies to a BAL or Bundler file" in err, err
    code, _, err = cli("grid", command, "--preset", "FC300S", "--image-size", SIZE)
    assert code == 2
    assert "--image-size applies to a BAL or Bundler BLOCK" in err, err
