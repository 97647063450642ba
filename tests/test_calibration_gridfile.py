"""The grids file: image ids keep their type, non-finite numbers, damaged files."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.calibration import GridLayout, ResidualGrid, load_grids, save_grids
from photogeom.calibration.gridfile import match_grid_ids
from photogeom.errors import FileFormatError, InputError

SUFFIXES = (".npz", ".json")


def _grid(seed: int = 0, width: int = 90, height: int = 60, spacing: float = 30) -> ResidualGrid:
    """A hand-made grid (no fit): random nodes, support and counts."""
    rng = np.random.default_rng(seed)
    layout = GridLayout(width, height, spacing)
    counts = rng.integers(0, 6, layout.shape)
    return ResidualGrid(
        layout=layout,
        nodes=rng.normal(0, 1, (*layout.shape, 2)),
        sigma0=float(rng.uniform(0.5, 2)),
        redundancy=int(rng.integers(1, 100)),
        sigma_obs=rng.uniform(0.1, 1, 7),
        sigma_constraint=0.1,
        support=counts >= 3,
        counts=counts,
        rms_before=1.0,
        rms_after=0.5,
        outliers=rng.random(8) < 0.2,
    )


# ------------------------------------------------------------------ ids keep their type
ids_st = st.lists(
    st.one_of(st.integers(-(2**63), 2**64 - 1), st.text(max_size=12)),
    min_size=1,
    max_size=4,
    unique_by=lambda k: (type(k), k),
)


@settings(max_examples=40, deadline=None)
@given(ids=ids_st)
def test_image_ids_round_trip_with_their_type(ids):
    grids = {k: _grid(n) for n, k in enumerate(ids)}
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in SUFFIXES:
            back = load_grids(save_grids(Path(tmp) / f"g{suffix}", grids, std=False))
            assert [(type(k), k) for k in back] == [(type(k), k) for k in ids]
            for k in ids:
                np.testing.assert_array_equal(back[k].nodes, grids[k].nodes)


def test_numpy_integer_ids_come_back_as_integers(tmp_path):
    grids = {np.int64(7): _grid(1), np.uint32(3): _grid(2)}
    for suffix in SUFFIXES:
        back = load_grids(save_grids(tmp_path / f"g{suffix}", grids, std=False))
        assert list(back) == [7, 3] and all(type(k) is int for k in back)


@pytest.mark.parametrize("key", [1.5, True, ("a", 1), None])
def test_ids_a_file_cannot_hold_are_refused(tmp_path, key):
    with pytest.raises(InputError, match="integer or text image ids"):
        save_grids(tmp_path / "g.json", {key: _grid()}, std=False)
    assert not (tmp_path / "g.json").exists()


def test_text_ids_of_older_files_match_only_when_unambiguous():
    g = _grid()
    # an older file's text ids against a block's integer ids
    found, missing = match_grid_ids([0, 1, 2], {"0": g, "1": g})
    assert found == {0: "0", 1: "1"} and missing == [2]
    # a CSV's text against integer grid ids
    assert match_grid_ids(["5"], {5: g}) == ({"5": 5}, [])
    # the same id wins over text
    assert match_grid_ids([1], {1: g, "1": g}) == ({1: 1}, [])
    # two ids with the text "1": the integer one is not guessed
    assert match_grid_ids([1, "1"], {"1": g}) == ({"1": "1"}, [1])
    # two grid keys with the text "1" (1 and "1"), asked for np.int64(1): exact match
    assert match_grid_ids([np.int64(1)], {"1": g, 1: g})[0] == {np.int64(1): 1}


# ------------------------------------------------------------------ non-finite and zero sigma0
def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a, float), np.asarray(b, float), equal_nan=True)


@settings(max_examples=40, deadline=None)
@given(
    sigma0=st.one_of(
        st.just(float("nan")), st.just(0.0), st.floats(1e-6, 1e3, allow_subnormal=False)
    ),
    rms_cv=st.one_of(st.just(float("nan")), st.floats(0, 10)),
    seed=st.integers(0, 2**16),
)
def test_standard_deviations_round_trip_exactly(sigma0, rms_cv, seed):
    """node_std = sigma0 sqrt(cofactor) comes back for any sigma0: 0 (all residuals zero),
    NaN (redundancy 0) or a number; NaN statistics come back as NaN (JSON null)."""
    rng = np.random.default_rng(seed)
    g = _grid(seed)
    g = ResidualGrid(
        **{**{f: getattr(g, f) for f in ("layout", "nodes", "redundancy", "sigma_obs")},
           **{f: getattr(g, f) for f in ("sigma_constraint", "support", "counts")},
           "sigma0": sigma0, "rms_before": 1.0, "rms_after": 0.5,
           "rms_cv_before": rms_cv, "rms_cv_after": rms_cv,
           "_std": [rng.uniform(0.01, 5, g.layout.shape)]},  # a given cofactor
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in SUFFIXES:
            path = save_grids(Path(tmp) / f"g{suffix}", {"a": g})
            if suffix == ".json":
                json.loads(path.read_text(), parse_constant=_no_constant)  # strict JSON
            b = load_grids(path)["a"]
            assert _same(b.sigma0, sigma0) and _same(b.rms_cv_before, rms_cv)
            np.testing.assert_array_equal(b.node_cofactor, g.node_cofactor)
            assert _same(b.node_std, g.node_std)
            assert b.to_dict() == g.to_dict()


def _no_constant(name):
    raise AssertionError(f"{name} in a JSON file")


def test_fit_without_redundancy_saves_as_json(cli, tmp_path):
    """Four points, one 2 x 2 cell with linear borders: redundancy 0, sigma0 NaN."""
    csv = tmp_path / "four.csv"
    csv.write_text(
        "image_id,u,v,rx,ry\nA,10,10,0.3,0\nA,80,15,0.2,0.1\nA,20,50,0,0.2\nA,70,55,1,1\n"
    )
    out = tmp_path / "g.json"
    code, _, err = cli(
        "grid", "fit", csv, "--image-size", "100x60", "--spacing", "99", "--border", "linear",
        "--folds", "0", "-o", out,
    )  # fmt: skip
    assert code == 0, err
    g = load_grids(out)["A"]
    assert g.redundancy == 0 and np.isnan(g.sigma0)
    assert np.isnan(g.node_std).all() and np.isfinite(g.node_cofactor).all()
    data = json.loads(out.read_text(), parse_constant=_no_constant)
    assert data["images"][0]["sigma0"] is None


# ------------------------------------------------------------------ damaged files
def _json_file(tmp_path) -> dict:
    path = save_grids(tmp_path / "good.json", {"a": _grid(1), "b": _grid(2)})
    return json.loads(path.read_text())


def _set(key, value):
    def change(data):
        data["images"][0][key] = value

    return change


def _drop(key):
    def change(data):
        del data["images"][0][key]

    return change


DAMAGES = {
    "no id": (_drop("id"), "image entry 1 has no integer or text 'id'"),
    "float id": (_set("id", 1.5), "image entry 1 has no integer or text 'id'"),
    "entry not an object": (lambda d: d.update(images=[5]), "image entry 1 is int 5"),
    "repeated id": (_set("id", "b"), "image 'b' appears twice"),
    "no width": (_drop("width"), "image a: incomplete grid, no width"),
    "no nodes": (_drop("nodes"), "incomplete grid, no nodes"),
    "no support": (_drop("support"), "incomplete grid, no support"),
    "width not whole": (_set("width", 90.5), "width is 90.5, not a whole number"),
    "spacing 0": (_set("spacing", 0), "not a valid grid layout"),
    "shape": (_set("shape", [9, 9]), "does not fit the layout"),
    "border": (_set("border", "wavy"), "border 'wavy'"),
    "support shape": (_set("support", [1, 2, 3]), r"support of shape \(3,\).*\(3, 4\)"),
    "support values": (_set("support", [[2] * 4] * 3), "support holds values other than"),
    "counts shape": (_set("counts", [[1] * 3] * 3), r"counts of shape \(3, 3\)"),
    "counts negative": (_set("counts", [[-1] * 4] * 3), "counts holds values other than"),
    "node_std shape": (_set("node_std", [1.0]), "node_std of shape"),
    "node_cofactor shape": (_set("node_cofactor", [[1.0] * 4]), "node_cofactor of shape"),
    "nodes null": (_set("nodes", [[[None, 0.0]] * 4] * 3), "nodes hold NaN"),
    "nodes text": (_set("nodes", [[["x", 0.0]] * 4] * 3), "nodes is not an array of numbers"),
    "sigma_obs 2-D": (_set("sigma_obs", [[1.0]]), "sigma_obs of shape"),
    "sigma0 text": (_set("sigma0", "big"), "sigma0 is 'big', not a number"),
}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_damaged_json_entries_are_named(tmp_path, damage):
    data = _json_file(tmp_path)
    assert _grid(1).layout.shape == (3, 4)  # the shapes in the messages above
    change, message = DAMAGES[damage]
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(FileFormatError, match=message) as exc:
        load_grids(path)
    assert str(path) in str(exc.value)


def test_damaged_npz_files_are_named(tmp_path):
    good = save_grids(tmp_path / "good.npz", {"a": _grid(1), "b": _grid(2)}).read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good[: len(good) // 2])
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"hello")
    scratched = tmp_path / "scratched.npz"
    middle = len(good) // 2
    scratched.write_bytes(good[:middle] + b"\0" * 40 + good[middle + 40 :])
    for path in (truncated, garbage, scratched):
        with pytest.raises(FileFormatError, match="grids NPZ file") as exc:
            load_grids(path)
        assert str(path) in str(exc.value)
    # an array of the wrong shape inside a sound archive
    with np.load(tmp_path / "good.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["support_1"] = np.ones(5, bool)
    np.savez(tmp_path / "shape.npz", **arrays)
    with pytest.raises(FileFormatError, match=r"image b: support of shape \(5,\)"):
        load_grids(tmp_path / "shape.npz")
    del arrays["counts_0"]
    np.savez(tmp_path / "missing.npz", **arrays)
    with pytest.raises(FileFormatError, match="image a: incomplete grid, no counts"):
        load_grids(tmp_path / "missing.npz")


def test_damaged_grids_file_in_the_cli(cli, tmp_path):
    (tmp_path / "g.npz").write_bytes(b"PK\x03\x04 cut short")
    obs = tmp_path / "obs.csv"
    obs.write_text("image_id,u,v\na,1,1\n")
    for args in (
        ("grid", "apply", tmp_path / "g.npz", obs, "-o", tmp_path / "out.csv"),
        ("grid", "correct-images", tmp_path / "g.npz", tmp_path, tmp_path / "out"),
    ):
        code, _, err = cli(*args)
        assert code == 2 and err.startswith("error:") and "g.npz" in err
        assert "Traceback" not in err
    assert not (tmp_path / "out.csv").exists() and not (tmp_path / "out").exists()
