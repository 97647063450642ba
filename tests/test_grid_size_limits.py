"""`grid fit --spacing 0.001` (or `--image-size 100000000x100000000`) ended in numpy's
traceback "_ArrayMemoryError: Unable to allocate 5.81 TiB ..." (exit 1); --image-size 0x10
said "image width must be ..." without naming the option."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import photogeom.calibration.grid as grid_mod
from photogeom.calibration.grid import (
    MAX_NODES,
    GridLayout,
    fit_grid,
    fit_grids,
    supported_spacing,
)
from photogeom.errors import InputError


def test_layout_refuses_too_many_nodes():
    with pytest.raises(InputError, match="nodes, more than 10,000,000: choose a larger spacing"):
        GridLayout(1000, 800, 0.001)
    g = GridLayout(7952, 5304, 100)  # a 42 Mpx image at 100 px: far below the limit
    assert g.nx * g.ny < MAX_NODES


@pytest.mark.parametrize(("size", "spacing", "expected"), [
    ("1000x800", "0.001", "error: --spacing 0.001 px on a 1000 x 800 px image gives"),
    ("100000000x100000000", "100", "choose a larger --spacing (at least 3.16e+04 px)"),
    ("0x10", "100", "error: --image-size: the width must be a positive whole number"),
])
def test_grid_fit_names_the_option(cli, tmp_path: Path, size, spacing, expected):
    res = tmp_path / "r.csv"
    res.write_text("image_id,u,v,rx,ry\nA,10,10,0.1,0.1\nA,500,400,0.2,0.1\n")
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", res, "--image-size", size, "--spacing", spacing,
                       "-o", out)
    assert code == 2 and expected in err, err
    assert not out.exists()


def test_out_of_memory_is_one_error_line(cli, monkeypatch):
    import numpy as np

    from photogeom import datasets

    def too_big(*args, **kwargs):
        return np.empty((10**9, 10**9))  # numpy's _ArrayMemoryError, a MemoryError

    import photogeom.orientation as orientation

    monkeypatch.setattr(orientation, "absolute_orientation", too_big)
    code, _, err = cli("orient", "absolute", datasets.path("lidar_wang2014"))
    assert code == 2
    assert err.startswith("error: not enough memory for this job (Unable to allocate")
    assert len(err.strip().splitlines()) == 1


def _scattered(n: int, size=(1000, 800), seed=0):
    rng = np.random.default_rng(seed)
    uv = rng.uniform(0, [size[0] - 1, size[1] - 1], (n, 2))
    return uv, rng.normal(0.0, 0.3, (n, 2))


def test_fit_grid_refuses_far_more_nodes_than_observations():
    # 1000 x 800 px at 1 px: 801 x 1001 nodes for 400 observations took 3 GB and minutes
    uv, res = _scattered(400)
    with pytest.raises(InputError) as exc:
        fit_grid(uv, res, (1000, 800), 1.0)
    msg = str(exc.value)
    assert "801 x 1001 = 801,801 nodes for 400 observations" in msg, msg
    assert "choose a spacing of at least 4.02 px" in msg, msg
    with pytest.raises(InputError, match="image A: grid spacing 1 px"):
        fit_grids({"A": _scattered(400, seed=1), "B": (uv, res)}, (1000, 800), 1.0)
    # the spacing named is one the data support: at most 50,000 nodes, independently counted
    g = supported_spacing(1000, 800, 400)
    assert (math.ceil(999.5 / g) + 1) * (math.ceil(799.5 / g) + 1) <= 50_000
    assert (math.ceil(999.5 / (g - 0.01)) + 1) * (math.ceil(799.5 / (g - 0.01)) + 1) > 50_000


def test_fine_grids_of_large_images_stay_allowed():
    # 42 Mpx at 100 px (4455 nodes) with only 20 observations; 100 000 nodes with 1000
    for size, spacing, n in (((7952, 5304), 100.0, 20), ((7952, 5304), 20.9, 1000)):
        uv, _ = _scattered(n, size)
        layout = GridLayout(*size, spacing)
        assert layout.n_nodes <= max(50_000, 100 * n)
        grid_mod._image_inputs(uv, uv * 0, size, spacing, 4, "")


def test_grid_fit_cli_names_the_supported_spacing(cli, tmp_path: Path):
    uv, res = _scattered(400)
    rows = "".join(f"A,{a:.3f},{b:.3f},{c:.3f},{d:.3f}\n" for (a, b), (c, d) in zip(uv, res))
    path = tmp_path / "v.csv"
    path.write_text("image_id,u,v,rx,ry\n" + rows)
    out = tmp_path / "g.npz"
    code, _, err = cli("grid", "fit", path, "--image-size", "1000x800", "--spacing", "1",
                       "-o", out)
    assert code == 2, err
    assert "error: image A: --spacing 1 px on a 1000 x 800 px image" in err, err
    assert "choose a --spacing of at least 4.02 px for 400 observations" in err, err
    assert not out.exists()
