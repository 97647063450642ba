"""A grids file keeps the pixel positions each grid was fitted to, so that ``readjust`` of
the block with grids read back finds that they were fitted to its own observations and
computes sigma0 over the chain's effective redundancy. Before, a grids file held no
positions: the grids read back said nothing, and sigma0 was over the re-adjustment's own
redundancy, without a note (on this block 1.086 over 415 instead of 1.478 over 224.0 for
``grid evaluate --grids`` on the same grids)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import fit_residual_grids, load_grids, readjust, save_grids


@pytest.fixture(scope="module")
def fitted():
    sim = pg.simulate.uav_block("FC300S", seed=3, strips=2, images_per_strip=3)
    ba = pg.bundle_adjust(sim.block, snooping=False)
    grids = fit_residual_grids(ba.block, 500.0, folds=0)
    return ba.block, grids, readjust(ba.block, grids, snooping=False)


@pytest.mark.parametrize("name", ["g.npz", "g.json"])
def test_grids_read_back_keep_the_chain(fitted, tmp_path, name):
    block, grids, re = fitted
    assert re.effective_redundancy is not None
    save_grids(tmp_path / name, grids)
    back = load_grids(tmp_path / name)
    for k, g in grids.items():  # images, not points
        assert np.array_equal(back[k].uv, g.uv)  # bit for bit, JSON too
    again = readjust(block, back, snooping=False)
    assert again.effective_redundancy is not None
    # the grids are factorised again (their fit's factor is not in the file): the same
    # trace and sigma0 to rounding
    assert again.effective_redundancy["value"] == pytest.approx(
        re.effective_redundancy["value"], rel=1e-10
    )
    assert again.sigma0 == pytest.approx(re.sigma0, rel=1e-10)
    # over the re-adjustment's own redundancy (as before) sigma0 was too small
    plain = again.sigma0 * np.sqrt(again.effective_redundancy["value"] / again.redundancy)
    assert again.sigma0 > 1.05 * plain


def test_a_file_whose_positions_do_not_fit_is_refused(fitted, tmp_path):
    import json

    from photogeom.errors import FileFormatError

    _, grids, _ = fitted
    save_grids(tmp_path / "g.json", grids)
    d = json.loads((tmp_path / "g.json").read_text())
    d["images"][0]["uv"] = d["images"][0]["uv"][:-1]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(FileFormatError, match="uv of shape"):
        load_grids(tmp_path / "bad.json")
