"""`pg.io.write_cloud`: finite coordinates only, and a named error when the scales cannot
store them.

It used to write a NaN offset for a NaN input (and lose the x of every finite point) and to
let laspy's bare OverflowError out when the coordinates did not fit the scale.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import photogeom as pg
from photogeom.errors import InputError

pytest.importorskip("laspy")


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("row, col", [(0, 0), (2, 1), (4, 2)])
def test_non_finite_coordinates_are_refused_naming_the_row(tmp_path, bad, row, col):
    xyz = np.arange(15, dtype=float).reshape(5, 3)
    xyz[row, col] = bad
    xyz[4 if row != 4 else 3, 0] = np.nan  # a later bad row: the first one is named
    path = tmp_path / "c.las"
    first = min(row, 4 if row != 4 else 3)
    with pytest.raises(InputError, match=rf"row {first} is not finite") as err:
        pg.io.write_cloud(path, xyz)
    assert "2 such row(s)" in str(err.value) and "finite coordinates only" in str(err.value)
    assert not path.exists() and list(tmp_path.iterdir()) == []


def test_a_refused_write_leaves_an_existing_file_as_it_was(tmp_path):
    path = tmp_path / "c.laz"
    pg.io.write_cloud(path, [[1.0, 2.0, 3.0]])
    before = path.read_bytes()
    with pytest.raises(InputError):
        pg.io.write_cloud(path, [[1.0, 2.0, np.nan]])
    with pytest.raises(InputError):
        pg.io.write_cloud(path, [[0.0, 0.0, 0.0], [1e7, 0.0, 0.0]])
    assert path.read_bytes() == before


@pytest.mark.parametrize(
    "xyz, kw, words",
    [
        ([[0.0, 0, 0], [1e7, 0, 0]], {}, "scales="),  # span 1e7 m at 1 mm: 1e10 integers
        ([[1e7, 2, 3]], {"offsets": (0, 0, 0)}, "offsets="),
        ([[1.0, 2, 3]], {"scales": (1e-3, 0, 1e-3)}, "scales="),
        ([[1.0, 2, 3]], {"offsets": (0, np.nan, 0)}, "offsets="),
    ],
)
def test_what_the_scales_cannot_store_is_a_named_error(tmp_path, xyz, kw, words):
    with pytest.raises(InputError, match=words):
        pg.io.write_cloud(tmp_path / "c.las", np.array(xyz, dtype=float), **kw)
    assert list(tmp_path.iterdir()) == []


def test_the_same_points_fit_with_larger_scales(tmp_path):
    xyz = np.array([[0.0, 0, 0], [1e7, 0, 0]])
    path = pg.io.write_cloud(tmp_path / "c.las", xyz, scales=(0.01, 0.01, 0.01))
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path), xyz, atol=0.005)


coords = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@settings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    arrays(np.float64, st.tuples(st.integers(1, 20), st.just(3)), elements=coords),
    st.sampled_from([1e-3, 1e-2, 0.25]),
)
def test_points_read_back_rounded_to_the_scale(tmp_path, xyz, scale):
    """Every point comes back within half a scale step; the offsets are round numbers
    (whole multiples of 1000 scales) as transform_cloud chooses them, and the header's
    bounds are those of the stored points."""
    path = pg.io.write_cloud(tmp_path / "c.laz", xyz, scales=(scale, scale, scale))
    back = pg.io.read_cloud_xyz(path)
    info = pg.io.cloud_info(path)
    off = info.offsets
    want = np.rint((xyz - off) / scale) * scale + off
    tol = 1e-9 * (1 + np.abs(xyz).max())
    np.testing.assert_allclose(back, want, rtol=0, atol=tol)
    assert np.all(np.abs(back - xyz) <= scale / 2 + tol)
    np.testing.assert_allclose(off / (1000 * scale), np.round(off / (1000 * scale)), atol=1e-9)
    np.testing.assert_allclose(info.mins, back.min(axis=0), atol=1e-9 * (1 + np.abs(back).max()))
    np.testing.assert_allclose(info.maxs, back.max(axis=0), atol=1e-9 * (1 + np.abs(back).max()))


def test_given_offsets_are_kept(tmp_path):
    xyz = np.array([[100.0, 200.0, 3.0], [101.0, 201.5, 4.25]])
    path = pg.io.write_cloud(tmp_path / "c.las", xyz, offsets=(100, 200, 0))
    np.testing.assert_array_equal(pg.io.cloud_info(path).offsets, [100, 200, 0])
    np.testing.assert_allclose(pg.io.read_cloud_xyz(path), xyz, atol=5e-4)


def test_an_empty_cloud_is_written(tmp_path):
    path = pg.io.write_cloud(tmp_path / "c.las", np.zeros((0, 3)))
    assert pg.io.cloud_info(path).point_count == 0
