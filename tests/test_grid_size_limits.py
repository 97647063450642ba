"""`grid fit --spacing 0.001` (or `--image-size 100000000x100000000`) ended in numpy's
traceback "_ArrayMemoryError: Unable to allocate 5.81 TiB ..." (exit 1); --image-size 0x10
said "image width must be ..." without naming the option."""

from __future__ import annotations

from pathlib import Path

import pytest

from photogeom.calibration.grid import MAX_NODES, GridLayout
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
