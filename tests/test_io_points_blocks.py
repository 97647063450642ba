"""Point CSVs read in blocks (pyarrow) and written in chunks: malformed input refused with the
line, results independent of the block size, streamed reading and atomic streamed writing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.errors import FileFormatError, InputError
from photogeom.io import (
    PointBlocks,
    PointWriter,
    format_points_csv,
    parse_points,
    read_points,
)
from photogeom.io.csvblocks import MAX_FIELD_BYTES, DelimitedText


def _write(tmp_path: Path, text: str, name: str = "a.csv") -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8"))
    return p


# --- input the csv module accepted silently ------------------------------------------------


def test_quoted_field_spanning_lines_is_refused():
    # Python's csv module joined the lines: x = 23 and the row count changed
    with pytest.raises(FileFormatError, match=r"line 2: a quote .* cannot span lines"):
        parse_points('id,x,y\n1,"2\n3",4\n5,6,7\n')


def test_stray_quote_does_not_swallow_the_rows_after_it():
    text = 'id,x,y\n1,0,0\n2,"1,1\n3,2,2\n4,3,3\n'
    with pytest.raises(FileFormatError, match=r"line 3: a quote"):
        parse_points(text)


def test_quoted_ids_and_spaces_are_fine():
    t = parse_points('id,x,y\n"P,1", 1.5 ,2\n"say ""hi""",3,4\n')
    assert t.ids == ("P,1", 'say "hi"')
    np.testing.assert_array_equal(t.coords, [[1.5, 2], [3, 4]])


@pytest.mark.parametrize(
    "text",
    [
        "id,x,y\n" + "a" * (MAX_FIELD_BYTES + 1) + ",1,2\n",
        "id,x,y\n1," + "9" * (MAX_FIELD_BYTES + 1) + ",2\n",
        "id,x,y\n" + "1,2,3\n" * 5 + "7,1," + "5" * (MAX_FIELD_BYTES + 10) + "\n",
    ],
)
def test_overlong_field_is_refused_with_its_line(text):
    with pytest.raises(FileFormatError, match=r"line \d+: column [a-z]+ holds a field longer than"):
        parse_points(text)


def test_header_checks_are_linear_and_name_the_duplicate():
    names = [f"c{i}" for i in range(60000)]
    with pytest.raises(FileFormatError, match=r"column name\(s\) c7 appear more than once"):
        parse_points("id," + ",".join([*names, "c7"]) + "\n")
    t = parse_points("id,x,y," + ",".join(names) + "\n1,2,3" + ",0" * len(names) + "\n")
    assert t.coords.tolist() == [[2.0, 3.0]]


def test_weights_must_be_positive_finite_numbers():
    with pytest.raises(FileFormatError, match=r"line 2: column weight holds 'heavy', not a number"):
        parse_points("id,x,y,weight\n1,0,0,heavy\n")
    with pytest.raises(InputError, match=r"sigma of point 1 is 1e\+308.*too small or too large"):
        parse_points("id,x,y,sigma\n1,0,0,1e308\n")
    with pytest.raises(InputError, match=r"NaN or infinite"):
        parse_points("id,x,y,weight\n1,0,0,inf\n")
    with pytest.raises(InputError, match="must be > 0"):
        parse_points("id,x,y,weight\n1,0,0,-1\n")


def test_comments_blank_lines_line_ends_and_encodings(tmp_path):
    text = "\ufeff# head\r\nid;x;y\r\n\r\n  \r\n1;1,0;2\r\n# middle\r\n2;3;4\r\n"
    with pytest.raises(FileFormatError, match=r"line 5: column x holds '1,0'"):
        parse_points(text)
    t = parse_points(text.replace("1,0", "1.0"))
    assert t.ids == ("1", "2") and t.comments == ("head", "middle")
    p = tmp_path / "latin.csv"
    p.write_bytes("id,x,y\nM\xfcnster,1,2\n".encode("latin-1"))
    assert read_points(p).ids == ("M\u00fcnster",)
    t = parse_points("id,x,y\n007,1,2\n7,3,4\n")  # ids are text
    assert t.ids == ("007", "7")


def test_ragged_lines_are_named_in_any_block(tmp_path):
    rows = "".join(f"{i},{i},{i}\n" for i in range(2000))
    p = _write(tmp_path, "id,x,y\n" + rows + "oops,1\n" + rows.replace(",", ",1", 1))
    src = DelimitedText(p, block_bytes=1000)
    with pytest.raises(FileFormatError, match=r"line 2002: 2 field\(s\) but the header has 3"):
        list(src.blocks(["id"], ["x", "y"]))


# --- the same result whatever the block size -------------------------------------------------

_ids = st.text(
    alphabet=st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters="#\ufeff"),
    min_size=1,
    max_size=8,
).filter(lambda s: s.strip() == s and s != "")


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(_ids, st.floats(allow_nan=False, allow_infinity=False, width=64)),
        min_size=1,
        max_size=40,
        unique_by=lambda r: r[0],
    ),
    st.integers(min_value=1, max_value=200),
    st.booleans(),
)
def test_block_size_does_not_change_the_result(rows, block, comments):
    ids = [r[0] for r in rows]
    xy = np.array([[r[1], -r[1]] for r in rows])
    text = format_points_csv(ids, xy, ["x", "y"], comments=["made"])
    if comments:  # comment and blank lines between the rows
        lines = text.split("\n")
        text = "\n".join(ln + ("\n# c\n\n" if k % 3 == 2 else "") for k, ln in enumerate(lines))
    whole = parse_points(text)
    src = DelimitedText(data=text.encode("utf-8"), block_bytes=block)
    parts = list(src.blocks(["id"], ["x", "y"]))
    got_ids = [v for b in parts for v in b.strings["id"].to_pylist()]
    got = np.concatenate([np.column_stack([b.numbers["x"], b.numbers["y"]]) for b in parts])
    assert tuple(got_ids) == whole.ids == tuple(ids)
    np.testing.assert_array_equal(got, whole.coords)
    np.testing.assert_array_equal(got, xy)  # the shortest round-trip text is lossless


def test_error_lines_are_right_across_blocks(tmp_path):
    rows = "".join(f"p{i},{i},{i}\n" for i in range(3000))
    p = _write(tmp_path, "# c\nid,x,y\n" + rows + "bad,nan,1\n")
    with pytest.raises(InputError, match=r"bad \(line 3003\)"):
        for _ in PointBlocks(p, block_bytes=997):
            pass
    with pytest.raises(InputError, match=r"bad \(line 3003\)"):
        read_points(p)


# --- streamed reading and writing ----------------------------------------------------------


def test_point_blocks_match_read_points(tmp_path):
    rng = np.random.default_rng(3)
    xyz = rng.normal(size=(5000, 3)) * 1e3
    roles = np.where(rng.random(5000) < 0.2, "check", "control")
    ids = [f"id{k:05d}" for k in range(5000)]
    p = tmp_path / "p.csv"
    with PointWriter(p, ["X", "Y", "Z"], extra=["role"], comments=["test"]) as w:
        for k in range(0, 5000, 1234):
            w.write(ids[k : k + 1234], xyz[k : k + 1234], {"role": list(roles[k : k + 1234])})
    whole = read_points(p)
    blocks = list(PointBlocks(p, block_bytes=10_000))
    assert len(blocks) > 10
    assert [v for b in blocks for v in b.ids.to_pylist()] == list(whole.ids) == ids
    np.testing.assert_array_equal(np.vstack([b.coords for b in blocks]), xyz)
    assert [v for b in blocks for v in b.roles.to_pylist()] == list(whole.roles) == list(roles)


def test_writer_quotes_only_ids_that_need_it_and_keeps_floats_floats():
    text = format_points_csv(
        ["a", "b,c", 'd"e'], np.array([[1.0, -0.0], [1e22, 0.1], [2.5e-8, 3.0]]), ["x", "y"]
    )
    assert text.splitlines() == [
        "id,x,y",
        "a,1.0,-0.0",
        '"b,c",1e+22,0.1',
        '"d""e",2.5e-8,3.0',
    ]
    t = parse_points(text)
    assert t.ids == ("a", "b,c", 'd"e')


def test_streamed_write_is_atomic(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("old\n")
    with pytest.raises(RuntimeError, match="stop"):
        with PointWriter(target, ["x", "y"]) as w:
            w.write(["1"], np.zeros((1, 2)))
            raise RuntimeError("stop")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]
    with PointWriter(target, ["x", "y"]) as w:
        w.write(["1"], np.ones((1, 2)))
    assert target.read_text() == "id,x,y\n1,1.0,1.0\n"
    if os.name == "posix":
        assert target.stat().st_mode & 0o777 != 0o600


# --- the Python parser of small inputs and pyarrow agree ----------------------------------

_number_texts = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.sampled_from(["5.", ".5", "+3", "1E5", "-0", "00012", "1e-400", "abc", "", "1_0", "١٢"]),
)


@st.composite
def _csv_texts(draw):
    n = draw(st.integers(1, 12))
    lines = ["id,x,y"]
    for k in range(n):
        pid = draw(st.sampled_from([f"p{k}", f'"q,{k}"', f" r{k} ", f"s{k}"]))
        x, y = draw(_number_texts), draw(_number_texts)
        pad = draw(st.sampled_from(["", " ", "\t"]))
        lines.append(f"{pid},{pad}{x}{pad},{y}")
        lines += draw(st.lists(st.sampled_from(["", "  ", "# note"]), max_size=2))
    if draw(st.booleans()):  # a corruption: a missing field, a stray quote, an extra field
        k = draw(st.integers(1, len(lines) - 1))
        lines[k] += draw(st.sampled_from([",", ',"', "", ",9"]))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return end.join(lines) + end


def _read(text: str, arrow: bool):
    src = DelimitedText(data=text.encode("utf-8"))
    try:
        parts = list(src.blocks(["id"], ["x", "y"], arrow=arrow))
    except FileFormatError:
        return "refused"
    ids = [v for b in parts for v in (b.strings["id"].to_pylist() if arrow else b.strings["id"])]
    xy = [np.column_stack([b.numbers["x"], b.numbers["y"]]) for b in parts]
    return ids, (np.vstack(xy) if xy else np.zeros((0, 2))).tolist(), tuple(src.comments)


@settings(max_examples=150, deadline=None)
@given(_csv_texts())
def test_python_and_arrow_parsers_agree(text):
    a, b = _read(text, arrow=True), _read(text, arrow=False)
    assert a == b


def test_small_reads_do_not_import_pyarrow():
    import subprocess
    import sys

    code = (
        "import sys; from photogeom.io import parse_points; "
        "t = parse_points('id,x,y\\n1,2,3\\n'); print('pyarrow' in sys.modules, t.coords.tolist())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.stdout.split(None, 1) == ["False", "[[2.0, 3.0]]\n"]


def test_join_refuses_weights_given_as_strings():
    from dataclasses import replace

    from photogeom.io import join_points

    a = parse_points("id,x,y\n1,0,0\n2,1,0\n")
    b = parse_points("id,X,Y\n1,0,0\n2,1,0\n")
    with pytest.raises(InputError, match=r"weights must be numbers.*'1'.*float\(\)"):
        join_points(a, replace(b, weights=np.array(["1", "2"])))
    with pytest.raises(InputError, match="positive finite"):
        join_points(a, replace(b, weights=np.array([1.0, -2.0])))
    pairs = join_points(a, replace(b, weights=np.array([1, 2])))
    assert pairs.weights.dtype == np.float64


def test_overlong_field_in_a_big_file_is_refused_by_the_block_reader(tmp_path):
    rows = "".join(f"{i},{i},{i}\n" for i in range(30000))  # over SMALL_BYTES: pyarrow reads it
    p = _write(tmp_path, "id,x,y\n" + rows + "7,1," + "5" * (MAX_FIELD_BYTES + 10) + "\n")
    with pytest.raises(FileFormatError, match=r"line 30002: column y holds a field longer than"):
        read_points(p)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="POSIX permissions, not root")
def test_streamed_write_refuses_a_read_only_file(tmp_path):
    from photogeom.errors import OutputError

    target = tmp_path / "ro.csv"
    target.write_text("old\n")
    target.chmod(0o444)
    with pytest.raises(OutputError, match="read-only"):
        with PointWriter(target, ["x"]) as w:
            w.write(["1"], np.zeros((1, 1)))
    assert target.read_text() == "old\n"


@pytest.mark.skipif(os.name != "posix", reason="symbolic links")
def test_streamed_write_follows_a_symbolic_link(tmp_path):
    real = tmp_path / "real.csv"
    real.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    with PointWriter(link, ["x"]) as w:
        w.write(["1"], np.ones((1, 1)))
    assert link.is_symlink() and real.read_text() == "id,x\n1,1.0\n"
