"""An adjusted block with an image of too few tie points for a grid.

Before: ``grid evaluate``, ``sweep`` and ``report`` refused such a block and advised "use
a larger --spacing or leave the image out"; no spacing helps (a grid needs 4 residuals at
any spacing) and those commands had no way to leave an image out (``evaluate --grids``
refused a grids file of ``grid fit --exclude``). Now ``--exclude ID`` leaves the image
without a grid, its observations re-adjusted uncorrected (``readjust(...,
uncorrected=)``, ``sweep_spacings(..., exclude=)`` in Python).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration.blocks import correct_block_observations
from photogeom.errors import InputError, TooFewPointsError

FEW = 1  # the image left with 3 tie points


@pytest.fixture(scope="module")
def few():
    """An adjusted block whose image FEW keeps 3 of its tie-point observations (points
    left in fewer than two images dropped)."""
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=2, strips=1, images_per_strip=4, tie_points_per_image=150
    )
    b = pg.bundle_adjust(sim.block, snooping=False).block
    rows = np.flatnonzero((b.obs_image == FEW) & (b.role[b.obs_point] == "tie"))
    keep = np.ones(b.n_observations, bool)
    keep[rows[3:]] = False
    return b.select_observations(keep).drop_weak_points()


@pytest.fixture(scope="module")
def folder(few, tmp_path_factory):
    d = tmp_path_factory.mktemp("few") / "adjusted"
    pg.bundle.write_csv_block(few, d)
    return d


def test_the_error_no_longer_advises_a_larger_spacing(few):
    for spacing in (100, 2000):  # no spacing helps
        with pytest.raises(TooFewPointsError, match=f"image {FEW}") as err:
            pg.calibration.fit_residual_grids(few, spacing, folds=0)
        assert "larger spacing" not in str(err.value)
        assert "leave the image out" in str(err.value)


def test_uncorrected_images_keep_their_observations(few):
    ids = few.image_ids.tolist()
    others = [k for k in ids if k != FEW]
    grids = pg.calibration.fit_residual_grids(few, 500, folds=0, images=others)
    with pytest.raises(InputError, match=f"no residual grid for image.*{FEW}.*uncorrected="):
        correct_block_observations(few, grids)
    out = correct_block_observations(few, grids, uncorrected=[FEW])
    uv, got = few.observations.uv, out.observations.uv
    mine = few.obs_image == FEW
    np.testing.assert_array_equal(got[mine], uv[mine])
    for i in range(1, len(ids)):  # images, not points
        sel = few.obs_image == (i if i != FEW else 0)
        k = ids[i if i != FEW else 0]
        np.testing.assert_allclose(got[sel], uv[sel] + grids[k].evaluate(uv[sel]), atol=1e-12)
    with pytest.raises(InputError, match="uncorrected: unknown image id"):
        correct_block_observations(few, grids, uncorrected=["nope"])
    re = pg.calibration.readjust(few, grids, uncorrected=[FEW], snooping=False)
    np.testing.assert_array_equal(re.block.observations.uv, got)


def test_grid_evaluate_exclude_equals_the_grids_of_grid_fit_exclude(cli, folder, tmp_path):
    code, _, err = cli("grid", "evaluate", folder, "--spacing", "500")
    assert code == 2 and f"image {FEW}" in err and "--exclude ID" in err
    assert "larger --spacing" not in err
    code, text, err = cli(
        "grid", "evaluate", folder, "--spacing", "500", "--exclude", FEW, "--json"
    )
    assert code == 0, err
    ev = json.loads(text)
    assert ev["excluded"] == [str(FEW)]
    # the same through a grids file: grid fit --exclude, then evaluate --grids --exclude
    g = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", folder, "--spacing", "500", "--exclude", FEW, "--folds",
                       "0", "-o", g)  # fmt: skip
    assert code == 0, err
    code, _, err = cli("grid", "evaluate", folder, "--grids", g)
    assert code == 2 and "--exclude ID" in err
    code, text, err = cli("grid", "evaluate", folder, "--grids", g, "--exclude", FEW, "--json")
    assert code == 0, err
    ev2 = json.loads(text)
    assert ev2["steps_after"] == pytest.approx(ev["steps_after"], rel=1e-9)
    for when in ("before", "after"):
        got, want = ev2["residuals"]["block"][when], ev["residuals"]["block"][when]
        assert got == pytest.approx(want, rel=1e-9)


def test_grid_sweep_exclude(cli, folder):
    code, _, err = cli("grid", "sweep", folder, "--spacings", "1000,2000")
    assert code == 2 and "--exclude ID" in err and "--spacings: or" not in err
    code, text, err = cli(
        "grid", "sweep", folder, "--spacings", "1000,2000", "--exclude", FEW, "--json"
    )
    assert code == 0, err
    sw = json.loads(text)
    assert sw["excluded"] == [str(FEW)] and len(sw["step"]) >= 1


def test_exclude_refusals(cli, folder):
    code, _, err = cli("grid", "evaluate", folder, "--exclude", "nope")
    assert code == 2 and "--exclude: no image nope" in err
    code, _, err = cli("grid", "evaluate", folder, "--exclude", FEW, "--in-adjustment")
    assert code == 2 and "give one of them" in err
