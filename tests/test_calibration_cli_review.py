"""`photogeom grid fit | apply`: ids, quoting, empty input, CLI words."""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.calibration import GridLayout, ResidualGrid, save_grids

W, H = 90, 60


def _grid(seed: int = 0) -> ResidualGrid:
    rng = np.random.default_rng(seed)
    layout = GridLayout(W, H, 30)
    zero = np.zeros(layout.shape)
    return ResidualGrid(
        layout=layout,
        nodes=rng.normal(0, 1, (*layout.shape, 2)),
        sigma0=1.0,
        redundancy=1,
        sigma_obs=np.ones(1),
        sigma_constraint=1.0,
        support=zero > 0,
        counts=zero.astype(int),
        rms_before=1.0,
        rms_after=1.0,
    )


def test_apply_matches_csv_text_ids_to_integer_grid_ids(cli, tmp_path):
    grids = {0: _grid(0), 1: _grid(1)}  # a simulated block's integer ids
    path = save_grids(tmp_path / "g.npz", grids, std=False)
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\n1,10.5,20.25\n0,3,4\n")
    code, text, err = cli("grid", "apply", path, obs)
    assert code == 0, err
    rows = [r.split(",") for r in text.strip().splitlines()[1:]]
    for (iid, u, v), key in zip(rows, (1, 0)):
        assert iid == str(key)
        uv = np.array([[10.5, 20.25]] if key == 1 else [[3.0, 4.0]])
        want = uv + grids[key].evaluate(uv)
        assert (float(u), float(v)) == pytest.approx(tuple(want[0]), abs=1e-12)
