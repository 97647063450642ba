"""``-0`` in an integer id column of a CSV block.

``-0`` is in integer form and is read as the integer 0, by design. Two rows ``-0`` and ``0``
of images.csv, points.csv or cameras.csv would then be one id: they are refused (they
were, but the message said "id '0' appears twice" on the line that holds ``-0``); the
message now shows both spellings, both lines, and the fix. An observation's ``-0`` refers
to the id 0 of an integer column, and to no image of a text column.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import FileFormatError


@pytest.fixture(scope="module")
def block_dir(tmp_path_factory) -> Path:
    b = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=3, tie_points_per_image=40
    ).block
    d = tmp_path_factory.mktemp("mz") / "block"
    pg.bundle.write_csv_block(b, d)
    return d


def _copy(src: Path, dst: Path, name: str, edit) -> Path:
    dst.mkdir()
    for f in ("cameras.csv", "images.csv", "points.csv", "observations.csv"):
        text = (src / f).read_text()
        (dst / f).write_text(edit(text) if f == name else text)
    return dst


def _line_of(text: str, prefix: str) -> int:
    return next(k for k, ln in enumerate(text.splitlines(), 1) if ln.startswith(prefix))


@pytest.mark.parametrize("name", ["images.csv", "points.csv"])
def test_minus_zero_and_zero_are_refused_naming_both(tmp_path, block_dir, name):
    d = _copy(block_dir, tmp_path / "b", name, lambda t: re.sub(r"(?m)^1,", "-0,", t))
    text = (d / name).read_text()
    with pytest.raises(FileFormatError) as e:
        pg.bundle.read_csv_block(d)
    msg = str(e.value)
    assert f"line {_line_of(text, '-0,')}: id '-0' is the integer 0" in msg
    assert f"as '0' on line {_line_of(text, '0,')}" in msg
    assert "quote the ids" in msg


def test_minus_zero_camera_ids_are_refused(tmp_path, block_dir):
    def two_cameras(t: str) -> str:
        lines = t.splitlines()
        row = next(ln for ln in lines if ln.startswith("FC300S,"))
        return t.replace("FC300S,", "0,") + row.replace("FC300S,", "-0,") + "\n"

    d = _copy(block_dir, tmp_path / "b", "cameras.csv", two_cameras)
    for f in ("images.csv",):
        (d / f).write_text((d / f).read_text().replace(",FC300S,", ",0,"))
    with pytest.raises(FileFormatError, match=r"camera '-0' is the integer 0, as '0'"):
        pg.bundle.read_csv_block(d)


def test_observation_minus_zero_refers_to_image_zero_of_an_integer_column(tmp_path, block_dir):
    d = _copy(
        block_dir, tmp_path / "b", "observations.csv", lambda t: re.sub(r"(?m)^0,", "-0,", t)
    )
    b = pg.bundle.read_csv_block(d)
    want = pg.bundle.read_csv_block(block_dir)
    assert np.array_equal(b.observations.image_ids, want.observations.image_ids)


def test_observation_minus_zero_is_no_image_of_a_text_column(tmp_path, block_dir):
    """Images "0" (quoted: text) and an observation's -0: refused, not merged."""
    d = _copy(block_dir, tmp_path / "b", "images.csv", lambda t: re.sub(r"(?m)^0,", '"0",', t))
    obs = d / "observations.csv"
    obs.write_text(re.sub(r"(?m)^0,", "-0,", obs.read_text(), count=1))
    with pytest.raises(FileFormatError, match=r"image_id '-0' is not one of the image"):
        pg.bundle.read_csv_block(d)
