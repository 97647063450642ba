"""`cloud transform`: options the chosen transformation would ignore are refused.

`--inverse` with `--from-crs/--to-crs` was silently ignored (the forward conversion was
written); so was `--from-crs` next to `--params`, and a `--crs` that contradicts the CRS the
points are transformed to was recorded in the output.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg

pytest.importorskip("laspy")
pyproj = pytest.importorskip("pyproj")


@pytest.fixture
def utm_cloud(tmp_path):
    rng = np.random.default_rng(5)
    xyz = np.c_[rng.uniform(480000, 480400, 200), rng.uniform(5.3e6, 5.3e6 + 300, 200),
                rng.uniform(200, 230, 200)]  # fmt: skip
    path = tmp_path / "utm.las"
    pg.io.write_cloud(path, xyz, scales=(1e-3, 1e-3, 1e-3), crs="EPSG:32633")
    return path


@pytest.fixture
def params(tmp_path):
    T = pg.Similarity3D.from_angles(1.00002, 0.001, -0.002, 0.3, [10.0, -20.0, 5.0])
    data = {"model_parameters": T.to_dict(), "crs": "EPSG:32633", "source_crs": "EPSG:32633"}
    path = tmp_path / "p.json"
    path.write_text(json.dumps(data))
    return path


def _run(cli, *args):
    return cli("cloud", "transform", *[str(a) for a in args], "-q")


def test_inverse_without_params_is_refused(cli, utm_cloud, tmp_path):
    out = tmp_path / "geo.las"
    code, _, err = _run(cli, utm_cloud, out, "--to-crs", "EPSG:4979", "--inverse")
    assert code == 2 and err.startswith("error: ") and "--inverse" in err and "swap" in err
    assert not out.exists()
    code, _, err = _run(cli, utm_cloud, out, "--from-crs", "EPSG:32633", "--to-crs", "EPSG:4979",
                        "--inverse")  # fmt: skip
    assert code == 2 and "--inverse" in err and not out.exists()
    # the way the message shows: the forward conversion, then back by swapping the CRSs
    code, _, err = _run(cli, utm_cloud, out, "--to-crs", "EPSG:4979", "--scales", "1e-9,1e-9,1e-3")
    assert code == 0, err
    back = tmp_path / "back.las"
    code, _, err = _run(cli, out, back, "--from-crs", "EPSG:4979", "--to-crs", "EPSG:32633",
                        "--scales", "1e-3,1e-3,1e-3")  # fmt: skip
    assert code == 0, err
    np.testing.assert_allclose(
        pg.io.read_cloud_xyz(back), pg.io.read_cloud_xyz(utm_cloud), atol=2e-3, rtol=0
    )


def test_from_crs_with_params_is_refused(cli, utm_cloud, params, tmp_path):
    out = tmp_path / "o.las"
    code, _, err = _run(cli, utm_cloud, out, "--params", params, "--from-crs", "EPSG:32633")
    assert code == 2 and "--from-crs" in err and "--params" in err and not out.exists()
    code, _, err = _run(cli, utm_cloud, out, "--params", params, "--inverse")
    assert code == 0, err  # --inverse is the parameters' own option


@pytest.mark.parametrize(
    "how, crs, ok",
    [
        (("--to-crs", "EPSG:4979"), "EPSG:4326", False),
        (("--to-crs", "EPSG:4979"), "EPSG:4979", True),
        (("--to-crs", "EPSG:4979"), "epsg:4979", True),
        (("--params", "P"), "EPSG:32632", False),
        (("--params", "P"), "EPSG:32633", True),
    ],
)
def test_crs_contradicting_the_output_is_refused(cli, utm_cloud, params, tmp_path, how, crs, ok):
    how = tuple(str(params) if a == "P" else a for a in how)
    out = tmp_path / "o.las"
    scales = "1e-9,1e-9,1e-3" if how[0] == "--to-crs" else "1e-3,1e-3,1e-3"
    code, _, err = _run(cli, utm_cloud, out, *how, "--crs", crs, "--scales", scales)
    if ok:
        assert code == 0, err
        assert pyproj.CRS(pg.io.cloud_info(out).crs) == pyproj.CRS(crs)
    else:
        assert code == 2 and f"--crs {crs}" in err and "leave --crs out" in err
        assert not out.exists()
