"""Progress of long jobs in pipes and logs.

Before: with stderr not a terminal (``grid fit ... 2> log``, a job scheduler, a pipe) no
command said anything while it ran, however long (``grid fit --spacing 1`` on big images:
minutes of silence). Now a job that runs longer than ``LOG_PROGRESS_DELAY`` seconds prints
plain lines ``photogeom: <stage> (<n> s)`` every ``LOG_PROGRESS_INTERVAL`` seconds and a
last ``... : done`` line; short jobs print nothing. The tests set the delay to 0 (the first
line at once) and the interval out of reach, so the lines do not depend on timing.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

W, H = 300, 200


@pytest.fixture(scope="module")
def residual_csv(tmp_path_factory):
    rng = np.random.default_rng(5)
    lines = ["image_id,u,v,rx,ry"]
    for im in ("IMG_1", "IMG_2"):
        uv = np.column_stack([rng.uniform(0, W - 1, 300), rng.uniform(0, H - 1, 300)])
        r = rng.normal(0, 0.1, uv.shape)
        lines += [f"{im},{a:.4f},{b:.4f},{c:.5f},{d:.5f}" for a, b, c, d in np.c_[uv, r]]
    p = tmp_path_factory.mktemp("grid") / "residuals.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def _fit(cli, residual_csv, out):
    return cli("grid", "fit", residual_csv, "--image-size", f"{W}x{H}", "--spacing", "50",
               "--folds", "0", "-o", out)  # fmt: skip


def test_short_jobs_print_nothing(cli, residual_csv, tmp_path):
    code, _, err = _fit(cli, residual_csv, tmp_path / "g.npz")
    assert code == 0 and "photogeom:" not in err


def test_grid_fit_counts_images_in_a_log(cli, residual_csv, tmp_path, at_once):
    code, _, err = _fit(cli, residual_csv, tmp_path / "g.npz")
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("photogeom: ")]
    assert lines[0].startswith("photogeom: fitting grids of 50 px (")
    assert any(ln.startswith("photogeom: fitting grids of 50 px: 2 of 2 images: done (")
               for ln in lines)  # fmt: skip
    assert "\r" not in err and "\x1b" not in err  # plain lines: no redrawing


def test_correct_images_counts_images_in_a_log(cli, residual_csv, tmp_path, at_once):
    grids = tmp_path / "g.npz"
    assert _fit(cli, residual_csv, grids)[0] == 0
    src = tmp_path / "in"
    src.mkdir()
    for k in (1, 2):
        Image.fromarray(np.zeros((H, W), np.uint8)).save(src / f"IMG_{k}.png")
    code, _, err = cli("grid", "correct-images", grids, src, tmp_path / "out")
    assert code == 0, err
    # the last line read "2 of 2 done: done": the count names images, as grid fit's does
    assert "photogeom: correcting images: 2 of 2 images: done (" in err
    assert "done: done" not in err


def test_streamed_job_reports_bytes_and_points(cli, tmp_path, at_once):
    p = tmp_path / "p.csv"
    p.write_text("id,x,y,z\n" + "".join(f"{i},{i},{2 * i},{3 * i}\n" for i in range(100)))
    params = tmp_path / "t.json"
    code, _, err = cli("transform", "estimate", "similarity3d", _pairs(tmp_path),
                       "--output-params", params)  # fmt: skip
    assert code == 0, err
    code, _, err = cli("transform", "apply", params, p, "-o", tmp_path / "o.csv")
    assert code == 0, err
    done = [ln for ln in err.splitlines() if ln.endswith("s)") and ": done (" in ln]
    assert done and "100 points: done" in done[-1]


def test_stage_lines_of_an_adjustment(cli, tmp_path, at_once):
    block = tmp_path / "b"
    code, _, err = cli("bundle", "simulate", block, "--strips", "1", "--images-per-strip", "4")
    assert code == 0, err
    assert "photogeom: simulating the FC300S block: done (" in err
    code, _, err = cli("bundle", "adjust", block)
    assert code == 0, err
    assert "photogeom: adjusting: iteration " in err and "cost" in err


def _pairs(tmp_path):
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 100, (6, 3))
    both = np.hstack([x, x + np.array([1.0, 2.0, 3.0])])
    p = tmp_path / "pairs.csv"
    p.write_text("id,x,y,z,X,Y,Z\n" + "".join(
        f"{i}," + ",".join(repr(float(v)) for v in row) + "\n"
        for i, row in enumerate(both)))  # fmt: skip
    return p


def test_grid_fit_of_a_block_counts_images_in_a_log(cli, tmp_path, at_once):
    # from an adjusted block folder the log said only "fitting grids of 500 px (0 s)", where
    # a residuals CSV counted its images
    block, adjusted = tmp_path / "b", tmp_path / "adjusted"
    code, _, err = cli("bundle", "simulate", block, "--strips", "1", "--images-per-strip", "3")
    assert code == 0, err
    code, _, err = cli("bundle", "adjust", block, "-o", adjusted)
    assert code == 0, err
    code, _, err = cli("grid", "fit", adjusted, "--spacing", "500", "--folds", "0",
                       "-o", tmp_path / "g.npz")  # fmt: skip
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("photogeom: fitting grids")]
    assert lines[-1].startswith("photogeom: fitting grids of 500 px: 3 of 3 images: done (")
