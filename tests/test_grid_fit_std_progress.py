"""`grid fit` counts the images of its node standard deviations.

The grids file holds each node's standard deviation, a selected inversion of each image's
normal matrix computed when the file is written. On the study's 250-image block (100 px
grids of 4455 nodes) that took 15 s after the line "fitting grids of 100 px: 250 of 250
images: done", with nothing said and no file yet. It is now a stage of its own, counted per
image as the fit is; ``--no-std`` skips it.
"""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.calibration import fit_grid, load_grids

W, H = 300, 200


@pytest.fixture(scope="module")
def residuals(tmp_path_factory):
    rng = np.random.default_rng(7)
    data, lines = {}, ["image_id,u,v,rx,ry"]
    for im in ("IMG_1", "IMG_2", "IMG_3"):
        uv = np.column_stack([rng.uniform(0, W - 1, 300), rng.uniform(0, H - 1, 300)])
        r = np.round(rng.normal(0, 0.1, uv.shape), 5)
        uv = np.round(uv, 4)
        data[im] = (uv, r)
        lines += [f"{im},{a:.4f},{b:.4f},{c:.5f},{d:.5f}" for a, b, c, d in np.c_[uv, r]]
    p = tmp_path_factory.mktemp("grid") / "residuals.csv"
    p.write_text("\n".join(lines) + "\n")
    return p, data


def _fit(cli, path, out, *more):
    return cli("grid", "fit", path, "--image-size", f"{W}x{H}", "--spacing", "50",
               "--folds", "0", "-o", out, *more)  # fmt: skip


def test_the_node_standard_deviations_are_a_counted_stage(cli, residuals, tmp_path, at_once):
    path, data = residuals
    code, _, err = _fit(cli, path, tmp_path / "g.npz")
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("photogeom: ")]
    fit_done = [i for i, ln in enumerate(lines) if ln.startswith(
        "photogeom: fitting grids of 50 px: 3 of 3 images: done (")]  # fmt: skip
    std_done = [i for i, ln in enumerate(lines) if ln.startswith(
        "photogeom: node standard deviations: 3 of 3 images: done (")]  # fmt: skip
    assert len(fit_done) == len(std_done) == 1 and fit_done[0] < std_done[0]
    # the file holds the same standard deviations as a grid fitted apart
    saved = load_grids(tmp_path / "g.npz")
    for im, (uv, r) in data.items():
        alone = fit_grid(uv, r, (W, H), 50, sigma_obs=1.0, sigma_constraint=1.0, folds=0)
        assert np.allclose(saved[im].node_std, alone.node_std, rtol=1e-9, atol=0)


def test_no_std_has_no_such_stage(cli, residuals, tmp_path, at_once):
    path, _ = residuals
    code, _, err = _fit(cli, path, tmp_path / "g.npz", "--no-std")
    assert code == 0, err
    assert "node standard deviations" not in err
