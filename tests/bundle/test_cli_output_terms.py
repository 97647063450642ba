"""`bundle adjust -o` into a format whose camera cannot hold the calibration the adjustment
estimates (BAL and Bundler: f, k1, k2 and the principal point; COLMAP: no K4, no B2) is
refused before the adjustment, naming the --free that fits the format; before, the writer
refused it after the adjustment, without a fix."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import photogeom.bundle as bundle
from photogeom import MetashapeCalibration
from photogeom.bundle import write_csv_block

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

CAL = MetashapeCalibration(3000, 2000, 2400.0, k1=-0.08, k2=0.03)


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("src") / "grid"
    write_csv_block(grid_block(2, rows=2, cols=3, n_points=120, noise=0.3, cal=CAL), d)
    return d


@pytest.fixture
def no_adjustment(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the adjustment ran")

    monkeypatch.setattr(bundle, "bundle_adjust", refuse)


@pytest.mark.parametrize(("name", "label"), [("x.bal", "BAL"), ("x.out", "Bundler")])
def test_terms_a_bal_or_bundler_camera_lacks_are_refused_first(
    block_dir, cli, tmp_path, no_adjustment, name, label
):
    out = tmp_path / name
    free = "f,cx,cy,k1,k2,k3,p1,p2"
    code, _, err = cli("bundle", "adjust", block_dir, "-o", out, "--free", free, "--drop-extras")
    assert code != 0
    assert f"a {label} file's camera has no K3 and no P1 and no P2" in err
    assert "--free f,cx,cy,k1,k2," in err and "--output-format csv" in err
    assert not out.exists()


def test_terms_colmap_lacks_are_refused_first(block_dir, cli, tmp_path, no_adjustment):
    out = tmp_path / "model"
    code, _, err = cli(
        "bundle", "adjust", block_dir, "-o", out, "--output-format", "colmap",
        "--free", "f,k1,k2,k4", "--drop-extras",
    )  # fmt: skip
    assert code != 0
    assert "a COLMAP model's camera has no K4" in err
    assert "--free f,cx,cy,k1,k2,k3,p1,p2,b1," in err
    assert not out.exists()


def test_what_the_format_holds_is_adjusted_and_written(block_dir, cli, tmp_path):
    out = tmp_path / "x.bal"
    code, _, err = cli(
        "bundle", "adjust", block_dir, "-o", out, "--free", "f,cx,cy,k1,k2", "--drop-extras",
        "--no-snooping",
    )  # fmt: skip
    assert code == 0, err
    assert bundle.read_bal(out).n_images == 6


def test_an_image_id_a_bundler_list_cannot_keep_is_refused_first(
    cli, tmp_path, no_adjustment
):
    # 'NAME 0 FOCAL' is a list line with Bundler's focal length: read back as 'img0'
    import numpy as np

    b = grid_block(2, rows=2, cols=3, n_points=120, noise=0.3, cal=CAL)
    ids = b.image_ids.tolist()
    ids[1] = "img0 0 1200"
    src = tmp_path / "src"
    write_csv_block(b.replace(image_ids=np.array(ids, dtype=object)), src)
    out = tmp_path / "x.out"
    code, _, err = cli("bundle", "adjust", src, "-o", out, "--free", "f,k1,k2", "--drop-extras")
    assert code != 0
    assert f"--output {out}" in err and "'img0 0 1200'" in err and "rename the image" in err
    assert not out.exists()
