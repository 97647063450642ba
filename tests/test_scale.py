"""Scale: jobs on big inputs stay linear in time and bounded in memory.

No timing or memory assertions: each test pins the new path against an independent
computation and checks the structure that keeps memory bounded (blocks of a bounded size).
"""

from __future__ import annotations

import numpy as np
import pytest

pyproj = pytest.importorskip("pyproj")


def _utm_file(path, n: int, seed: int = 0) -> tuple[list[str], np.ndarray, list[str]]:
    """A point CSV in UTM 32N (EPSG:32632) of n points with a role column (some blank)."""
    rng = np.random.default_rng(seed)
    xyz = np.column_stack(
        [rng.uniform(4e5, 6e5, n), rng.uniform(5.0e6, 5.4e6, n), rng.uniform(0, 3000, n)]
    )
    ids = [f"p{i}" for i in range(n)]
    roles = np.array(["control", "check", ""])[rng.integers(0, 3, n)].tolist()
    body = "".join(
        f"{i},{x!r},{y!r},{z!r},{r}\n" for i, (x, y, z), r in zip(ids, xyz.tolist(), roles)
    )
    path.write_text("# crs: EPSG:32632\nid,x,y,z,role\n" + body)
    return ids, xyz, roles


def test_crs_convert_streams_blocks_and_matches_proj(cli, tmp_path, monkeypatch):
    """`crs convert` read the whole file and formatted the whole output in memory (1e7
    points: 3.2 GB peak); it converts block by block now, building the PROJ operation once,
    with the output of PROJ on all points at once."""
    import photogeom.crs as pcrs
    from photogeom.io import format_points_csv

    n = 60_000  # about 3 MB of text: several blocks of 1 MiB
    src = tmp_path / "utm.csv"
    ids, xyz, roles = _utm_file(src, n)
    sizes: list[int] = []
    built = {"n": 0}
    make = pcrs.points_converter

    def counting(*args, **kwargs):
        built["n"] += 1
        convert = make(*args, **kwargs)

        def run(points):
            sizes.append(len(points))
            return convert(points)

        return run

    monkeypatch.setattr(pcrs, "points_converter", counting)
    out = tmp_path / "geo.csv"
    code, _, err = cli("crs", "convert", src, "--to", "EPSG:4979", "-o", out)
    assert code == 0, err
    assert f"wrote {n} point(s)" in err
    assert built["n"] == 1
    assert sum(sizes) == n and len(sizes) >= 3 and max(sizes) < n // 2

    t = pyproj.Transformer.from_crs(32632, 4979, always_xy=True)
    expected = np.column_stack(t.transform(*xyz.T))
    text = format_points_csv(
        ids,
        expected,
        ["lon", "lat", "h"],
        extra={"role": [r or "control" for r in roles]},
        comments=["EPSG:32632 -> EPSG:4979; lon in deg, lat in deg, h in m", "crs: EPSG:4979"],
    )
    assert out.read_text() == text


def test_crs_convert_to_a_local_frame_in_blocks(cli, tmp_path):
    """Through a local frame (geocentric WGS 84 in between), block by block: the same as
    points_between on all points at once, also to standard output."""
    import photogeom.crs as pcrs

    n = 40_000
    src = tmp_path / "utm.csv"
    _, xyz, _ = _utm_file(src, n, seed=3)
    code, out, err = cli("crs", "convert", src, "--to", "enu:47.1,8.5,500")
    assert code == 0, err
    rows = [ln for ln in out.splitlines() if not ln.startswith("#")][1:]
    got = np.array([[float(v) for v in r.split(",")[1:4]] for r in rows])
    expected = pcrs.points_between(xyz, "EPSG:32632", "enu:47.1,8.5,500")
    assert got.shape == (n, 3)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize(
    "src, dst",
    [
        ("EPSG:32632", "EPSG:4979"),
        ("EPSG:32632", "EPSG:32632"),
        ("enu:47.1,8.5,500", "EPSG:4978"),
        ("enu:47.1,8.5,500", "enu:47.2,8.4,400"),
        ("EPSG:4978", "enu:47.1,8.5,500"),
        ("EPSG:32632", "enu:47.1,8.5,500"),
    ],
)
def test_points_converter_equals_points_between_steps(src, dst):
    """The converter gives what the steps of points_between give (frame to geocentric WGS 84,
    PROJ, geocentric to frame), call after call."""
    import photogeom.crs as pcrs

    rng = np.random.default_rng(1)
    local = rng.uniform(-500, 500, (200, 3))
    pts = local if src.startswith("enu") else pcrs.points_between(local, "enu:47.1,8.5,500", src)
    convert = pcrs.points_converter(src, dst)
    f_src, f_dst = pcrs.frame_from_text(src), pcrs.frame_from_text(dst)
    step = f_src.to_ecef(pts) if f_src else pts
    mid_src = "EPSG:4978" if f_src else src
    mid_dst = "EPSG:4978" if f_dst else dst
    if mid_src != mid_dst:
        t = pyproj.Transformer.from_crs(mid_src, mid_dst, always_xy=True)
        step = np.column_stack(t.transform(*step.T))
    expected = f_dst.from_ecef(step) if f_dst else step
    for part in (pts[:70], pts[70:]):
        k = len(part)
        np.testing.assert_array_equal(convert(part), expected[:k] if k == 70 else expected[70:])
    assert convert(np.zeros((0, 3))).shape == (0, 3)


# --- CSV block reader ----------------------------------------------------------------------


def _reference_table(text: str, path):
    """The CSV block rules line by line (the reader before it split the file column-wise):
    blank and '#' lines skipped, the separator from the header, lines without quotes by
    the csv module (cells stripped), lines with quotes by _split_quoted."""
    import csv

    from photogeom.bundle.io_csv import _split_quoted

    body, numbers = [], []
    for k, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            body.append(line)
            numbers.append(k)
    sep = ","
    if "," not in body[0]:
        sep = ";" if ";" in body[0] else "\t" if "\t" in body[0] else ","
    rows, quoted = [], set()
    for i, line in enumerate(body):
        if '"' in line:
            cells, q = _split_quoted(line, sep, path, numbers[i])
            if i:
                quoted |= q
        else:
            row = next(csv.reader([line], delimiter=sep, skipinitialspace=True))
            cells = [c.strip() for c in row]
        rows.append(cells)
    for i, r in enumerate(rows[1:]):
        if len(r) != len(rows[0]):
            return ("error", f"line {numbers[i + 1]}: {len(r)} field(s)")
    return rows[0], rows[1:], numbers[1:], quoted


def _random_line(rng, width: int, sep: str) -> str:
    pieces = []
    for _ in range(width + int(rng.choice([0, 0, 0, 0, 0, 0, 0, 0, 1, -1]))):
        text = "".join(rng.choice(list('ab1 .-#"' + sep), size=int(rng.integers(0, 5))))
        kind = rng.integers(0, 6)
        if kind == 0:  # a well-formed quoted cell (quotes doubled inside), maybe padded
            pad = " " if rng.integers(0, 3) == 0 else ""
            text = pad + '"' + text.replace('"', '""') + '"' + pad
        elif kind == 1:  # a plain cell: no separator, no quote
            text = text.replace(sep, "").replace('"', "")
        elif kind == 2:
            text = '"' + text.replace(sep, "").replace('"', "") + '"'
        pieces.append(text)
    return sep.join(pieces)


@pytest.mark.parametrize("sep", [",", ";", "\t"])
def test_csv_block_tables_equal_the_line_by_line_rules(tmp_path, sep):
    """The column-wise reader gives the cells, line numbers and quoted columns (or the
    error) of the line-by-line rules on random lines: quoted and plain cells, doubled quotes,
    separators inside quotes, white space, '#', wrong field counts, blank and comment lines."""
    from photogeom.bundle.io_csv import _read_table
    from photogeom.errors import FileFormatError

    rng = np.random.default_rng(8)
    for trial in range(300):
        width = int(rng.integers(1, 5))
        lines = ["# c", sep.join(f"h{j}" for j in range(width))]
        for _ in range(int(rng.integers(0, 12))):
            r = rng.integers(0, 12)
            lines.append("" if r == 0 else "  # note" if r == 1 else _random_line(rng, width, sep))
        text = "\n".join(lines) + "\n"
        path = tmp_path / f"t{trial}.csv"
        path.write_text(text, encoding="utf-8")
        try:
            expected = _reference_table(text, path)
        except FileFormatError as exc:
            expected = ("error", str(exc))
        try:
            t = _read_table(path)
            got = (t.header, [list(r) for r in zip(*[c.tolist() for c in t.columns])],
                   t.lines.tolist(), t.quoted)  # fmt: skip
            if not t.columns or not t.n_rows:
                got = (t.header, [], t.lines.tolist(), t.quoted)
        except FileFormatError as exc:
            got = ("error", str(exc))
        if expected[0] == "error" and got[0] == "error":
            assert expected[1] in got[1] or expected[1] == got[1], (text, expected, got)
        else:
            assert got == expected, text


def test_csv_block_with_every_cell_quoted_is_not_read_cell_by_cell(tmp_path, monkeypatch):
    """A block folder whose every cell is quoted (a spreadsheet export) was parsed cell by
    cell by regular expressions (1e6 observations: 18 s against 6.5 s unquoted); such lines
    are split column-wise now, with the same block (quoted ids are text ids)."""
    import photogeom.bundle.io_csv as io_csv
    from photogeom.bundle import read_csv_block, write_csv_block
    from photogeom.simulate import uav_block

    block = uav_block("FC300S", seed=2).block
    write_csv_block(block, tmp_path / "plain")
    (tmp_path / "quoted").mkdir()
    for name in io_csv.FILES:
        out = []
        for line in (tmp_path / "plain" / name).read_text().splitlines():
            if line.startswith("#"):
                out.append(line)
            else:
                out.append(",".join(f'"{c}"' if c else "" for c in line.split(",")))
        (tmp_path / "quoted" / name).write_text("\n".join(out) + "\n")
    calls = {"n": 0}
    split = io_csv._split_quoted

    def counting(*args):
        calls["n"] += 1
        return split(*args)

    monkeypatch.setattr(io_csv, "_split_quoted", counting)
    got = read_csv_block(tmp_path / "quoted")
    assert calls["n"] <= len(io_csv.FILES)  # the header lines at most
    ref = read_csv_block(tmp_path / "plain")
    assert got.image_ids.dtype.kind == "U" and got.point_ids.dtype.kind == "U"
    np.testing.assert_array_equal(got.image_ids, ref.image_ids.astype(str))
    np.testing.assert_array_equal(got.point_ids, ref.point_ids.astype(str))
    np.testing.assert_array_equal(got.observations.uv, ref.observations.uv)
    np.testing.assert_array_equal(got.observations.sigma, ref.observations.sigma)
    np.testing.assert_array_equal(
        got.observations.point_ids, ref.observations.point_ids.astype(str)
    )
    np.testing.assert_array_equal(got.xyz, ref.xyz)
    np.testing.assert_array_equal(got.exterior, ref.exterior)


def test_csv_block_integer_ids_in_integer_form_only(tmp_path):
    """Ids are integers when every id is written as one ('-0' included, as before); '07',
    '+7', ' 7 ' quoted, '1_0' or digits of other scripts make them text."""
    from photogeom.bundle.io_csv import _integer_cells

    assert _integer_cells(["1", "-0", "23"]).tolist() == [1, 0, 23]
    assert _integer_cells(["0", "-12"]).tolist() == [0, -12]
    for bad in (["07"], ["+7"], ["1_0"], ["\u0663"], ["1", "x"], ["1.0"]):
        assert _integer_cells(bad) is None, bad


# --- terminal summaries -----------------------------------------------------------------------


def _pairs_file(path, ids, seed: int = 0, noise: float = 0.01):
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 100, (len(ids), 3))
    dst = src * 1.0001 + [10.0, 20.0, 30.0] + rng.normal(0, noise, src.shape)
    rows = [f"{i},{a[0]!r},{a[1]!r},{a[2]!r},{b[0]!r},{b[1]!r},{b[2]!r}" for i, a, b in
            zip(ids, src.tolist(), dst.tolist())]  # fmt: skip
    path.write_text("id,x,y,z,X,Y,Z\n" + "\n".join(rows) + "\n")
    return path


def test_point_ids_are_shown_as_written_not_as_markup(cli, tmp_path):
    """Ids went to rich as markup: 'P[/x]' stopped the summary with a MarkupError
    traceback, '[b]P1' lost its brackets, ':smile:' became an emoji."""
    ids = ["[b]P1", ":smile:", "P[/x]", "P4", "P5", "P6"]
    pts = _pairs_file(tmp_path / "p.csv", ids)
    code, out, err = cli("transform", "estimate", "similarity3d", pts)
    assert code == 0, err
    for i in ids:
        assert f"  {i} " in out


def _render(renderable, **kw) -> str:
    import io

    from rich.console import Console, Group
    from rich.text import Text

    c = Console(file=io.StringIO(), width=kw.pop("width", 110), **kw)
    c.print(Group(Text("residuals", style="bold"), renderable, Text("footer", style="dim")))
    return c.file.getvalue()


@pytest.mark.parametrize("seed", range(6))
def test_point_table_draws_what_rich_table_draws(seed):
    """The residual table is written line by line (rich's Table took 190 s on the 1e5
    residuals of 'transform estimate'): the same text as rich's Table, flagged cells in bold
    red on a terminal, rich's Table itself where the fast lines do not apply."""
    import re

    from photogeom.report.console import PointTable

    rng = np.random.default_rng(seed)
    ncol = int(rng.integers(1, 9))
    cols = [
        "id",
        *(f"v_{j}" if j % 2 else f"w{'x' * int(rng.integers(0, 9))}" for j in range(1, ncol)),
    ]
    n = int(rng.integers(1, 40))
    ids = [f"P{'-' * int(rng.integers(0, 12))}{k}" for k in range(n)]
    rows = [[ids[k], *(f"{v:.{rng.integers(0, 6)}f}" for v in rng.normal(0, 10, ncol - 1))]
            for k in range(n)]  # fmt: skip
    flags = (rng.random((n, ncol)) < 0.2).tolist()
    table = PointTable(cols, rows, flags)
    assert table.simple
    assert _render(table, color_system=None) == _render(table.rich_table(), color_system=None)
    ansi = re.compile(r"\x1b\[[0-9;]*m")
    fast = _render(table, color_system="standard", force_terminal=True)
    slow = _render(table.rich_table(), color_system="standard", force_terminal=True)
    assert ansi.sub("", fast) == ansi.sub("", slow)
    for k, row in enumerate(rows):
        for c, f in zip(row, flags[k]):
            if f:
                assert f"\x1b[1;31m{c}\x1b[0m" in fast
    narrow = max(10, table.width - 5)  # too wide: rich's Table shrinks it
    assert _render(table, color_system=None, width=narrow) == _render(
        table.rich_table(), color_system=None, width=narrow
    )


def test_point_table_with_wide_characters_is_rich_table():
    from photogeom.report.console import PointTable

    table = PointTable(["id", "v_X"], [["点1", "0.1"], ["P\u00e92", "-0.25"]], [[False] * 2] * 2)
    assert not table.simple
    assert _render(table, color_system=None) == _render(table.rich_table(), color_system=None)


def test_summary_of_many_points_is_the_rich_table_text(tmp_path):
    """fit_text (reports, tests) of a fit on 3000 points, three flagged: the same text as
    rich's Table gives."""
    import photogeom as pg
    from photogeom.report import console as rc

    rng = np.random.default_rng(5)
    src = rng.uniform(0, 100, (3000, 3))
    dst = src + np.array([1.0, 2.0, 3.0]) + rng.normal(0, 0.01, src.shape)
    dst[:3] += 0.5
    fit = pg.absolute_orientation(src, dst, method="gauss-markov")
    fast = rc.fit_text(fit)

    class Slow(rc.PointTable):
        def __rich_console__(self, console, options):
            yield self.rich_table()

    orig = rc.PointTable
    rc.PointTable = Slow
    try:
        slow = rc.fit_text(fit)
    finally:
        rc.PointTable = orig
    assert fast == slow
    assert fast.count("\n") > 3000
    assert "\u2500" in fast


def _jsonable_elementwise(value):
    """The element-by-element conversion _jsonable did before (the reference)."""
    import math
    from collections.abc import Mapping

    if isinstance(value, np.ndarray):
        if value.ndim:
            return [_jsonable_elementwise(v) for v in value.tolist()]
        return _jsonable_elementwise(value.item())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable_elementwise(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable_elementwise(v) for v in value]
    return value


def test_jsonable_converts_whole_arrays_as_elementwise():
    """JSON of fits converted every array element by a Python call (1e5 points: 3.9 s of
    the 6.5 s of 'transform estimate --json'); whole arrays now, the same values (NaN and
    infinities None; ints, bools, nested and 0-d arrays, float32, object arrays)."""
    import json

    from photogeom.adjust.fit import _jsonable

    rng = np.random.default_rng(3)
    f = rng.normal(size=(50, 3))
    f[3, 1], f[7, 0], f[9, 2] = np.nan, np.inf, -np.inf
    cases = [
        f,
        f[:, 0],
        rng.normal(size=(4, 2, 3)),
        f.astype(np.float32),
        np.arange(12).reshape(3, 4),
        np.arange(5, dtype=np.uint64) + 2**63,
        np.array([True, False]),
        np.array(2.5),
        np.array(np.nan),
        np.array(["a", "b"]),
        np.array([1, None, 2.5, np.float64(np.nan)], dtype=object),
        np.zeros((0, 3)),
        {"a": f, 1: [np.float64(np.inf), np.int64(3)], "b": (np.bool_(True), 2)},
    ]
    for value in cases:
        got, want = _jsonable(value), _jsonable_elementwise(value)
        assert json.dumps(got) == json.dumps(want)
        assert got == want or json.dumps(got) == json.dumps(want)


def test_jsonable_does_not_recurse_into_number_arrays(monkeypatch):
    import photogeom.adjust.fit as fit_module

    calls = {"n": 0}
    inner = fit_module._jsonable

    def counting(value):
        calls["n"] += 1
        return inner(value)

    monkeypatch.setattr(fit_module, "_jsonable", counting)
    values = np.random.default_rng(0).normal(size=(1000, 3))
    values[5, 1] = np.nan
    out = counting({"residuals": values, "ids": np.arange(1000)})
    assert out["residuals"][5][1] is None and len(out["residuals"]) == 1000
    assert calls["n"] <= 3


def test_fit_grids_checks_every_image_before_fitting_any(monkeypatch):
    """A point outside its image in the last of many images was found only after every image
    before it was fitted (250 images of 2000 residuals: the error of image 2 after 19 s); all
    inputs are checked first now, with the same message."""
    import photogeom.calibration.grid as grid
    from photogeom.errors import InputError, TooFewPointsError

    rng = np.random.default_rng(0)
    per_image = {k: (rng.uniform(0, 999, (200, 2)), rng.normal(0, 0.3, (200, 2))) for k in range(6)}
    fitted = []
    fit = grid._fit_grid

    def counting(*args, **kwargs):
        fitted.append(kwargs.get("image_id"))
        return fit(*args, **kwargs)

    monkeypatch.setattr(grid, "_fit_grid", counting)
    bad = dict(per_image)
    uv = bad[5][0].copy()
    uv[17] = [500.0, 999.7]
    bad[5] = (uv, bad[5][1])
    with pytest.raises(InputError, match=r"image 5: uv: 1 point\(s\) outside the 1000 x 1000"):
        grid.fit_grids(bad, (1000, 1000), 250.0, folds=0)
    few = dict(per_image)
    few[4] = (few[4][0][:3], few[4][1][:3])
    with pytest.raises(TooFewPointsError, match="image 4"):
        grid.fit_grids(few, (1000, 1000), 250.0, folds=0)
    assert fitted == []
    grids = grid.fit_grids(per_image, (1000, 1000), 250.0, folds=0)
    assert list(grids) == list(per_image) and fitted == list(per_image)


def _random_json(rng, depth: int = 0):
    kind = int(rng.integers(0, 9 if depth < 3 else 4))
    if kind == 0:
        return float(rng.normal() * 10.0 ** rng.integers(-12, 12))
    if kind == 1:
        return int(rng.integers(-(10**12), 10**12))
    if kind == 2:
        return [None, True, False, "a, b", 'q"], [x', "\u00e9\u70b9", ""][int(rng.integers(0, 7))]
    if kind == 3:
        return float(rng.integers(-5, 5))
    if kind in (4, 5):  # rows of numbers, equally long (or not), maybe empty
        n, w = int(rng.integers(0, 5)), int(rng.integers(0, 4))
        rows = [[_random_json(rng, 9) if rng.random() < 0.2 else float(rng.normal())
                 for _ in range(w + (1 if kind == 5 and rng.random() < 0.3 else 0))]
                for _ in range(n)]  # fmt: skip
        return [tuple(r) for r in rows] if rng.random() < 0.2 else rows
    if kind == 6:
        return [_random_json(rng, depth + 1) for _ in range(int(rng.integers(0, 4)))]
    keys = ["id", "residuals", "a b", "\u00fc", ""]
    return {keys[int(rng.integers(0, 5))] + str(k): _random_json(rng, depth + 1)
            for k in range(int(rng.integers(0, 4)))}  # fmt: skip


def test_json_text_equals_json_dumps():
    """--json text came from json's indenting encoder, written in Python (1e6 points: most of
    a 31 s run); number rows are encoded by the C encoder now, with the same text."""
    import json

    from photogeom.cli._common import json_text

    rng = np.random.default_rng(11)
    for _ in range(400):
        data = _random_json(rng)
        assert json_text(data) == json.dumps(data, indent=2, allow_nan=False) + "\n", data
    residuals = rng.normal(size=(1000, 3)).tolist()
    residuals[7][1] = None
    data = {"residuals": residuals, "ids": [f"P{k}" for k in range(1000)], "n": 1000}
    assert json_text(data) == json.dumps(data, indent=2, allow_nan=False) + "\n"
    for bad in ({"x": [1.0, float("nan")]}, {"x": [[float("inf")]]}, {1: [1.0]}, {"a": {1, 2}}):
        try:
            want = json.dumps(bad, indent=2, allow_nan=False) + "\n"
        except (ValueError, TypeError) as exc:
            with pytest.raises(type(exc)):
                json_text(bad)
        else:
            assert json_text(bad) == want


def test_json_text_encodes_number_rows_in_one_call(monkeypatch):
    import json

    import photogeom.cli._common as common

    indents = []
    dumps = json.dumps

    def counting(*args, **kwargs):
        indents.append(kwargs.get("indent"))
        return dumps(*args, **kwargs)

    monkeypatch.setattr(common.json, "dumps", counting)
    rows = np.random.default_rng(0).normal(size=(500, 3)).tolist()
    text = common.json_text({"residuals": rows})
    monkeypatch.setattr(common.json, "dumps", dumps)
    assert text == json.dumps({"residuals": rows}, indent=2, allow_nan=False) + "\n"
    assert indents and all(i is None for i in indents)  # never the Python encoder
    assert len(indents) <= 3


@pytest.mark.parametrize("command", ["localize", "project"])
def test_rpc_crs_builds_the_proj_operation_once(cli, tmp_path, monkeypatch, command):
    """rpc localize / project --crs built the PROJ operation again for every block of a
    streamed file (1e6 points: 3.9-4.1 s, now 3.5 s); once now, the same output."""
    import photogeom as pg
    import photogeom.crs as pcrs

    rpc_file = pg.datasets.path("quickbird")
    rng = np.random.default_rng(0)
    n = 60_000  # several blocks of 1 MiB
    pix = tmp_path / "pix.csv"
    cr = np.column_stack([rng.uniform(0, 30000, n), rng.uniform(0, 32000, n)])
    pix.write_text(
        "id,col,row\n" + "".join(f"p{k},{c!r},{r!r}\n" for k, (c, r) in enumerate(cr.tolist()))
    )
    code, _, err = cli(
        "rpc", "localize", rpc_file, pix, "--height", "100", "-o", tmp_path / "g.csv"
    )
    assert code == 0, err
    ground = tmp_path / "g.csv"
    if command == "localize":
        args = ["rpc", "localize", rpc_file, pix, "--height", "100"]
    else:  # project the UTM points back
        utm = tmp_path / "utm.csv"
        code, _, err = cli("crs", "convert", ground, "--to", "EPSG:32652", "-o", utm)
        assert code == 0, err
        args = ["rpc", "project", rpc_file, utm]
    built = []
    make = pcrs._proj_transformer

    def counting(*a, **k):
        built.append(a[:2])
        return make(*a, **k)

    monkeypatch.setattr(pcrs, "_proj_transformer", counting)
    out = tmp_path / "out.csv"
    code, _, err = cli(*args, "--crs", "EPSG:32652", "-o", out)
    assert code == 0, err
    assert len(built) == 1
    monkeypatch.setattr(pcrs, "_proj_transformer", make)
    rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")][1:]
    assert len(rows) == n
    if command == "localize":  # the default output (EPSG:4979) converted afterwards
        utm = tmp_path / "utm.csv"
        code, _, err = cli("crs", "convert", ground, "--to", "EPSG:32652", "-o", utm)
        assert code == 0, err
        ref = [ln.split(",") for ln in utm.read_text().splitlines() if not ln.startswith("#")]
        got = np.array([[float(v) for v in r[1:4]] for r in rows])
        want = np.array([[float(v) for v in r[1:4]] for r in ref[1:]])
        np.testing.assert_array_equal(got, want)
