"""`photogeom grid`: finite-element residual grids of UAV images.

``fit`` reads per-observation image residuals (CSV columns ``image_id, u, v, rx, ry``;
pixels, computed minus observed) and writes the grids file (NPZ or JSON); ``apply``
corrects the image coordinates of an observation CSV; ``correct-images`` resamples a folder
of images into another folder (in parallel, optionally on a Dask cluster).
"""

from __future__ import annotations

import csv
import io
import operator
import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .._lazy import LazyModule
from ..errors import FileFormatError, InputError, PhotogeomError
from ._common import (
    JsonOpt,
    LogProgress,
    OutputCsvOpt,
    ReportOpt,
    alpha_help,
    batch_failed,
    check_alpha,
    check_outputs,
    console,
    emit_points,
    image_sizes_option,
    json_id,
    json_text,
    options_in_errors,
    pixels,
    print_id_table,
    refuse_stdout_dash,
    say,
    scheduler_option,
    sigterm_stops,
    split_names,
    typed_option,
    unit_hint,
)

np = LazyModule("numpy")  # imported when a command needs it: quick start-up

app = typer.Typer(
    help="Finite-element residual grids: fit per image, correct coordinates and images.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


class Border(str, Enum):
    mean = "mean"
    linear = "linear"


class Interp(str, Enum):
    bilinear = "bilinear"
    bicubic = "bicubic"


class Outside(str, Enum):
    replicate = "replicate"
    constant = "constant"
    reflect = "reflect"


#: Columns of at least this many cells are converted to numbers by pyarrow (fewer: by
#: :func:`float`, without importing pyarrow, which takes longer than converting them).
ARROW_CELLS = 20_000


class _Cells:
    """The cells of a CSV file: header, field count and file line of each body row, and the
    body's columns (built once every row has the header's field count)."""

    def __init__(
        self,
        header: list[str],
        widths: np.ndarray,
        lines: np.ndarray,
        rows: list[list[str]] | None = None,
        split: tuple | None = None,
    ) -> None:
        self.header = header
        #: per column, whether each cell was quoted (set by :meth:`columns`)
        self.quoted: list = []
        #: fields of each body row (numpy int array)
        self.widths = widths
        #: file line on which each body row starts (numpy int array)
        self.lines = lines
        self._rows = rows  # the body as rows of cells (the line-wise reader)
        self._rows_quoted: dict[int, set[int]] = {}  # body row -> its quoted cells (rows)
        # the body as (cells of all lines split at once, index of each body row's first
        # cell there or -1, {body row: its cells} of the rows read by the csv module)
        self._split = split

    def columns(self) -> list[list[str]]:
        """The cells of each header field, one list per column (every row must have them
        all; called once: the cells are let go)."""
        width = len(self.header)
        self.quoted = [np.zeros(self.lines.size, dtype=bool) for _ in range(width)]
        if self._rows is not None:
            if not self._rows:
                return [[] for _ in range(width)]
            for i, q in self._rows_quoted.items():
                for j in q:
                    self.quoted[j][i] = True
            return [list(c) for c in zip(*self._rows, strict=True)]
        pieces, first, others, marks = self._split
        self._split = None
        if isinstance(pieces, list):  # no quotes: the rows are slices of the cells
            if not first.size:
                return [[] for _ in range(width)]
            lo, hi = int(first[0]), int(first[-1]) + width
            if hi - lo == width * first.size:  # no blank row among them: one block
                block = pieces[lo:hi]
                del pieces
                return [block[j::width] for j in range(width)]
            pieces = np.array(pieces, dtype=object)
        split = np.flatnonzero(first >= 0)
        at = first[split][:, None] + np.arange(width)
        table = pieces[at]  # one gather: (rows, width)
        del pieces
        if marks is not None:  # the whole quoted cells of the split lines
            for j in range(width):
                self.quoted[j][split] = marks[at[:, j]]
        if not others:
            return [table[:, j].tolist() for j in range(width)]
        out = []
        rows = np.fromiter(others, dtype=np.intp, count=len(others))
        for j, cells in enumerate(zip(*(c for c, _ in others.values()), strict=True)):
            column = np.empty(self.lines.size, dtype=object)
            column[split] = table[:, j]
            column[rows] = cells
            out.append(column.tolist())
        for i, (_, q) in others.items():
            for j in q:
                self.quoted[j][i] = True
        return out


def _read_cells(path: Path, comments: list[str] | None) -> _Cells:
    """The rows of a CSV file as Python's csv module reads them (``#`` lines taken out
    before it, blank rows skipped), split column-wise.

    All lines are split at their commas at once; a line with a quote that is not around a
    whole cell (``"a,b"``, ``"a""b"``, ``x"y``) is read by the csv module on its own. A file
    the csv module must read as a stream (a quoted cell across lines, text after a closing
    quote, a field over its size limit, text that is not UTF-8) is read by
    :func:`_read_rows_linewise`, with the same rules and messages.
    """
    from ..io.sources import device_message, input_kind

    kind = input_kind(path)
    if kind == "device":
        raise FileFormatError(device_message(path, "CSV file"))
    from ..io.sources import read_input_bytes

    try:
        raw = read_input_bytes(path, None)  # a pipe read once: _is_block may have read it
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    # a pipe can be read once: its bytes are kept for the line-wise reader; a file is opened
    # again by it (only when needed, and without holding the bytes meanwhile)
    kept = raw if kind == "pipe" else None
    try:
        text = raw.decode("utf-8-sig")  # newline="" as the csv module wants: no translation
    except UnicodeDecodeError:
        return _read_rows_linewise(path, comments, kept)
    del raw
    if "\r" in text:  # the line ends of a file read with newline="": \n, \r\n and \r
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    any_quote = '"' in text
    all_lines = text.split("\n")
    del text
    stripped = list(map(str.strip, all_lines))
    first = np.empty(len(stripped), dtype=object)  # first character: blank lines, comments
    first[:] = list(map(operator.itemgetter(slice(0, 1)), stripped))
    blank, hashed = first == "", first == "#"
    del first
    found = [stripped[k][1:].strip() for k in np.flatnonzero(hashed).tolist()]
    del stripped
    keep = np.flatnonzero(~(blank | hashed))
    data = [all_lines[k] for k in keep.tolist()]
    del all_lines
    n = len(data)
    if n and max(map(len, data)) >= csv.field_size_limit():
        return _read_rows_linewise(path, comments, kept)
    widths = np.fromiter(map(operator.methodcaller("count", ","), data), dtype=np.int64, count=n)
    widths += 1
    starts = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(widths, out=starts[1:])
    pieces: list | np.ndarray = ",".join(data).split(",")  # every line at once: linear
    others: dict[int, tuple[list[str], set[int]]] = {}  # lines read by the csv module
    marks = None  # which pieces are whole quoted cells
    if any_quote:
        pieces = np.array(pieces, dtype=object)
        quotes = np.fromiter(
            map(operator.methodcaller("count", '"'), pieces), dtype=np.int64, count=pieces.size
        )
        # a whole quoted cell: a quote at either end and none inside (its text between them)
        two = np.flatnonzero(quotes == 2)
        inner = np.empty(two.size, dtype=object)
        inner[:] = list(map(operator.itemgetter(slice(1, -1)), pieces[two]))
        whole = np.fromiter(
            map(operator.methodcaller("count", '"'), inner), dtype=np.int64, count=two.size
        )
        pieces[two[whole == 0]] = inner[whole == 0]
        marks = np.zeros(pieces.size, dtype=bool)
        marks[two[whole == 0]] = True
        simple = quotes == 0
        simple[two[whole == 0]] = True
        other = np.flatnonzero(~np.logical_and.reduceat(simple, starts[:-1]))
        if other.size:
            try:  # strict: a quote left open or text after a closing one is read line-wise
                parsed = list(csv.reader([data[k] for k in other.tolist()], strict=True))
            except csv.Error:
                return _read_rows_linewise(path, comments, kept)
            if len(parsed) != other.size:  # a quoted cell spans lines
                return _read_rows_linewise(path, comments, kept)
            others = {
                k: (r, _quoted_fields(data[k])) for k, r in zip(other.tolist(), parsed, strict=True)
            }
            widths[other] = np.fromiter(map(len, parsed), dtype=np.int64, count=other.size)
    del data
    # rows whose cells are all blank are skipped, as blank lines are: only a row whose first
    # cell is blank (or that the csv module read) is looked at
    firsts = map(pieces.__getitem__, starts[:-1].tolist())
    first_blank = np.fromiter(map(operator.not_, map(str.strip, firsts)), dtype=bool, count=n)
    is_other = np.zeros(n, dtype=bool)
    is_other[list(others)] = True
    empty = np.zeros(n, dtype=bool)
    for k in np.flatnonzero(first_blank | is_other).tolist():
        cells = others[k][0] if k in others else pieces[starts[k] : starts[k + 1]]
        empty[k] = not "".join(list(cells)).strip()
    rows = np.flatnonzero(~empty)
    if comments is not None:
        comments.extend(found)
    if not rows.size:
        raise FileFormatError(f"{path}: empty file")
    top = int(rows[0])
    header = others[top][0] if top in others else list(pieces[starts[top] : starts[top + 1]])
    body = rows[1:]
    first_cell = starts[body]
    in_body = np.flatnonzero(is_other[body])  # body rows read by the csv module
    first_cell[in_body] = -1
    return _Cells(
        [c.strip() for c in header],
        widths[body],
        keep[body] + 1,
        split=(pieces, first_cell, {i: others[int(body[i])] for i in in_body.tolist()}, marks),
    )


def _quoted_fields(record: str) -> set[int]:
    """Which cells of a CSV record (a line, or the lines of a record with a quoted line
    break) are quoted: those whose first character is a quote, as the csv module reads
    them; the record is one the csv module has read."""
    out: set[int] = set()
    pos, k, n = 0, 0, len(record)
    try:
        while True:
            if pos < n and record[pos] == '"':
                out.add(k)
                pos += 1
                while True:  # to the closing quote (a doubled quote is one inside)
                    q = record.index('"', pos)
                    if record[q + 1 : q + 2] != '"':
                        pos = q + 1
                        break
                    pos = q + 2
            c = record.find(",", pos)
            if c < 0:
                return out
            pos, k = c + 1, k + 1
    except ValueError:  # a quote left open: the csv module's reading stands, unmarked
        return out


def _read_rows_linewise(path: Path, comments: list[str] | None, data: bytes | None) -> _Cells:
    """:func:`_read_cells` for the files it does not split itself: the csv module over the
    whole file, line by line (quoted line breaks counted in the line numbers); ``data``: the
    bytes of a pipe already read (a pipe cannot be opened again), else the file is opened."""
    rows, lines = [], []
    physical: list[int] = []  # file line of each line handed to the csv reader
    raw: list[str] = []  # and its text
    quoted: list[set[int]] = []  # the quoted cells of each row

    def data_lines(fh):
        for number, line in enumerate(fh, start=1):
            if line.lstrip().startswith("#"):
                if comments is not None:
                    comments.append(line.strip()[1:].strip())
                continue
            physical.append(number)
            raw.append(line)
            yield line

    start = 0  # the csv reader's count of lines before the row being read
    try:
        if data is None:
            fh = open(path, newline="", encoding="utf-8-sig")
        else:
            fh = io.TextIOWrapper(io.BytesIO(data), newline="", encoding="utf-8-sig")
        with fh:
            reader = csv.reader(data_lines(fh))
            for r in reader:
                if r and any(c.strip() for c in r):
                    rows.append(r)
                    lines.append(physical[start])
                    text = "".join(raw[start : reader.line_num]) if '"' in raw[start] else ""
                    quoted.append(_quoted_fields(text) if '"' in text else set())
                start = reader.line_num
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a UTF-8 CSV file ({exc})") from None
    except csv.Error as exc:  # a field over the csv module's limit, e.g. an unclosed quote
        raise FileFormatError(
            f"{path}, line {physical[min(start, len(physical) - 1)] if physical else 1}: "
            "cannot split the line into "
            f'fields ({exc}); an id or a number is a few characters: a quote (") left '
            "open, or not a CSV file?"
        ) from None
    if not rows:
        raise FileFormatError(f"{path}: empty file")
    body = rows[1:]
    cells = _Cells(
        [c.strip() for c in rows[0]],
        np.fromiter(map(len, body), dtype=np.int64, count=len(body)),
        np.asarray(lines[1:], dtype=np.int64),
        rows=body,
    )
    cells._rows_quoted = {i: q for i, q in enumerate(quoted[1:]) if q}
    return cells


#: Separators of other CSV dialects, named in the message of a header that holds one.
_OTHER_SEPARATORS = ((";", "semicolons"), ("\t", "tabs"), (" ", "spaces"))


def _listing(names: list[str], most: int = 20) -> str:
    """Column names for a message: at most ``most``, then the count of the others; each
    shown as Python shows text (a tab or a NUL visible)."""
    shown = ", ".join(repr(n)[1:-1][:40] for n in names[:most])
    return shown + (f", ... ({len(names) - most} more)" if len(names) > most else "")


def _read_csv(
    path: Path,
    need: tuple[str, ...],
    comments: list[str] | None = None,
    quoted: list | None = None,
) -> tuple[list[str], list, dict, np.ndarray]:
    """Header, columns (one object array of str per header field), the column index of each
    needed column (case-insensitive) and the file line on which each row starts (blank lines
    skipped, quoted line breaks counted).

    Lines that begin with ``#`` are comments, as in every point file of photogeom (the
    observations.csv of a block folder starts with one); their text is appended to
    ``comments`` when a list is given. ``quoted``, when a list is given, receives one
    boolean array per column: which of its cells were quoted (a quoted cell is its text
    exactly, as in a block folder: see :func:`_ids`). Reading is linear in the file size:
    see :func:`_read_cells`."""
    cells = _read_cells(path, comments)
    header = cells.header
    low = [c.lower() for c in header]
    col = {}
    for name in need:
        aliases = {"image_id": ("image_id", "image", "id")}.get(name, (name,))
        hit = next((low.index(a) for a in aliases if a in low), None)
        if hit is None:
            other = next((w for c, w in _OTHER_SEPARATORS if len(header) == 1 and c in
                          header[0]), None)  # fmt: skip
            if len(header) == 1 and _looks_like_bal(header[0]):
                raise FileFormatError(
                    f"{path}: its first line holds three integers ({header[0].strip()}), "
                    "the header of a BAL file (cameras, points, observations), not a CSV "
                    f"with the columns {', '.join(need)}; a BAL file is a block for 'grid "
                    "fit BLOCK', not an input here: give the CSV"
                )
            raise FileFormatError(
                f"{path}: no column {name!r} (columns: {_listing(header)}); "
                f"the file needs {', '.join(need)}"
                + (
                    f"; its header is separated by {other}: photogeom reads this file "
                    "comma-separated (replace the separators with commas)"
                    if other
                    else ""
                )
            )
        col[name] = hit
    bad = np.flatnonzero(cells.widths != len(header))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(
            f"{path}: line {cells.lines[k]} has {cells.widths[k]} fields, the header {len(header)}"
        )
    columns = cells.columns()
    if quoted is not None:
        quoted.extend(cells.quoted)
    return header, columns, col, cells.lines


def _ids(cells: list[str], quoted: np.ndarray) -> list[str]:
    """Image ids of a CSV column by the rules of a block folder: a quoted cell is its text
    exactly (white space at its ends kept), an unquoted one is stripped of white space."""
    if not np.any(quoted):
        return list(map(str.strip, cells))
    out = np.array(cells, dtype=object)
    plain = np.flatnonzero(~quoted)
    out[plain] = list(map(str.strip, out[plain].tolist()))
    return out.tolist()


def _refuse_empty_ids(path: Path, ids: list[str], lines: np.ndarray) -> None:
    """Refuse rows whose image_id cell is empty (or white space only, or ``""``): they would
    make an image named by the empty text, a grid no image of a block folder can have."""
    empty = np.flatnonzero(np.fromiter(map(len, ids), dtype=np.intp, count=len(ids)) == 0)
    if empty.size:
        shown = ", ".join(str(int(x)) for x in np.asarray(lines)[empty[:10]])
        more = f" ({empty.size} rows in all)" if empty.size > 10 else ""
        raise FileFormatError(
            f"{path}: empty image_id on line(s) {shown}{more}; give each row the id of its "
            "image, or remove those rows"
        )


def _numbers(path: Path, cells, name: str, lines: np.ndarray) -> np.ndarray:
    """The cells of one column as finite numbers; a FileFormatError names the file line of
    the first cell that is not one (NaN and infinities included).

    A number is a decimal number (:func:`photogeom.numbers.is_decimal_number`, the rule of
    every reader of photogeom): :func:`float`'s ``3_500.5`` and non-ASCII digits are not."""
    from ..numbers import is_decimal_number

    values = _arrow_floats(cells) if len(cells) >= ARROW_CELLS else None
    if values is not None:
        return values
    joined = "".join(cells)  # "_" or a non-ASCII character: a cell to look at one by one
    try:
        if "_" in joined or not joined.isascii():
            raise ValueError
        values = np.fromiter(map(float, cells), dtype=np.float64, count=len(cells))
    except ValueError:
        for k, c in enumerate(cells):
            if not is_decimal_number(c):
                raise FileFormatError(
                    f"{path}: line {lines[k]}, column {name}: not a number ({c!r})"
                ) from None
        values = np.fromiter(map(float, cells), dtype=np.float64, count=len(cells))
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(
            f"{path}: line {lines[k]}, column {name}: {cells[k]!r} is not a finite number "
            f"({bad.size} row(s) in all); remove those rows or give their values"
        )
    return values


def _arrow_floats(cells: list[str]) -> np.ndarray | None:
    """The cells as float64 by pyarrow's conversion (compiled, correctly rounded, as
    :func:`float`), or None unless it reads every cell as a finite number.

    pyarrow reads a subset of what :func:`float` reads (no ``_``, no non-ASCII digits, blanks
    only at the ends trimmed here) and, of finite numbers, the same values; it also reads
    ``nan(...)``, which :func:`float` refuses: a column with a NaN or an infinity is left to
    :func:`float`, whose messages name the cell."""
    import pyarrow as pa
    import pyarrow.compute as pc

    try:
        text = pc.utf8_trim(pa.array(cells, type=pa.string()), " \t")
        values = pc.cast(text, pa.float64()).to_numpy(zero_copy_only=False)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError):
        return None
    return values if np.isfinite(values).all() else None


def _refuse_outside(
    path: Path,
    ids: list[str],
    uv: np.ndarray,
    lines: np.ndarray,
    width: np.ndarray,
    height: np.ndarray,
    fix: str,
) -> None:
    """Refuse rows whose ``u, v`` (px) lie outside their image, ``[-0.5, width - 0.5] x
    [-0.5, height - 0.5]`` (the area of a grid), naming the file line of the first; the
    library names a row counted within one image, which the file does not show.

    Parameters
    ----------
    path : Path
        The CSV file (for the message).
    ids, uv, lines : list of str, numpy.ndarray (n, 2), numpy.ndarray (n,)
        Image id, pixel coordinates and file line of each row.
    width, height : numpy.ndarray (n,)
        Size in pixels of each row's image.
    fix : str
        What to do, in the words of the command.
    """
    out = (
        (uv[:, 0] < -0.5) | (uv[:, 0] > width - 0.5) | (uv[:, 1] < -0.5) | (uv[:, 1] > height - 0.5)
    )
    if not out.any():
        return
    k = int(np.flatnonzero(out)[0])
    raise InputError(
        f"{path}: line {lines[k]}, image {ids[k]}: u, v = ({uv[k, 0]:g}, {uv[k, 1]:g}) px "
        f"lie outside the {width[k]:.0f} x {height[k]:.0f} px image ({int(out.sum())} row(s) "
        f"in all); {fix}"
    )


def _groups(ids: list[str]) -> dict:
    """Row indices of each image id (numpy int arrays): ids in the order of their first row,
    rows in file order (a stable sort of the ids' codes, linear in the rows)."""
    if not ids:
        return {}
    order = list(dict.fromkeys(ids))
    code = dict(zip(order, range(len(order)), strict=True))
    inverse = np.fromiter(map(code.__getitem__, ids), dtype=np.intp, count=len(ids))
    rows = np.argsort(inverse, kind="stable")
    cuts = np.cumsum(np.bincount(inverse, minlength=len(order)))[:-1]
    return dict(zip(order, np.split(rows, cuts), strict=True))


@app.command("fit")
@options_in_errors(alpha="--alpha", border="--border")
def fit(
    residuals: Annotated[
        Path,
        typer.Argument(
            help="CSV with image_id, u, v, rx, ry (px; residuals computed minus observed) "
            "and optionally sigma (px), "
            "or an adjusted block (a CSV block folder or COLMAP text or binary model, a BAL "
            "file: .bal, .bz2 or any name or pipe by its content, a Bundler file: .out, its "
            "image list beside it): "
            "the reprojection residuals of its tie points, the image sizes of its cameras."
        ),
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Grids file: .npz, or JSON for any other suffix.")
    ],
    image_size: Annotated[
        str | None,
        typer.Option(
            "--image-size",
            help="Image size WIDTHxHEIGHT in pixels (all images) of a residuals CSV, a BAL "
            "file (BAL holds none) or a Bundler file (default: read from the images its "
            "list names), or SIZES.csv of image_id,width,height rows (images of several "
            "sizes).",
        ),
    ] = None,
    spacing: Annotated[
        float, typer.Option(help="Node spacing in pixels.", parser=pixels("--spacing"))
    ] = 100.0,
    sigma_obs: Annotated[
        float | None,
        typer.Option(
            "--sigma-obs",
            "--sigma",
            help="Standard deviation of the residuals (px); default: the sigma column of a "
            "residuals CSV (px; 1 px without one), each observation's sigma for a block. "
            "--sigma is the same option (the name of bundle adjust).",
            parser=pixels("--sigma-obs"),
        ),
    ] = None,
    sigma_constraint: Annotated[
        str | None,
        typer.Option(
            help="Standard deviation of the smoothness pseudo-observations: px, 'scaled' "
            "(0.1 px x (spacing / 100 px)^2) or 'vce' (estimate both variances); default: "
            "1 px for a residuals CSV, 'scaled' for a block (as 'grid evaluate' and "
            "'grid sweep')."
        ),
    ] = None,
    border: Annotated[
        Border,
        typer.Option(
            help="Constraint of border nodes: mean of the neighbours they have, "
            "or linear along the edge."
        ),
    ] = Border.mean,
    folds: Annotated[int, typer.Option(help="k-fold cross-validation, k >= 2 (0: none).")] = 5,
    snooping: Annotated[
        bool,
        typer.Option("--snooping/--no-snooping", help="Reject outliers by data snooping (w-test)."),
    ] = False,
    alpha: Annotated[
        float | None,
        typer.Option(
            help=alpha_help(
                "point's w-test of --snooping",
                uses="--snooping rejects at it, --json and --report list what it rejected; "
                "refused without --snooping",
            ),
            show_default=False,
        ),
    ] = None,
    max_snooping_rounds: Annotated[
        int,
        typer.Option(
            min=0,
            help="Most refits of data snooping per image; points still flagged after them "
            "are named.",
        ),
    ] = 10,
    min_support: Annotated[
        int, typer.Option(help="Observations in a node's cells for it to count as supported.")
    ] = 3,
    std: Annotated[
        bool, typer.Option("--std/--no-std", help="Compute and store node standard deviations.")
    ] = True,
    exclude: Annotated[
        str | None,
        typer.Option(
            help="Image ids to leave out, comma-separated (e.g. images with too few "
            'residuals for the spacing); they get no grid. Quote an id with white space at '
            "its ends or a comma, as in the CSV: '\" im0 \",IMG_7'."
        ),
    ] = None,
    report: ReportOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Fit one residual grid per image and write the grids file."""
    from ._stream import single_threaded_blas

    # many small systems and the block recurrence of the node standard deviations: BLAS
    # threads only wait on each other (12 images of 42 Mpx at 100 px: 10.4 s with, 3.0 s
    # without them on 2 cores)
    single_threaded_blas()
    from ..atomicfile import atomic_write_many
    from ..calibration.gridfile import grids_file_bytes

    # both outputs checked before the fit and written together: all or none; neither may
    # replace the residuals CSV
    inputs = {"RESIDUALS": residuals}
    if residuals.is_dir():  # a block folder: its files are inputs
        inputs = {f"RESIDUALS ({f.name} of the block)": f for f in residuals.iterdir()
                  if f.name in _BLOCK_FILES}  # fmt: skip
    check_outputs(inputs, output=output, report=report)
    # a level is refused where no test runs, not silently ignored (as bundle adjust)
    alpha = check_alpha(
        alpha, off=None if snooping else "is off without --snooping: add --snooping or leave "
        "--alpha out",
    )  # fmt: skip

    if folds < 0 or folds == 1:  # the library reads both as "no cross-validation"
        raise InputError(
            f"--folds {folds}: give the number of cross-validation folds, 2 or more, or 0 "
            "for no cross-validation"
        )
    s_c = _fit_sigma_constraint(sigma_constraint)
    options = dict(
        border=border.value, folds=folds, snooping=snooping, alpha=alpha, min_support=min_support,
        max_snooping_rounds=max_snooping_rounds,
    )  # fmt: skip
    left_out = list(dict.fromkeys(_exclude_ids(exclude)))  # an id given twice: once
    if not residuals.exists():
        raise FileFormatError(
            f"{residuals}: no such file or folder (give a residuals CSV or an adjusted block)"
        )
    where: dict = {}  # image id -> (kind, label of every input row)
    if _is_block(residuals):
        grids = _fit_block(
            residuals, image_size, spacing, sigma_obs, s_c, options, left_out, where
        )
    else:
        grids = _fit_csv(residuals, image_size, spacing, sigma_obs, s_c, options, left_out, where)
    if std:  # a selected inversion per image, 15 s for 250 images at 100 px: counted
        _node_cofactors(grids)
    outputs = [(output, grids_file_bytes(output, grids, std=std))]
    # keyed by text (JSON keys are text); "image_id" keeps the id's type (an int stays one)
    stats = {str(k): {"image_id": json_id(k), **g.to_dict()} for k, g in grids.items()}
    rejected = _rejected(grids, where, alpha, max_snooping_rounds) if snooping else None
    if report is not None:
        outputs.append((report, _report_html(grids, rejected).encode("utf-8")))
    atomic_write_many(outputs)
    if as_json:
        doc = {
            "output": str(output),
            # as the table's title says, and the grids file's "convention"
            "residual_convention": "computed minus observed",
            "units": {
                **dict.fromkeys(
                    ("width", "height", "spacing", "sigma_constraint", "sigma_obs_rms",
                     "rms_before", "rms_after", "rms_cv_before", "rms_cv_after"),
                    "px",
                ),
                **dict.fromkeys(("sigma0", "reduction", "reduction_cv"), "1"),
            },
            "spacing": spacing,
            "images": stats,
        }
        if rejected is not None:
            doc["snooping"] = rejected
        typer.echo(json_text(doc), nl=False)
        return
    from rich.table import Table

    t = Table(title=f"Residual grids, {spacing:g} px (residuals computed minus observed, px)")
    for c in (
        "image",
        "n",
        "outliers",
        "nodes",
        "supported",
        "sigma0",
        "RMS before",
        "RMS after",
        "reduction",
        "CV reduction",
    ):
        t.add_column(c, justify="right")
    for k, s in stats.items():
        t.add_row(*_grid_row(k, s))
    out = console()
    print_id_table(out, t)
    if rejected is not None:
        say(_snooping_heading(rejected), out)
        if rejected["still_flagged"]:
            kind = rejected["located_by"]
            shown = ", ".join(
                f"image {r['image']} {kind} {r[kind]}" for r in rejected["still_flagged"][:10]
            )
            more = len(rejected["still_flagged"]) - 10
            say(
                f"warning: {len(rejected['still_flagged'])} point(s) still fail the w-test "
                f"after {rejected['max_rounds']} rounds and stay in the grids: {shown}"
                + (f" and {more} more" if more > 0 else "")
                + "; give a larger --max-snooping-rounds",
                out,
            )
        if rejected["rejected"]:
            r = Table(title="Rejected by data snooping (largest |w| first)")
            for c in ("image", rejected["located_by"], "|w|"):
                r.add_column(c, justify="right")
            for row in rejected["rejected"][:_SHOWN_REJECTED]:
                r.add_row(str(row["image"]), str(row[rejected["located_by"]]), f"{row['w']:.2f}")
            print_id_table(out, r)
            more = len(rejected["rejected"]) - _SHOWN_REJECTED
            if more > 0:
                say(f"... and {more} more (all in --json)", out)
    say(f"wrote {len(stats)} grid(s) to {output}", out)
    if report is not None:
        say(f"wrote {report}", out)


#: Rejected points listed in the printed table (all in --json and the report).
_SHOWN_REJECTED = 50


def _rejected(grids: dict, where: dict, alpha: float, max_rounds: int) -> dict:
    """The data-snooping summary of ``grid fit``: the test, alpha, the critical value,
    every rejected point (image id, its CSV line or point id, |w| at rejection), largest
    |w| first, and the points still flagged after ``max_rounds`` rounds."""
    from ..adjust.snooping import w_critical_value

    kind = "line"
    rows = []
    for k, g in grids.items():
        sn = g.snooping
        if sn is None or k not in where:
            continue
        kind, labels = where[k]
        idx = np.flatnonzero(g.outliers)
        for i, w in zip(idx.tolist(), np.asarray(sn["w"])[idx].tolist()):  # rejected only
            label = labels[i]
            rows.append({"image": k, kind: label.item() if hasattr(label, "item") else label,
                         "w": float(w)})  # fmt: skip
    rows.sort(key=lambda r: -r["w"])
    still = []
    for k, g in grids.items():
        if g.snooping is None or k not in where:
            continue
        labels = where[k][1]
        for i in np.flatnonzero(g.snooping["still_flagged"]).tolist():  # flagged only
            label = labels[i]
            still.append({"image": k, kind: label.item() if hasattr(label, "item") else label})
    return {
        "test": "w",
        "alpha": float(alpha),
        "critical_value": w_critical_value(alpha),
        "located_by": kind,
        "rejected": rows,
        "max_rounds": int(max_rounds),
        "still_flagged": still,
    }


def _snooping_heading(rejected: dict) -> str:
    """One line naming the test, alpha, the critical value and the count rejected."""
    return (
        f"data snooping: Baarda's w-test per component (the larger |w| of rx, ry), alpha "
        f"{rejected['alpha']:g}, critical value {rejected['critical_value']:.2f}: "
        f"{len(rejected['rejected'])} point(s) rejected"
    )


#: Suffixes of a BAL or Bundler file, the block formats stored in a single file
_BLOCK_SUFFIXES = (".bal", ".bz2", ".out")


#: Files of a CSV block folder and of a COLMAP text or binary model (inputs of ``grid fit
#: BLOCK``).
_BLOCK_FILES = frozenset(
    ("cameras.csv", "images.csv", "points.csv", "observations.csv", "cameras.txt",
     "images.txt", "points3D.txt", "cameras.bin", "images.bin", "points3D.bin")
)  # fmt: skip


def _is_block(path: Path) -> bool:
    """Whether ``grid fit``'s input is an adjusted block (a folder, a BAL or Bundler file)
    rather than a residuals CSV: a folder, a name ending in .bal, .bz2 or .out, or a regular
    file or a pipe whose content is BAL (bzip2-compressed, or a first line of three integers:
    cameras, points, observations) or Bundler (a first line ``# Bundle file``). A pipe is
    read once, whole, and its bytes kept (:func:`photogeom.io.sources.pipe_bytes`) for the
    block or CSV reader."""
    if path.is_dir() or path.suffix.lower() in _BLOCK_SUFFIXES:
        return True
    from ..io.sources import input_kind, pipe_bytes

    kind = input_kind(path)
    try:
        if kind == "pipe":  # read once, whole (as the CSV reader would), kept for the reader
            head = pipe_bytes(path, None)[:4096]
        elif kind == "file":
            with open(path, "rb") as fh:
                head = fh.read(4096)
        else:
            return False
    except OSError:
        return False  # the CSV reader names the problem
    return (
        head.startswith(b"BZh")
        or head.lstrip(b"\xef\xbb\xbf").startswith(b"# Bundle file")
        or _looks_like_bal(head.decode("latin-1"))
    )


def _looks_like_bal(text: str) -> bool:
    """Whether the first non-blank line of ``text`` holds three integers and nothing else,
    as the header of a BAL file (cameras, points, observations)."""
    for line in text.splitlines():
        if line.strip():
            return bool(_BAL_HEADER.fullmatch(line.strip()))
    return False


#: The first line of a BAL file: three non-negative integers separated by blanks.
_BAL_HEADER = re.compile(r"\d+[ \t]+\d+[ \t]+\d+")


def _fit_sigma_constraint(text: str | None) -> float | str | None:
    """The --sigma-constraint of ``grid fit``: None (the input's default), a positive number
    of px, ``"scaled"`` or ``"vce"``."""
    if text is None:
        return None
    t = text.strip().lower()
    if t in ("vce", "scaled"):
        return t
    try:
        return float(t)
    except ValueError:
        raise InputError(
            f"--sigma-constraint: a number (px), 'scaled' or 'vce', not {text!r}"
            + unit_hint(text, "--sigma-constraint")
        ) from None


def _fit_block(
    path: Path,
    image_size: str | None,
    spacing: float,
    sigma_obs: float | None,
    sigma_constraint: float | str | None,
    options: dict,
    exclude: list[str],
    where: dict | None = None,
) -> dict:
    """The grids of an adjusted block's tie-point residuals (``fit_residual_grids``, the
    fit of ``grid evaluate``), each image's size from its camera; the images of
    ``exclude`` (ids as text, --exclude) left out. ``where`` receives, per image, ``("point",
    the point id of each of its rows)``."""

    from ..calibration import fit_residual_grids
    from .grid_block import read_sized_block

    # BAL without --image-size: a warning
    block, _ = read_sized_block(
        path, image_size, takes_size="a residuals CSV, a BAL or a Bundler file"
    )
    seen = np.unique(block.obs_image)
    if seen.size == 1:  # its tie points in one image only: no adjustment of this block
        raise InputError(
            f"{path}: the block has one image with observations ({block.image_ids[seen[0]]}): "
            "a block of one image cannot have been adjusted (a bundle adjustment needs two "
            "images that observe the same points), so its residuals are not those of an "
            "adjustment; give the adjusted block the image belongs to (--exclude leaves "
            "images out), or the image's residuals as a CSV (image_id,u,v,rx,ry)"
        )
    from .grid_block import warn_if_unadjusted

    warn_if_unadjusted(block, path)
    ids = block.image_ids.tolist()
    _refuse_unknown(exclude, [str(k) for k in ids], path)
    left_out = set(exclude)
    keep = [k for k in ids if str(k) not in left_out]
    if where is not None:  # the rows of each image as block_residuals orders them
        tie = np.flatnonzero(block.role[block.obs_point] == "tie")
        tie = tie[np.argsort(block.obs_image[tie], kind="stable")]
        cuts = np.cumsum(np.bincount(block.obs_image[tie], minlength=block.n_images))[:-1]
        pids = block.observations.point_ids
        where.update(
            {k: ("point", pids[r]) for k, r in zip(ids, np.split(tie, cuts), strict=True)}
        )
    try:
        with _images_progress(f"fitting grids of {spacing:g} px") as progress:
            return fit_residual_grids(
                block,
                spacing,
                images=keep,
                sigma_obs="block" if sigma_obs is None else sigma_obs,
                sigma_constraint="scaled" if sigma_constraint is None else sigma_constraint,
                progress=progress,
                **options,
            )
    except PhotogeomError as exc:
        raise _reworded(exc, _cli_words) from None


@contextmanager
def _images_progress(what: str) -> Iterator[bool | Callable[[int, int], None]]:
    """The ``progress`` argument of the grid fits: a bar on a terminal, else lines
    ``WHAT: N of M images`` in pipes and logs (:class:`LogProgress`)."""
    if console(stderr=True).is_terminal:
        yield True
        return
    with LogProgress(what) as log:

        def counted(done: int, total: int) -> None:
            log.update(f"{what}: {done} of {total} images")

        yield counted


def _node_cofactors(grids: dict) -> None:
    """Compute (and keep in each grid) the node cofactors that the grids file's standard
    deviations are made of, one image after another with the progress of the fit."""
    from ..calibration.grid import progress_over

    with _images_progress("node standard deviations") as progress:
        for g in progress_over(list(grids.values()), progress):  # images, not points
            g.node_cofactor  # noqa: B018 - computed on first use and kept


def _fit_csv(
    path: Path,
    image_size: str | None,
    spacing: float,
    sigma_obs: float | None,
    sigma_constraint: float | str | None,
    options: dict,
    exclude: list[str],
    where: dict | None = None,
) -> dict:
    """The grids of a residuals CSV (image_id, u, v, rx, ry, and optionally sigma: each
    residual's standard deviation in px, as in a block's observations.csv) of images of one
    size (--image-size WIDTHxHEIGHT) or each of its own (--image-size SIZES.csv); the images
    of ``exclude`` (--exclude) left out. Without --sigma-obs a sigma column weighs each
    residual, as the observations' sigmas do for a block (before, it was ignored and every
    residual had 1 px). ``where`` receives, per image, ``("line", the CSV line of each of
    its rows)``."""
    from ..calibration import GridLayout, fit_grids
    from ..calibration.grid import scaled_constraint_sigma

    if image_size is None:
        raise InputError(
            f"{path}: a residuals CSV needs the images' size: give --image-size "
            "WIDTHxHEIGHT (pixels), or SIZES.csv of image_id,width,height rows for images of "
            "several sizes"
        )
    size = image_sizes_option(image_size)
    s_c = 1.0 if sigma_constraint is None else sigma_constraint
    quoted: list = []
    _h, columns, col, lines = _read_csv(path, ("image_id", "u", "v", "rx", "ry"), None, quoted)
    if not lines.size:
        raise FileFormatError(
            f"no residuals in {path}: the file has a header and no rows; it needs one "
            "row per observation (image_id, u, v, rx, ry)"
        )
    ids = _ids(columns[col["image_id"]], quoted[col["image_id"]])
    _refuse_empty_ids(path, ids, lines)
    data = np.stack(
        [_numbers(path, columns[col[c]], c, lines) for c in ("u", "v", "rx", "ry")],
        axis=1,
    )
    sigma = None
    at = [i for i, c in enumerate(_h) if c.strip().lower() == "sigma"]
    if at and sigma_obs is None:
        sigma = _numbers(path, columns[at[0]], "sigma", lines)
        bad = np.flatnonzero(~(sigma > 0))
        if bad.size:
            raise FileFormatError(
                f"{path}: line {int(lines[bad[0]])}, column sigma: {sigma[bad[0]]:g} is not a "
                "positive number of pixels; give each residual's standard deviation (px), or "
                "--sigma-obs for all of them"
            )
    groups = _groups(ids)
    if isinstance(size, dict):  # --image-size SIZES.csv: each image its own size
        none = [k for k in groups if k not in size and k not in exclude]
        if none:
            raise InputError(
                f"--image-size {image_size} gives no size for image {none[0]!r} of {path} "
                f"({len(none)} image(s) without one); add a row image_id,width,height for "
                "each, or --exclude them"
            )
        size = {k: size[k] for k in groups if k in size}
        row_size = np.zeros((len(ids), 2))
        for k, r in groups.items():
            row_size[r] = size.get(k, (np.inf, np.inf))
        fix = "give each image's size in the CSV of --image-size, or remove those rows"
    else:
        row_size = np.tile(np.asarray(size, dtype=float), (len(ids), 1))
        fix = (
            "give the images' size with --image-size WIDTHxHEIGHT (or SIZES.csv of "
            "image_id,width,height rows for images of several sizes), or remove those rows"
        )
    try:  # the image size and the spacing are refused first, as fit_grids does
        for w, h in dict.fromkeys(size.values()) if isinstance(size, dict) else [size]:
            GridLayout(w, h, spacing)
    except PhotogeomError as exc:
        raise _reworded(exc, _cli_words) from None
    _refuse_outside(path, ids, data[:, :2], lines, row_size[:, 0], row_size[:, 1], fix)
    _refuse_unknown(exclude, list(groups), path)
    for k in exclude:
        del groups[k]
    if isinstance(size, dict):
        size = {k: size[k] for k in groups}
    per_image = {k: (data[r, :2], data[r, 2:]) for k, r in groups.items()}
    if where is not None:
        where.update({k: ("line", np.asarray(lines)[r]) for k, r in groups.items()})
    if sigma is not None:  # each residual its own sigma, as a block's observations
        weights = {k: sigma[r] for k, r in groups.items()}
    else:
        weights = 1.0 if sigma_obs is None else sigma_obs
    try:
        with _images_progress(f"fitting grids of {spacing:g} px") as progress:
            return fit_grids(
                per_image,
                size,
                spacing,
                sigma_obs=weights,
                sigma_constraint=scaled_constraint_sigma(s_c, spacing),
                progress=progress,
                **options,
            )
    except PhotogeomError as exc:  # every error (ConvergenceError of vce too) in CLI words
        raise _reworded(exc, _cli_words) from None


def _exclude_ids(text: str | None) -> list[str]:
    """The image ids of --exclude: comma-separated as a CSV line, a quoted id exactly
    (``" im0 ",IMG_7``: white space at the ends, commas kept), others stripped; without a
    quote, semicolons separate too (as in the other name lists)."""
    if text is None:
        return []
    if '"' not in text:
        return split_names(text) or []
    try:
        cells = next(csv.reader([text], strict=True), [])
    except csv.Error:
        raise InputError(
            f"--exclude {text!r}: a quote is not closed, or text follows a closing quote; "
            'quote an id whole, inner quotes doubled (" im0 ",IMG_7)'
        ) from None
    quoted = _quoted_fields(text)
    ids = [c if k in quoted else c.strip() for k, c in enumerate(cells)]
    return [c for k, c in enumerate(ids) if c or k in quoted]


def _id_text(image_id: str) -> str:
    """An id as --exclude takes it: quoted when white space at its ends, a comma, a quote
    or a semicolon would change it."""
    if image_id != image_id.strip() or any(ch in image_id for ch in ',";') or not image_id:
        return '"' + image_id.replace('"', '""') + '"'
    return image_id


def _refuse_unknown(exclude: list[str], ids: list[str], path: Path) -> None:
    """Refuse --exclude ids that name no image of the input (a typo would fit them)."""
    known = set(ids)
    unknown = [k for k in exclude if k not in known]
    if unknown:
        raise InputError(
            f"--exclude: no image {', '.join(map(_id_text, unknown[:5]))} in {path} (its "
            f"images: {', '.join(map(_id_text, ids[:10]))}{' ...' if len(ids) > 10 else ''}; "
            'quote ids with white space at the ends or a comma: --exclude \'" im0 ",IMG_7\')'
        )
    if ids and known <= set(exclude):
        raise InputError(f"--exclude leaves no image of {path} to fit")


def _cli_words(msg: str) -> str:
    return (
        msg.replace("sigma_constraint", "--sigma-constraint")
        .replace("image width must be", "--image-size: the width must be")
        .replace("image height must be", "--image-size: the height must be")
        .replace("sigma_obs", typed_option("--sigma-obs", "--sigma"))
        .replace("min_observations", "observations")
        .replace("min_support", "--min-support")
        .replace("grid spacing", "--spacing")
        .replace("a larger spacing", "a larger --spacing")
        .replace("choose a spacing", "choose a --spacing")
        .replace("a larger alpha", "a larger --alpha")
        .replace("leave the image out", "leave the image out with --exclude ID")
    )


def _reworded(exc: PhotogeomError, words) -> PhotogeomError:
    """The same error (its class kept) with its message passed through ``words``."""
    exc.args = (words(str(exc)),)
    return exc


def _f(x) -> str:
    return "-" if x is None else f"{x:.4f}"


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def _grid_row(image_id, s: dict) -> list[str]:
    """One image's row of ``grid fit``'s table (printed and in the report) from
    :meth:`ResidualGrid.to_dict`: id, observations, outliers, nodes, supported nodes,
    sigma0, RMS before and after (px), reductions (per cent)."""
    return [
        str(image_id),
        str(s["n_observations"]),
        str(s["n_outliers"]),
        f"{s['shape'][0]}x{s['shape'][1]}",
        str(s["supported_nodes"]),
        _f(s["sigma0"]),
        _f(s["rms_before"]),
        _f(s["rms_after"]),
        _pct(s["reduction"]),
        _pct(s["reduction_cv"]),
    ]


def _report_html(grids: dict, rejected: dict | None = None) -> str:
    """The HTML report of ``grid fit``: the per-image table with the numbers and rounding of
    the printed table (RMS in px to 4 decimals, reductions in per cent) and the mean node
    vectors of the images of the first image's layout, with a scale arrow of their true
    length (px)."""
    from matplotlib.figure import Figure

    from ..report import Report
    from ..report.plots import CLIPPED_COLOUR, arrow_scale

    first = next(iter(grids.values()))
    rep = Report(
        "Finite-element residual grids",
        f"{first.layout.spacing:g} px node spacing; image residuals computed minus observed, px",
    )
    from ..report.grid_study import grid_settings

    rep.add_table(
        "Grids",
        ["setting", "value"],
        grid_settings(grids),
        note="the grids written to the grids file (--output)",
    )
    rows = [_grid_row(k, g.to_dict()) for k, g in grids.items()]
    rep.add_table(
        "Per image",
        [
            "image",
            "n",
            "outliers",
            "nodes",
            "supported",
            "sigma0",
            "RMS before [px]",
            "RMS after [px]",
            "reduction",
            "CV reduction",
        ],
        rows,
        note="sigma0: a-posteriori standard deviation of unit weight (unitless); reduction: "
        "1 - RMS after / RMS before; CV reduction: the same from the k-fold cross-validation",
    )
    if rejected is not None:
        kind = rejected["located_by"]
        rep.add_table(
            "Rejected by data snooping",
            ["image", kind, "|w|"],
            [[str(r["image"]), str(r[kind]), f"{r['w']:.2f}"] for r in rejected["rejected"]],
            note=_snooping_heading(rejected)
            + "; largest |w| first"
            + (
                f"; {len(rejected['still_flagged'])} point(s) still fail the test after the "
                "last round and stay in the grids"
                if rejected["still_flagged"]
                else ""
            ),
        )
    same = [g for g in grids.values() if g.layout == first.layout]
    mean = np.mean([g.nodes for g in same], axis=0)
    u, v = first.layout.node_coordinates()
    nodes = np.column_stack([u.ravel(), v.ravel()])
    vec = mean.reshape(-1, 2)
    # the scale follows the 90th percentile of the node vectors (a node of little support
    # with a long vector would otherwise shrink every other to a dot): with an extent of 4
    # node spacings the typical vector is drawn at most 0.6 spacings long and the longest
    # at most 1.2; longer vectors are drawn clipped in their own colour and counted
    sc = arrow_scale(vec, 4.0 * first.layout.spacing)
    factor, key = sc.factor, sc.key
    drawn = sc.drawn(vec)
    fig = Figure(figsize=(8, 8 * first.layout.height / first.layout.width + 0.6))
    ax = fig.add_subplot()
    plain_rows = sc.shown & ~sc.clipped
    q = sc.quiver(ax, nodes, drawn, plain_rows)
    n_clipped = int(sc.clipped.sum())
    if n_clipped:
        sel = sc.shown & sc.clipped
        sc.quiver(
            ax,
            nodes,
            drawn,
            sel,
            color=CLIPPED_COLOUR,
            label=f"longer than {sc.clip:.3g} px, clipped ({n_clipped})",
        )
        ax.legend(loc="lower right", fontsize=8)
    if key > 0:
        ax.quiverkey(
            q, X=0.78, Y=1.03, U=key, label=f"{key:g} px", labelpos="E", coordinates="axes"
        )
    ax.set_xlim(-0.5, first.layout.width - 0.5)
    ax.set_ylim(first.layout.height - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u (column) [px]")
    ax.set_ylabel("v (row) [px]")
    ex = f"{factor:,.0f}" if factor >= 10 else f"{factor:.3g}"
    clipped_note = (
        f"; {n_clipped} longer than {sc.clip:.3g} px clipped (orange)" if n_clipped else ""
    )
    ax.set_title(f"mean node vector, arrows x{ex}{clipped_note}", fontsize=9, loc="left")
    rep.add_figure(
        f"Mean grid of {len(same)} image(s)",
        fig,
        caption="Mean node vector (rx, ry) of the grids over the images of "
        f"{first.layout.width} x {first.layout.height} px, exaggerated by the factor in the "
        "title (set by the 90th percentile of their lengths); the scale arrow gives the true "
        "length. Vectors longer than 3 times that percentile are drawn clipped to it, in "
        "orange.",
    )
    return rep.to_html()


@app.command("apply")
def apply(
    grids_file: Annotated[Path, typer.Argument(help="Grids file written by 'photogeom grid fit'.")],
    observations: Annotated[
        Path, typer.Argument(help="CSV with image_id, u, v (px); other columns are kept.")
    ],
    output: OutputCsvOpt = None,
) -> None:
    """Correct image coordinates: u, v replaced by u + rx(u, v), v + ry(u, v)."""
    from ..calibration import correct_observations, load_grids
    from ..calibration.gridfile import match_grid_ids

    check_outputs({"GRIDS_FILE": grids_file}, output=output)  # -o OBSERVATIONS is allowed
    _refuse_folder_observations(observations)

    grids = load_grids(grids_file)
    comments: list[str] = []
    quoted: list = []
    header, columns, col, lines = _read_csv(
        observations, ("image_id", "u", "v"), comments, quoted
    )
    ids = _ids(columns[col["image_id"]], quoted[col["image_id"]])
    uv = np.stack([_numbers(observations, columns[col[c]], c, lines) for c in ("u", "v")], axis=1)
    per_image = _groups(ids)
    key_of, missing = match_grid_ids(per_image, grids)  # CSV text against integer ids too
    if missing:
        # an empty id (or one with white space at its ends, quoted) shown quoted, so that
        # the message names it; the first row of the first one by its line
        shown = [repr(m) if not m or m != m.strip() else m for m in map(str, missing[:10])]
        more = f" ({len(missing)} in all)" if len(missing) > 10 else ""
        raise InputError(
            f"{observations}: no grid in {grids_file} for image(s) {', '.join(shown)}{more} "
            f"(first row: line {int(lines[per_image[missing[0]][0]])}); fit their grids with "
            "photogeom grid fit, or remove their rows"
        )
    width, height = np.empty(len(ids)), np.empty(len(ids))
    for k, r in per_image.items():  # per image, not per point
        layout = grids[key_of[k]].layout
        width[r], height[r] = layout.width, layout.height
    reach = f"u = {uv[:, 0].max():g}, v = {uv[:, 1].max():g} px" if len(uv) else ""
    _refuse_outside(
        observations, ids, uv, lines, width, height,
        f"a grid of {grids_file} covers its image only: remove those rows, or, when "
        f"{grids_file} holds the grids of another camera or block (the rows reach {reach}), "
        "give the grids fitted for these observations (photogeom grid fit)",
    )  # fmt: skip
    corrected = correct_observations(
        {k: uv[r] for k, r in per_image.items()},
        {k: grids[key_of[k]] for k in per_image},
    )
    new = uv.copy()
    for k, r in per_image.items():
        new[r] = corrected[k]
    # the cells as read (quoted ones quoted again), u and v replaced; each column formatted
    # at once, rows joined
    for j in range(len(columns)):
        columns[j] = _csv_column(columns[j], quoted[j])
    columns[col["u"]] = list(map(repr, new[:, 0].tolist()))
    columns[col["v"]] = list(map(repr, new[:, 1].tolist()))
    out = [f"# {c}" for c in comments if c]  # the conventions of the input stay with it
    out.append(",".join(_csv_cell(c) for c in header))
    out.extend(map(",".join, zip(*columns, strict=True)))
    del columns
    emit_points("\n".join(out) + "\n", output, int(lines.size))


def _refuse_folder_observations(path: Path) -> None:
    """Refuse a folder as the OBSERVATIONS of ``grid apply``, naming the CSV file to give.

    Parameters
    ----------
    path : Path
        The OBSERVATIONS argument.

    Raises
    ------
    InputError
        ``path`` is a folder: the message names its ``observations.csv`` when it is a CSV
        block folder, else the columns the CSV needs.
    """
    if not path.is_dir():
        return
    inner = path / "observations.csv"
    if inner.is_file():
        raise InputError(
            f"{path}: a block folder, not an observations CSV; give its observations file "
            f"{inner} (image_id, u, v in px; written again with u, v corrected)"
        )
    raise InputError(
        f"{path}: a folder, not an observations CSV; give a CSV file with the columns "
        "image_id, u, v (px; other columns are kept)"
    )


def _csv_cell(text: str) -> str:
    """One CSV cell (RFC 4180): quoted, inner quotes doubled, when it holds a comma, a quote
    or a line break (``\r`` too, which the csv module leaves bare with ``\n`` line ends), or
    begins with ``#`` (a line beginning with it is a comment to the readers)."""
    if any(ch in text for ch in ',"\r\n') or text.lstrip().startswith("#"):
        return '"' + text.replace('"', '""') + '"'
    return text


def _csv_column(cells, quoted=None) -> list[str]:
    """The cells of one column formatted by :func:`_csv_cell`, the cells marked in
    ``quoted`` (the ones quoted in the file read: their text is exact, white space at the
    ends and integer form included) quoted in any case; a column without a character that
    needs quotes (one search of its joined text) and without marks is returned as it is."""
    joined = "".join(cells)
    marked = quoted is not None and bool(np.any(quoted))
    if not marked and not any(ch in joined for ch in ',"\r\n#'):
        return cells
    if not marked:
        return list(map(_csv_cell, cells))
    out = np.array(list(map(_csv_cell, cells)), dtype=object)
    again = np.array(cells, dtype=object)[quoted]
    out[quoted] = ['"' + c + '"' for c in map(operator.methodcaller("replace", '"', '""'), again)]
    return out.tolist()


def _scheduler_mode(scheduler: str, workers: int) -> tuple[bool | str, int]:
    """``(dask, workers)`` of ``correct_folder`` for ``--scheduler``: True and the worker
    count for ``local`` / ``local:N``, the checked address for an address; other forms (and
    ``threads`` / ``sync``, which have no workers to resample on) are refused by name."""
    try:
        kind, arg = scheduler_option(scheduler)
    except InputError as exc:  # threads and sync are no choice here
        text = str(exc).replace("'local', 'local:N', 'threads', 'sync' or", "'local', 'local:N' or")
        raise InputError(text) from None
    if kind == "address":
        return arg, workers
    if kind == "local":
        if arg is not None and workers not in (1, arg):
            raise InputError(
                f"--scheduler {scheduler} and --workers {workers} both give the number of "
                "workers: give one of them"
            )
        return True, arg or workers
    raise InputError(
        f"--scheduler {scheduler}: grid correct-images resamples in worker processes; give "
        "'local', 'local:N' or the address of a running scheduler (tcp://host:8786), or leave "
        "--scheduler out (--workers N processes)"
    )


@app.command("correct-images")
def correct_images(
    grids_file: Annotated[Path, typer.Argument(help="Grids file written by 'photogeom grid fit'.")],
    src_dir: Annotated[
        Path, typer.Argument(help="Folder of the original images (file name or stem = image id).")
    ],
    dst_dir: Annotated[
        Path, typer.Argument(help="Output folder (created; must differ from the input).")
    ],
    workers: Annotated[int, typer.Option(help="Parallel workers.")] = 1,
    dask: Annotated[
        bool, typer.Option("--dask", help="Run on a Dask local cluster of --workers workers.")
    ] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler: the address of a running one (tcp://host:8786), or 'local' / "
            "'local:N' (as --dask, with --workers or N workers)."
        ),
    ] = None,
    interpolation: Annotated[Interp, typer.Option(help="Resampling.")] = Interp.bilinear,
    outside: Annotated[
        Outside,
        typer.Option(
            help="Pixels whose source lies outside the image: replicate the edge, "
            "constant (0) or reflect."
        ),
    ] = Outside.replicate,
    as_json: JsonOpt = False,
) -> None:
    """Resample every image that has a grid; failures are listed, the rest processed (exit
    1 when some image failed)."""
    from ..calibration import correct_folder, load_grids

    refuse_stdout_dash("DST_DIR", dst_dir, folder=True)
    mode: bool | str = dask
    if scheduler:
        mode, workers = _scheduler_mode(scheduler, workers)
    grids = load_grids(grids_file)
    terminal = console(stderr=True).is_terminal
    try:
        with (
            sigterm_stops(),  # SIGTERM as Ctrl-C: the job's clean-up runs
            nullcontext() if terminal else LogProgress("correcting images") as log,
        ):

            def counted(done: int, total: int) -> None:
                log.update(f"correcting images: {done} of {total} images")

            res = correct_folder(
                src_dir,
                dst_dir,
                grids,
                workers=workers,
                dask=mode,
                interpolation=interpolation.value,
                progress=True if terminal else counted,
                border=outside.value,
            )
    except InputError as exc:
        raise InputError(str(exc).replace("workers must", "--workers must")) from None
    if as_json:
        typer.echo(json_text(res.to_dict()), nl=False)
    else:
        say(f"corrected {len(res.written)} image(s) into {dst_dir}")
        for k, note in res.notes.items():
            say(f"  {k}: {note}")
        if res.skipped:
            say(
                f"{len(res.skipped)} image file(s) without a grid, not corrected: "
                f"{', '.join(res.skipped[:10])}"
            )
        _say_failures(res, src_dir)
    if res.failures:
        failed = len(res.failures)
        batch_failed(
            f"{failed} of {failed + len(res.written)} image(s) failed (listed above; the "
            f"other {len(res.written)} corrected into {dst_dir})"
        )


#: Images without a file that ``grid correct-images`` names one per line; the others are
#: counted in one line (a folder holding a few of a 250-image block's images gave a line per
#: image, and a damaged file's failure among them).
MISSING_SHOWN = 10


def _say_failures(res, src_dir: Path) -> None:
    """The failures of ``correct_folder`` on stderr: every image whose file failed, then the
    first :data:`MISSING_SHOWN` images without a file and a count of the rest."""
    missing = set(res.missing)
    for k, msg in res.failures.items():
        if k not in missing:
            say(f"failed {k}: {msg}", stderr=True)
    shown = [k for k in res.missing if k in res.failures][:MISSING_SHOWN]
    for k in shown:
        say(f"failed {k}: {res.failures[k]}", stderr=True)
    more = len(missing) - len(shown)
    if more > 0:
        say(
            f"failed: {more} more image(s) with a grid and no image file of their name in "
            f"{src_dir} (--json gives the reason for each)",
            stderr=True,
        )


# block-level commands (evaluate, sweep, report) live in their own module
from .grid_block import register as _register_block_commands  # noqa: E402

_register_block_commands(app)
