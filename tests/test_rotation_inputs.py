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


def test_polynomial_term_count_checks_its_dimension():
    from photogeom.transforms.polynomial import polynomial_term_count

    assert polynomial_term_count(2, 2) == 6 and polynomial_term_count(2, 3) == 10
    with pytest.raises(InputError, match="dim must be 2 or 3"):
        polynomial_term_count(2, 5)
    with pytest.raises(InputError, match="order must be >= 0"):
        polynomial_term_count(-1, 2)


def test_comparison_row_of_a_method_not_compared():
    rng = np.random.default_rng(0)
    x = rng.uniform(-10, 10, (8, 3))
    cmp = pg.compare_absolute_methods(x, x + 1.0, methods=["svd", "quaternion"])
    assert cmp.row("svd").method == "svd"
    with pytest.raises(InputError, match="was not compared"):
        cmp.row("closed-form")
