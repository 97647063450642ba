"""``euler_from_matrix`` near gimbal lock.

Before, the angles came from scipy's ``as_euler``, which declares the lock within 1e-7 rad
of it and sets the third angle to 0 there: the angles gave the matrix back only to 2e-7
(every one of the 24 sequences). They are now computed in closed form: the matrix comes
back to rounding at any distance from the lock; away from it and at the lock itself they
are scipy's."""

import itertools
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import photogeom as pg

SEQUENCES = [a + b + c for a, b, c in itertools.product("xyz", repeat=3) if a != b != c]
SEQUENCES += [s.upper() for s in SEQUENCES]
DISTANCES = [1e-15, 1e-12, 1e-9, 3e-8, 1e-7, 2e-7, 1e-6, 1e-3]


def _middle(seq: str, lock: int, d: float) -> float:
    """The middle angle ``d`` rad from the lock number ``lock`` (0 or 1) of ``seq``."""
    if seq[0].lower() == seq[2].lower():  # proper: locks at 0 and pi
        return d if lock == 0 else np.pi - d
    return np.pi / 2 - d if lock == 0 else -np.pi / 2 + d


@pytest.mark.parametrize("seq", SEQUENCES)
def test_round_trip_to_rounding_near_the_lock(seq):
    rng = np.random.default_rng(sum(map(ord, seq)))
    worst = 0.0
    for lock, d in itertools.product((0, 1), DISTANCES):
        a = rng.uniform(-np.pi, np.pi, 3)
        a[1] = _middle(seq, lock, d)
        R = pg.matrix_from_euler(seq, a)  # scipy's from_euler: an independent composition
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no gimbal-lock warning either
            e = pg.euler_from_matrix(R, seq)
        worst = max(worst, float(np.abs(pg.matrix_from_euler(seq, e) - R).max()))
    assert worst < 4e-15, worst  # before: 1e-7 to 2e-7


@pytest.mark.parametrize("seq", SEQUENCES)
def test_scipys_angles_away_from_and_at_the_lock(seq):
    R = Rotation.random(500, random_state=3).as_matrix()
    ours = pg.euler_from_matrix(R, seq)
    theirs = Rotation.from_matrix(R).as_euler(seq)
    np.testing.assert_allclose(np.angle(np.exp(1j * (ours - theirs))), 0.0, atol=1e-12)
    # exactly at the lock: the third angle 0, as scipy sets it, the first one scipy's
    for lock in (0, 1):
        a = np.array([0.7, _middle(seq, lock, 0.0), -0.4])
        R = pg.matrix_from_euler(seq, a)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns of the lock
            theirs = Rotation.from_matrix(R).as_euler(seq)
        ours = pg.euler_from_matrix(R, seq)
        assert ours[2] == 0.0
        np.testing.assert_allclose(np.angle(np.exp(1j * (ours - theirs))), 0.0, atol=1e-12)


def test_batches_and_units():
    R = Rotation.random(12, random_state=4).as_matrix().reshape(3, 4, 3, 3)
    e = pg.euler_from_matrix(R, "ZYX", unit="deg")
    assert e.shape == (3, 4, 3)
    np.testing.assert_allclose(pg.matrix_from_euler("ZYX", e, unit="deg"), R, atol=1e-14)
