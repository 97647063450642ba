"""Damaged bundled data sets: named errors (file and line) instead of TypeError, KeyError or
UnicodeDecodeError; a missing file named as missing; `examples run` goes on after a failed
example, marks it and ends with exit 2."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from photogeom import datasets
from photogeom.errors import FileFormatError, InputError, PhotogeomError


@pytest.fixture
def data(tmp_path, monkeypatch):
    """A copy of the bundled files that the tests may damage (the installed copy is left
    alone)."""
    copy = tmp_path / "data"
    shutil.copytree(datasets._data_dir(), copy)
    monkeypatch.setattr(datasets, "_data_dir", lambda: copy)
    return copy


def _lines(p):
    return p.read_text(encoding="utf-8").splitlines(keepends=True)


def test_intact_data_sets_load_with_their_columns():
    for name in datasets.names():
        t = datasets.load(name)
        assert tuple(t) == datasets.COLUMNS[name]
        for col, values in t.items():
            if col in datasets.TEXT_COLUMNS:
                assert values.dtype.kind == "U"
            else:
                assert values.dtype == float and np.isfinite(values).all()
    ids, src, dst = datasets.point_pairs("lidar_wang2014")
    assert ids[0] == "1" and src.shape == dst.shape == (18, 3)


def test_truncated_row(data):
    p = data / "lidar_wang2014.csv"
    lines = _lines(p)
    last = len(lines)
    p.write_text("".join(lines[:-1]) + "18,-29.781,-0.026")  # a truncated last line
    with pytest.raises(FileFormatError) as info:
        datasets.point_pairs("lidar_wang2014")
    msg = str(info.value)
    assert f"{p}, line {last}: 3 field(s) where the header has 7" in msg
    assert "reinstall" in msg


def test_row_with_too_many_fields(data):
    p = data / "kraus_absolute_orientation.csv"
    lines = _lines(p)
    n = next(i for i, s in enumerate(lines) if s[0].isdigit())  # first data row
    lines[n] = lines[n].rstrip("\n") + ",7\n"
    p.write_text("".join(lines))
    with pytest.raises(FileFormatError, match=rf"line {n + 1}: 8 field\(s\) where"):
        datasets.load("kraus_absolute_orientation")


def test_non_numeric_cell(data):
    p = data / "afary2024_simulated.csv"
    text = p.read_text()
    p.write_text(text.replace("100.0000,200.0000,120.0000", "100.0000,2OO.0000,120.0000"))
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "100.0000,200.0000" in s)
    with pytest.raises(FileFormatError) as info:
        datasets.point_pairs("afary2024_simulated", "true")
    assert f"line {line}: column 'Y' holds '2OO.0000', not a finite number" in str(info.value)


@pytest.mark.parametrize("cell", ["", "nan", "inf"])
def test_empty_or_non_finite_cell(data, cell):
    p = data / "lidar_wang2014.csv"
    lines = _lines(p)
    fields = lines[-1].rstrip("\n").split(",")
    fields[3] = cell
    lines[-1] = ",".join(fields) + "\n"
    p.write_text("".join(lines))
    with pytest.raises(FileFormatError, match=rf"line {len(lines)}: column 'z' holds"):
        datasets.load("lidar_wang2014")


def test_wrong_columns(data):
    p = data / "lidar_wang2014.csv"
    p.write_text(p.read_text().replace("id,x,y,z,X,Y,Z", "id,a,b,c,X,Y,Z"))
    with pytest.raises(FileFormatError) as info:
        datasets.point_pairs("lidar_wang2014")
    msg = str(info.value)
    assert f"{p}: column(s) x, y, z missing" in msg and "id, a, b, c, X, Y, Z" in msg


def test_not_utf8(data):
    p = data / "lidar_wang2014.csv"
    raw = p.read_bytes()
    first = raw.index(b"\n")
    second = raw.index(b"\n", first + 1)
    p.write_bytes(raw[:second] + b" Gen\xe8ve (Latin-1)" + raw[second:])  # in line 2
    for call in (
        lambda: datasets.load("lidar_wang2014"),
        lambda: datasets.header("lidar_wang2014"),
    ):
        with pytest.raises(FileFormatError, match=r"line 2: not UTF-8 text \(byte 0xe8\)"):
            call()


def test_header_only(data):
    p = data / "lecture_two_images.csv"
    p.write_text("# comment\nid,x1,y1,x2,y2\n")
    with pytest.raises(FileFormatError, match="a header but no rows"):
        datasets.load("lecture_two_images")


def test_path_checks_point_data_sets(data):
    """Readers other than load (read_point_pairs in the examples) get the same check."""
    p = data / "lecture_fiducials.csv"
    lines = _lines(p)
    p.write_text("".join(lines[:-1]) + "8,check,113.011\n")
    with pytest.raises(FileFormatError, match=rf"line {len(lines)}: 3 field\(s\)"):
        datasets.path("lecture_fiducials")


@pytest.mark.parametrize(
    ("name", "file"),
    [("worldview2", "rpc/rpc_WV2.xml"), ("lidar_wang2014", "lidar_wang2014.csv")],
)
def test_missing_file_is_missing_not_unknown(data, name, file):
    (data / file).unlink()
    with pytest.raises(PhotogeomError) as info:
        datasets.path(name)
    msg = str(info.value)
    assert not isinstance(info.value, InputError)
    assert f"its file {data / file} is missing" in msg and "no bundled data set" not in msg


def test_unknown_name_still_lists_known():
    with pytest.raises(InputError, match=r"no bundled data set 'nope'; known: .*worldview2"):
        datasets.path("nope")


def test_kind_choice():
    with pytest.raises(InputError, match="kind= one of 'noisy', 'true'"):
        datasets.point_pairs("afary2024_simulated")
    with pytest.raises(InputError, match="not 'both'"):
        datasets.point_pairs("afary2024_simulated", "both")


def test_examples_run_one_damaged(cli, data):
    p = data / "lidar_wang2014.csv"
    p.write_text("".join(_lines(p)[:-1]) + "18,-29.781,-0.026")
    code, out, err = cli("examples", "run", "absolute-lidar")
    assert code == 1  # a batch with a failed item (was 2, as bad input)
    assert "Traceback" not in err
    assert err.startswith(f"error: example absolute-lidar failed: {p}, line ")
    assert "FAILED" in out


def test_examples_run_all_goes_on_and_reports(cli, data, tmp_path, monkeypatch):
    from photogeom import examples

    (data / "rpc" / "rpc_WV2.xml").unlink()
    p = data / "lidar_wang2014.csv"
    p.write_text(p.read_text().replace("id,x,y,z,X,Y,Z", "id,a,b,c,X,Y,Z"))
    # run a few cheap examples around the damaged ones (the whole set takes seconds more)
    keep = ("fiducials", "absolute-lidar", "absolute-kraus", "rpc-bias", "collinearity")
    everything = examples.all_examples
    monkeypatch.setattr(
        examples, "all_examples", lambda: [e for e in everything() if e.name in keep]
    )
    report = tmp_path / "r.html"
    code, out, err = cli("examples", "run", "--all", "--report", report)
    assert code == 1
    assert err.startswith("error: 2 of 5 examples failed: absolute-lidar (")
    assert "rpc-bias (bundled data set 'worldview2': its file" in err
    assert "(the other 3 ran, see the report)" in err
    rows = {
        ln.split()[0]: ln.split()[1]
        for ln in out.splitlines()
        if ln.strip().split()[:1] and ln.split()[0] in keep and len(ln.split()) >= 3
    }
    assert rows == {
        "fiducials": "ok",
        "absolute-lidar": "FAILED",
        "absolute-kraus": "ok",
        "rpc-bias": "FAILED",
        "collinearity": "ok",
    }
    html = report.read_text()
    assert "absolute-lidar failed" in html and "rpc-bias failed" in html
    assert "column(s) x, y, z missing" in html
    # the examples that ran are in the report with their results
    assert html.count("<h2") >= 5 and "Kraus" in html
