"""Rotation helpers refuse malformed input in photogeom's words (before: scipy's ValueError,
IndexError, numpy's broadcasting ValueError)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError


@pytest.mark.parametrize("seq", ["abc", "xy", "xxy", "xYz", "xyzx", 3])
def test_bad_euler_sequences(seq):
    with pytest.raises(InputError, match="Euler sequence"):
        pg.euler_from_matrix(np.eye(3), seq)
    with pytest.raises(InputError, match="Euler sequence"):
        pg.matrix_from_euler(seq, [0.1, 0.2, 0.3])


def test_good_euler_sequences_round_trip():
    for seq in ("xyz", "ZYX", "zxz", "XZX"):
        R = pg.matrix_from_euler(seq, [10.0, 20.0, 30.0], unit="deg")
        np.testing.assert_allclose(pg.euler_from_matrix(R, seq, unit="deg"), [10, 20, 30],
                                   atol=1e-9)


def test_wrong_shapes():
    with pytest.raises(InputError, match=r"Euler angles: expected shape \(3,\)"):
        pg.matrix_from_euler("xyz", [0.1, 0.2])
    with pytest.raises(InputError, match="Rodrigues vector"):
        pg.matrix_from_rodrigues([1.0, 2.0])
    with pytest.raises(InputError, match="nearest_rotation"):
        pg.nearest_rotation(np.eye(2))
    np.testing.assert_allclose(pg.nearest_rotation(np.eye(3) * 1.001), np.eye(3), atol=1e-12)
