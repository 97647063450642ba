"""`transform apply` applies the row/y flip that `transform estimate` records for a
left-handed system (pixel) paired with a right-handed one (fiducial, image)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from photogeom.io import read_points

# pixel (col, row) -> fiducial mm: x = 0.1 col - 120, y = -0.1 row + 122 with a small
# rotation; exact, so the estimate reproduces the targets to rounding
_ANG = 0.003
_R = np.array([[np.cos(_ANG), -np.sin(_ANG)], [np.sin(_ANG), np.cos(_ANG)]])
_PIX = np.array(
    [[100, 120], [2300, 130], [2290, 2330], [110, 2320], [1200, 125], [1195, 2325],
     [640, 1710], [1830, 480]],
    dtype=float,
)


def _fiducial(pix: np.ndarray) -> np.ndarray:
    """By hand: scale, then the y axis turned up (row down -> y up), a rotation, a shift."""
    right_handed = np.column_stack([0.1 * pix[:, 0], -0.1 * pix[:, 1]])
    return right_handed @ _R.T + np.array([-120.0, 122.0])


_MM = _fiducial(_PIX)


def _pairs(tmp_path: Path) -> Path:
    lines = ["id,col,row,x,y"]
    lines += [
        f"{i + 1},{float(c)!r},{float(r)!r},{float(x)!r},{float(y)!r}"
        for i, ((c, r), (x, y)) in enumerate(zip(_PIX, _MM, strict=True))
    ]
    path = tmp_path / "pairs.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _estimate(cli, tmp_path, model, source_side, how):
    """Parameters of ``model`` pixel -> fiducial (``source_side="pixel"``) or fiducial ->
    pixel, from --output-params or --json."""
    pairs = _pairs(tmp_path)
    if source_side == "pixel":
        args = ["--source-cols", "col,row", "--target-cols", "x,y",
                "--source-system", "pixel", "--target-system", "fiducial"]
    else:
        args = ["--source-cols", "x,y", "--target-cols", "col,row",
                "--source-system", "fiducial", "--target-system", "pixel"]
    par = tmp_path / f"{model}-{source_side}-{how}.json"
    if how == "params":
        code, _, err = cli("transform", "estimate", model, pairs, *args, "--output-params", par)
    else:
        code, out, err = cli("transform", "estimate", model, pairs, *args, "--json")
        par.write_text(out)
    assert code == 0, err
    hand = json.loads(par.read_text())["extras"]["handedness"]
    assert hand["source_flip_y"] is (source_side == "pixel")
    assert hand["target_flip_y"] is (source_side != "pixel")
    return pairs, par


@pytest.mark.parametrize("model", ["similarity2d", "affine2d", "projective2d"])
@pytest.mark.parametrize("how", ["params", "json"])
def test_pixel_source_apply_reproduces_the_targets(tmp_path, cli, model, how):
    pairs, par = _estimate(cli, tmp_path, model, "pixel", how)
    out = tmp_path / "mm.csv"
    code, _, err = cli("transform", "apply", par, pairs, "--cols", "col,row", "--out-cols",
                       "X,Y", "-o", out)
    assert code == 0, err
    mm = read_points(out)
    np.testing.assert_allclose(mm.coords, _MM, atol=1e-8)
    assert "input row/y negated" in out.read_text().splitlines()[0]
    # the inverse takes the fiducial coordinates back to (col, row) as given, rows positive
    back = tmp_path / "px.csv"
    code, _, err = cli("transform", "apply", par, pairs, "--cols", "x,y", "--inverse",
                       "--out-cols", "col,row", "-o", back)
    assert code == 0, err
    np.testing.assert_allclose(read_points(back).coords, _PIX, atol=1e-6)


@pytest.mark.parametrize("model", ["similarity2d", "affine2d", "projective2d"])
@pytest.mark.parametrize("how", ["params", "json"])
def test_pixel_target_apply_reproduces_the_targets(tmp_path, cli, model, how):
    pairs, par = _estimate(cli, tmp_path, model, "fiducial", how)
    out = tmp_path / "px.csv"
    code, _, err = cli("transform", "apply", par, pairs, "--cols", "x,y", "--out-cols",
                       "col,row", "-o", out)
    assert code == 0, err
    np.testing.assert_allclose(read_points(out).coords, _PIX, atol=1e-6)
    assert "output row/y negated" in out.read_text().splitlines()[0]
    back = tmp_path / "mm.csv"
    code, _, err = cli("transform", "apply", par, pairs, "--cols", "col,row", "--inverse",
                       "--out-cols", "X,Y", "-o", back)
    assert code == 0, err
    np.testing.assert_allclose(read_points(back).coords, _MM, atol=1e-8)


def test_same_handedness_is_applied_as_it_stands(tmp_path, cli):
    pairs = _pairs(tmp_path)
    par = tmp_path / "p.json"
    code, _, err = cli("transform", "estimate", "affine2d", pairs, "--source-cols", "col,row",
                       "--target-cols", "x,y", "--output-params", par)
    assert code == 0, err
    code, out, err = cli("transform", "apply", par, pairs, "--cols", "col,row")
    assert code == 0, err and "negated" not in out
    got = np.array([[float(v) for v in line.split(",")[1:3]] for line in out.splitlines()[2:]])
    np.testing.assert_allclose(got, _MM, atol=1e-8)  # an affinity fits the reflection itself


@pytest.mark.parametrize(
    ("handedness", "words"),
    [("[true]", "must be an object"), ('{"source_flip_y": "yes"}', "true or false")],
)
def test_malformed_handedness_is_refused(tmp_path, cli, handedness, words):
    pairs, par = _estimate(cli, tmp_path, "affine2d", "pixel", "params")
    text = par.read_text()
    data = json.loads(text)
    data["extras"]["handedness"] = json.loads(handedness)
    par.write_text(json.dumps(data))
    code, out, err = cli("transform", "apply", par, pairs, "--cols", "col,row")
    assert code == 2 and out == ""
    assert "error:" in err and "extras.handedness" in err and words in err


def test_handedness_on_a_3d_model_is_refused(tmp_path, cli):
    par = tmp_path / "p.json"
    par.write_text(json.dumps({
        "model_parameters": {"model": "rigid3d", "rotation": np.eye(3).tolist(),
                             "translation": [0, 0, 0]},
        "extras": {"handedness": {"source_flip_y": True, "target_flip_y": False}},
    }))
    pts = tmp_path / "p.csv"
    pts.write_text("id,x,y,z\n1,1,2,3\n")
    code, _, err = cli("transform", "apply", par, pts)
    assert code == 2 and "2D transformations only" in err
