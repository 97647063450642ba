"""`photogeom grid fit | apply | correct-images`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from photogeom.calibration import load_grids

W, H = 300, 200


@pytest.fixture(scope="module")
def residual_csv(tmp_path_factory):
    rng = np.random.default_rng(5)
    lines = ["image_id,u,v,rx,ry"]
    for im in ("IMG_1", "IMG_2"):
        uv = np.column_stack([rng.uniform(0, W - 1, 400), rng.uniform(0, H - 1, 400)])
        r = np.column_stack([np.sin(uv[:, 0] / 80), np.cos(uv[:, 1] / 60)])
        r += rng.normal(0, 0.1, r.shape)
        lines += [
            f"{im},{a:.4f},{b:.4f},{c:.5f},{d:.5f}" for a, b, c, d in np.column_stack([uv, r])
        ]
    p = tmp_path_factory.mktemp("grid") / "residuals.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_fit_apply_and_report(cli, residual_csv, tmp_path):
    out = tmp_path / "grids.npz"
    rep = tmp_path / "r.html"
    code, text, err = cli(
        "grid", "fit", str(residual_csv), "--image-size", f"{W}x{H}", "--spacing", "50",
        "-o", str(out), "--report", str(rep),
    )  # fmt: skip
    assert code == 0, err
    assert "IMG_2" in text and "computed minus observed" in text
    assert text.count("wrote ") == 2  # the grids and the report
    assert rep.read_text().count("<img") == 1
    grids = load_grids(out)
    assert set(grids) == {"IMG_1", "IMG_2"} and grids["IMG_1"].layout.shape == (5, 7)
    code, text, err = cli(
        "grid", "fit", str(residual_csv), "--image-size", f"{W}x{H}", "--spacing", "50",
        "-o", str(tmp_path / "g.json"), "--sigma-constraint", "vce", "--json", "--no-std",
    )  # fmt: skip
    assert code == 0, err
    data = json.loads(text)
    assert data["images"]["IMG_1"]["vce_iterations"] > 0
    # the estimated observation sigma is reported (it is what the variance components change)
    vg = load_grids(tmp_path / "g.json")["IMG_1"]
    assert data["images"]["IMG_1"]["sigma_obs_rms"] == pytest.approx(
        float(np.sqrt(np.mean(vg.sigma_obs**2))), rel=1e-12
    )
    obs = tmp_path / "obs.csv"
    obs.write_text("name,image_id,u,v\np1,IMG_2,10.5,20.25\np2,IMG_1,100,150\n")
    code, text, err = cli("grid", "apply", str(out), str(obs))
    assert code == 0, err
    rows = [r.split(",") for r in text.strip().splitlines()]
    assert rows[0] == ["name", "image_id", "u", "v"] and rows[1][0] == "p1"
    expected = grids["IMG_2"].correct([[10.5, 20.25]])[0]
    assert float(rows[1][2]) == pytest.approx(expected[0]) and float(rows[1][3]) == pytest.approx(
        expected[1]
    )


def test_bad_input_in_cli_words(cli, residual_csv, tmp_path):
    base = ("grid", "fit", str(residual_csv), "-o", str(tmp_path / "g.npz"))
    code, _, err = cli(*base, "--image-size", f"{W}x{H}", "--spacing", "0")
    assert code == 2 and "--spacing must be a positive number" in err
    code, _, err = cli(*base, "--image-size", f"{W}x{H}", "--spacing", "400")
    assert code == 2 and "larger than the image" in err
    code, _, err = cli(*base, "--image-size", "300 by 200")
    assert code == 2 and "--image-size" in err
    few = tmp_path / "few.csv"
    few.write_text("image_id,u,v,rx,ry\nA,1,1,0,0\nA,2,2,0,0\n")
    code, _, err = cli(
        "grid", "fit", str(few), "-o", str(tmp_path / "g.npz"), "--image-size", "300x200"
    )
    assert code == 2 and "image A" in err and "at least 4" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("image_id,u,v,rx\nA,1,1,0\n")
    code, _, err = cli(
        "grid", "fit", str(bad), "-o", str(tmp_path / "g.npz"), "--image-size", "300x200"
    )
    assert code == 2 and "no column 'ry'" in err
    assert not (tmp_path / "g.npz").exists()


def test_correct_images_lists_failures(cli, residual_csv, tmp_path):
    grids = tmp_path / "grids.npz"
    assert cli("grid", "fit", str(residual_csv), "--image-size", f"{W}x{H}", "-o", str(grids),
               "--spacing", "60", "--folds", "0")[0] == 0  # fmt: skip
    src = tmp_path / "in"
    src.mkdir()
    Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(src / "IMG_1.jpg")
    code, text, err = cli("grid", "correct-images", str(grids), str(src), str(tmp_path / "out"))
    assert code == 1
    assert "corrected 1 image(s)" in text and "failed IMG_2: no image file named IMG_2" in err
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["IMG_1.jpg"]
    code, _, err = cli("grid", "correct-images", str(grids), str(src), str(src))
    assert code == 2 and "must differ" in err


def test_grid_fit_keeps_blas_on_one_thread(residual_csv, tmp_path):
    """grid fit solves many small systems: in a fresh process without a BLAS thread setting
    it runs numpy's BLAS on one thread (BLAS threads made it 3x slower on 2 cores)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")}  # fmt: skip
    code = (
        "import os, sys\n"
        "from photogeom.cli.main import main\n"
        "try:\n"
        f"    main(['grid', 'fit', {str(residual_csv)!r}, '--image-size', '{W}x{H}', "
        f"'--spacing', '50', '-o', {str(tmp_path / 'g.npz')!r}, '--json'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "print('BLAS', os.environ.get('OPENBLAS_NUM_THREADS'), file=sys.stderr)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert "BLAS 1" in r.stderr, r.stderr
