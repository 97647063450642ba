"""An adjusted block keeps its survey: adjusting it again is the same adjustment."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.bundle import bundle_adjust
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block


@pytest.fixture(scope="module")
def surveyed_block():
    """A block whose control points carry 1 cm survey noise and its adjustment."""
    ideal = grid_block(3, noise=0.5, rows=2, cols=4, n_points=200, n_control=6, n_check=3)
    rng = np.random.default_rng(8)
    xyz = ideal.xyz.copy()
    known = ideal.role != "tie"
    xyz[known] += rng.normal(0.0, 0.01, (int(known.sum()), 3))
    block = ideal.replace(xyz=xyz)
    return block, bundle_adjust(block, snooping=False)


def test_the_adjusted_block_keeps_the_survey(surveyed_block):
    block, fit = surveyed_block
    known = block.role != "tie"
    assert block.surveyed is None and fit.block.surveyed is not None
    np.testing.assert_array_equal(fit.block.surveyed[known], block.xyz[known])
    assert np.all(np.isnan(fit.block.surveyed[~known]))
    # the adjusted block's xyz are the estimates: control points moved, checks triangulated
    assert not np.allclose(fit.block.xyz[known], block.xyz[known], atol=1e-6)
    np.testing.assert_array_equal(fit.block.surveyed_xyz[known], block.xyz[known])
    np.testing.assert_array_equal(fit.block.surveyed_xyz[~known], fit.block.xyz[~known])


def test_adjusting_an_adjusted_block_again_changes_nothing(surveyed_block):
    """The second adjustment observes the control points where they were surveyed (not where
    the first put them) and compares the check points with the survey: same minimum, same
    control and check statistics, same sigma0."""
    _, fit = surveyed_block
    again = bundle_adjust(fit.block, snooping=False)
    assert again.cost_history[0] == pytest.approx(fit.cost_history[-1], rel=1e-9)
    assert again.cost_history[-1] == pytest.approx(fit.cost_history[-1], rel=1e-9)
    assert again.sigma0 == pytest.approx(fit.sigma0, rel=1e-6)
    np.testing.assert_allclose(again.block.xyz, fit.block.xyz, atol=1e-6)
    np.testing.assert_allclose(again.control["errors"], fit.control["errors"], atol=1e-6)
    np.testing.assert_allclose(again.check["errors"], fit.check["errors"], atol=1e-6)
    np.testing.assert_array_equal(again.block.surveyed, fit.block.surveyed, strict=True)


def test_surveyed_follows_the_points(surveyed_block):
    _, fit = surveyed_block
    b = fit.block
    with pytest.raises(InputError, match=r"surveyed must have shape"):
        b.replace(surveyed=np.zeros((3, 3)))
    # a new survey given explicitly is the one used
    moved = b.surveyed.copy()
    moved[b.role == "control"] += 0.5
    refit = bundle_adjust(b.replace(surveyed=moved), snooping=False)
    shift = refit.block.xyz[b.role == "control"] - fit.block.xyz[b.role == "control"]
    assert np.all(np.abs(shift.mean(axis=0) - 0.5) < 0.05)


def test_the_survey_survives_the_csv_folder(surveyed_block, tmp_path):
    """Written and read back, the adjusted block still holds the survey: adjusting the folder
    again is the same adjustment; a block without a survey of its own writes no columns."""
    from photogeom.bundle import read_csv_block, write_csv_block

    block, fit = surveyed_block
    d = write_csv_block(fit.block, tmp_path / "adjusted")
    assert "surveyed_X" in (d / "points.csv").read_text()
    back = read_csv_block(d)
    np.testing.assert_array_equal(back.surveyed, fit.block.surveyed, strict=True)
    again = bundle_adjust(back, snooping=False)
    np.testing.assert_allclose(again.control["errors"], fit.control["errors"], atol=1e-6)
    np.testing.assert_allclose(again.check["errors"], fit.check["errors"], atol=1e-6)
    d2 = write_csv_block(block, tmp_path / "input")
    assert "surveyed_X" not in (d2 / "points.csv").read_text()
    assert read_csv_block(d2).surveyed is None


@settings(max_examples=25, deadline=None)
@given(
    offsets=st.lists(
        st.tuples(*[st.floats(-1e4, 1e4, allow_nan=False, width=64)] * 3),
        min_size=9,
        max_size=9,
    ),
    missing=st.lists(st.booleans(), min_size=9, max_size=9),
)
def test_any_survey_round_trips_through_a_csv_folder(surveyed_block, offsets, missing):
    """Whatever survey (any values, any control or check point without one) the block keeps,
    a CSV folder gives it back exactly, and surveyed_xyz falls back to xyz where it is
    missing."""
    import tempfile

    from photogeom.bundle import read_csv_block, write_csv_block

    _, fit = surveyed_block
    b = fit.block
    known = np.flatnonzero(b.role != "tie")
    s = b.surveyed.copy()
    s[known] = b.xyz[known] + np.array(offsets)[: known.size]
    s[known[np.array(missing)[: known.size]]] = np.nan
    block = b.replace(surveyed=s)
    with tempfile.TemporaryDirectory() as d:
        back = read_csv_block(write_csv_block(block, Path(d) / "b"))
    np.testing.assert_array_equal(back.surveyed, s, strict=True)
    want = np.where(np.isfinite(s), s, b.xyz)
    np.testing.assert_array_equal(back.surveyed_xyz, want)


def test_triangulating_every_point_keeps_the_survey(surveyed_block):
    """``triangulate(block).apply(block)`` replaces the coordinates by estimates; the control
    and check points' survey stays the survey (it was overwritten, and the adjustment then
    held the control points at their triangulated positions)."""
    from photogeom.bundle import triangulate

    block, fit = surveyed_block
    known = block.role != "tie"
    tri = triangulate(block).apply(block, on_failure="keep")
    assert not np.allclose(tri.xyz[known], block.xyz[known], atol=1e-6)
    np.testing.assert_array_equal(tri.surveyed_xyz[known], block.xyz[known])
    again = bundle_adjust(tri, snooping=False)
    np.testing.assert_allclose(again.control["errors"], fit.control["errors"], atol=1e-7)
    np.testing.assert_allclose(again.check["errors"], fit.check["errors"], atol=1e-7)
    # on an adjusted block (with a survey) the survey is kept as it is
    tri2 = triangulate(fit.block).apply(fit.block, on_failure="keep")
    np.testing.assert_array_equal(tri2.surveyed, fit.block.surveyed)


def test_the_adjusted_block_records_the_free_parameters_estimated(surveyed_block, tmp_path):
    """``free=`` overrides the block's own set; the result block (and its files) name
    what was estimated, so adjusting it again without ``free`` is the same adjustment."""
    from photogeom.bundle import read_csv_block, write_csv_block

    block, _ = surveyed_block
    fit = bundle_adjust(block, free=("f", "k1", "k2"), snooping=False)
    assert all(v == ("f", "k1", "k2") for v in fit.block.free.values())
    write_csv_block(fit.block, tmp_path / "adj")
    again = bundle_adjust(read_csv_block(tmp_path / "adj"), snooping=False)
    assert again.redundancy == fit.redundancy
    assert again.sigma0 == pytest.approx(fit.sigma0, rel=1e-6)
    assert bundle_adjust(fit.block, snooping=False).redundancy == fit.redundancy
