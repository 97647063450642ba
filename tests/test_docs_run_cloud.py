"""`photogeom cloud transform --scheduler` reaches the transformation (docs run).

docs/crs-and-clouds.md documents ``cloud transform ... [--scheduler local:2]`` (pieces of the
file as Dask tasks). The option was accepted and dropped: the command always ran in this
process, and ``--scheduler foo`` or ``--scheduler local:0`` passed without a word.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg

laspy = pytest.importorskip("laspy")
pytest.importorskip("dask")


@pytest.fixture
def scan(tmp_path):
    rng = np.random.default_rng(9)
    x = rng.uniform([0, 0, 0], [100, 80, 20], (3000, 3))
    src = tmp_path / "scan.laz"
    pg.io.write_cloud(src, x, scales=(1e-3, 1e-3, 1e-3))
    T = pg.Similarity3D.from_helmert(
        10.0, -5.0, 2.0, 1.0, 2.0, 3.0, 5.0, convention="position_vector"
    )
    return src, T


def _params(tmp_path, T):
    import json

    path = tmp_path / "helmert.json"
    path.write_text(json.dumps(T.to_dict()), encoding="utf-8")
    return path


def test_scheduler_is_used(cli, scan, tmp_path, monkeypatch):
    src, T = scan
    params = _params(tmp_path, T)
    import photogeom.io.cloud as cloud

    seen = []
    real = cloud.transform_cloud_dask

    def spy(*args, **kwargs):
        seen.append(kwargs.get("scheduler"))
        return real(*args, **kwargs)

    monkeypatch.setattr(cloud, "transform_cloud_dask", spy)
    out_dask = tmp_path / "dask.laz"
    code, _, err = cli(
        "cloud", "transform", src, out_dask, "--params", params, "--scheduler", "threads"
    )
    assert code == 0, err
    assert seen == ["threads"]
    out_seq = tmp_path / "seq.laz"
    code, _, err = cli("cloud", "transform", src, out_seq, "--params", params)
    assert code == 0, err
    assert seen == ["threads"]  # no scheduler: in this process
    a, b = laspy.read(out_dask), laspy.read(out_seq)
    assert np.array_equal(a.X, b.X) and np.array_equal(a.Y, b.Y) and np.array_equal(a.Z, b.Z)


@pytest.mark.parametrize("value", ["foo", "local:0"])
def test_bad_scheduler_is_refused(cli, scan, tmp_path, value):
    src, T = scan
    params = _params(tmp_path, T)
    out = tmp_path / "out.laz"
    code, _, err = cli("cloud", "transform", src, out, "--params", params, "--scheduler", value)
    assert code == 2
    assert f"error: --scheduler '{value}'" in err
    assert not out.exists()


@pytest.mark.parametrize("value", ["foo", "local:0", "http://host:8787"])
def test_register_bad_scheduler_names_the_option(cli, scan, tmp_path, value):
    src, _ = scan
    code, _, err = cli("cloud", "register", src, src, "--scheduler", value)
    assert code == 2
    assert f"error: --scheduler '{value}'" in err
