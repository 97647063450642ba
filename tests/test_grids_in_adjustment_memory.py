"""Grids inside the bundle adjustment couple all nodes of a grid through its datum
conditions (a dense block of (2 nodes)^2 entries per grid): a spacing whose blocks cannot fit
in memory is refused at once, naming the way out, instead of numpy's "Unable to allocate
27.5 GiB" (20 px on 4000 x 3000 px images) or minutes of swapping (40 px)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import adjust_with_grids
from photogeom.calibration import in_adjustment as ia
from photogeom.errors import InputError


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block


def test_a_grid_too_fine_for_the_memory_is_refused(block, monkeypatch):
    monkeypatch.setattr(ia, "_physical_memory", lambda: 2**30)  # a 1 GiB machine
    layout = pg.calibration.GridLayout(4000, 3000, 50)
    need = ia.BYTES_PER_DATUM_ENTRY * block.n_images * (2.0 * layout.n_nodes) ** 2
    assert need > 2**30  # 6 grids of 81 x 61 nodes: about 65 GiB
    with pytest.raises(InputError) as exc:
        adjust_with_grids(block, 50)
    msg = str(exc.value)
    assert f"{layout.n_nodes} nodes per grid over {block.n_images} grid(s)" in msg
    assert f"{need / 2**30:.1f} GiB" in msg and "1.0 GiB" in msg
    assert "larger spacing" in msg and "fit_residual_grids" in msg


def test_the_estimate_is_of_every_grid_and_coarse_grids_pass(monkeypatch):
    monkeypatch.setattr(ia, "_physical_memory", lambda: 10**9)
    ia._check_memory(np.array([63] * 16), 500.0)  # 16 images at 500 px: 16 MB
    with pytest.raises(InputError, match="16 grid"):
        ia._check_memory(np.array([1271] * 16), 100.0)  # 16 x 2542^2 x 120 B: 12.4 GB
    monkeypatch.setattr(ia, "_physical_memory", lambda: None)  # unknown memory: no guard
    ia._check_memory(np.array([10**6]), 1.0)
