"""`grid fit` / `grid apply` read their CSV column-wise.

The reader splits the lines without quotes all at once and converts number columns in
compiled code; it must read every file as the csv-module reader it replaced did: the same
cells, line numbers, comments and error messages, and `grid apply` must write the same bytes.
A copy of the replaced functions is kept here as the reference.
"""

from __future__ import annotations

import csv
import random

import numpy as np
import pytest

from photogeom.calibration import correct_observations, fit_grids, load_grids, save_grids
from photogeom.cli import grid as gridcli
from photogeom.errors import FileFormatError, PhotogeomError
from photogeom.numbers import is_decimal_number

# --- the replaced reader (photogeom 2026-11-24, cli/grid.py), the reference -----------------


def _old_read_csv(path, need, comments=None):
    rows, lines = [], []
    physical = []

    def data_lines(fh):
        for number, line in enumerate(fh, start=1):
            if line.lstrip().startswith("#"):
                if comments is not None:
                    comments.append(line.strip()[1:].strip())
                continue
            physical.append(number)
            yield line

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(data_lines(fh))
            start = 0
            for r in reader:
                if r and any(c.strip() for c in r):
                    rows.append(r)
                    lines.append(physical[start])
                start = reader.line_num
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a UTF-8 CSV file ({exc})") from None
    except csv.Error as exc:  # was also "not a UTF-8 CSV file", without a line
        line = physical[min(start, len(physical) - 1)] if physical else 1
        raise FileFormatError(
            f"{path}, line {line}: cannot split the line into fields ({exc}); an id or a "
            'number is a few characters: a quote (") left open, or not a CSV file?'
        ) from None
    if not rows:
        raise FileFormatError(f"{path}: empty file")
    header = [c.strip() for c in rows[0]]
    low = [c.lower() for c in header]
    col = {}
    for name in need:
        aliases = {"image_id": ("image_id", "image", "id")}.get(name, (name,))
        hit = next((low.index(a) for a in aliases if a in low), None)
        if hit is None:  # names shown as repr (tabs visible), at most 20, and
            # the separator of a one-column header named
            other = next(
                (w for c, w in gridcli._OTHER_SEPARATORS if len(header) == 1 and c in header[0]),
                None,
            )
            raise FileFormatError(
                f"{path}: no column {name!r} (columns: {gridcli._listing(header)}); "
                f"the file needs {', '.join(need)}"
                + (
                    f"; its header is separated by {other}: photogeom reads this file "
                    "comma-separated (replace the separators with commas)"
                    if other
                    else ""
                )
            )
        col[name] = hit
    body, lines = rows[1:], lines[1:]
    bad = [k for k, r in enumerate(body) if len(r) != len(header)]
    if bad:
        raise FileFormatError(
            f"{path}: line {lines[bad[0]]} has {len(body[bad[0]])} fields, the header {len(header)}"
        )
    return header, body, col, lines


def _old_numbers(path, body, idx, name, lines):
    try:
        values = np.array([float(r[idx]) for r in body])
    except ValueError:
        for k, r in enumerate(body):
            try:
                float(r[idx])
            except ValueError:
                raise FileFormatError(
                    f"{path}: line {lines[k]}, column {name}: not a number ({r[idx]!r})"
                ) from None
        raise
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(
            f"{path}: line {lines[k]}, column {name}: {body[k][idx]!r} is not a finite number "
            f"({bad.size} row(s) in all); remove those rows or give their values"
        )
    return values


def _expected_numbers(path, body, idx, name, lines):
    """:func:`_old_numbers` with the decimal-number rule of every reader of photogeom (a
    later fix: ``1_0`` and non-ASCII digits are not numbers)."""
    for k, r in enumerate(body):
        if not is_decimal_number(r[idx]):
            raise FileFormatError(
                f"{path}: line {lines[k]}, column {name}: not a number ({r[idx]!r})"
            )
    return _old_numbers(path, body, idx, name, lines)


def _old_cell(text):
    if any(ch in text for ch in ',"\r\n') or text.lstrip().startswith("#"):
        return '"' + text.replace('"', '""') + '"'
    return text


def _old_apply_text(observations, grids):
    """The text the replaced `grid apply` wrote (grids keyed by the CSV's ids)."""
    comments = []
    header, body, col, lines = _old_read_csv(observations, ("image_id", "u", "v"), comments)
    ids = [r[col["image_id"]].strip() for r in body]
    uv = np.stack([_old_numbers(observations, body, col[c], c, lines) for c in ("u", "v")], 1)
    per_image = {}
    for i, k in enumerate(ids):
        per_image.setdefault(k, []).append(i)
    corrected = correct_observations({k: uv[np.asarray(r)] for k, r in per_image.items()}, grids)
    new = uv.copy()
    for k, r in per_image.items():
        new[np.asarray(r)] = corrected[k]
    out = [f"# {c}" for c in comments if c]
    out.append(",".join(_old_cell(c) for c in header))
    for i, r in enumerate(body):
        r = list(r)
        r[col["u"]] = repr(float(new[i, 0]))
        r[col["v"]] = repr(float(new[i, 1]))
        out.append(",".join(_old_cell(c) for c in r))
    return "\n".join(out) + "\n"


# --- random files -------------------------------------------------------------------------

NUMBERS = ["1.5", " 2", "3 ", "-4e2", "nan", "inf", "-Infinity", "abc", "", "1_0", "\u0663",
           "nan(1)", "+.5", "7", "1e400", '"8.25"', '" 9"', "0x1", "\t5\t"]  # fmt: skip
IDS = ["IMG_1", " IMG_2 ", "7", "07", '"q,id"', '"a""b"', '"#x"', "x#y", '"IMG_1"', "é",
       '" "', "I\x0bJ", "a\x00b"]  # fmt: skip
HEADERS = [
    ["image_id", "u", "v", "rx", "ry"],
    ["Image", "U", "V", "RX", "RY"],
    ["id", " u ", "v", "rx", "ry", "extra"],
    ["ID", "u", "v", "rx", "ry", "u"],
    ["image_id", "u", "v"],
    ['"image_id"', "u", '"v"', "rx", "ry"],
    ["image_id", "u", "rx", "ry"],
]
ODD_LINES = ['"open', '"a"b,1,2,3,4', 'x,"multi\nline",1,2,3', '#c, inside', "   ", ",,,,",
             " , ,", '""', '"",""', "a,b", "a,1,2,3,4,5,6", '"unclosed,1,2,3,4', 'a"b,1,2,3,4',
             "\x0c", "  # indented comment", '"  ,  "', '" ",""', '"a",b"', 'x,"y"z', '"",',
             ' "a",b', '"IMG_1","1","2","3","4"', '"",,,,', '"#a",1,2,3,4']  # fmt: skip


def _random_file(rng: random.Random, odd: float) -> bytes:
    head = rng.choice(HEADERS)
    lines = []
    if rng.random() < 0.5:
        lines.append("# " + rng.choice(["crs: x", "", "a,b"]))
    if rng.random() < 0.2:
        lines.append("")
    lines.append(",".join(head))
    for _ in range(rng.randint(0, 12)):
        r = rng.random()
        if r < odd:
            lines.append(rng.choice(ODD_LINES))
        elif r < odd + 0.05:
            lines.append("# note")
        elif r < odd + 0.1:
            lines.append("")
        else:
            cells = [rng.choice(IDS)] + [
                rng.choice(NUMBERS) if rng.random() < 0.3 else repr(rng.uniform(0, 300))
                for _ in head[1:]
            ]
            lines.append(",".join(cells))
    end = rng.choice(["\n", "\r\n", "\r"])
    data = (end.join(lines) + (end if rng.random() < 0.7 else "")).encode("utf-8")
    if rng.random() < 0.1:
        data = b"\xef\xbb\xbf" + data
    if rng.random() < 0.03:
        data += b"\xff\n"
    return data


def _outcome(path, need, reader):
    """What a reader makes of a file: its cells, lines and numbers, or its error."""
    comments = []
    try:
        if reader == "old":
            header, body, col, lines = _old_read_csv(path, need, comments)
            columns = [list(c) for c in zip(*body, strict=True)] if body else [[] for _ in header]
            lines = list(lines)
        else:
            header, columns, col, lines = gridcli._read_csv(path, need, comments)
            columns = [list(c) for c in columns]
            lines = [int(x) for x in lines]
    except PhotogeomError as exc:
        return ("error", type(exc).__name__, str(exc), comments)
    numbers = []
    for name in need[1:]:
        try:
            if reader == "old":
                values = _expected_numbers(path, body, col[name], name, lines)
            else:
                values = gridcli._numbers(path, columns[col[name]], name, np.asarray(lines))
            numbers.append(values.tolist())
        except PhotogeomError as exc:
            numbers.append(("error", type(exc).__name__, str(exc)))
    return ("read", header, columns, col, lines, comments, numbers)


@pytest.mark.parametrize("arrow_cells", [20_000, 1])
@pytest.mark.parametrize("odd", [0.0, 0.03, 0.15])
def test_random_files_read_as_before(tmp_path, monkeypatch, odd, arrow_cells):
    """Cells, line numbers, comments, numbers and every error message as the csv-module
    reader gave them, on random files (quoted cells, comments, blank rows, CR and CRLF line
    ends, a BOM, quoted line breaks, bad numbers and field counts, aliases), with the
    number columns converted by float() and by pyarrow."""
    monkeypatch.setattr(gridcli, "ARROW_CELLS", arrow_cells)
    rng = random.Random(int(1000 * odd) + arrow_cells)
    path = tmp_path / "t.csv"
    for _ in range(150):
        path.write_bytes(_random_file(rng, odd))
        for need in (("image_id", "u", "v", "rx", "ry"), ("image_id", "u", "v")):
            old, new = _outcome(path, need, "old"), _outcome(path, need, "new")
            assert repr(new) == repr(old), path.read_bytes()


def test_plain_and_quoted_lines_are_not_read_line_by_line(tmp_path, monkeypatch):
    """A file of plain lines, and one with quoted cells on their lines, are split without
    the line-wise csv-module reader (kept for quoted line breaks and malformed quotes)."""

    def refuse(*_a, **_k):
        raise AssertionError("read line by line")

    path = tmp_path / "obs.csv"
    path.write_text('# c\nimage_id,u,v,name\nA,1,2,x\n"B,1",3,4,"y ""z"""\n\nA,5,6,w\n')
    monkeypatch.setattr(gridcli, "_read_rows_linewise", refuse)
    header, columns, col, lines = gridcli._read_csv(path, ("image_id", "u", "v"))
    assert header == ["image_id", "u", "v", "name"] and col == {"image_id": 0, "u": 1, "v": 2}
    assert columns == [["A", "B,1", "A"], ["1", "3", "5"], ["2", "4", "6"], ["x", 'y "z"', "w"]]
    assert lines.tolist() == [3, 4, 6]


def test_error_messages_name_the_file_line(tmp_path):
    p = tmp_path / "r.csv"
    need = ("image_id", "u", "v", "rx", "ry")
    p.write_text('# c\nimage_id,u,v,rx,ry\n"A\nB",1,2,3,4\nA,1,2,3\n')
    with pytest.raises(FileFormatError, match=r"r\.csv: line 5 has 4 fields, the header 5$"):
        gridcli._read_csv(p, need)
    p.write_text("image_id,u,v\nA,1,2\n")
    with pytest.raises(FileFormatError, match=r"no column 'rx' \(columns: image_id, u, v\)"):
        gridcli._read_csv(p, need)
    p.write_text("image_id,u,v\n\n# c\nA,1,2\nA,x1,2\n")
    _, columns, col, lines = gridcli._read_csv(p, ("image_id", "u", "v"))
    with pytest.raises(FileFormatError, match=r"line 5, column u: not a number \('x1'\)"):
        gridcli._numbers(p, columns[col["u"]], "u", lines)
    p.write_text("image_id,u,v\nA,1,2\nA,nan,2\n")
    _, columns, col, lines = gridcli._read_csv(p, ("image_id", "u", "v"))
    with pytest.raises(FileFormatError, match=r"line 3, column u: 'nan' is not a finite"):
        gridcli._numbers(p, columns[col["u"]], "u", lines)


def test_grid_apply_writes_the_same_bytes(cli, tmp_path):
    """`grid apply` on random observations with quoted cells, comments and extra columns:
    the bytes the replaced row-by-row writer gave."""
    rng = np.random.default_rng(8)
    ids = ["IMG_1", " IMG_2", "I,3", 'I"4', "#5"]
    grids = {}
    for k in ids:
        uv = rng.uniform(0, [299, 199], (60, 2))
        grids[k.strip()] = fit_grids(
            {0: (uv, rng.normal(0, 0.5, (60, 2)))}, (300, 200), 100.0, folds=0
        )[0]
    save_grids(tmp_path / "g.npz", grids)
    assert set(load_grids(tmp_path / "g.npz")) == {k.strip() for k in ids}
    lines = ["# observations, px", "image_id,point_id,u,v,note"]
    for i in range(3000):
        k = ids[rng.integers(len(ids))]
        cell = '"' + k.replace('"', '""') + '"' if any(c in k for c in ',"#') else k
        note = rng.choice(["", "a b", '"x, y"', '"say ""hi"""', "  #n", "ok"])
        u, v = rng.uniform(0, 299), rng.uniform(0, 199)
        lines.append(f"{cell},P{i},{u!r},{v:.3f},{note}")
        if i % 700 == 0:
            lines += ["# more", ""]
    obs = tmp_path / "obs.csv"
    obs.write_text("\r\n".join(lines) + "\r\n")
    code, _, err = cli("grid", "apply", tmp_path / "g.npz", obs, "-o", tmp_path / "c.csv")
    assert code == 0, err
    expected = _old_apply_text(obs, grids)
    assert (tmp_path / "c.csv").read_text() == expected


def test_grid_apply_of_a_header_only_file(cli, tmp_path):
    """No rows: the comments and the header are written back, as before."""
    rng = np.random.default_rng(2)
    uv = rng.uniform(0, [299, 199], (60, 2))
    save_grids(tmp_path / "g.npz", fit_grids({"A": (uv, uv * 0)}, (300, 200), 100.0, folds=0))
    obs = tmp_path / "obs.csv"
    obs.write_text("# c\nimage_id,u,v,p\n")
    code, text, err = cli("grid", "apply", tmp_path / "g.npz", obs)
    assert code == 0, err
    assert text == _old_apply_text(obs, {}) == "# c\nimage_id,u,v,p\n"


def test_cells_in_quotes_are_split_with_the_others(tmp_path, monkeypatch):
    """Cells that are one quoted text each are unwrapped in place, without the csv module
    (which reads only the lines with a quote inside a cell or around a comma)."""

    class NoReader:
        Error = csv.Error
        field_size_limit = staticmethod(csv.field_size_limit)

        @staticmethod
        def reader(*_a, **_k):
            raise AssertionError("csv module used")

    path = tmp_path / "obs.csv"
    path.write_text('"image_id","u","v"\n"A","1",2\n"",""," "\n"B ",3,"4"\n')
    monkeypatch.setattr(gridcli, "csv", NoReader)
    header, columns, _, lines = gridcli._read_csv(path, ("image_id", "u", "v"))
    assert header == ["image_id", "u", "v"] and lines.tolist() == [2, 4]
    assert columns == [["A", "B "], ["1", "3"], ["2", "4"]]
