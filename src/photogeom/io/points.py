"""Point files: CSV with a header, an id column and named coordinate columns.

Format
------
* Lines starting with ``#`` (comments) and blank lines are skipped anywhere in the file.
* The first other line is the header. Columns are separated by commas (or, if the header
  has no comma, by semicolons, tabs or runs of white space).
* An ``id`` column names each point; ids are text (``"7"`` and ``"07"`` differ).
* Coordinate columns are chosen by name; without a choice the first complete set of
  :data:`DEFAULT_COLUMN_SETS` found in the header is used (``x,y,z``, ``x,y``, ``X,Y,Z``,
  ``X,Y``, ``E,N,H``, ``E,N``, ``col,row``, ...).
* An optional ``role`` column says ``control`` (enters the estimate) or ``check`` (does not;
  reported separately). Points without a role column are control points.
* An optional ``weight`` column (per-point weight, unitless) or ``sigma`` column (per-point
  standard deviation in the coordinate unit; weight = 1 / sigma^2) weights the points.

Example::

    # fiducial marks, mm
    id,role,x,y,X,Y
    1,control,113.016,0.002,243.031,130.007
    5,check,113.008,112.995,243.016,243.001
"""

from __future__ import annotations

import csv
import io
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from .atomic import atomic_write_text

#: Coordinate column sets tried, in this order, when none is given.
DEFAULT_COLUMN_SETS: tuple[tuple[str, ...], ...] = (
    ("x", "y", "z"),
    ("x", "y"),
    ("X", "Y", "Z"),
    ("X", "Y"),
    ("E", "N", "H"),
    ("E", "N"),
    ("easting", "northing", "height"),
    ("easting", "northing"),
    ("col", "row"),
)

#: Default (source, target) column sets of a file holding both coordinate sets.
DEFAULT_PAIR_COLUMN_SETS: tuple[tuple[tuple[str, ...], tuple[str, ...]], ...] = (
    (("x", "y", "z"), ("X", "Y", "Z")),
    (("x", "y"), ("X", "Y")),
    (("x1", "y1", "z1"), ("x2", "y2", "z2")),
    (("x1", "y1"), ("x2", "y2")),
    (("col", "row"), ("x", "y")),
    (("col", "row"), ("X", "Y", "Z")),
)

ID_COLUMNS = ("id", "point", "point_id", "name")
ROLE_COLUMN = "role"
WEIGHT_COLUMNS = ("weight", "w")
SIGMA_COLUMNS = ("sigma", "sd", "std")
ROLES = ("control", "check")


@dataclass(frozen=True)
class PointTable:
    """Points read from a file.

    Attributes
    ----------
    ids : tuple of str
        Point ids, in file order.
    coords : numpy.ndarray, shape (n, d)
        Coordinates (float64) in the columns ``columns``.
    roles : numpy.ndarray of str or None, shape (n,)
        ``"control"`` or ``"check"`` per point; None when the file has no role column.
    weights : numpy.ndarray or None, shape (n,)
        Per-point weights (from a weight column, or 1 / sigma^2 from a sigma column).
    columns : tuple of str
        Names of the coordinate columns, in the order of ``coords``.
    path : pathlib.Path or None
        File the table was read from.
    weight_source : str or None
        Name of the column the weights came from.
    header : tuple of str
        All column names of the file.
    comments : tuple of str
        Comment lines of the file (without ``#``), e.g. its source and units.
    """

    ids: tuple[str, ...]
    coords: np.ndarray
    roles: np.ndarray | None = None
    weights: np.ndarray | None = None
    columns: tuple[str, ...] = ()
    path: Path | None = None
    weight_source: str | None = None
    header: tuple[str, ...] = ()
    comments: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def dim(self) -> int:
        """Coordinate dimension."""
        return int(self.coords.shape[1])

    @property
    def check_mask(self) -> np.ndarray:
        """Boolean mask of check points (all False without a role column)."""
        return _check_mask(self.roles, len(self.ids))


@dataclass(frozen=True)
class PointPairs:
    """Corresponding points of a source and a target system.

    Unpacks as ``ids, source, target, roles, weights`` (so
    ``ids, src, dst, roles, w = join_points(a, b)`` works).

    Attributes
    ----------
    ids : tuple of str
    source, target : numpy.ndarray, shape (n, d_source) and (n, d_target)
    roles : numpy.ndarray of str or None
        ``"control"`` / ``"check"`` per pair; None when no file has a role column.
    weights : numpy.ndarray or None
        Per-pair weights.
    source_columns, target_columns : tuple of str
    unmatched_source, unmatched_target : tuple of str
        Ids found only in the source (target) file and left out of the pairs.
    notes : tuple of str
        Remarks to show the user (e.g. the ids left out).
    """

    ids: tuple[str, ...]
    source: np.ndarray
    target: np.ndarray
    roles: np.ndarray | None = None
    weights: np.ndarray | None = None
    source_columns: tuple[str, ...] = ()
    target_columns: tuple[str, ...] = ()
    unmatched_source: tuple[str, ...] = ()
    unmatched_target: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default=())

    def __iter__(self) -> Iterator:
        return iter((self.ids, self.source, self.target, self.roles, self.weights))

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def check_mask(self) -> np.ndarray:
        """Boolean mask of check points (all False without roles)."""
        return _check_mask(self.roles, len(self.ids))


def _check_mask(roles: np.ndarray | None, n: int) -> np.ndarray:
    if roles is None:
        return np.zeros(n, dtype=bool)
    return roles == "check"


# --------------------------------------------------------------------------------------------
# low-level parsing


@dataclass(frozen=True)
class _RawTable:
    path: Path | None
    header: tuple[str, ...]
    rows: list[list[str]]
    line_numbers: list[int]
    comments: tuple[str, ...]

    def column(self, name: str) -> list[str]:
        j = self.header.index(name)
        return [r[j] for r in self.rows]

    @property
    def label(self) -> str:
        return str(self.path) if self.path is not None else "point table"


def _read_text(path: str | os.PathLike) -> str:
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise FileFormatError(f"cannot read {p}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"cannot read {p}: it is a directory, not a CSV file") from None
    except PermissionError:
        raise FileFormatError(f"cannot read {p}: permission denied") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {p}: {exc.strerror or exc}") from None
    if b"\x00" in data[:4096]:
        raise FileFormatError(f"cannot read {p}: it looks like a binary file, not a CSV text file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        try:
            return data.decode("latin-1")
        except UnicodeDecodeError as exc:  # pragma: no cover - latin-1 decodes any byte
            raise FileFormatError(f"cannot read {p}: not a text file ({exc})") from None


def _split_function(header_line: str):
    if "," in header_line:
        return lambda lines: csv.reader(lines, delimiter=",", skipinitialspace=True)
    if ";" in header_line:
        return lambda lines: csv.reader(lines, delimiter=";", skipinitialspace=True)
    if "\t" in header_line:
        return lambda lines: csv.reader(lines, delimiter="\t", skipinitialspace=True)
    return lambda lines: (re.split(r"\s+", ln.strip()) for ln in lines)


def _parse(text: str, path: Path | None) -> _RawTable:
    label = str(path) if path is not None else "point table"
    comments: list[str] = []
    body: list[str] = []
    numbers: list[int] = []
    for k, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            comments.append(stripped[1:].strip())
            continue
        body.append(line)
        numbers.append(k)
    if not body:
        raise FileFormatError(
            f"{label}: no header line and no data (the file is empty or all comments)"
        )
    reader = _split_function(body[0])
    parsed = [[c.strip() for c in row] for row in reader(body)]
    header = tuple(parsed[0])
    if any(not h for h in header):
        raise FileFormatError(
            f"{label}, line {numbers[0]}: the header has an empty column name: {body[0]!r}"
        )
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise FileFormatError(
            f"{label}: column name(s) {', '.join(dup)} appear more than once in the header"
        )
    if all(_is_number(h) for h in header):
        raise FileFormatError(
            f"{label}, line {numbers[0]}: the first line holds numbers, not column names; "
            "a header line such as 'id,x,y' is required"
        )
    rows = parsed[1:]
    lines = numbers[1:]
    for row, ln in zip(rows, lines):
        if len(row) != len(header):
            raise FileFormatError(
                f"{label}, line {ln}: {len(row)} field(s) but the header has {len(header)} "
                f"({', '.join(header)})"
            )
    return _RawTable(path, header, rows, lines, tuple(comments))


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _find(header: Sequence[str], name: str) -> str | None:
    """Exact column match, else a unique case-insensitive match."""
    if name in header:
        return name
    hits = [h for h in header if h.lower() == name.lower()]
    return hits[0] if len(hits) == 1 else None


def _resolve_columns(raw: _RawTable, wanted: Sequence[str], what: str) -> tuple[str, ...]:
    found = [_find(raw.header, c) for c in wanted]
    missing = [c for c, f in zip(wanted, found) if f is None]
    if missing:
        raise FileFormatError(
            f"{raw.label}: {what} column(s) {', '.join(missing)} not found; the file has columns "
            f"{', '.join(raw.header)} (choose others by name, e.g. --source-cols x,y)"
        )
    return tuple(f for f in found if f is not None)


def _auto_columns(raw: _RawTable, exclude: Sequence[str] = ()) -> tuple[str, ...]:
    for cand in DEFAULT_COLUMN_SETS:
        if any(c in exclude for c in cand):
            continue
        if all(c in raw.header for c in cand):
            return cand
    expected = " or ".join(",".join(c) for c in DEFAULT_COLUMN_SETS)
    raise FileFormatError(
        f"{raw.label}: no coordinate columns found; the file has columns {', '.join(raw.header)}, "
        f"expected {expected} (or name the columns to use)"
    )


def _numbers(raw: _RawTable, columns: Sequence[str], ids: Sequence[str]) -> np.ndarray:
    idx = [raw.header.index(c) for c in columns]
    cells = [[row[j] for j in idx] for row in raw.rows]
    try:
        arr = np.array(cells, dtype=np.float64).reshape(len(raw.rows), len(columns))
    except ValueError:
        for row, ln in zip(cells, raw.line_numbers):
            for c, v in zip(columns, row):
                if not _is_number(v):
                    shown = "an empty field" if v == "" else repr(v)
                    raise FileFormatError(
                        f"{raw.label}, line {ln}: column {c} holds {shown}, not a number"
                    ) from None
        raise  # pragma: no cover
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        where = [f"{ids[i]} (line {raw.line_numbers[i]})" for i in np.flatnonzero(bad)[:10]]
        more = " ..." if bad.sum() > 10 else ""
        raise InputError(
            f"{raw.label}: {int(bad.sum())} point(s) have NaN or infinite coordinates in "
            f"{', '.join(columns)}: {', '.join(where)}{more}; fix or remove them"
        )
    return arr


def _ids(raw: _RawTable, id_column: str | None) -> tuple[tuple[str, ...], str | None]:
    name = None
    if id_column is not None:
        name = _find(raw.header, id_column)
        if name is None:
            raise FileFormatError(
                f"{raw.label}: id column {id_column!r} not found; the file has columns "
                f"{', '.join(raw.header)}"
            )
    else:
        for cand in ID_COLUMNS:
            name = _find(raw.header, cand)
            if name is not None:
                break
    if name is None:
        raise FileFormatError(
            f"{raw.label}: no id column; the file has columns {', '.join(raw.header)}, "
            f"expected one named {' or '.join(ID_COLUMNS)}"
        )
    ids = tuple(raw.column(name))
    empty = [ln for v, ln in zip(ids, raw.line_numbers) if v == ""]
    if empty:
        raise FileFormatError(
            f"{raw.label}: empty point id on line(s) {', '.join(map(str, empty[:10]))}"
        )
    _check_unique(ids, raw.label)
    return ids, name


def _check_unique(ids: Sequence[str], label: str) -> None:
    seen: dict[str, int] = {}
    for v in ids:
        seen[v] = seen.get(v, 0) + 1
    dup = [k for k, c in seen.items() if c > 1]
    if dup:
        shown = ", ".join(f"{d} ({seen[d]}x)" for d in dup[:10])
        raise InputError(
            f"{label}: duplicate point id(s) {shown}{' ...' if len(dup) > 10 else ''}; "
            "every id must appear once"
        )


def _roles(raw: _RawTable, role_column: str | None) -> np.ndarray | None:
    if role_column is None:
        return None
    name = _find(raw.header, role_column)
    if name is None:
        return None
    vals = np.array([v.lower() for v in raw.column(name)], dtype=object)
    vals[vals == ""] = "control"
    bad = ~np.isin(vals, ROLES)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{raw.label}, line {raw.line_numbers[i]}: role "
            f"{raw.rows[i][raw.header.index(name)]!r} is neither 'control' nor 'check'"
        )
    return vals.astype(str)


def _weights(
    raw: _RawTable,
    ids: Sequence[str],
    weight_column: str | None,
    sigma_column: str | None,
    auto: bool,
) -> tuple[np.ndarray | None, str | None]:
    if weight_column is not None and sigma_column is not None:
        raise InputError("give a weight column or a sigma column, not both")
    wname = sname = None
    if weight_column is not None:
        wname = _resolve_columns(raw, [weight_column], "weight")[0]
    elif sigma_column is not None:
        sname = _resolve_columns(raw, [sigma_column], "sigma")[0]
    elif auto:
        wname = next((c for c in WEIGHT_COLUMNS if c in raw.header), None)
        if wname is None:
            sname = next((c for c in SIGMA_COLUMNS if c in raw.header), None)
    if wname is None and sname is None:
        return None, None
    col = wname or sname
    v = _numbers(raw, [col], ids)[:, 0]
    if np.any(v <= 0):
        i = int(np.flatnonzero(v <= 0)[0])
        raise InputError(
            f"{raw.label}, line {raw.line_numbers[i]}: {col} of point {ids[i]} is {v[i]:g}; "
            f"every {'weight' if wname else 'sigma'} must be > 0"
        )
    return (v if wname else 1.0 / v**2), col


# --------------------------------------------------------------------------------------------
# public reading functions


def read_points(
    path: str | os.PathLike,
    columns: Sequence[str] | str | None = None,
    *,
    id_column: str | None = None,
    role_column: str | None = ROLE_COLUMN,
    weight_column: str | None = None,
    sigma_column: str | None = None,
    auto_weights: bool = True,
) -> PointTable:
    """Read a point CSV.

    Parameters
    ----------
    path : path-like
        CSV file with a header line (see the module documentation for the format).
    columns : sequence of str or comma-separated str, optional
        Coordinate columns, e.g. ``("X", "Y", "Z")`` or ``"col,row"``. Default: the first
        complete set of :data:`DEFAULT_COLUMN_SETS` in the header.
    id_column : str, optional
        Name of the id column (default: ``id``, ``point``, ``point_id`` or ``name``).
    role_column : str or None
        Column with ``control`` / ``check`` (default ``role``; ignored when absent;
        None: ignore roles).
    weight_column, sigma_column : str, optional
        Column of per-point weights (unitless) or standard deviations (coordinate unit;
        weight = 1 / sigma^2).
    auto_weights : bool
        Without an explicit column, use a column named ``weight``/``w`` or ``sigma``/``sd``/
        ``std`` if there is one.

    Returns
    -------
    PointTable

    Raises
    ------
    FileFormatError
        The file cannot be read, has no header, lacks the columns asked for (the message lists
        the columns found), or holds text where numbers are expected.
    InputError
        Duplicate ids, NaN / infinite coordinates, weights <= 0.
    """
    p = Path(path)
    raw = _parse(_read_text(p), p)
    return _table(raw, columns, id_column, role_column, weight_column, sigma_column, auto_weights)


def parse_points(
    text: str,
    columns: Sequence[str] | str | None = None,
    *,
    id_column: str | None = None,
    role_column: str | None = ROLE_COLUMN,
    weight_column: str | None = None,
    sigma_column: str | None = None,
    auto_weights: bool = True,
) -> PointTable:
    """:func:`read_points` on CSV text instead of a file (same arguments)."""
    raw = _parse(text, None)
    return _table(raw, columns, id_column, role_column, weight_column, sigma_column, auto_weights)


def _as_names(columns: Sequence[str] | str | None) -> tuple[str, ...] | None:
    if columns is None:
        return None
    if isinstance(columns, str):
        columns = [c for c in re.split(r"[,\s]+", columns.strip()) if c]
    names = tuple(str(c) for c in columns)
    if not 1 <= len(names) <= 3:
        raise InputError(
            f"give 2 or 3 coordinate column names, got {len(names)}: {', '.join(names)}"
        )
    return names


def _table(raw, columns, id_column, role_column, weight_column, sigma_column, auto_weights):
    ids, _ = _ids(raw, id_column)
    names = _as_names(columns)
    cols = _resolve_columns(raw, names, "coordinate") if names else _auto_columns(raw)
    coords = _numbers(raw, cols, ids)
    roles = _roles(raw, role_column)
    weights, wsrc = _weights(raw, ids, weight_column, sigma_column, auto_weights)
    return PointTable(
        ids=ids,
        coords=coords,
        roles=roles,
        weights=weights,
        columns=cols,
        path=raw.path,
        weight_source=wsrc,
        header=raw.header,
        comments=raw.comments,
    )


def read_point_pairs(
    path: str | os.PathLike,
    source_columns: Sequence[str] | str | None = None,
    target_columns: Sequence[str] | str | None = None,
    *,
    id_column: str | None = None,
    role_column: str | None = ROLE_COLUMN,
    weight_column: str | None = None,
    sigma_column: str | None = None,
    auto_weights: bool = True,
) -> PointPairs:
    """Read one CSV that holds both coordinate sets of each point.

    Default columns: the first pair of :data:`DEFAULT_PAIR_COLUMN_SETS` present in the
    header (``x,y,z`` -> ``X,Y,Z``; ``x,y`` -> ``X,Y``; ``x1,y1`` -> ``x2,y2``; ...).
    The other arguments are those of :func:`read_points`.

    Raises
    ------
    FileFormatError, InputError
        As :func:`read_points`; also when source and target columns overlap.
    """
    p = Path(path)
    raw = _parse(_read_text(p), p)
    ids, _ = _ids(raw, id_column)
    src_names, dst_names = _as_names(source_columns), _as_names(target_columns)
    if src_names is None and dst_names is None:
        for s_c, t_c in DEFAULT_PAIR_COLUMN_SETS:
            if all(c in raw.header for c in s_c + t_c):
                src_names, dst_names = s_c, t_c
                break
        else:
            expected = "; ".join(
                f"{','.join(s)} and {','.join(t)}" for s, t in DEFAULT_PAIR_COLUMN_SETS
            )
            raise FileFormatError(
                f"{raw.label}: cannot tell which columns hold the source and target coordinates; "
                f"the file has columns {', '.join(raw.header)}, expected {expected} "
                "(or name them, e.g. --source-cols x2,y2 --target-cols x1,y1)"
            )
    elif src_names is None:
        t_cols = _resolve_columns(raw, dst_names, "target coordinate")
        src_names = _auto_columns(raw, exclude=t_cols)
    elif dst_names is None:
        s_cols = _resolve_columns(raw, src_names, "source coordinate")
        dst_names = _auto_columns(raw, exclude=s_cols)
    s_cols = _resolve_columns(raw, src_names, "source coordinate")
    t_cols = _resolve_columns(raw, dst_names, "target coordinate")
    overlap = sorted(set(s_cols) & set(t_cols))
    if overlap:
        raise InputError(
            f"{raw.label}: column(s) {', '.join(overlap)} chosen for both source and target "
            "coordinates"
        )
    src = _numbers(raw, s_cols, ids)
    dst = _numbers(raw, t_cols, ids)
    roles = _roles(raw, role_column)
    weights, _ = _weights(raw, ids, weight_column, sigma_column, auto_weights)
    return PointPairs(
        ids=ids,
        source=src,
        target=dst,
        roles=roles,
        weights=weights,
        source_columns=s_cols,
        target_columns=t_cols,
    )


def join_points(
    source: PointTable,
    target: PointTable,
    *,
    allow_unmatched: bool = False,
) -> PointPairs:
    """Pair the points of two tables by id (in the order of ``source``).

    Parameters
    ----------
    source, target : PointTable
    allow_unmatched : bool
        Ids found in only one table raise :class:`InputError` listing them (default). With
        ``True`` they are left out, listed in ``PointPairs.unmatched_source`` /
        ``unmatched_target`` and in ``PointPairs.notes``.

    Returns
    -------
    PointPairs
        Unpacks as ``ids, source, target, roles, weights``. Roles come from whichever table
        has a role column (they must agree if both have one); weights likewise.

    Raises
    ------
    InputError
        Duplicate ids in a table, ids in only one table (unless ``allow_unmatched``), no
        common id, or conflicting roles / weights.
    """
    s_label = str(source.path) if source.path else "source"
    t_label = str(target.path) if target.path else "target"
    _check_unique(source.ids, s_label)
    _check_unique(target.ids, t_label)
    t_index = {pid: k for k, pid in enumerate(target.ids)}
    s_set = set(source.ids)
    only_s = tuple(pid for pid in source.ids if pid not in t_index)
    only_t = tuple(pid for pid in target.ids if pid not in s_set)
    notes: list[str] = []
    if only_s or only_t:
        parts = []
        if only_s:
            parts.append(f"only in {s_label}: {_list(only_s)}")
        if only_t:
            parts.append(f"only in {t_label}: {_list(only_t)}")
        if not allow_unmatched:
            raise InputError(
                "point ids do not match between the files (" + "; ".join(parts) + "); "
                "fix the ids, or allow unmatched points to leave them out"
            )
        notes.append("left out, no partner: " + "; ".join(parts))
    si = np.array([k for k, pid in enumerate(source.ids) if pid in t_index], dtype=int)
    if si.size == 0:
        raise InputError(f"{s_label} and {t_label} have no point id in common")
    ti = np.array([t_index[source.ids[k]] for k in si], dtype=int)
    ids = tuple(source.ids[k] for k in si)

    roles = None
    s_roles = None if source.roles is None else source.roles[si]
    t_roles = None if target.roles is None else target.roles[ti]
    if s_roles is not None and t_roles is not None:
        diff = np.flatnonzero(s_roles != t_roles)
        if diff.size:
            raise InputError(
                f"point role differs between the files for id(s) {_list([ids[k] for k in diff])}"
            )
    roles = s_roles if s_roles is not None else t_roles

    s_w = None if source.weights is None else source.weights[si]
    t_w = None if target.weights is None else target.weights[ti]
    if s_w is not None and t_w is not None and not np.allclose(s_w, t_w, rtol=1e-12, atol=0):
        raise InputError(
            "both files give point weights and they differ; keep the weight (or sigma) column "
            "in one file only"
        )
    weights = t_w if t_w is not None else s_w
    return PointPairs(
        ids=ids,
        source=source.coords[si],
        target=target.coords[ti],
        roles=roles,
        weights=weights,
        source_columns=source.columns,
        target_columns=target.columns,
        unmatched_source=only_s,
        unmatched_target=only_t,
        notes=tuple(notes),
    )


def _list(ids: Sequence[str], limit: int = 20) -> str:
    ids = list(ids)
    shown = ", ".join(ids[:limit])
    return shown + (f" ... ({len(ids)} in all)" if len(ids) > limit else "")


# --------------------------------------------------------------------------------------------
# writing


def format_points_csv(
    ids: Sequence,
    coords: np.ndarray,
    columns: Sequence[str],
    *,
    extra: dict[str, Sequence] | None = None,
    comments: Sequence[str] = (),
) -> str:
    """CSV text of points: optional ``# comment`` lines, header ``id,<columns>,<extra>``, rows.

    Numbers are written with the shortest representation that reads back to the same
    float64 (lossless round trip).
    """
    coords = np.asarray(coords, dtype=float)
    if coords.ndim != 2 or coords.shape[1] != len(columns):
        raise InputError(f"{len(columns)} column name(s) for coordinates of shape {coords.shape}")
    if len(ids) != coords.shape[0]:
        raise InputError(f"{len(ids)} id(s) for {coords.shape[0]} point(s)")
    extra = dict(extra or {})
    for k, v in extra.items():
        if len(v) != coords.shape[0]:
            raise InputError(f"column {k}: {len(v)} value(s) for {coords.shape[0]} point(s)")
    buf = io.StringIO()
    for c in comments:
        for line in str(c).splitlines() or [""]:
            buf.write(f"# {line}\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["id", *columns, *extra])
    cols = [coords[:, j].tolist() for j in range(coords.shape[1])]
    extra_cols = [list(v) for v in extra.values()]
    writer.writerows(
        [str(pid), *(repr(c[k]) for c in cols), *(_cell(e[k]) for e in extra_cols)]
        for k, pid in enumerate(ids)
    )
    return buf.getvalue()


def _cell(v) -> str:
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(v)


def write_points(
    path: str | os.PathLike,
    ids: Sequence,
    coords: np.ndarray,
    columns: Sequence[str],
    *,
    extra: dict[str, Sequence] | None = None,
    comments: Sequence[str] = (),
) -> Path:
    """Write points as CSV, atomically (see :func:`format_points_csv` for the layout)."""
    text = format_points_csv(ids, coords, columns, extra=extra, comments=comments)
    return atomic_write_text(path, text)
