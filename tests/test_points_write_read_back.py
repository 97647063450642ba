"""write_points writes only what read_points gives back.

Before: ids ``"P\\x001"`` (a NUL: the reader takes the file for a binary one), ``""``,
``" "`` or ``"\\xa0"`` (white space only: read back empty, refused), ``"a"`` twice or
``"a"`` and ``" a"`` (one id once trimmed: refused as repeated), a further text column with a
line break or a NUL, and a comment with a NUL were all written, and reading the file back
failed. Now the writer refuses them, naming the id and its row.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photogeom.errors import InputError
from photogeom.io.points import read_points, write_points

XYZ = ["X", "Y", "Z"]


@pytest.mark.parametrize(
    "ids,match",
    [
        (["P\x001", "Q"], r"'P\\x001' \(row 1\) holds a NUL character"),
        (["A", ""], r"'' \(row 2\) is empty or only white space"),
        (["A", " "], r"' ' \(row 2\) is empty or only white space"),
        (["\xa0", "A"], r"'\\xa0' \(row 1\) is empty or only white space"),
        (["\x1f", "A"], r"'\\x1f' \(row 1\) is empty or only white space"),
        (["a", "b", "a"], r"'a' \(row 1\) and 'a' \(row 3\) read back as the same id 'a'"),
        (["b", "a", " a"], r"'a' \(row 2\) and ' a' \(row 3\) read back as the same id 'a'"),
    ],
)
def test_ids_the_reader_refuses_are_refused_by_the_writer(tmp_path, ids, match):
    with pytest.raises(InputError, match=match):
        write_points(tmp_path / "p.csv", ids, np.zeros((len(ids), 3)), XYZ)
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize("value", ["a\nb", "a\rb", "a\x00b"])
def test_further_text_the_reader_refuses_is_refused(tmp_path, value):
    with pytest.raises(InputError, match=r"column note: value .* \(row 2\) holds a line break"):
        write_points(tmp_path / "p.csv", ["A", "B"], np.zeros((2, 3)), XYZ,
                     extra={"note": ["ok", value]})  # fmt: skip


def test_a_comment_with_nul_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"comment .* holds a NUL character"):
        write_points(tmp_path / "p.csv", ["A"], np.zeros((1, 3)), XYZ, comments=["a\x00b"])


_IDS = st.text(st.characters(blacklist_categories=("Cs",)), max_size=6) | st.sampled_from(
    ["1", "01", " 1", 'a"b', "#x", "a,b", "", " ", "\u3000", "e\u0301", "\xe9", "\x85"]
)
_FLOATS = st.floats(allow_nan=False, allow_infinity=False) | st.sampled_from(
    [-0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 0.1 + 0.2]
)


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(ids=st.lists(_IDS, max_size=6), data=st.data())
def test_what_is_written_reads_back_exactly(tmp_path_factory, ids, data):
    """Any ids and float64: refused by the writer, or read back as written (ids trimmed
    of white space at the ends, as documented; coordinates bit for bit, -0.0 included)."""
    n = len(ids)
    xyz = np.array(data.draw(st.lists(st.tuples(_FLOATS, _FLOATS, _FLOATS), min_size=n,
                                      max_size=n))).reshape(n, 3)  # fmt: skip
    path = tmp_path_factory.mktemp("pts") / "p.csv"
    try:
        write_points(path, ids, xyz, XYZ)
    except InputError:
        assert len({i.strip() for i in ids}) < n or not all(i.strip() for i in ids) or any(
            c in i for i in ids for c in "\r\n\x00"
        )
        return
    table = read_points(path)
    assert list(table.ids) == [i.strip() for i in ids]
    assert table.coords.tobytes() == xyz.tobytes()


@pytest.mark.parametrize(
    "columns,extra,match",
    [
        (["X", "X", "Z"], {}, r"column names 'X' and 'X' read back as the same name 'X'"),
        (["X ", "X", "Z"], {}, r"column names 'X ' and 'X' read back as the same name 'X'"),
        (["id", "Y", "Z"], {}, r"column names 'id' and 'id' read back as the same name"),
        (["X", "Y", "Z"], {"X": [1.0]}, r"column names 'X' and 'X' read back as the same"),
        (["", "Y", "Z"], {}, r"column name '' is empty or only white space"),
        (["X", "\u3000", "Z"], {}, r"column name '\\u3000' is empty or only white space"),
        (["a\nb", "Y", "Z"], {}, r"column name 'a\\nb' holds a line break"),
    ],
)
def test_header_names_the_reader_refuses_are_refused(tmp_path, columns, extra, match):
    """Before: written, and read_points refused the header ("column name(s) X appear more
    than once in the header", "the header has an empty column name")."""
    with pytest.raises(InputError, match=match):
        write_points(tmp_path / "p.csv", ["A"], np.zeros((1, 3)), columns, extra=extra)
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize("columns", [["X,1", 'Y"', "Z"], ["#X", "\xfc", "Z"], [" X", "Y", "Z"]])
def test_unusual_header_names_read_back(tmp_path, columns):
    write_points(tmp_path / "p.csv", ["A"], np.ones((1, 3)), columns)
    table = read_points(tmp_path / "p.csv", [c.strip() for c in columns])
    assert table.columns == tuple(c.strip() for c in columns) and table.coords.tolist() == [
        [1.0, 1.0, 1.0]
    ]
