"""review10 (failure injection): output names a plain ``open()`` accepts are accepted, failed
writes name the destination, and nothing is left behind."""

from __future__ import annotations

import os

import numpy as np
import pytest

import photogeom as pg
from photogeom.atomicfile import _temporary_name, atomic_write_text
from photogeom.io import PointWriter, write_points

posix = pytest.mark.skipif(os.name != "posix", reason="POSIX file names")


def _limit(directory) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (AttributeError, OSError, ValueError):
        return 255


def _longest(directory, suffix: str, char: str = "a") -> str:
    """A file name exactly at the file system's limit (bytes), ending in ``suffix``."""
    room = _limit(directory) - len(suffix.encode())
    return char * (room // len(char.encode())) + "x" * (room % len(char.encode())) + suffix


def _names(d) -> list[str]:
    return sorted(p.name for p in d.iterdir())


@posix
@pytest.mark.parametrize("char", ["a", "\u00e9", "\u6c34"])  # 1, 2 and 3 UTF-8 bytes
def test_temporary_names_fit_the_limit(tmp_path, char):
    name = _longest(tmp_path, ".csv", char)
    tmp = _temporary_name(tmp_path, name, ".0123456789ab.tmp")
    raw = os.fsencode(tmp.name)
    assert len(raw) <= _limit(tmp_path)
    assert tmp.name.startswith(".") and tmp.name.endswith(".0123456789ab.tmp")
    raw.decode("utf-8")  # whole characters kept
    assert _temporary_name(tmp_path, "short.csv", ".x.tmp").name == ".short.csv.x.tmp"


@posix
def test_text_and_point_files_with_the_longest_names(tmp_path):
    """A 255-byte name failed with 'the file name is too long' (its temporary name did)."""
    p = tmp_path / _longest(tmp_path, ".json")
    atomic_write_text(p, "{}\n")
    atomic_write_text(p, "{}\n")  # replaced, too
    assert p.read_text() == "{}\n"
    q = tmp_path / _longest(tmp_path, ".csv", "\u00e9")
    write_points(q, ["a"], np.array([[1.0, 2.0]]), ["x", "y"])
    with PointWriter(q, ["x", "y"]) as w:
        w.write(["b"], np.array([[3.0, 4.0]]))
    assert q.read_text().splitlines()[-1] == "b,3.0,4.0"
    assert _names(tmp_path) == sorted([p.name, q.name])


@posix
@pytest.mark.parametrize("scheduler", [None, "threads"])
def test_clouds_with_the_longest_names(tmp_path, scheduler):
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    xyz = np.random.default_rng(1).uniform(0, 50, (300, 3))
    src = tmp_path / _longest(tmp_path, ".laz", "s")
    pg.io.write_cloud(src, xyz)
    dst = tmp_path / _longest(tmp_path, ".laz", "d")
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [10.0, 20.0, 30.0])
    res = pg.io.transform_cloud(src, dst, T, scheduler=scheduler)
    assert res.point_count == 300
    assert np.allclose(pg.io.read_cloud_xyz(dst), T.apply(xyz), atol=1e-3)
    assert _names(tmp_path) == sorted([src.name, dst.name])


@posix
def test_cli_output_with_the_longest_name(cli, tmp_path):
    src = tmp_path / "in.csv"
    src.write_text("id,x,y\na,1,2\n")
    params = tmp_path / "p.json"
    fiducials = pg.datasets.path("lecture_fiducials")
    code, _, err = cli(
        "transform", "estimate", "similarity2d", fiducials, "--output-params", params
    )
    assert code == 0, err
    out = tmp_path / _longest(tmp_path, ".csv")
    code, _, err = cli("transform", "apply", params, src, "-o", out)
    assert code == 0, err
    assert out.read_text().splitlines()[-2] == "id,X,Y"
