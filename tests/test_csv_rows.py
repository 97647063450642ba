"""Point CSVs written by pyarrow in worker threads: rows in order, the same bytes as one
thread, floats and ids (commas, quotes, unicode) read back exactly by Python's csv module,
failures leave no file and no thread behind."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import threading
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.io import PointWriter, csvrows, format_points_csv
from photogeom.io.csvblocks import _lines_at_most

_SPECIAL = [0.0, -0.0, 1.0, -3.0, 1e15, 1e16, 1e22, -1e300, 1e-5, 1.234e-7, 0.1, 5e-324,
            2.2250738585072014e-308, 1.7976931348623157e308, 123456789012345.0,
            9007199254740993.0, math.nan, math.inf, -math.inf]  # fmt: skip
_ID_PARTS = ["p", "a,b", 'say "hi"', "Straße", "点", "🛰", ",", '"', "x y", 'é,"ç"']


def _rows_back(text: str) -> list[list[str]]:
    """Rows of CSV text by Python's csv module (an independent reader), comments dropped."""
    lines = [ln for ln in text.splitlines(keepends=True) if not ln.startswith("#")]
    return list(csv.reader(io.StringIO("".join(lines))))


def _same_floats(texts, values) -> bool:
    got = np.array([float(t) for t in texts])
    number = ~np.isnan(values)  # the sign of -0.0 is kept; a nan has none to keep
    return bool(np.array_equal(got, values, equal_nan=True)) and bool(
        np.array_equal(np.signbit(got[number]), np.signbit(values[number]))
    )


def _data(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    ids = [f"{_ID_PARTS[k % len(_ID_PARTS)]}{k}" for k in range(n)]
    xyz = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-8, 12, size=(n, 3))
    xyz[: len(_SPECIAL), 0] = _SPECIAL
    xyz[::7, 1] = np.round(xyz[::7, 1])  # integral values among the others
    status = np.where(rng.random(n) < 0.3, "check", "con,trol")
    count = rng.integers(0, 30, n)
    return ids, xyz, status, count


def _write(path, chunks, ids, xyz, status, count, workers=None, monkeypatch=None):
    if workers is not None:
        monkeypatch.setattr(csvrows, "worker_count", lambda: workers)
    with PointWriter(path, ["X", "Y", "Z"], extra=["status", "n"], comments=["c"]) as w:
        for a, b in pairwise(chunks):
            w.write(ids[a:b], xyz[a:b], {"status": list(status[a:b]), "n": count[a:b]})


def test_threaded_write_matches_one_thread_and_reads_back_exactly(tmp_path, monkeypatch):
    n = 3 * csvrows.SLICE_ROWS + 1234
    ids, xyz, status, count = _data(n)
    # chunks below and above the threaded size, several slices each
    chunks = [0, 10, csvrows.MIN_THREADED_ROWS + 5, 2 * csvrows.SLICE_ROWS + 7, n - 3, n]
    threaded, single = tmp_path / "t.csv", tmp_path / "s.csv"
    _write(threaded, chunks, ids, xyz, status, count, 3, monkeypatch)
    _write(single, chunks, ids, xyz, status, count, 1, monkeypatch)
    assert threaded.read_bytes() == single.read_bytes()
    rows = _rows_back(threaded.read_text(encoding="utf-8"))
    assert rows[0] == ["id", "X", "Y", "Z", "status", "n"]
    rows = rows[1:]
    assert [r[0] for r in rows] == ids  # order kept, commas, quotes and unicode intact
    for j in range(3):
        assert _same_floats([r[1 + j] for r in rows], xyz[:, j])
    assert [r[4] for r in rows] == list(status)
    assert [int(r[5]) for r in rows] == list(count)
    # integral floats keep a decimal point or an exponent: they read back as floats
    assert all(("." in t or "e" in t or "n" in t) for r in rows for t in r[1:4])


@settings(max_examples=25)
@given(st.lists(st.floats(width=64), min_size=1, max_size=200))
def test_float_text_is_the_shortest_round_trip(values):
    v = np.array(values, dtype=np.float64)
    texts = csvrows.float_text(v).to_pylist()
    assert _same_floats(texts, v)
    for t, x in zip(texts, v):
        if math.isfinite(x):  # the digits of Python's repr (the notation may differ)
            assert _digits(t) == _digits(repr(float(x)))


def _digits(text: str) -> str:
    """Significant digits of a number's text."""
    return text.lstrip("-").split("e")[0].replace(".", "").strip("0")


def test_format_points_csv_quotes_like_the_csv_module():
    ids = ["a", "b,c", 'd"e', "f\ng", "Ω", "h i"]
    text = format_points_csv(ids, np.arange(12.0).reshape(6, 2), ["x", "y"])
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["id", "x", "y"])
    writer.writerows([i, f"{2.0 * k}", f"{2.0 * k + 1}"] for k, i in enumerate(ids))
    assert text == buf.getvalue()


def test_a_failure_mid_stream_leaves_no_file_and_no_thread(tmp_path, monkeypatch):
    monkeypatch.setattr(csvrows, "worker_count", lambda: 2)
    before = threading.active_count()
    target = tmp_path / "out.csv"
    n = 4 * csvrows.SLICE_ROWS
    with pytest.raises(RuntimeError, match="stop"):
        with PointWriter(target, ["x", "y"]) as w:
            w.write([f"p{k}" for k in range(n)], np.ones((n, 2)))
            raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []
    assert threading.active_count() == before


def test_cli_keeps_ids_and_writes_the_api_floats(tmp_path, cli):
    """`transform apply` on a file of several blocks: ids with commas, quotes and unicode come
    back unchanged and in order; the numbers are those of the API, to the last bit."""
    n = 40_000
    rng = np.random.default_rng(5)
    ids = [f"{_ID_PARTS[k % len(_ID_PARTS)]}-{k}" for k in range(n)]
    xyz = rng.uniform(-1e6, 1e6, (n, 3)) + np.array([4e6, 3e5, 5e6])
    src, out, par = tmp_path / "in.csv", tmp_path / "out.csv", tmp_path / "h.json"
    pg.io.write_points(src, ids, xyz, ["x", "y", "z"])
    t = pg.Similarity3D.from_helmert(
        -87.0, -98.0, -121.0, 0.1, -0.247, 0.3, 1.5, convention="position_vector"
    )
    par.write_text(json.dumps({"model_parameters": t.to_dict()}))
    assert src.stat().st_size > 2 << 20  # more than one block of the streamed reader
    code, _, err = cli("transform", "apply", par, src, "-o", out)
    assert code == 0, err
    rows = _rows_back(out.read_text(encoding="utf-8"))
    assert rows[0] == ["id", "X", "Y", "Z"]
    assert [r[0] for r in rows[1:]] == ids
    got = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    # the text reads back to the float written (tested above); the command computes block by
    # block, which may change the last bit of a BLAS product against one call on all points
    np.testing.assert_array_max_ulp(got, t.apply(xyz), maxulp=2)


def test_streamed_commands_keep_blas_on_one_thread_only_in_a_fresh_process(monkeypatch):
    from photogeom.cli._stream import BLAS_THREAD_VARIABLES, single_threaded_blas

    for v in BLAS_THREAD_VARIABLES:  # set, then removed: restored after the test
        monkeypatch.setenv(v, "1")
        monkeypatch.delenv(v)
    assert not single_threaded_blas()  # numpy is loaded here: too late, nothing is set
    assert not any(v in os.environ for v in BLAS_THREAD_VARIABLES)
    monkeypatch.delitem(sys.modules, "numpy")
    assert single_threaded_blas()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")  # the user's choice is kept
    assert not single_threaded_blas()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"


@settings(max_examples=200)
@given(
    st.lists(st.integers(min_value=0, max_value=30), max_size=8),
    st.booleans(),
    st.integers(min_value=1, max_value=40),
)
def test_line_length_gate(lengths, final_newline, limit):
    block = b"\n".join(b"x" * k for k in lengths) + (b"\n" if final_newline else b"")
    lines = block.split(b"\n")
    want = all(len(ln) + 1 <= limit for ln in lines[:-1]) and len(lines[-1]) <= limit
    assert _lines_at_most(block, limit) == want


def test_arrays_reused_by_the_caller_do_not_change_rows_already_written(tmp_path, monkeypatch):
    monkeypatch.setattr(csvrows, "worker_count", lambda: 2)
    n = 2 * csvrows.SLICE_ROWS
    buf, count = np.zeros((n, 2)), np.zeros(n, dtype=int)
    target = tmp_path / "out.csv"
    with PointWriter(target, ["x", "y"], extra=["k"]) as w:
        for k in range(3):  # one buffer refilled for every chunk, as a reader might
            buf[:] = k
            count[:] = k
            w.write([f"p{k}-{i}" for i in range(n)], buf, {"k": count})
    rows = _rows_back(target.read_text())[1:]
    assert [r[1:] for r in rows[::n]] == [[f"{k}.0", f"{k}.0", str(k)] for k in range(3)]
    assert {r[0].split("-")[0][1:] == r[1][0] for r in rows} == {True}


def test_missing_text_values_are_empty_fields_not_lost_rows():
    import pyarrow as pa

    text = format_points_csv(
        pa.array(["a", None, "c"]),
        np.zeros((3, 1)),
        ["x"],
        extra={"note": pa.array([None, "n,1", "z"])},
    )
    assert text.splitlines() == ["id,x,note", "a,0.0,", ',0.0,"n,1"', "c,0.0,z"]
