"""`grid fit` / `grid apply`: a point outside its image is named by its file line,
not by its row counted within one image."""

from __future__ import annotations

import numpy as np

from photogeom.calibration import fit_grids, save_grids


def _residuals(tmp_path, outside_at: int | None):
    rng = np.random.default_rng(3)
    lines = ["# residuals, px", "image_id,u,v,rx,ry"]
    for i in range(200):
        lines.append(f"{'AB'[i % 2]},{rng.uniform(0, 299):.2f},{rng.uniform(0, 199):.2f},0.1,0.2")
    if outside_at is not None:
        lines.insert(outside_at - 1, "A,350.5,20,0.1,0.1")
    p = tmp_path / "res.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_fit_names_the_file_line_of_a_point_outside(cli, tmp_path):
    res = _residuals(tmp_path, 152)  # the 76th row of image A
    base = ("grid", "fit", res, "--folds", "0", "-o", tmp_path / "g.npz")
    code, _, err = cli(*base, "--image-size", "300x200", "--spacing", "100")
    assert code == 2
    assert "res.csv: line 152, image A: u, v = (350.5, 20) px lie outside the 300 x 200 px" in err
    assert "1 row(s) in all" in err and "--image-size" in err and "row 75" not in err
    # the image size and the spacing are checked first, as before
    code, _, err = cli(*base, "--image-size", "300x200", "--spacing", "1000")
    assert code == 2 and "--spacing 1000 px is larger than the image" in err
    code, _, err = cli(*base, "--image-size", "400x200", "--spacing", "100")
    assert code == 0, err


def test_apply_names_the_file_line_of_a_point_outside(cli, tmp_path):
    rng = np.random.default_rng(4)
    uv = rng.uniform(0, [299, 199], (60, 2))
    grids = fit_grids({"A": (uv, uv * 0), "B": (uv, uv * 0)}, (300, 200), 100.0, folds=0)
    save_grids(tmp_path / "g.npz", grids)
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\nB,1,1\nA,5,5\n\nA,10,10\nA,400,10\nB,-3,2\n")
    code, _, err = cli("grid", "apply", tmp_path / "g.npz", obs)
    assert code == 2
    assert "obs.csv: line 6, image A: u, v = (400, 10) px lie outside the 300 x 200 px" in err
    assert "2 row(s) in all" in err and "row 2" not in err
