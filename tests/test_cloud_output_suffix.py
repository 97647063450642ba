"""`cloud transform in.las out.txt` wrote a LAS file under the name out.txt (exit 0); an
output name that does not end in .las or .laz is now refused before anything is read."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError

laspy = pytest.importorskip("laspy")


@pytest.fixture
def scan(tmp_path):
    x = np.random.default_rng(1).uniform([0, 0, 0], [40, 30, 3], (200, 3))
    src = tmp_path / "scan.las"
    pg.io.write_cloud(src, x, scales=(1e-3, 1e-3, 1e-3))
    return src


@pytest.mark.parametrize(("name", "found"), [
    ("out.txt", "ends in '.txt'"), ("out", "has no suffix"), ("out.las.csv", "ends in '.csv'"),
])
def test_cli_refuses_output_that_is_not_las_or_laz(cli, scan, tmp_path, name, found):
    out = tmp_path / name
    code, _, err = cli("cloud", "transform", scan, out, "--from-crs", "EPSG:32633",
                       "--to-crs", "EPSG:32632")
    assert code == 2, err
    assert f"error: OUTPUT {out} {found}: a point cloud is written as LAS or LAZ" in err, err
    assert "give a name ending in .las (uncompressed) or .laz (compressed)" in err
    assert not out.exists()


def test_python_refuses_it_too_and_keeps_las_laz_any_case(scan, tmp_path):
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [10.0, 20.0, 0.0])
    with pytest.raises(InputError, match=r"out\.txt ends in '\.txt'"):
        pg.io.transform_cloud(scan, tmp_path / "out.txt", T)
    with pytest.raises(InputError, match=r"c\.xyz ends in '\.xyz'"):
        pg.io.write_cloud(tmp_path / "c.xyz", [[1.0, 2.0, 3.0]])
    assert not list(tmp_path.glob("out*")) and not list(tmp_path.glob("c.*"))
    for name, compressed in (("a.LAS", False), ("b.Laz", True)):
        pg.io.transform_cloud(scan, tmp_path / name, T)
        with laspy.open(tmp_path / name) as r:  # the bytes say what the name says
            assert r.header.are_points_compressed == compressed
