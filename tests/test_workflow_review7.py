"""Workflow review 7: files written by one command read back by the next."""

from __future__ import annotations

import numpy as np

from photogeom.io import read_points, write_points


def test_ids_beginning_with_hash_survive_a_write_and_read(tmp_path):
    """An id such as '#12' written unquoted made its row a comment line: the point was
    silently lost by the next command (camera project -> orient resection)."""
    ids = ["# 1", "#2", " #3", "007", "P 3"]
    coords = np.arange(15, dtype=float).reshape(5, 3)
    path = tmp_path / "pts.csv"
    write_points(path, ids, coords, columns=("X", "Y", "Z"))
    back = read_points(path)
    assert list(back.ids) == ["# 1", "#2", "#3", "007", "P 3"]
    np.testing.assert_array_equal(back.coords, coords)
    assert '"#2"' in path.read_text()
