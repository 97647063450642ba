"""Evaluation helpers of the residual grids and the grids file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.calibration import (
    choose_spacing,
    compare_residuals,
    fit_grids,
    load_grids,
    min_max_normalise,
    most_frequent_spacing,
    residual_statistics,
    save_grids,
)
from photogeom.errors import FileFormatError, InputError


def test_residual_statistics_by_hand():
    s = residual_statistics([[3.0, 4.0], [0.0, 0.0], [0.0, -2.0], [1.0, 0.0]])
    assert s["n"] == 4
    assert s["rms"] == pytest.approx(np.sqrt((25 + 0 + 4 + 1) / 4))
    assert s["mean_length"] == pytest.approx((5 + 0 + 2 + 1) / 4)
    assert s["rms_x"] == pytest.approx(np.sqrt(10 / 4))
    assert s["rms_y"] == pytest.approx(np.sqrt(20 / 4))
    with pytest.raises(InputError):
        residual_statistics([[1.0, np.nan]])


def test_compare_residuals_per_image_and_block():
    before = {"a": np.array([[2.0, 0.0], [0.0, 2.0]]), "b": np.array([[4.0, 0.0]])}
    after = {"a": np.array([[1.0, 0.0], [0.0, 1.0]]), "b": np.array([[1.0, 0.0]])}
    out = compare_residuals(before, after)
    assert out["images"]["a"]["reduction_rms"] == pytest.approx(0.5)
    assert out["images"]["b"]["reduction_mean_length"] == pytest.approx(0.75)
    assert out["block"]["before"]["rms"] == pytest.approx(np.sqrt(24 / 3))
    assert out["block"]["reduction_rms"] == pytest.approx(1 - 1 / np.sqrt(8))
    with pytest.raises(InputError, match="differ in images"):
        compare_residuals(before, {"a": after["a"]})


def test_sweep_rule():
    np.testing.assert_allclose(min_max_normalise([2.0, 4.0, 3.0]), [0, 1, 0.5])
    np.testing.assert_allclose(min_max_normalise([5.0, 5.0]), [0, 0])
    spacings = [50, 100, 150, 200, 400, 2000]
    # step falls with finer grids, time rises: the knee is at 150-200 px
    step = [[10.0, 10.2, 10.5, 11.0, 14.0, 20.0], [3.0, 3.0, 3.05, 3.1, 3.3, 3.4]]
    time = [[40.0, 12.0, 6.0, 4.0, 2.0, 1.0], [40.0, 12.0, 6.0, 4.0, 2.0, 1.0]]
    res = choose_spacing(spacings, step, time)
    # by hand, model 1: 150 px: step (10.5 - 10) / 10 = 0.05, time (6 - 1) / 39;
    # 200 px: step 0.1, time 3 / 39 -> 200 px is closer to the origin
    assert res["distance"][0, 2] == pytest.approx(np.hypot(0.05, 5 / 39))
    assert res["distance"][0, 3] == pytest.approx(np.hypot(0.1, 3 / 39))
    assert list(res["spacing"]) == [200.0, 150.0]
    assert most_frequent_spacing([150, 200, 200, 150, 200]) == 200.0
    assert most_frequent_spacing([150, 200]) == 150.0  # plain tie: the smaller spacing
    # a tie of the models' choices goes to the smaller sum of distances: 150 px here
    # (0.138 + 0.179 against 0.126 + 0.262)
    assert most_frequent_spacing(res) == 150.0
    with pytest.raises(InputError, match="spacings"):
        choose_spacing(spacings, step, np.ones((2, 5)))


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_grids_file_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(0)
    per = {
        "IMG_1": (rng.uniform(0, 599, (300, 2)) * [1, 0.66], rng.normal(0, 1, (300, 2))),
        "B 2": (rng.uniform(0, 399, (200, 2)), rng.normal(0, 1, (200, 2))),
    }
    grids = fit_grids(per, {"IMG_1": (600, 400), "B 2": (400, 400)}, 70, folds=3)
    path = save_grids(tmp_path / f"grids{suffix}", grids)
    back = load_grids(path)
    assert list(back) == ["IMG_1", "B 2"]
    for k, g in grids.items():
        b = back[k]
        assert b.layout == g.layout
        np.testing.assert_array_equal(b.nodes, g.nodes)
        np.testing.assert_allclose(b.node_std, g.node_std, rtol=1e-12)
        np.testing.assert_array_equal(b.support, g.support)
        assert b.to_dict() == g.to_dict()
        uv = per[k][0][:5]
        np.testing.assert_array_equal(b.evaluate(uv), g.evaluate(uv))
    if suffix == ".json":
        data = json.loads(path.read_text())
        assert data["format"] == "photogeom-residual-grids" and len(data["images"][0]["nodes"]) == 7


def test_grids_file_errors(tmp_path):
    with pytest.raises(FileFormatError, match="no such grids file"):
        load_grids(tmp_path / "none.npz")
    (tmp_path / "x.json").write_text('{"format": "other"}')
    with pytest.raises(FileFormatError, match="not a photogeom residual-grids file"):
        load_grids(tmp_path / "x.json")
    (tmp_path / "y.npz").write_bytes(b"junk")
    with pytest.raises(FileFormatError, match="not a grids NPZ file"):
        load_grids(tmp_path / "y.npz")


def test_choose_spacing_ties_do_not_depend_on_the_order():
    """Two spacings normalise to {0, 1}: both at distance 1 for every model, a tie that the
    order of the list decided (the first one listed won)."""
    a = choose_spacing([100, 2000], [[3, 5], [2, 4]], [[10, 1], [10, 1]])
    b = choose_spacing([2000, 100], [[5, 3], [4, 2]], [[1, 10], [1, 10]])
    np.testing.assert_array_equal(a["spacing"], [100, 100])  # the better step
    np.testing.assert_array_equal(b["spacing"], [100, 100])
    # equal steps too: the smaller spacing
    c = choose_spacing([300, 200], [[1, 1]], [[1, 1]])
    assert c["spacing"][0] == 200


@settings(max_examples=80, deadline=None)
@given(st.integers(2, 6), st.integers(1, 4), st.integers(0, 2**32 - 1), st.booleans())
def test_choose_spacing_is_invariant_to_permutations(n, models, seed, rounded):
    rng = np.random.default_rng(seed)
    g = rng.choice(np.arange(100, 2100, 100), n, replace=False).astype(float)
    step = rng.uniform(0, 5, (models, n))
    time = rng.uniform(0, 5, (models, n))
    if rounded:  # many exact ties
        step, time = np.round(step), np.round(time)
    p = rng.permutation(n)
    r1 = choose_spacing(g, step, time)
    r2 = choose_spacing(g[p], step[:, p], time[:, p])
    np.testing.assert_array_equal(r1["spacing"], r2["spacing"])


@pytest.mark.parametrize(
    ("spacings", "step", "time", "message"),
    [
        # numpy converted each of these and the rule ranked them as numbers
        (["100", "200"], [[1, 2]], [[3, 1]], r"spacings\[0\] must be a number of pixels, not '1"),
        ([100, True], [[1, 2]], [[3, 1]], r"spacings\[1\] must be a number of pixels, not True"),
        ("100,200", [[1, 2]], [[3, 1]], "spacings must be a list of numbers of pixels"),
        ([100, 200], [["1.5", "2"]], [[3, 1]], r"step \(GSD\) must be numbers, not text"),
        ([100, 200], [[1, 2]], [[b"3", b"1"]], r"time \(s\) must be numbers, not text"),
        ([100, 200], [[1, 2]], [[True, False]], r"time \(s\) must be numbers, not booleans"),
        ([100, 200], [[1, 2]], [[1 + 0j, 2]], r"time \(s\) must be numbers, not complex"),
        ([100, 0], [[1, 2]], [[3, 1]], r"spacings\[1\] must be a positive number of pixels"),
    ],
)
def test_choose_spacing_refuses_what_is_not_a_number(spacings, step, time, message):
    with pytest.raises(InputError, match=r"^choose_spacing: " + message):
        choose_spacing(spacings, step, time)


def test_choose_spacing_takes_numbers_of_any_real_type():
    ref = choose_spacing([100.0, 200.0, 500.0], [[1.0, 2.0, 4.0]], [[3.0, 1.0, 0.5]])
    got = choose_spacing(
        np.array([100, 200, 500], dtype=np.int32),
        np.array([[1, 2, 4]], dtype=np.int64),
        np.array([[3, 1, 0.5]], dtype=np.float32),
    )
    np.testing.assert_array_equal(got["spacing"], ref["spacing"])
    np.testing.assert_allclose(got["distance"], ref["distance"], rtol=1e-7)
