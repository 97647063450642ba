"""Point CSV reading and writing: format, column choice, roles, weights and every bad input."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom import datasets
from photogeom.errors import FileFormatError, InputError, PhotogeomError
from photogeom.io import (
    atomic_write_text,
    format_points_csv,
    join_points,
    parse_points,
    read_point_pairs,
    read_points,
    write_points,
)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --- the bundled files -------------------------------------------------------------------------


def test_fiducials_one_file_both_sets():
    pairs = read_point_pairs(datasets.path("lecture_fiducials"))
    assert pairs.source_columns == ("x", "y") and pairs.target_columns == ("X", "Y")
    assert pairs.ids == tuple(str(k) for k in range(1, 9))
    assert list(pairs.roles) == ["control"] * 4 + ["check"] * 4
    assert pairs.check_mask.sum() == 4
    np.testing.assert_array_equal(pairs.source[0], [113.016, 0.002])
    np.testing.assert_array_equal(pairs.target[7], [243.025, 16.999])
    _ids, src, dst, _roles, w = pairs  # unpacks like a tuple
    assert w is None and src.shape == dst.shape == (8, 2)


def test_two_images_named_columns():
    pairs = read_point_pairs(datasets.path("lecture_two_images"), "x2,y2", ["x1", "y1"])
    np.testing.assert_array_equal(pairs.source[0], [175, 44])
    np.testing.assert_array_equal(pairs.target[0], [253, 64])
    assert pairs.roles is None


def test_default_columns_and_comments(tmp_path):
    p = _write(
        tmp_path,
        "a.csv",
        "# a comment\n\nid,E,N,H\n# inline comment line\nA,1,2,3\nB,4,5,6\n",
    )
    t = read_points(p)
    assert t.columns == ("E", "N", "H") and t.dim == 3
    assert t.ids == ("A", "B") and t.comments == ("a comment", "inline comment line")
    np.testing.assert_array_equal(t.coords, [[1, 2, 3], [4, 5, 6]])
    assert t.roles is None and not t.check_mask.any()


def test_semicolon_and_whitespace_separators():
    t = parse_points("id;col;row\n1;10.5;20\n2;11;21\n")
    assert t.columns == ("col", "row")
    np.testing.assert_array_equal(t.coords, [[10.5, 20], [11, 21]])
    t = parse_points("id   x   y\n1  1.0  2.0\n2  3  4\n")
    np.testing.assert_array_equal(t.coords, [[1, 2], [3, 4]])


def test_case_insensitive_unique_match_only():
    t = parse_points("ID,x,y\n1,0,0\n", columns=["X", "Y"])  # unique case-insensitive match
    assert t.columns == ("x", "y") and t.ids == ("1",)


def test_weights_and_sigmas():
    t = parse_points("id,x,y,sigma\n1,0,0,0.5\n2,1,1,2\n")
    np.testing.assert_allclose(t.weights, [4.0, 0.25])
    assert t.weight_source == "sigma"
    t = parse_points("id,x,y,weight\n1,0,0,3\n2,1,1,1\n")
    np.testing.assert_allclose(t.weights, [3.0, 1.0])
    t = parse_points("id,x,y,q\n1,0,0,3\n2,1,1,1\n", weight_column="q")
    np.testing.assert_allclose(t.weights, [3.0, 1.0])
    t = parse_points("id,x,y,weight\n1,0,0,3\n", auto_weights=False)
    assert t.weights is None
    with pytest.raises(InputError, match="must be > 0"):
        parse_points("id,x,y,sigma\n1,0,0,0\n")


def test_roles_blank_means_control_and_bad_role():
    t = parse_points("id,role,x,y\n1,,0,0\n2,CHECK,1,1\n")
    assert list(t.roles) == ["control", "check"]
    with pytest.raises(FileFormatError, match=r"line 3.*'chek'.*control.*check"):
        parse_points("id,role,x,y\n1,control,0,0\n2,chek,1,1\n")


# --- bad input: file level ---------------------------------------------------------------------


def test_missing_columns_names_found_and_expected(tmp_path):
    p = _write(tmp_path, "a.csv", "id,east,north\n1,0,0\n")
    with pytest.raises(FileFormatError) as exc:
        read_points(p)
    msg = str(exc.value)
    assert "east, north" in msg and "x,y" in msg and "col,row" in msg and str(p) in msg
    with pytest.raises(FileFormatError, match=r"column\(s\) Z not found.*id, east, north"):
        read_points(p, columns="east,north,Z")


def test_pair_columns_missing_or_overlapping(tmp_path):
    p = _write(tmp_path, "a.csv", "id,a,b,c,d\n1,0,0,0,0\n")
    with pytest.raises(FileFormatError, match=r"cannot tell.*id, a, b, c, d.*source_columns="):
        read_point_pairs(p)
    with pytest.raises(InputError, match="both source and target"):
        read_point_pairs(p, "a,b", "b,c")
    with pytest.raises(FileFormatError, match=r"target coordinate column\(s\) q not found"):
        read_point_pairs(p, "a,b", "c,q")


def test_missing_id_column(tmp_path):
    p = _write(tmp_path, "a.csv", "x,y\n1,2\n")
    with pytest.raises(FileFormatError, match=r"no id column.*x, y.*id"):
        read_points(p)


def test_no_header(tmp_path):
    p = _write(tmp_path, "a.csv", "1,2,3\n4,5,6\n")
    with pytest.raises(FileFormatError, match="header"):
        read_points(p)


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("", "empty"),
        ("# only a comment\n", "empty"),
        ("id,x,y\n1,2\n", r"line 2: 2 field\(s\) but the header has 3"),
        ("id,x,y\n1,2,abc\n", r"line 2: column y holds 'abc', not a number"),
        ("id,x,y\n1,2,\n", "empty field"),
        ("id,x,x\n1,2,3\n", "more than once"),
        ("id,x,y\n,1,2\n", "empty point id"),
    ],
)
def test_malformed_files(tmp_path, text, pattern):
    with pytest.raises(FileFormatError, match=pattern):
        read_points(_write(tmp_path, "a.csv", text))


def test_nan_and_inf_name_the_points(tmp_path):
    p = _write(tmp_path, "a.csv", "id,x,y\nP1,0,0\nP2,nan,1\nP3,1,inf\n")
    with pytest.raises(InputError) as exc:
        read_points(p)
    msg = str(exc.value)
    assert "2 point(s)" in msg and "P2 (line 3)" in msg and "P3 (line 4)" in msg and "NaN" in msg


def test_unreadable_files(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_points(tmp_path / "missing.csv")
    with pytest.raises(FileFormatError, match="directory"):
        read_points(tmp_path)
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\x89PNG\x00\x00\x01")
    with pytest.raises(FileFormatError, match="binary"):
        read_points(binary)
    if os.name == "posix" and os.geteuid() != 0:
        locked = _write(tmp_path, "locked.csv", "id,x,y\n1,0,0\n")
        locked.chmod(0)
        try:
            with pytest.raises(FileFormatError, match="permission denied"):
                read_points(locked)
        finally:
            locked.chmod(0o644)


def test_errors_are_photogeom_errors(tmp_path):
    # the CLI turns these into one-line messages
    with pytest.raises(PhotogeomError):
        read_points(tmp_path / "missing.csv")


# --- joining -----------------------------------------------------------------------------------


def test_join_by_id_in_source_order():
    a = parse_points("id,x,y\n1,0,0\n2,1,0\n3,0,1\n")
    b = parse_points("id,X,Y\n3,30,31\n1,10,11\n2,20,21\n")
    ids, src, dst, roles, w = join_points(a, b)
    assert ids == ("1", "2", "3")
    np.testing.assert_array_equal(dst, [[10, 11], [20, 21], [30, 31]])
    np.testing.assert_array_equal(src, a.coords)
    assert roles is None and w is None


def test_join_duplicate_ids_are_named():
    with pytest.raises(InputError, match=r"duplicate point id\(s\) 2 \(2x\)"):
        parse_points("id,x,y\n1,0,0\n2,1,0\n2,0,1\n")


def test_join_ids_in_one_file_only_are_reported():
    a = parse_points("id,x,y\n1,0,0\n2,1,0\n3,0,1\n4,1,1\n")
    b = parse_points("id,X,Y\n1,0,0\n2,1,0\n3,0,1\n9,5,5\n")
    with pytest.raises(InputError) as exc:
        join_points(a, b)
    msg = str(exc.value)
    assert "only in source: 4" in msg and "only in target: 9" in msg
    pairs = join_points(a, b, allow_unmatched=True)
    assert pairs.ids == ("1", "2", "3")
    assert pairs.unmatched_source == ("4",) and pairs.unmatched_target == ("9",)
    assert any("4" in n and "9" in n for n in pairs.notes)


def test_join_no_common_id():
    a = parse_points("id,x,y\n1,0,0\n")
    b = parse_points("id,X,Y\n2,0,0\n")
    with pytest.raises(InputError, match="no point id in common"):
        join_points(a, b, allow_unmatched=True)


def test_join_roles_and_weights():
    a = parse_points("id,role,x,y\n1,control,0,0\n2,check,1,0\n")
    b = parse_points("id,X,Y,sigma\n2,1,0,0.1\n1,0,0,0.2\n")
    pairs = join_points(a, b)
    assert list(pairs.roles) == ["control", "check"]
    np.testing.assert_allclose(pairs.weights, [25.0, 100.0])
    c = parse_points("id,role,X,Y\n1,check,0,0\n2,check,1,0\n")
    with pytest.raises(InputError, match=r"role differs.*1"):
        join_points(a, c)


# --- writing -----------------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(allow_nan=False, allow_infinity=False, width=64),
            st.floats(allow_nan=False, allow_infinity=False, width=64),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_write_read_round_trip_is_lossless(rows):
    coords = np.array(rows, dtype=float)
    ids = [f"p{k}" for k in range(len(rows))]
    text = format_points_csv(ids, coords, ["X", "Y"], comments=["transformed"])
    t = parse_points(text)
    assert t.ids == tuple(ids) and t.comments == ("transformed",)
    np.testing.assert_array_equal(t.coords, coords)


def test_write_points_with_extra_columns(tmp_path):
    out = write_points(
        tmp_path / "o.csv",
        ["a", "b"],
        np.array([[1.5, 2.0], [3.0, 4.0]]),
        ["x", "y"],
        extra={"role": ["control", "check"]},
    )
    t = read_points(out)
    assert list(t.roles) == ["control", "check"]
    with pytest.raises(InputError, match="column name"):
        format_points_csv(["a"], np.zeros((1, 3)), ["x", "y"])


def test_failed_write_leaves_old_file(tmp_path, monkeypatch):
    target = tmp_path / "out.csv"
    target.write_text("old content\n")

    def broken_fsync(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", broken_fsync)
    with pytest.raises(OSError, match="disk full"):
        write_points(target, ["1"], np.zeros((1, 2)), ["x", "y"])
    assert target.read_text() == "old content\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary file left


def test_write_into_missing_directory(tmp_path):
    with pytest.raises(PhotogeomError, match="does not exist"):
        atomic_write_text(tmp_path / "nope" / "x.csv", "a")


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_atomic_write_gives_normal_permissions(tmp_path):
    mask = os.umask(0o022)
    os.umask(mask)
    new = atomic_write_text(tmp_path / "new.csv", "a")
    assert new.stat().st_mode & 0o777 == 0o666 & ~mask  # not the 0600 of a temporary file
    new.chmod(0o640)
    atomic_write_text(new, "b")
    assert new.stat().st_mode & 0o777 == 0o640  # mode of the replaced file is kept
