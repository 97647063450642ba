"""A block as CSV files a person can edit: cameras, images, points, observations.

A folder holds four files (comma-separated, or semicolons or tabs when the header has no
comma; a header line; ``#`` comment lines and blank lines skipped anywhere)::

    cameras.csv       camera, width, height, f, cx, cy, k1, k2, k3, k4, p1, p2, b1, b2,
                      free, image_variant
    images.csv        id, camera, X0, Y0, Z0, omega_deg, phi_deg, kappa_deg
                      [, df, dcx, dcy]
                      [, gnss_X, gnss_Y, gnss_Z, gnss_sX, gnss_sY, gnss_sZ]
                      [, imu_omega_deg, imu_phi_deg, imu_kappa_deg,
                         imu_somega_deg, imu_sphi_deg, imu_skappa_deg]
    points.csv        id, role, X, Y, Z, sX, sY, sZ [, surveyed_X, surveyed_Y, surveyed_Z]
    observations.csv  image_id, point_id, u, v, sigma

* Cameras: the Metashape frame model in pixels (``cx, cy`` offsets from the image centre);
  ``free`` and ``image_variant`` list parameter names separated by spaces (``f cx cy k1``).
  Instead of (or over) ``cameras.csv``, Metashape calibration XML files can give the starting
  cameras: ``read_csv_block(folder, calibrations={"cam": "cam.xml"})``.
* Angles carry their unit in the column name: ``_deg``, ``_gon`` or ``_rad`` (the writer
  uses degrees unless ``angle_unit`` says otherwise). ``df, dcx, dcy`` are per-image offsets
  of f, cx, cy (image-variant calibration), pixels. GNSS and IMU cells are empty for images
  without them. A block without start values (no GNSS/IMU, a matcher's output) is read
  with ``start_values=False``: ``X0, Y0, Z0``, the angles and the tie points' ``X, Y, Z``
  may then be missing or empty (read as 0, placeholders for
  :func:`photogeom.bundle.start_from_relative_orientation`).
* Points: role ``tie``, ``control`` or ``check``; ``sX, sY, sZ`` standard deviations of
  surveyed coordinates (empty for tie points). An adjusted block is written with its
  estimates in ``X, Y, Z`` (check points triangulated) and the survey of its control and
  check points in ``surveyed_X, surveyed_Y, surveyed_Z`` (``Block.surveyed``; empty for tie
  points), so that adjusting the folder again observes the survey. An optional
  ``# crs: ...`` comment line in ``points.csv`` names the coordinate reference system.
* Observations: ``u, v`` pixels with the centre of the top-left pixel at (0, 0), u right,
  v down; ``sigma`` pixels (optional column; default ``sigma`` of the reader).
* Ids are integers when every id of a column is written as one (``7``, not ``07`` or
  ``+7``) and none is quoted, otherwise text; the observations' ids are read as the kind of
  the ids they refer to. ``-0`` reads as 0; ``-0`` and ``0`` in one id column are refused.
* ``images.csv`` columns ``colmap_image_id`` and ``colmap_name`` (both or neither) hold
  ``Block.colmap_images`` (COLMAP's IMAGE_ID and NAME of a block read from COLMAP).
* The block of the final fit of :func:`~photogeom.calibration.adjust_with_grids`
  (``Block.joint_adjustment``) is written with a folder ``joint_adjustment`` holding the
  joint estimate (the four files, angles in radians) and ``settings.json`` (the settings
  of that adjustment), read back with the block: ``readjust`` on the folder takes the joint
  adjustment as the first adjustment of its chain. Writing a block without it removes
  that folder's files.
* A cell in double quotes (inner quotes doubled) is its text exactly: not a comment, not
  stripped, text even in integer form. The writer quotes the text ids the reader would
  otherwise change (white space at either end, a leading ``#``, a comma, a quote, integer
  form), so every id round-trips; ids a line cannot hold (empty, a line break, NUL) are
  refused with :class:`~photogeom.errors.OutputError`.

Errors name the file, the line and the column. Each file is written atomically, and all four
are formatted before any is replaced.
"""

from __future__ import annotations

import collections
import csv
import functools
import operator
import os
import re
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera.metashape import MetashapeCalibration, read_metashape_xml
from ..errors import FileFormatError, InputError, OutputError
from ..io.csvblocks import empty_column
from ..numbers import decimal_comma_hint
from ..units import from_radians, normalize_angle_unit, to_radians
from ._textio import NO_NAME_CHARS, format_floats, read_text
from .block import CALIBRATION_NAMES, Block, ColmapImages

FILES = ("cameras.csv", "images.csv", "points.csv", "observations.csv")
_INT = re.compile(r"-?(?:0|[1-9][0-9]*)")
_EO_ANGLES = ("omega", "phi", "kappa")

#: The route of a block without start values, appended to the errors of empty or missing
#: exterior-orientation and tie-point cells (the command line names its options instead).
NO_START_HINT = (
    "a block without start values (no GNSS/IMU, no earlier adjustment) is read with "
    "read_csv_block(..., start_values=False) and given them by "
    "photogeom.bundle.start_from_relative_orientation (relative orientations, strips, "
    "control points)"
)


@dataclass
class _Table:
    path: Path
    header: list[str]
    #: the cells of each column (object arrays of str, one per header name)
    columns: list[np.ndarray]
    lines: np.ndarray
    comments: list[str]
    #: indices of the columns with a quoted cell
    quoted: set[int]

    @property
    def n_rows(self) -> int:
        return int(self.lines.size)

    def find(self, name: str) -> int | None:
        if name in self.header:
            return self.header.index(name)
        hits = [k for k, h in enumerate(self.header) if h.lower() == name.lower()]
        return hits[0] if len(hits) == 1 else None

    def col(self, name: str) -> list[str]:
        k = self.find(name)
        if k is None:
            raise FileFormatError(
                f"{self.path}: column {name!r} not found; the file has columns "
                f"{_listing(self.header)}"
            )
        return self.columns[k].tolist()

    def has(self, name: str) -> bool:
        return self.find(name) is not None

    def any_quoted(self, name: str) -> bool:
        """Whether a cell of column ``name`` was quoted."""
        k = self.find(name)
        return k is not None and k in self.quoted

    def floats(self, name: str, *, optional_cells: bool = False) -> np.ndarray:
        cells = self.col(name)
        has_empty = "" in cells
        if has_empty:
            empty = np.fromiter(map(operator.not_, cells), dtype=bool, count=len(cells))
            if not optional_cells:
                k = int(np.flatnonzero(empty)[0])
                raise FileFormatError(
                    f"{self.path}, line {self.lines[k]}: column {name!r} is empty"
                )
            cells = [c or "nan" for c in cells]
        else:
            empty = np.zeros(len(cells), dtype=bool)
        try:
            out = np.fromiter(map(float, cells), dtype=np.float64, count=len(cells))
        except ValueError:
            for k, c in enumerate(cells):
                try:
                    float(c)
                except ValueError:
                    raise FileFormatError(
                        f"{self.path}, line {self.lines[k]}: column {name!r}: {c!r} is not a number"
                        + decimal_comma_hint(c)
                    ) from None
            raise  # pragma: no cover
        bad = ~np.isfinite(out) & ~empty
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            raise FileFormatError(
                f"{self.path}, line {self.lines[k]}: column {name!r} is NaN or infinite"
            )
        return out


@functools.lru_cache(maxsize=8)
def _cell_patterns(sep: str) -> tuple[re.Pattern, re.Pattern, re.Pattern]:
    """Regular expressions of a quoted cell, the start of one, and an unquoted cell (each
    with the separator after it, or the end of the line)."""
    ws = "[^\\S\\r\\n" + re.escape(sep) + "]*"
    after = "(" + re.escape(sep) + "|$)"
    return (
        re.compile(ws + '"((?:[^"]|"")*)"' + ws + after),
        re.compile(ws + '"'),
        re.compile("([^" + re.escape(sep) + "]*)" + after),
    )


def _split_quoted(line: str, sep: str, path: Path, number: int) -> tuple[list[str], set[int]]:
    """Cells of a line holding a quote, and which of them were quoted.

    Unquoted cells are stripped of white space; a quoted cell is its text exactly (inner
    quotes doubled). A quote that is not closed on its line, or text between a closing quote
    and the next separator, is refused.
    """
    quoted_cell, opens, plain_cell = _cell_patterns(sep)
    cells: list[str] = []
    quoted: set[int] = set()
    pos = 0
    while True:
        m = quoted_cell.match(line, pos)
        if m is not None:
            quoted.add(len(cells))
            cells.append(m.group(1).replace('""', '"'))
        elif opens.match(line, pos):
            raise FileFormatError(
                f'{path}, line {number}: cell {len(cells) + 1}: a quote (") opens a cell that '
                "is not closed on its line, or text follows the closing quote; a quoted cell "
                'ends with a quote and doubles the quotes inside it ("a ""b""")'
            )
        else:
            m = plain_cell.match(line, pos)
            cells.append(m.group(1).strip())
        if not m.group(2):  # the end of the line, not a separator
            return cells, quoted
        pos = m.end()


def _split_line(line: str, sep: str, path: Path, number: int) -> tuple[list[str], set[int]]:
    """Cells of one line and which of them were quoted: lines without quotes by the csv
    module (cells stripped), lines with quotes by :func:`_split_quoted`."""
    if '"' in line:
        return _split_quoted(line, sep, path, number)
    try:
        row = next(csv.reader([line], delimiter=sep, skipinitialspace=True), [])
    except csv.Error as exc:  # a field over the csv module's limit (128 KiB)
        raise FileFormatError(
            f"{path}, line {number}: cannot split the line into fields ({exc}); "
            "a field of a block file is a name or a number: wrong file?"
        ) from None
    return [c.strip() for c in row], set()


def _simple_cells(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which stripped pieces of lines (split at the separator) are whole cells on their own,
    and which of those are quoted: a piece without quotes (its text), or one quote at either
    end and none inside (the text between them, kept exactly). Other pieces (doubled quotes,
    a separator or text beside a quote) need :func:`_split_quoted`.

    Returns the masks ``simple`` and ``quoted`` and the texts of the quoted cells.
    """
    n = cells.size
    quotes = np.fromiter(map(operator.methodcaller("count", '"'), cells), dtype=np.int64, count=n)
    quoted = quotes == 2
    inner = np.empty(int(quoted.sum()), dtype=object)
    if inner.size:
        inner[:] = list(map(operator.itemgetter(slice(1, -1)), cells[quoted]))
        # two quotes, none left inside once the first and the last character are cut off
        ends = np.fromiter(
            map(operator.methodcaller("count", '"'), inner), dtype=np.int64, count=inner.size
        )
        ok = ends == 0
        quoted[np.flatnonzero(quoted)[~ok]] = False
        inner = inner[ok]
    return (quotes == 0) | quoted, quoted, inner


#: Column names a message lists at most (a header of thousands of names is a wrong file).
MAX_LISTED_COLUMNS = 20


def _listing(names: list[str]) -> str:
    """``names`` joined by commas for a message; after :data:`MAX_LISTED_COLUMNS` names, the
    count of the others."""
    shown = ", ".join(_short(n) for n in names[:MAX_LISTED_COLUMNS])
    more = len(names) - MAX_LISTED_COLUMNS
    return shown + (f", ... ({more} more)" if more > 0 else "")


def _repeated(names: list[str]) -> list[str]:
    """The names that occur more than once, sorted (one pass: linear in the header)."""
    return sorted(n for n, c in collections.Counter(names).items() if c > 1)


def _read_table(path: Path) -> _Table:
    """The cells of a CSV file as columns, with the line number of each row.

    Rows are split column-wise over the whole file (one split of the joined lines, cells
    stripped by ``map``), so that reading is linear and runs at the speed of the string
    methods; only lines that hold a quoted cell with a separator or a doubled quote inside,
    white space or text beside a quote, or another number of separators than the header
    are taken cell by cell (:func:`_split_quoted`), with the same rules and messages.
    """
    text = read_text(path, "CSV file")
    all_lines = text.splitlines()
    del text
    stripped = list(map(str.strip, all_lines))
    n_all = len(all_lines)
    blank = np.fromiter(map(operator.not_, stripped), dtype=bool, count=n_all)
    hashed = np.fromiter(
        map(operator.methodcaller("startswith", "#"), stripped), dtype=bool, count=n_all
    )
    comments = [stripped[k][1:].strip() for k in np.flatnonzero(hashed).tolist()]
    del stripped
    keep = np.flatnonzero(~(blank | hashed))
    if not keep.size:
        raise FileFormatError(f"{path}: no header line (the file is empty or all comments)")
    numbers = keep + 1
    first = all_lines[int(keep[0])]
    # comma-separated; a header without commas but with semicolons or tabs (spreadsheet
    # exports in some locales) selects that separator for the whole file
    sep = ","
    if "," not in first:
        sep = ";" if ";" in first else "\t" if "\t" in first else ","
    header, _ = _split_line(first, sep, path, int(numbers[0]))
    if any(not h for h in header):
        raise FileFormatError(f"{path}, line {numbers[0]}: {empty_column(header, sep)}")
    dup = _repeated(header)
    if dup:
        raise FileFormatError(
            f"{path}: column(s) {_listing(dup)} appear more than once; give each column once"
        )
    width = len(header)
    body = [all_lines[k] for k in keep[1:].tolist()]
    del all_lines
    lines = numbers[1:].astype(np.int64)
    n = len(body)
    # lines with as many separators as the header has: split all at once
    seps = np.fromiter(map(operator.methodcaller("count", sep), body), dtype=np.int64, count=n)
    fast = seps == width - 1
    fast_rows = np.flatnonzero(fast)
    if fast_rows.size == n:
        fast_lines = body
    else:
        fast_lines = [body[k] for k in fast_rows.tolist()]
    joined = sep.join(fast_lines)
    del fast_lines
    has_quotes = '"' in joined
    pieces = list(map(str.strip, joined.split(sep))) if fast_rows.size else []
    del joined
    cells = np.empty(len(pieces), dtype=object)
    cells[:] = pieces
    del pieces
    cells = cells.reshape(-1, width)
    quoted_cols: set[int] = set()
    if has_quotes:
        simple, quoted, inner = _simple_cells(cells.ravel())
        simple, quoted = simple.reshape(cells.shape), quoted.reshape(cells.shape)
        whole = simple.all(axis=1)  # rows whose every cell stands on its own
        cells[quoted] = inner
        quoted_cols.update(np.flatnonzero((quoted & whole[:, None]).any(axis=0)).tolist())
        if not whole.all():
            fast[fast_rows[~whole]] = False
            cells = cells[whole]
    columns = [np.empty(n, dtype=object) for _ in range(width)]
    fast_rows = np.flatnonzero(fast)
    for j in range(width):
        columns[j][fast_rows] = cells[:, j]
    del cells
    # the other lines, cell by cell in file order (errors name the first bad line)
    slow_rows = np.flatnonzero(~fast).tolist()
    bad = None
    for k in slow_rows:
        row, q = _split_line(body[k], sep, path, int(lines[k]))
        quoted_cols.update(q)
        if len(row) != width:
            if bad is None:
                bad = (k, len(row))
            continue
        for j in range(width):
            columns[j][k] = row[j]
    if bad is not None:
        k, got = bad
        raise FileFormatError(
            f"{path}, line {lines[k]}: {got} field(s) but the header has {width} "
            f"({_listing(header)})"
        )
    return _Table(path, header, columns, lines, comments, quoted_cols)


def _canonical_ints(cells: list[str]) -> np.ndarray | None:
    """The cells as int64 when every one is an integer written as one (``7``, not ``07``,
    ``+7`` or ``-0``: ``str(int(c)) == c``), else None. One pass of ``int`` and ``str``."""
    try:
        values = list(map(int, cells))
    except ValueError:
        return None
    if list(map(str, values)) != cells:
        return None
    try:
        return np.array(values, dtype=np.int64)
    except OverflowError:
        return None


def _integer_cells(cells: list[str]) -> np.ndarray | None:
    """The cells as int64 when each is in integer form (:data:`_INT`) and fits 64 bits,
    else None."""
    ids = _canonical_ints(cells)
    if ids is None and all(_INT.fullmatch(c) for c in cells):  # "-0" is in integer form
        if np.all(_fits_int64(cells)):  # else an id beyond 64 bits: not an int64 column
            ids = np.array([int(c) for c in cells], dtype=np.int64)
    return ids


def _id_array(cells: list[str], table: _Table, name: str) -> np.ndarray:
    if "" in cells:
        k = cells.index("")
        raise FileFormatError(f"{table.path}, line {table.lines[k]}: {name!r} is empty")
    ids = _integer_cells(cells) if cells and not table.any_quoted(name) else None
    if ids is None:
        ids = np.array(cells, dtype=str)
    _, first, counts = np.unique(ids, return_index=True, return_counts=True)
    if np.any(counts > 1):
        k = int(first[counts > 1][0])
        again = int(np.flatnonzero(ids == ids[k])[1])
        if cells[again] != cells[k]:  # "-0" and "0": one integer, two spellings
            raise FileFormatError(
                f"{table.path}, line {table.lines[again]}: {name} {cells[again]!r} is the "
                f"integer {int(ids[k])}, as {cells[k]!r} on line {table.lines[k]}: the ids of "
                "an integer column are numbers, so the two rows would be one; give them "
                "different ids, or quote the ids to make them text"
            )
        raise FileFormatError(
            f"{table.path}, line {table.lines[again]}: {name} {cells[k]!r} appears twice "
            f"(first on line {table.lines[k]})"
        )
    return ids


def _fits_int64(cells: list[str]) -> np.ndarray:
    """Which integer cells (``_INT`` form) fit 64 bits (long ones are never converted)."""
    return np.array(
        [len(c) <= 20 and -(2**63) <= int(c) < 2**63 for c in cells], dtype=bool
    )


def _short(text: str, n: int = 40) -> str:
    return text if len(text) <= n else text[:n] + "..."


def _ids_like(cells: list[str], keys: np.ndarray, table: _Table, name: str, what: str):
    """Read the referring ids ``cells`` as the kind of ``keys``; name unknown ones."""
    if keys.dtype.kind in "iu":
        ids = _integer_cells(cells)
        if ids is None:  # not in integer form, or beyond 64 bits: not one of the ids
            ok = np.array([bool(_INT.fullmatch(c)) for c in cells], dtype=bool)
            ok[ok] = _fits_int64([c for c, g in zip(cells, ok) if g])
            k = int(np.flatnonzero(~ok)[0])
            raise FileFormatError(
                f"{table.path}, line {table.lines[k]}: {name} {_short(cells[k])!r} is not one "
                f"of the {what} ids"
            )
    else:
        ids = np.array(cells, dtype=str)
    known = np.isin(ids, keys)
    if not np.all(known):
        k = int(np.flatnonzero(~known)[0])
        raise FileFormatError(
            f"{table.path}, line {table.lines[k]}: {name} {cells[k]!r} is not one of the {what} ids"
            + _look_alike_hint(cells[k], keys)
        )
    return ids


def _look_alike_hint(cell: str, keys: np.ndarray) -> str:
    """For an unknown text id that prints like a known one but is written with other
    characters (composed 'é' against 'e' + combining accent, a no-break space, full-width
    digits: equal compatibility normal forms, NFKC), both spellings escaped; for one that
    differs from a known one in letter case only (``dsc1.jpg``, ``DSC1.JPG``), the known
    one; else ''. Ids are compared as written, never merged."""
    if keys.dtype.kind != "U":
        return ""
    form = unicodedata.normalize("NFKC", cell)
    for key in keys.tolist():
        if key != cell and unicodedata.normalize("NFKC", key) == form:
            return (
                f" (it looks like {key!a} but is written with other characters: {cell!a}; "
                "write the id alike in both files)"
            )
    # letter case: an id typed by hand, or a file name from another tool (DSC1.JPG, dsc1.jpg)
    folded = form.casefold()
    for key in keys.tolist():
        if unicodedata.normalize("NFKC", key).casefold() == folded:
            return (
                f" (it differs from the id {key!r} in letter case only; ids are compared as "
                "written: write the id alike in both files)"
            )
    return ""


def _angle_column(table: _Table, base: str) -> tuple[str, str] | None:
    for unit in ("deg", "gon", "rad"):
        name = f"{base}_{unit}"
        if table.has(name):
            return name, unit
    return None


def _angles(
    table: _Table, bases, *, optional: bool, empty_cells: bool | None = None
) -> np.ndarray | None:
    """Angle columns named ``<base>_<unit>``, in radians; ``optional``: the columns may be
    absent (None); ``empty_cells``: cells may be empty (NaN; default: as ``optional``)."""
    empty_cells = optional if empty_cells is None else empty_cells
    found = [_angle_column(table, b) for b in bases]
    if all(f is None for f in found) and optional:
        return None
    missing = [b for b, f in zip(bases, found) if f is None]
    if missing:
        raise FileFormatError(
            f"{table.path}: angle column(s) {', '.join(missing)} not found: name them with "
            f"their unit ({missing[0]}_deg, {missing[0]}_gon or {missing[0]}_rad); the file has "
            f"columns {_listing(table.header)}"
        )
    return np.column_stack(
        [to_radians(table.floats(n, optional_cells=empty_cells), u) for n, u in found]
    )


def _names(cell: str) -> tuple[str, ...]:
    return tuple(cell.replace(",", " ").split())


def _read_cameras(path: Path):
    t = _read_table(path)
    ids = _id_array(t.col("camera"), t, "camera")
    w, h = t.floats("width"), t.floats("height")
    vals = {
        n: (t.floats(n) if n == "f" else t.floats(n, optional_cells=True))
        for n in CALIBRATION_NAMES
        if n == "f" or t.has(n)
    }
    cams, free, variant = {}, {}, {}
    free_cells = t.col("free") if t.has("free") else None
    var_cells = t.col("image_variant") if t.has("image_variant") else None
    for k, cid in enumerate(ids.tolist()):
        kw = {n: (0.0 if np.isnan(v[k]) else float(v[k])) for n, v in vals.items()}
        try:
            cams[cid] = MetashapeCalibration(w[k], h[k], **kw)
        except InputError as exc:
            raise FileFormatError(f"{path}, line {t.lines[k]}: camera {cid!r}: {exc}") from None
        if free_cells is not None:
            free[cid] = _names(free_cells[k])
        if var_cells is not None:
            variant[cid] = _names(var_cells[k])
    return ids, cams, (free if free_cells is not None else None), variant


def read_csv_block(
    directory: str | os.PathLike,
    *,
    calibrations: Mapping[object, MetashapeCalibration | str | os.PathLike] | None = None,
    sigma: float = 0.5,
    start_values: bool = True,
) -> Block:
    """Read a block from a folder of CSV files (see the module docstring).

    Parameters
    ----------
    directory : path-like
        Folder with ``images.csv``, ``points.csv``, ``observations.csv`` and (unless
        ``calibrations`` gives every camera) ``cameras.csv``.
    calibrations : mapping camera id -> MetashapeCalibration or path of a Metashape
        calibration XML or camera export, optional
        Starting cameras; they replace the calibration of ``cameras.csv`` for those ids
        (``free`` and ``image_variant`` stay those of ``cameras.csv``, or the defaults). A
        camera export with several sensors is given as ``(path, sensor)``, the sensor's id
        or label (:func:`photogeom.camera.read_metashape_xml`).
    sigma : float
        Standard deviation of observations without a ``sigma`` column, pixels.
    start_values : bool
        True (default): every image has its exterior orientation (``X0, Y0, Z0`` and the
        angles) and every tie point its ``X, Y, Z``. False: a block without start values
        (no GNSS/IMU, a matcher's output): those columns may be missing and their cells
        empty; an empty value is read as 0, a placeholder for
        :func:`photogeom.bundle.start_from_relative_orientation` to replace (control and
        check points still need their ``X, Y, Z``).

    Returns
    -------
    Block
        The block (angles converted to radians, pixels from the centre of the first pixel).

    Raises
    ------
    FileFormatError
        Missing files or columns, cells that are not numbers, unknown ids (each naming file
        and line), angle columns without a unit, unknown roles.
    """
    d = Path(directory)
    if not d.is_dir():
        raise FileFormatError(f"{d}: not a directory (a CSV block is a folder of CSV files)")
    given: dict = {}
    for k, v in (calibrations or {}).items():
        if isinstance(v, MetashapeCalibration):
            given[k] = v
        elif isinstance(v, tuple) and len(v) == 2:  # (camera export, its sensor)
            given[k] = read_metashape_xml(v[0], sensor=v[1])
        else:
            try:
                given[k] = read_metashape_xml(v)
            except FileFormatError as exc:
                from ..camera.metashape_export import CHOOSE_SENSOR

                raise FileFormatError(
                    str(exc).replace(
                        CHOOSE_SENSOR,
                        f"choose one with calibrations={{{k!r}: (path, sensor id or label)}}",
                    )
                ) from None
    cam_path = d / "cameras.csv"
    free = variant = None
    if cam_path.exists():
        cam_ids, cams, free, variant = _read_cameras(cam_path)
    else:
        if not given:
            raise FileFormatError(
                f"{d}: no cameras.csv; give the cameras in it or as Metashape calibration XML "
                "files (calibrations={camera id: path})"
            )
        cams = {}
        cam_ids = np.array(list(given))
    ti = _read_table(d / "images.csv")
    img_ids = _id_array(ti.col("id"), ti, "id")
    cam_cells = ti.col("camera")
    if not cams:
        # the XML keys are the camera ids; read the images' cameras as the same kind
        kinds = {type(k) for k in given}
        cam_ids = (
            np.array(list(given), dtype=np.int64)
            if kinds == {int}
            else np.array([str(k) for k in given], dtype=str)
        )
        given = dict(zip(cam_ids.tolist(), given.values()))
    img_cam = _ids_like(cam_cells, cam_ids, ti, "camera", "camera")
    for k in given:
        if k not in set(cam_ids.tolist()):
            raise InputError(
                f"calibrations: camera {k!r} is not a camera of {cam_path} "
                f"({', '.join(map(str, cam_ids.tolist()))})"
            )
    cams = {**cams, **given}
    cams = {k: cams[k] for k in cam_ids.tolist()}
    exterior = _exterior(ti, start_values)
    offset = None
    if any(ti.has(n) for n in ("df", "dcx", "dcy")):
        offset = np.column_stack(
            [
                np.nan_to_num(ti.floats(n, optional_cells=True))
                if ti.has(n)
                else np.zeros(ti.n_rows)
                for n in ("df", "dcx", "dcy")
            ]
        )
    gnss = gnss_s = imu = imu_s = None
    if ti.has("gnss_X"):
        gnss = np.column_stack([ti.floats(f"gnss_{a}", optional_cells=True) for a in "XYZ"])
        gnss_s = np.column_stack([ti.floats(f"gnss_s{a}", optional_cells=True) for a in "XYZ"])
    imu = _angles(ti, [f"imu_{a}" for a in _EO_ANGLES], optional=True)
    if imu is not None:
        imu_s = _angles(ti, [f"imu_s{a}" for a in _EO_ANGLES], optional=False, empty_cells=True)
    colmap = _colmap_images(ti, img_ids)
    tp = _read_table(d / "points.csv")
    pt_ids = _id_array(tp.col("id"), tp, "id")
    role = np.array(tp.col("role"), dtype=str) if tp.has("role") else np.full(tp.n_rows, "tie")
    bad = ~np.isin(role, ("tie", "control", "check"))
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{tp.path}, line {tp.lines[k]}: role {str(role[k])!r} is not tie, control or check"
        )
    xyz = _point_xyz(tp, role, start_values)
    psig = None
    if tp.has("sX"):
        psig = np.column_stack([tp.floats(f"s{a}", optional_cells=True) for a in "XYZ"])
        need = (role != "tie") & ~np.all(np.isfinite(psig) & (psig > 0), axis=1)
        if np.any(need):
            k = int(np.flatnonzero(need)[0])
            raise FileFormatError(
                f"{tp.path}, line {tp.lines[k]}: {role[k]} point {pt_ids[k]} needs positive "
                "sX, sY, sZ"
            )
    surveyed = None
    if tp.has("surveyed_X"):
        surveyed = np.column_stack(
            [tp.floats(f"surveyed_{a}", optional_cells=True) for a in "XYZ"]
        )
    crs = None
    for c in tp.comments:
        if c.lower().startswith("crs:"):
            crs = c[4:].strip() or None
    to = _read_table(d / "observations.csv")
    oi = _ids_like(to.col("image_id"), img_ids, to, "image_id", "image (images.csv)")
    op = _ids_like(to.col("point_id"), pt_ids, to, "point_id", "point (points.csv)")
    _refuse_repeated_observations(oi, op, to)
    uv = np.column_stack([to.floats("u"), to.floats("v")])
    sg = to.floats("sigma") if to.has("sigma") else sigma
    if np.any(np.asarray(sg) <= 0):
        k = int(np.flatnonzero(np.asarray(sg) <= 0)[0])
        raise FileFormatError(f"{to.path}, line {to.lines[k]}: sigma must be positive")
    try:
        block = Block.from_arrays(
            cameras=cams,
            image_ids=img_ids,
            image_camera=img_cam,
            exterior=exterior,
            point_ids=pt_ids,
            xyz=xyz,
            obs_image_ids=oi,
            obs_point_ids=op,
            uv=uv,
            sigma=sg,
            role=role,
            point_sigma=psig,
            gnss=gnss,
            gnss_sigma=gnss_s,
            imu=imu,
            imu_sigma=imu_s,
            calibration_offset=offset,
            free=free,
            image_variant=variant or None,
            crs=crs,
        )
    except InputError as exc:
        raise FileFormatError(f"{d}: {exc}") from None
    if colmap is not None:
        block = block.replace(colmap_images=colmap)
    block = block if surveyed is None else block.replace(surveyed=surveyed)
    from ..calibration.in_adjustment import RECORD_FOLDER, RECORD_SETTINGS, JointAdjustmentRecord

    if (d / RECORD_FOLDER / RECORD_SETTINGS).is_file():  # the final fit of adjust_with_grids
        record = JointAdjustmentRecord.read(d / RECORD_FOLDER, block)
        block = block.replace(joint_adjustment=record)
    return block


def _with_start_hint(exc: FileFormatError) -> FileFormatError:
    """``exc`` with :data:`NO_START_HINT` when it is about an empty or missing cell."""
    text = str(exc)
    if re.search(r"column '\w+' (is empty|not found)", text):
        return FileFormatError(f"{text}; {NO_START_HINT}")
    return exc


def _exterior(ti: _Table, start_values: bool) -> np.ndarray:
    """(n, 6) ``X0, Y0, Z0, omega, phi, kappa`` of images.csv (radians); without
    ``start_values`` missing columns and empty cells are 0 (placeholders)."""
    if start_values:
        try:
            xyz0 = np.column_stack([ti.floats(n) for n in ("X0", "Y0", "Z0")])
            ang = _angles(ti, _EO_ANGLES, optional=False)
        except FileFormatError as exc:
            raise _with_start_hint(exc) from None
        return np.column_stack([xyz0, ang])
    xyz0 = np.column_stack(
        [
            ti.floats(n, optional_cells=True) if ti.has(n) else np.zeros(ti.n_rows)
            for n in ("X0", "Y0", "Z0")
        ]
    )
    ang = _angles(ti, _EO_ANGLES, optional=True)
    if ang is None:
        ang = np.zeros((ti.n_rows, 3))
    return np.nan_to_num(np.column_stack([xyz0, ang]), nan=0.0)


def _point_xyz(tp: _Table, role: np.ndarray, start_values: bool) -> np.ndarray:
    """(n, 3) ``X, Y, Z`` of points.csv; empty cells of tie points are refused with the
    route to start values, or (without ``start_values``) read as 0 (placeholders)."""
    xyz = np.column_stack([tp.floats(n, optional_cells=True) for n in ("X", "Y", "Z")])
    empty = ~np.all(np.isfinite(xyz), axis=1)
    need = empty & ((role != "tie") | start_values)
    if np.any(need):
        k = int(np.flatnonzero(need)[0])
        hint = "" if role[k] != "tie" else f"; {NO_START_HINT}"
        raise FileFormatError(
            f"{tp.path}, line {tp.lines[k]}: {role[k]} point: X, Y or Z is empty{hint}"
        )
    xyz[empty] = 0.0
    return xyz


def _colmap_images(ti: _Table, img_ids: np.ndarray) -> ColmapImages | None:
    """``Block.colmap_images`` from the columns ``colmap_image_id`` and ``colmap_name`` of
    images.csv (both or neither), or None."""
    has = [ti.has(n) for n in ("colmap_image_id", "colmap_name")]
    if not any(has):
        return None
    if not all(has):
        missing = "colmap_name" if has[0] else "colmap_image_id"
        raise FileFormatError(
            f"{ti.path}: a COLMAP image identity needs both columns colmap_image_id and "
            f"colmap_name; {missing} is missing (add it, or remove the other)"
        )
    cells = ti.col("colmap_image_id")
    if ti.any_quoted("colmap_image_id"):
        raise FileFormatError(
            f"{ti.path}: column colmap_image_id holds quoted cells; COLMAP image ids are "
            "integers: write them unquoted"
        )
    num = _canonical_ints(cells)
    if num is None:  # not integers as written, or beyond 64 bits
        bad = np.array(
            [len(c) > 10 or not _INT.fullmatch(c) or c != str(int(c)) for c in cells], dtype=bool
        )
        k = int(np.argmax(bad))  # the first such cell
    else:
        bad = (num < 0) | (num >= 2**32 - 1)
        _, first, counts = np.unique(num, return_index=True, return_counts=True)
        for j in first[counts > 1].tolist():  # a repeated id: its second row
            bad[np.flatnonzero(num == num[j])[1]] = True
        k = int(np.argmax(bad))
    if num is None or np.any(bad):
        raise FileFormatError(
            f"{ti.path}, line {ti.lines[k]}: colmap_image_id {_short(cells[k])!r}: COLMAP "
            "image ids are distinct integers from 0 to 4294967294 (written as such, "
            "unquoted)"
        )
    names = np.array(ti.col("colmap_name"), dtype=str)
    return ColmapImages(img_ids, num, names)


def _refuse_repeated_observations(image: np.ndarray, point: np.ndarray, table: _Table) -> None:
    """Refuse two rows of observations.csv with the same (image_id, point_id), naming both
    lines (the first such pair in the file); the block's own check names no file or line.

    Vectorised: one stable sort of the pairs' codes."""
    if image.size < 2:
        return
    ci = np.unique(image, return_inverse=True)[1].ravel().astype(np.int64)
    cp = np.unique(point, return_inverse=True)[1].ravel().astype(np.int64)
    key = ci * (int(cp.max()) + 1) + cp
    order = np.argsort(key, kind="stable")  # equal pairs stay in file order
    same = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    if not same.size:
        return
    j = same[int(np.argmin(order[same + 1]))]  # the pair whose repetition comes first
    a, b = int(order[j]), int(order[j + 1])
    raise FileFormatError(
        f"{table.path}, lines {table.lines[a]} and {table.lines[b]}: both are image "
        f"{image[a]}'s observation of point {point[a]}; an image observes a point once: "
        "remove one of the two rows"
    )


def _csv(header: list[str], columns: list[list[str]], comments: list[str] = ()) -> str:
    """CSV text; the cells are written as given (id cells come quoted from :func:`_id_cells`,
    the other cells are numbers and names that need no quotes)."""
    lines = [f"# {c}" for c in comments]
    lines.append(",".join(header))
    lines.extend(map(",".join, zip(*columns)))
    return "\n".join(lines) + "\n"


def _id_cells(ids: np.ndarray, what: str) -> list[str]:
    """The cells of an id column: integers as they are; text quoted (inner quotes doubled)
    when the reader would otherwise change it: leading or trailing white space, a leading
    ``#`` (a comment line), a comma or a quote, or the form of an integer (read as one).

    Raises
    ------
    OutputError
        An empty id, or one with a line break or a NUL character (a CSV line cannot hold it).
    """
    cells = list(map(str, ids.tolist()))
    if ids.dtype.kind in "iu":
        return cells
    for k, c in enumerate(cells):
        bad = NO_NAME_CHARS.search(c)
        if not c or bad is not None:
            why = "is empty" if not c else f"holds the character {bad.group()!r}"
            raise OutputError(
                f"cannot write {what} id {c!r} to a CSV block: it {why}, which a CSV line cannot "
                "hold; rename it (Block.replace with new ids), or write a COLMAP or BAL block"
            )
        if c != c.strip() or c[0] == "#" or "," in c or '"' in c or _INT.fullmatch(c):
            cells[k] = '"' + c.replace('"', '""') + '"'
    return cells


def _cells(values: np.ndarray) -> list[str]:
    """Shortest round-trip text, empty for NaN."""
    out = format_floats(values)
    nan = np.isnan(np.asarray(values, dtype=float).ravel())
    if np.any(nan):
        for k in np.flatnonzero(nan).tolist():
            out[k] = ""
    return out


def _length_label(crs: str | None) -> str:
    """The length unit of a block's object coordinates for the files' comment lines: that
    of its CRS (``ftUS`` for EPSG:2263), ``m`` without a CRS (the unit the product labels
    object coordinates with unless told), or the CRS's own words when PROJ cannot name one
    length unit (an unknown or geographic CRS)."""
    if not crs:
        return "m"
    from ..crs import cartesian_crs
    from ..errors import PhotogeomError

    try:
        info = cartesian_crs(crs, what="the block's CRS")
    except PhotogeomError:
        info = None
    if info is None or not info.unit:
        return "the unit of the CRS on the crs: line of points.csv"
    return info.unit


def csv_block_texts(block: Block, *, angle_unit: str = "deg") -> dict[str, str]:
    """The texts of the four CSV files of a block (see :func:`write_csv_block`).

    Their comment lines name the unit of every number: pixels for the calibration and the
    observations, the length unit of the block's CRS (``m`` without one) for projection
    centres, GNSS positions and points, ``angle_unit`` for the angles (also in their
    column names)."""
    unit = normalize_angle_unit(angle_unit)
    if unit not in ("deg", "gon", "rad"):
        raise InputError(f"angle_unit must be deg, gon or rad, not {angle_unit!r}")
    gids = block.camera_ids.tolist()
    camera_cells = _id_cells(block.camera_ids, "camera")
    image_cells = _id_cells(block.image_ids, "image")
    point_cells = _id_cells(block.point_ids, "point")
    cal = np.array(
        [[getattr(c, n) for n in CALIBRATION_NAMES] for c in block.calibrations]
    ).reshape(-1, len(CALIBRATION_NAMES))
    cams = _csv(
        ["camera", "width", "height", *CALIBRATION_NAMES, "free", "image_variant"],
        [
            camera_cells,
            [str(c.width) for c in block.calibrations],
            [str(c.height) for c in block.calibrations],
            *[_cells(cal[:, k]) for k in range(len(CALIBRATION_NAMES))],
            [" ".join(block.free[g]) for g in gids],
            [" ".join(block.image_variant[g]) for g in gids],
        ],
        [
            "Metashape frame calibration in pixels (cx, cy from the image centre); free and "
            "image_variant: parameter names separated by spaces"
        ],
    )
    e = block.exterior
    ang = from_radians(e[:, 3:], unit)
    header = ["id", "camera", "X0", "Y0", "Z0", *[f"{a}_{unit}" for a in _EO_ANGLES]]
    cols = [
        image_cells,
        [camera_cells[g] for g in block.image_camera.tolist()],
        *[_cells(e[:, k]) for k in range(3)],
        *[_cells(ang[:, k]) for k in range(3)],
    ]
    if np.any(block.calibration_offset != 0):
        header += ["df", "dcx", "dcy"]
        cols += [_cells(block.calibration_offset[:, k]) for k in range(3)]
    if np.any(np.isfinite(block.gnss)):
        header += [f"gnss_{a}" for a in "XYZ"] + [f"gnss_s{a}" for a in "XYZ"]
        cols += [_cells(block.gnss[:, k]) for k in range(3)]
        cols += [_cells(block.gnss_sigma[:, k]) for k in range(3)]
    if np.any(np.isfinite(block.imu)):
        header += [f"imu_{a}_{unit}" for a in _EO_ANGLES]
        header += [f"imu_s{a}_{unit}" for a in _EO_ANGLES]
        im, ims = from_radians(block.imu, unit), from_radians(block.imu_sigma, unit)
        cols += [_cells(im[:, k]) for k in range(3)] + [_cells(ims[:, k]) for k in range(3)]
    kept = None if block.colmap_images is None else block.colmap_images.lookup(block.image_ids)
    if kept is not None:  # read from COLMAP: its IMAGE_ID and NAME, for write_colmap
        header += ["colmap_image_id", "colmap_name"]
        cols += [
            list(map(str, kept[0].tolist())),
            _id_cells(np.asarray(kept[1]).astype(str), "COLMAP image name"),
        ]
    length = _length_label(block.crs)
    # one comment line, as before the optional columns were described (a reader that skips
    # a fixed number of lines keeps working)
    described = [
        f"exterior orientation: projection centre X0, Y0, Z0 in {length}, omega, phi, kappa "
        f"in {unit} (M = M3(kappa) M2(phi) M1(omega), object -> image)"
    ]
    if "df" in header:
        described.append("df, dcx, dcy: per-image offsets of f, cx, cy in pixels")
    if "gnss_X" in header:
        described.append(
            f"gnss_X, gnss_Y, gnss_Z: GNSS projection centre and gnss_sX, gnss_sY, gnss_sZ "
            f"its standard deviations in {length}"
        )
    if "imu_omega_" + unit in header:
        described.append(f"imu_*: IMU attitude and imu_s* its standard deviations in {unit}")
    imgs = _csv(header, cols, ["; ".join(described)])
    comments = [
        f"object coordinates X, Y, Z in {length}; sX, sY, sZ: standard deviations of "
        f"surveyed points in {length}"
    ]
    head = ["id", "role", "X", "Y", "Z", "sX", "sY", "sZ"]
    cols = [
        point_cells,
        block.role.tolist(),
        *[_cells(block.xyz[:, k]) for k in range(3)],
        *[_cells(block.point_sigma[:, k]) for k in range(3)],
    ]
    if block.surveyed is not None:
        comments.append(
            "X, Y, Z: adjusted (check points triangulated); surveyed_X, surveyed_Y, "
            f"surveyed_Z: the survey of control and check points, in {length}"
        )
        head += [f"surveyed_{a}" for a in "XYZ"]
        cols += [_cells(block.surveyed[:, k]) for k in range(3)]
    if block.crs:
        # one comment line: a multi-line (pretty) WKT is written with its line breaks and
        # indentation as single spaces, the same CRS (WKT ignores white space between
        # its tokens)
        comments.append("crs: " + " ".join(block.crs.split()))
    pts = _csv(head, cols, comments)
    o = block.observations
    obs = _csv(
        ["image_id", "point_id", "u", "v", "sigma"],
        [
            [image_cells[i] for i in block.obs_image.tolist()],
            [point_cells[j] for j in block.obs_point.tolist()],
            _cells(o.uv[:, 0]),
            _cells(o.uv[:, 1]),
            _cells(o.sigma),
        ],
        ["pixels: centre of the top-left pixel at (0, 0), u right, v down; sigma in pixels"],
    )
    return {
        "cameras.csv": cams,
        "images.csv": imgs,
        "points.csv": pts,
        "observations.csv": obs,
    }


def record_files(block: Block, directory: Path) -> dict[Path, bytes]:
    """The files of the record of the joint adjustment with grids that ``block`` is the final
    fit of (``Block.joint_adjustment``) in the CSV block folder ``directory``: its folder
    ``joint_adjustment``; none without a record."""
    rec = block.joint_adjustment
    if rec is None:
        return {}
    from ..calibration.in_adjustment import RECORD_FOLDER

    d = Path(directory) / RECORD_FOLDER
    return {d / k: v.encode("utf-8") for k, v in rec.texts().items()}


def remove_stale_record(directory: Path, written: Mapping[Path, bytes] | None = None) -> None:
    """Remove the record of a joint adjustment with grids (folder ``joint_adjustment``, its
    settings first) from the CSV block folder ``directory``, just written with a block that
    has none: it belongs to a block written there before.

    Parameters
    ----------
    directory : Path
        The CSV block folder written.
    written : mapping of Path -> bytes, optional
        The files written with the block (:func:`record_files` among them for a block with
        a record): a record among them is the block's own and stays.

    Raises
    ------
    OutputError
        A file of the record that cannot be removed.
    """
    from ..calibration.in_adjustment import RECORD_FOLDER, RECORD_SETTINGS

    stale = Path(directory) / RECORD_FOLDER
    if written is not None and stale / RECORD_SETTINGS in written:
        return
    for name in (RECORD_SETTINGS, *FILES):
        if (stale / name).is_file():
            try:
                (stale / name).unlink()
            except OSError as exc:
                raise OutputError(
                    f"cannot remove {stale / name}, the record of a joint adjustment with "
                    f"grids that the block written to {directory} does not have: {exc}; "
                    "remove the folder yourself"
                ) from None
    if stale.is_dir() and not any(stale.iterdir()):
        stale.rmdir()


def write_csv_block(block: Block, directory: str | os.PathLike, *, angle_unit: str = "deg") -> Path:
    """Write a block as a folder of CSV files (created if missing; see the module docstring).

    All four files are formatted first, then each is replaced atomically. The block of the
    final fit of :func:`~photogeom.calibration.adjust_with_grids` is written with the record
    of its joint adjustment (folder ``joint_adjustment``); a block without a record removes
    that folder's files.

    Parameters
    ----------
    block : Block
        The block to write.
    directory : path-like
        The folder (created with its parents when missing).
    angle_unit : {"deg", "gon", "rad"}
        Unit of the angles written, named in the column headers.

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    OutputError
        A text id that a CSV line cannot hold (empty, a line break, NUL), or a folder that
        cannot be written.
    """
    texts = csv_block_texts(block, angle_unit=angle_unit)
    d = Path(directory)
    from .io_formats import check_block_target, write_files  # (io_formats imports this module)

    check_block_target(d, "csv")
    files = {d / k: v.encode("utf-8") for k, v in texts.items()} | record_files(block, d)
    write_files(files, folders=sorted({f.parent for f in files}))
    remove_stale_record(d, files)
    return d
