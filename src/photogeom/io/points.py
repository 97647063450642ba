"""Point files: CSV with a header, an id column and named coordinate columns.

Format
------
* Lines starting with ``#`` (comments) and blank lines are skipped anywhere in the file.
* The first other line is the header. Columns are separated by commas (or, if the header
  has no comma, by semicolons, tabs or runs of white space).
* An ``id`` column names each point; ids are text (``"7"`` and ``"07"`` differ).
* Coordinate columns are chosen by name; without a choice the first complete set of
  :data:`DEFAULT_COLUMN_SETS` found in the header is used (``x,y,z``, ``x,y``, ``X,Y,Z``,
  ``X,Y``, ``E,N,H``, ``E,N,U``, ``E,N``, ``col,row``, ...).
* An optional ``role`` column says ``control`` (enters the estimate) or ``check`` (does not;
  reported separately). Points without a role column are control points.
* An optional ``weight`` column (per-point weight, unitless) or ``sigma`` column (per-point
  standard deviation in the coordinate unit; weight = 1 / sigma^2) weights the points.

* A quoted field (``"P,1"``) must close on its line; fields are at most 128 KiB; every line
  has as many fields as the header. Anything else is refused with the line number.

Example::

    # fiducial marks, mm
    id,role,x,y,X,Y
    1,control,113.016,0.002,243.031,130.007
    5,check,113.008,112.995,243.016,243.001

Reading and writing
-------------------
Files are parsed block by block by :mod:`photogeom.io.csvblocks` (pyarrow's CSV reader;
small files in Python, by the same rules), so reading is linear in the file size.
:func:`read_points` and :func:`read_point_pairs` return whole tables; :class:`PointBlocks`
yields blocks of any file with the memory of one block, for jobs that treat each point on
its own. :class:`PointWriter` writes chunks (numbers as the shortest text that reads back to
the same float64) to a file renamed into place at the end; :func:`format_points_csv` and
:func:`write_points` are its one-chunk forms.
"""

from __future__ import annotations

import os
import re
import unicodedata
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from ..records import ReadOnlyRecord
from .csvblocks import DelimitedText

#: Coordinate column sets tried, in this order, when none is given.
DEFAULT_COLUMN_SETS: tuple[tuple[str, ...], ...] = (
    ("x", "y", "z"),
    ("x", "y"),
    ("X", "Y", "Z"),
    ("X", "Y"),
    ("E", "N", "H"),
    ("E", "N", "U"),
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


@dataclass(frozen=True, eq=False)
class PointTable(ReadOnlyRecord):
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
    weights_from_sigma : bool
        The weights are ``1 / sigma^2`` of a sigma column (standard deviations in the
        coordinate unit), not unitless weights: with an a-priori sigma0 ``s0`` the weight
        of the adjustment is ``s0^2 / sigma^2``.
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
    weights_from_sigma: bool = False
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


@dataclass(frozen=True, eq=False)
class PointPairs(ReadOnlyRecord):
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
    weights_from_sigma : bool
        The weights are ``1 / sigma^2`` of a sigma column (see :class:`PointTable`).
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
    weights_from_sigma: bool = False
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
# low-level reading


class _Source:
    """A point file opened for reading: its header and the columns read from it."""

    def __init__(self, path: Path | None = None, data: bytes | None = None) -> None:
        self.text = DelimitedText(path, data)
        self.path = path
        self.header = self.text.header
        self.label = self.text.label

    def read(self, strings: Sequence[str], numbers: Sequence[str]) -> tuple[dict, dict]:
        """Whole columns: strings as lists of str, numbers as float64 arrays."""
        s_parts: dict[str, list] = {c: [] for c in strings}
        n_parts: dict[str, list] = {c: [] for c in numbers}
        for block in self.text.blocks(strings, numbers, arrow=False):
            for c in strings:
                s_parts[c].append(block.strings[c])
            for c in numbers:
                n_parts[c].append(block.numbers[c])
        out_s = {c: [v for part in parts for v in part] for c, parts in s_parts.items()}
        out_n = {
            c: (np.concatenate(parts) if parts else np.zeros(0)) for c, parts in n_parts.items()
        }
        return out_s, out_n

    @property
    def comments(self) -> tuple[str, ...]:
        return tuple(self.text.comments)

    def lines(self, rows) -> list[int]:
        return self.text.line_numbers(list(rows))


def _source(path: str | os.PathLike) -> _Source:
    return _Source(Path(path))


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
    low = name.lower()
    hits = [h for h in header if h.lower() == low]
    return hits[0] if len(hits) == 1 else None


def _resolve_columns(raw: _Source, wanted: Sequence[str], what: str) -> tuple[str, ...]:
    found = [_find(raw.header, c) for c in wanted]
    missing = [c for c, f in zip(wanted, found) if f is None]
    if missing:
        exc = FileFormatError(
            f"{raw.label}: {what} column(s) {', '.join(missing)} not found; the file has columns "
            f"{_names(raw.header)} ({COLUMN_HINT})"
        )
        exc.column_kind = what  # the command line names its option for this kind
        raise exc
    return tuple(f for f in found if f is not None)


#: End of the message of a missing column: how to choose others (the command line replaces it
#: with its option, e.g. ``--image-cols``).
COLUMN_HINT = "choose others by name"
#: End of the message of a file without any of the default column names (as above).
AUTO_COLUMN_HINT = "(or name the columns to use)"
#: End of the message of a pair file whose source and target columns cannot be told apart
#: (:func:`read_point_pairs`; the command line names its two options instead).
PAIR_COLUMN_HINT = "(or name them, e.g. source_columns='x2,y2', target_columns='x1,y1')"



def _auto_columns(raw: _Source, exclude: Sequence[str] = ()) -> tuple[str, ...]:
    present = set(raw.header)
    for cand in DEFAULT_COLUMN_SETS:
        if any(c in exclude for c in cand):
            continue
        if all(c in present for c in cand):
            return cand
    expected = " or ".join(",".join(c) for c in DEFAULT_COLUMN_SETS)
    raise FileFormatError(
        f"{raw.label}: no coordinate columns found; the file has columns {_names(raw.header)}, "
        f"expected {expected} {AUTO_COLUMN_HINT}"
    )


def _preferred_columns(raw: _Source, preferred: tuple[str, ...]) -> tuple[str, ...]:
    """``preferred`` when the header has them all (exact names) and the usual names are
    missing or as many (a file with x,y,z read as x,y would lose its z: it stays x,y,z and
    the caller names the mismatch); else the usual names (:func:`_auto_columns`)."""
    present = bool(preferred) and all(c in raw.header for c in preferred)
    try:
        found = _auto_columns(raw)
    except FileFormatError:
        if present:
            return preferred
        raise
    return preferred if present and len(found) == len(preferred) else found


def _names(header: Sequence[str], limit: int = 30) -> str:
    shown = ", ".join(header[:limit])
    return shown + (f" ... ({len(header)} in all)" if len(header) > limit else "")


def _finite(raw: _Source, arr: np.ndarray, columns: Sequence[str], ids: Sequence[str]) -> None:
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)[:10]
        lines = raw.lines(rows)
        where = [f"{ids[i]} (line {ln})" for i, ln in zip(rows, lines)]
        more = " ..." if bad.sum() > 10 else ""
        raise InputError(
            f"{raw.label}: {int(bad.sum())} point(s) have NaN or infinite coordinates in "
            f"{', '.join(columns)}: {', '.join(where)}{more}; fix or remove them"
        )


def _id_column(raw: _Source, id_column: str | None) -> str:
    name = None
    if id_column is not None:
        name = _find(raw.header, id_column)
        if name is None:
            raise FileFormatError(
                f"{raw.label}: id column {id_column!r} not found; the file has columns "
                f"{_names(raw.header)}"
            )
        return name
    for cand in ID_COLUMNS:
        name = _find(raw.header, cand)
        if name is not None:
            return name
    raise FileFormatError(
        f"{raw.label}: no id column; the file has columns {_names(raw.header)}, "
        f"expected one named {' or '.join(ID_COLUMNS)}"
    )


def _check_ids(raw: _Source, ids: Sequence[str]) -> None:
    if "" in ids:
        empty = [k for k, v in enumerate(ids) if v == ""][:10]
        raise FileFormatError(
            f"{raw.label}: empty point id on line(s) {', '.join(map(str, raw.lines(empty)))}"
        )
    _check_unique(ids, raw.label)


def _check_unique(ids: Sequence[str], label: str) -> None:
    if len(set(ids)) == len(ids):
        return
    seen: dict[str, int] = {}
    for v in ids:
        seen[v] = seen.get(v, 0) + 1
    dup = [k for k, c in seen.items() if c > 1]
    shown = ", ".join(f"{d} ({seen[d]}x)" for d in dup[:10])
    raise InputError(
        f"{label}: duplicate point id(s) {shown}{' ...' if len(dup) > 10 else ''}; "
        "every id must appear once"
    )


def _role_column(raw: _Source, role_column: str | None) -> str | None:
    if role_column is None:
        return None
    return _find(raw.header, role_column)


def _roles(raw: _Source, name: str | None, values: list[str] | None) -> np.ndarray | None:
    if name is None or values is None:
        return None
    vals = np.array([v.lower() for v in values], dtype=object)
    vals[vals == ""] = "control"
    bad = ~np.isin(vals, ROLES)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{raw.label}, line {raw.lines([i])[0]}: role {values[i]!r} is neither 'control' "
            "nor 'check'"
        )
    return vals.astype(str)


def _weight_column(
    raw: _Source, weight_column: str | None, sigma_column: str | None, auto: bool
) -> tuple[str | None, bool]:
    """Name of the weight (or sigma) column and whether it holds sigmas."""
    if weight_column is not None and sigma_column is not None:
        raise InputError("give a weight column or a sigma column, not both")
    if weight_column is not None:
        return _resolve_columns(raw, [weight_column], "weight")[0], False
    if sigma_column is not None:
        return _resolve_columns(raw, [sigma_column], "sigma")[0], True
    if auto:
        present = set(raw.header)
        w = next((c for c in WEIGHT_COLUMNS if c in present), None)
        if w is not None:
            return w, False
        s = next((c for c in SIGMA_COLUMNS if c in present), None)
        if s is not None:
            return s, True
    return None, False


def _weights(
    raw: _Source, ids: Sequence[str], col: str | None, is_sigma: bool, v: np.ndarray | None
) -> np.ndarray | None:
    if col is None or v is None:
        return None
    _finite(raw, v[:, None], [col], ids)
    with np.errstate(divide="ignore", over="ignore"):
        w = 1.0 / v**2 if is_sigma else v
    bad = ~(v > 0) | ~np.isfinite(w) | ~(w > 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        kind = "sigma" if is_sigma else "weight"
        why = (
            f"every {kind} must be > 0"
            if not v[i] > 0
            else f"the weight {'1 / sigma^2 ' if is_sigma else ''}is not a positive finite "
            "number (too small or too large)"
        )
        raise InputError(
            f"{raw.label}, line {raw.lines([i])[0]}: {col} of point {ids[i]} is {v[i]:g}; {why}"
        )
    return w


def _table(raw, columns, id_column, role_column, weight_column, sigma_column, auto_weights):
    id_name = _id_column(raw, id_column)
    names = _as_names(columns)
    cols = _resolve_columns(raw, names, "coordinate") if names else _auto_columns(raw)
    role_name = _role_column(raw, role_column)
    wcol, is_sigma = _weight_column(raw, weight_column, sigma_column, auto_weights)
    strings = [id_name] + ([role_name] if role_name else [])
    numbers = list(dict.fromkeys([*cols, *([wcol] if wcol else [])]))
    s, n = raw.read(strings, numbers)
    ids = tuple(s[id_name])
    _check_ids(raw, ids)
    coords = _stack(n, cols)
    _finite(raw, coords, cols, ids)
    roles = _roles(raw, role_name, s.get(role_name) if role_name else None)
    weights = _weights(raw, ids, wcol, is_sigma, n.get(wcol) if wcol else None)
    return PointTable(
        ids=ids,
        coords=coords,
        roles=roles,
        weights=weights,
        columns=cols,
        path=raw.path,
        weight_source=wcol,
        weights_from_sigma=bool(is_sigma and weights is not None),
        header=raw.header,
        comments=raw.comments,
    )


def _stack(numbers: dict, cols: Sequence[str]) -> np.ndarray:
    n = len(numbers[cols[0]]) if cols else 0
    out = np.empty((n, len(cols)))
    for j, c in enumerate(cols):
        out[:, j] = numbers[c]
    return out


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
    raw = _source(path)
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
    """:func:`read_points` on CSV text instead of a file (same arguments).

    Parameters
    ----------
    text : str
        CSV text with a header line.
    columns : sequence of str or comma-separated str, optional
        Coordinate columns; default: the first complete set of :data:`DEFAULT_COLUMN_SETS`.
    id_column : str, optional
        Name of the id column (default: ``id``, ``point``, ``point_id`` or ``name``).
    role_column : str or None, default "role"
        Column with ``control`` / ``check`` (ignored when absent; None: ignore roles).
    weight_column, sigma_column : str, optional
        Column of per-point weights (unitless) or standard deviations (coordinate unit;
        weight = 1 / sigma^2).
    auto_weights : bool, default True
        Without an explicit column, use a column named ``weight``/``w`` or ``sigma``/``sd``/
        ``std`` if there is one.

    Returns
    -------
    PointTable

    Raises
    ------
    FileFormatError, InputError
        As :func:`read_points`.
    """
    raw = _Source(None, text.encode("utf-8"))
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


@dataclass(frozen=True, eq=False)
class PointBlock(ReadOnlyRecord):
    """One block of points read by :class:`PointBlocks`.

    Attributes
    ----------
    ids : pyarrow.StringArray
        Point ids (text), in file order.
    coords : numpy.ndarray, shape (n, d)
        Coordinates (float64).
    roles : pyarrow.StringArray or None
        ``control`` / ``check`` per point (a blank role is ``control``), when the file has a
        role column.
    first_row : int
        Index of the block's first point among all points of the file.
    bytes_done : int
        Bytes of the file read so far.
    """

    ids: object
    coords: np.ndarray
    roles: object
    first_row: int
    bytes_done: int

    def __len__(self) -> int:
        return int(self.coords.shape[0])


class PointBlocks:
    """The points of a CSV read block by block, for files of any size.

    Memory use is that of one block (a few MiB of text), whatever the size of the file. The
    checks of :func:`read_points` apply (columns, numbers, NaN, empty ids) except that ids
    are not checked for duplicates, which would need every id of the file in memory; use it
    for jobs that treat each point on its own (projection, transformation).

    Parameters
    ----------
    path : path-like
        Point CSV (format of :func:`read_points`).
    columns : sequence of str or comma-separated str, optional
        Coordinate columns (default: ``prefer_columns`` when the file has all of them, else
        found by name as in :func:`read_points`).
    id_column : str, optional
        Id column (default: ``id``, ``point``, ``point_id`` or ``name``).
    role_column : str or None
        Role column to pass through (``role`` by default, when present).
    block_bytes : int
        Bytes of text per block.
    prefer_columns : sequence of str, optional
        Coordinate columns to read without ``columns`` when the header has every one of
        them (exact names) and the usual names are missing or as many: the input columns
        of a saved estimate, which a file holding both sets of coordinates must not lose to
        ``x,y`` or ``X,Y``.

    Attributes
    ----------
    columns : tuple of str
        Coordinate columns read.
    header : tuple of str
    size : int
        File size in bytes (for progress display).
    has_roles : bool
    """

    def __init__(
        self,
        path: str | os.PathLike,
        columns: Sequence[str] | str | None = None,
        *,
        id_column: str | None = None,
        role_column: str | None = ROLE_COLUMN,
        block_bytes: int = 1 << 20,
        prefer_columns: Sequence[str] | None = None,
    ) -> None:
        self._raw = _Source(Path(path))
        self._raw.text.block_bytes = int(block_bytes)
        self.path = Path(path)
        self.label = self._raw.label
        self.header = self._raw.header
        self._id = _id_column(self._raw, id_column)
        names = _as_names(columns)
        if names:
            self.columns = _resolve_columns(self._raw, names, "coordinate")
        else:
            self.columns = _preferred_columns(self._raw, tuple(prefer_columns or ()))
        self._role = _role_column(self._raw, role_column)
        self.has_roles = self._role is not None
        self.size = self._raw.text.size

    @property
    def dim(self) -> int:
        return len(self.columns)

    @property
    def comments(self) -> tuple[str, ...]:
        """Comment lines read so far (all of them once the blocks are read)."""
        return self._raw.comments

    def __iter__(self) -> Iterator[PointBlock]:
        import pyarrow.compute as pc

        strings = [self._id] + ([self._role] if self._role else [])
        for block in self._raw.text.blocks(strings, self.columns):
            ids = block.strings[self._id]
            if pc.any(pc.equal(ids, "")).as_py():
                empty = np.flatnonzero(pc.equal(ids, "").to_numpy(zero_copy_only=False))[:10]
                lines = self._raw.lines(block.first_row + empty)
                raise FileFormatError(
                    f"{self.label}: empty point id on line(s) {', '.join(map(str, lines))}"
                )
            coords = _stack(block.numbers, self.columns)
            bad = ~np.isfinite(coords).all(axis=1)
            if bad.any():
                rows = np.flatnonzero(bad)[:10]
                lines = self._raw.lines(block.first_row + rows)
                where = [f"{ids[int(i)].as_py()} (line {ln})" for i, ln in zip(rows, lines)]
                raise InputError(
                    f"{self.label}: point(s) with NaN or infinite coordinates in "
                    f"{', '.join(self.columns)}: {', '.join(where)}"
                    f"{' ...' if bad.sum() > 10 else ''}; fix or remove them"
                )
            roles = block.strings[self._role] if self._role else None
            if roles is not None:
                low = pc.utf8_lower(roles)
                ok = pc.is_in(low, value_set=_pa_roles())
                ok = pc.or_(ok, pc.equal(low, ""))
                if not pc.all(ok).as_py():
                    k = int(np.flatnonzero(~ok.to_numpy(zero_copy_only=False))[0])
                    raise FileFormatError(
                        f"{self.label}, line {self._raw.lines([block.first_row + k])[0]}: role "
                        f"{roles[k].as_py()!r} is neither 'control' nor 'check'"
                    )
                roles = pc.if_else(pc.equal(low, ""), "control", low)
            yield PointBlock(ids, coords, roles, block.first_row, block.bytes_done)


def _pa_roles():
    import pyarrow as pa

    return pa.array(list(ROLES))


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

    Parameters
    ----------
    path : str or os.PathLike
        CSV file with a header line.
    source_columns, target_columns : sequence of str or comma-separated str, optional
        Coordinate columns of the source and of the target system (both or neither).
    id_column : str, optional
        Name of the id column (default: ``id``, ``point``, ``point_id`` or ``name``).
    role_column : str or None, default "role"
        Column with ``control`` / ``check`` (ignored when absent; None: ignore roles).
    weight_column, sigma_column : str, optional
        Column of per-point weights (unitless) or standard deviations (coordinate unit;
        weight = 1 / sigma^2).
    auto_weights : bool, default True
        Without an explicit column, use a column named ``weight``/``w`` or ``sigma``/``sd``/
        ``std`` if there is one.

    Returns
    -------
    PointPairs
        Unpacks as ``ids, source, target, roles, weights``.

    Raises
    ------
    FileFormatError, InputError
        As :func:`read_points`; also when source and target columns overlap or cannot be
        told from the header.
    """
    raw = _source(path)
    id_name = _id_column(raw, id_column)
    src_names, dst_names = _as_names(source_columns), _as_names(target_columns)
    present = set(raw.header)
    if src_names is None and dst_names is None:
        for s_c, t_c in DEFAULT_PAIR_COLUMN_SETS:
            if all(c in present for c in s_c + t_c):
                src_names, dst_names = s_c, t_c
                break
        else:
            expected = "; ".join(
                f"{','.join(s)} and {','.join(t)}" for s, t in DEFAULT_PAIR_COLUMN_SETS
            )
            raise FileFormatError(
                f"{raw.label}: cannot tell which columns hold the source and target coordinates; "
                f"the file has columns {_names(raw.header)}, expected {expected} "
                + PAIR_COLUMN_HINT
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
    role_name = _role_column(raw, role_column)
    wcol, is_sigma = _weight_column(raw, weight_column, sigma_column, auto_weights)
    strings = [id_name] + ([role_name] if role_name else [])
    numbers = list(dict.fromkeys([*s_cols, *t_cols, *([wcol] if wcol else [])]))
    s, n = raw.read(strings, numbers)
    ids = tuple(s[id_name])
    _check_ids(raw, ids)
    src = _stack(n, s_cols)
    dst = _stack(n, t_cols)
    _finite(raw, src, s_cols, ids)
    _finite(raw, dst, t_cols, ids)
    roles = _roles(raw, role_name, s.get(role_name) if role_name else None)
    weights = _weights(raw, ids, wcol, is_sigma, n.get(wcol) if wcol else None)
    return PointPairs(
        ids=ids,
        source=src,
        target=dst,
        roles=roles,
        weights=weights,
        weights_from_sigma=bool(is_sigma and weights is not None),
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
        alike = _look_alike(only_s, only_t)
        if alike:
            parts.append(
                "ids that look alike are written with different characters (Unicode forms: "
                + ", ".join(f"{a!a} in {s_label} vs {b!a} in {t_label}" for a, b in alike)
                + "); write them alike in both files"
            )
        if not allow_unmatched:
            raise InputError(
                "point ids do not match between the files (" + "; ".join(parts) + "); "
                "fix the ids, or pass allow_unmatched=True to leave them out"
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

    s_w = None if source.weights is None else _numeric_weights(source.weights, s_label)[si]
    t_w = None if target.weights is None else _numeric_weights(target.weights, t_label)[ti]
    if s_w is not None and t_w is not None and not np.allclose(s_w, t_w, rtol=1e-12, atol=0):
        raise InputError(
            "both files give point weights and they differ; keep the weight (or sigma) column "
            "in one file only"
        )
    weights = t_w if t_w is not None else s_w
    from_sigma = target.weights_from_sigma if t_w is not None else source.weights_from_sigma
    return PointPairs(
        ids=ids,
        source=source.coords[si],
        target=target.coords[ti],
        roles=roles,
        weights=weights,
        weights_from_sigma=bool(weights is not None and from_sigma),
        source_columns=source.columns,
        target_columns=target.columns,
        unmatched_source=only_s,
        unmatched_target=only_t,
        notes=tuple(notes),
    )


def _numeric_weights(weights, label: str) -> np.ndarray:
    """Weights as positive finite float64, or an InputError naming the table."""
    w = np.asarray(weights)
    if w.dtype.kind not in "fiu":
        raise InputError(
            f"{label}: weights must be numbers, not {w.dtype.name} values such as "
            f"{str(w.reshape(-1)[0])!r}; convert them with float() (or read the file with "
            "read_points, which does)"
        )
    w = w.astype(np.float64)
    if not np.all(np.isfinite(w) & (w > 0)):
        raise InputError(f"{label}: weights must be positive finite numbers")
    return w


def _look_alike(a: Sequence[str], b: Sequence[str], limit: int = 5) -> list[tuple[str, str]]:
    """Pairs of ids from ``a`` and ``b`` that differ as text but not in their compatibility
    normal form (NFKC: a composed 'é' against 'e' + combining accent, a no-break space, a
    full-width digit), at most ``limit``: ids are compared as written, never merged."""
    if not a or not b:
        return []
    by_form: dict[str, str] = {}
    for pid in b:
        by_form.setdefault(unicodedata.normalize("NFKC", str(pid)), pid)
    out = []
    for pid in a:
        other = by_form.get(unicodedata.normalize("NFKC", str(pid)))
        if other is not None and other != pid:
            out.append((pid, other))
            if len(out) == limit:
                break
    return out


def _list(ids: Sequence[str], limit: int = 20) -> str:
    ids = list(ids)
    shown = ", ".join(ids[:limit])
    return shown + (f" ... ({len(ids)} in all)" if len(ids) > limit else "")


# --------------------------------------------------------------------------------------------
# writing


class PointWriter:
    """Point CSV output in chunks: ``# comment`` lines, header ``id,<columns>,<extra>``, rows.

    Numbers are written with the shortest representation that reads back to the same
    float64 (a lossless round trip); ids are written as text, quoted only when they hold a
    comma, a quote or a line break or begin with ``#`` (which would make the row a comment
    line when read back). A file is written atomically: rows go to a temporary
    file beside it, renamed over ``path`` when the ``with`` block ends without an error (and
    removed when it ends with one), so a failed job never leaves a half-written file. To the
    standard output (or ``stream``) the comments and the header go out with the first rows,
    so a job that fails before its first rows prints nothing. Large
    chunks are formatted by pyarrow in worker threads (see :mod:`photogeom.io.csvrows`)
    while the caller prepares the next chunk; memory use is that of a few chunks.

    Parameters
    ----------
    path : path-like or None
        Output file; None writes to ``stream``.
    columns : sequence of str
        Coordinate column names.
    extra : sequence of str
        Names of further columns (text or numbers), after the coordinates.
    comments : sequence of str
        Comment lines written before the header.
    stream : binary file, optional
        Where to write when ``path`` is None (default: standard output).

    Examples
    --------
    >>> with PointWriter("out.csv", ["X", "Y"]) as w:  # doctest: +SKIP
    ...     for ids, xy in chunks:
    ...         w.write(ids, xy)
    """

    def __init__(
        self,
        path: str | os.PathLike | None,
        columns: Sequence[str],
        *,
        extra: Sequence[str] = (),
        comments: Sequence[str] = (),
        stream=None,
    ) -> None:
        self.path = Path(path) if path is not None else None
        self.columns = tuple(str(c) for c in columns)
        self.extra = tuple(str(c) for c in extra)
        self.comments = tuple(comments)
        self._stream = stream
        self._fh = None
        self._tmp: str | None = None
        self._rows = None
        self._direct = False  # a device or a named pipe, written in place
        self._pending_head = False  # the header is still to be printed (standard output)
        self.n_written = 0

    def __enter__(self) -> PointWriter:
        if self.path is None:
            import sys

            if self._stream is not None:
                self._fh = self._stream
            else:
                sys.stdout.flush()
                self._fh = getattr(sys.stdout, "buffer", None) or _TextSink(sys.stdout)
        else:
            self._open_temporary()
        from .csvrows import OrderedRows

        self._rows = OrderedRows(self._put)
        if self.path is None:
            # printed with the first rows (or at the end of a job without rows): a job that
            # stops at its first block, on an option or a row it cannot take, prints nothing
            self._pending_head = True
            return self
        self._write_head()
        return self

    def _write_head(self) -> None:
        self._pending_head = False
        try:
            self._fh.write(self._head().encode("utf-8"))
        except OSError as exc:
            self._abort()
            raise self._failure(exc) from exc
        except BaseException:
            self._abort()
            raise

    def _open_temporary(self) -> None:
        """A temporary file beside the destination, by the policy of
        :mod:`photogeom.atomicfile` (symbolic links followed, read-only files and missing
        directories refused, the mode, owner and group of a replaced file kept, 0666 minus
        umask for a new one; a device or a named pipe written in place)."""
        from ..atomicfile import _create_temporary, _destination, _failure, _stream, _take_over

        given, target = _destination(self.path)
        self._given, self._target = given, target
        if _stream(target):  # /dev/null, /dev/stdout, a named pipe: written in place
            try:
                self._fh = open(given, "wb")  # closed in __exit__ / _abort
            except OSError as exc:
                raise _failure(given, exc) from exc
            self._direct = True
            return
        fd, tmp, old = _create_temporary(given, target)
        self._tmp = str(tmp)
        try:
            _take_over(fd, old)
            self._fh = os.fdopen(fd, "wb")
        except BaseException as exc:
            os.close(fd)
            os.unlink(self._tmp)
            self._tmp = None
            if isinstance(exc, OSError):
                raise _failure(given, exc) from exc
            raise

    def _failure(self, exc: OSError):
        from ..atomicfile import _failure

        if self.path is None:  # the standard output, or the stream given
            where = "the standard output" if self._stream is None else "the output stream"
            return _failure(Path(where), exc)
        return _failure(getattr(self, "_given", self.path), exc)

    def _head(self) -> str:
        import csv
        import io

        buf = io.StringIO()
        for c in self.comments:
            for line in str(c).splitlines() or [""]:
                buf.write(f"# {line}\n")
        csv.writer(buf, lineterminator="\n").writerow(["id", *self.columns, *self.extra])
        return buf.getvalue()

    def write(self, ids, coords: np.ndarray, extra: dict | None = None) -> None:
        """Write rows.

        Large chunks are formatted in worker threads while the caller prepares the next
        one; their bytes reach the file in row order (all of them when the ``with`` block
        ends).

        Parameters
        ----------
        ids : sequence of str or pyarrow string array
            One id per row (other types are written as text).
        coords : numpy.ndarray, shape (n, len(columns))
            Coordinates; written with the shortest representation that reads back exactly.
        extra : dict, optional
            The declared extra column names -> sequences of n values (numbers or text).

        Raises
        ------
        InputError
            When the shapes or lengths do not match the declared columns, or the extra column
            names differ from those declared.
        """
        import pyarrow as pa

        from .csvrows import text_column

        # a copy: rows may be formatted after this call returns, and the caller may reuse
        # its arrays
        coords = np.array(coords, dtype=float)
        if coords.ndim != 2 or coords.shape[1] != len(self.columns):
            raise InputError(
                f"{len(self.columns)} column name(s) for coordinates of shape {coords.shape}"
            )
        n = coords.shape[0]
        if len(ids) != n:
            raise InputError(f"{len(ids)} id(s) for {n} point(s)")
        extra = dict(extra or {})
        if set(extra) != set(self.extra):
            raise InputError(
                f"extra columns {', '.join(extra)} given, {', '.join(self.extra)} declared"
            )
        ids = _id_array(ids)
        extras = []
        for name in self.extra:
            v = extra[name]
            if len(v) != n:
                raise InputError(f"column {name}: {len(v)} value(s) for {n} point(s)")
            if not isinstance(v, (pa.Array, pa.ChunkedArray)):
                arr = np.array(v)  # a copy, as the coordinates
                v = arr if arr.dtype.kind in "iuf" else text_column(v)
            extras.append(v)
        if self._pending_head:
            self._write_head()
        try:
            self._rows.add([ids], coords, extras)
        except OSError as exc:
            if self.path is None:
                raise
            raise self._failure(exc) from exc
        self.n_written += n

    def _put(self, data) -> None:
        self._fh.write(data)

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self._abort()
            return
        if self.path is None:
            if self._pending_head:  # no rows: the comments and the header alone
                self._write_head()
            try:
                self._rows.close()
            except BaseException:
                self._rows.close(discard=True)
                raise
            self._fh.flush()
            return
        from ..atomicfile import _fsync_directory

        if self._direct:
            try:
                self._rows.close()
                self._fh.close()
            except OSError as exc:
                self._abort()
                raise self._failure(exc) from exc
            except BaseException:
                self._abort()
                raise
            return
        try:
            self._rows.close()
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            os.replace(self._tmp, self._target)
            self._tmp = None
            _fsync_directory(self._target.parent if str(self._target.parent) else Path("."))
        except OSError as exc:
            self._abort()
            raise self._failure(exc) from exc
        except BaseException:
            self._abort()
            raise

    def _abort(self) -> None:
        if self._rows is not None:
            self._rows.close(discard=True)
        if self._direct:
            try:
                self._fh.close()
            except OSError:  # pragma: no cover - closing a broken pipe
                pass
            return
        if self.path is None or self._tmp is None:
            return
        try:
            self._fh.close()
        except Exception:  # pragma: no cover - closing a broken file
            pass
        try:
            os.unlink(self._tmp)
        except FileNotFoundError:
            pass
        self._tmp = None


class _TextSink:
    """Bytes written to a text stream (standard output replaced by a text-only object)."""

    def __init__(self, stream) -> None:
        self.stream = stream

    def write(self, data: bytes) -> None:
        self.stream.write(bytes(data).decode("utf-8"))

    def flush(self) -> None:
        self.stream.flush()


def _id_array(ids):
    """The ids as a pyarrow string array (other types written as text)."""
    import pyarrow as pa

    from .csvrows import text_column

    if isinstance(ids, pa.ChunkedArray):
        ids = ids.combine_chunks()
    if not isinstance(ids, pa.Array):
        return pa.array(_texts(ids), pa.string())
    return ids if pa.types.is_string(ids.type) else text_column(ids)


#: Python's white space (``str.isspace``), which the readers trim from the ends of a field:
#: the body of an RE2 character class, for pyarrow.
_SPACE = "\t\n\x0b\x0c\r\x1c-\x1f \x85\xa0\u1680\u2000-\u200a\u2028\u2029\u202f\u205f\u3000"
#: An id made of these characters only reads back empty.
_BLANK_ID = f"^[{_SPACE}]*$"


def _check_ids_read_back(ids) -> None:
    """Refuse ids that a point CSV cannot hold: a line break (the readers refuse a quoted
    field over two lines), a NUL character (the readers take the file for a binary one),
    nothing but white space (read back as an empty id) and ids that read back as one (the
    readers refuse repeated ids). White space at the ends is written and trimmed on
    reading, as in any point file (``' #3'`` reads back as ``'#3'``)."""
    import pyarrow.compute as pc

    for pattern, why in (
        (r"[\r\n]", "holds a line break, which a point file cannot hold (the readers refuse "
         "a quoted field over two lines); remove it from the id"),
        ("\x00", "holds a NUL character, which a point file cannot hold (the readers take "
         "the file for a binary one); remove it from the id"),
        (_BLANK_ID, "is empty or only white space, which reads back as an empty id (the "
         "readers refuse it); give the point a name"),
    ):
        bad = pc.fill_null(pc.match_substring_regex(ids, pattern), False)
        if pc.any(bad).as_py():
            k = int(np.flatnonzero(bad.to_numpy(zero_copy_only=False))[0])
            raise InputError(f"point id {ids[k].as_py()!r} (row {k + 1}) {why}")
    read = pc.replace_substring_regex(ids, f"^[{_SPACE}]+|[{_SPACE}]+$", "")
    if len(pc.unique(read)) < len(read):
        _, first, inverse = np.unique(
            read.to_numpy(zero_copy_only=False).astype(str), return_index=True,
            return_inverse=True,
        )
        k = int(np.flatnonzero(first[inverse] != np.arange(len(read)))[0])  # a repeat
        j = int(first[inverse[k]])
        raise InputError(
            f"point ids {ids[j].as_py()!r} (row {j + 1}) and {ids[k].as_py()!r} (row {k + 1}) "
            f"read back as the same id {read[k].as_py()!r} (the readers trim white space at "
            "the ends and refuse repeated ids); make them distinct"
        )


def _check_header_read_back(names: Sequence[str]) -> None:
    """Refuse column names the readers refuse in a header: empty or white space only, with a
    line break or a NUL character, or two names that read back as one (white space at the
    ends is trimmed; ``id`` is the first column's)."""
    seen: dict[str, str] = {}
    for name in names:
        if re.search("[\r\n\x00]", name):
            raise InputError(
                f"column name {name!r} holds a line break or a NUL character, which a point "
                "file's header cannot hold; rename the column"
            )
        key = name.strip()
        if not key:
            raise InputError(
                f"column name {name!r} is empty or only white space, which the readers "
                "refuse in a header; name the column"
            )
        if key in seen:
            raise InputError(
                f"column names {seen[key]!r} and {name!r} read back as the same name {key!r} "
                "(the readers trim white space at the ends and refuse repeated column "
                "names; the first column is 'id'); rename one"
            )
        seen[key] = name


def _check_text_read_back(extra: dict, comments: Sequence[str]) -> None:
    """Refuse text a point CSV cannot hold in the further columns (a line break or a NUL
    character) and in the comment lines (a NUL character; comments are split into lines)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from .csvrows import text_column

    for name, values in extra.items():
        numbers = not isinstance(values, (pa.Array, pa.ChunkedArray))
        if numbers and np.asarray(values).dtype.kind in "iufb":
            continue
        values = text_column(values)
        bad = pc.fill_null(pc.match_substring_regex(values, "[\r\n\x00]"), False)
        if pc.any(bad).as_py():
            k = int(np.flatnonzero(bad.to_numpy(zero_copy_only=False))[0])
            raise InputError(
                f"column {name}: value {values[k].as_py()!r} (row {k + 1}) holds a line break "
                "or a NUL character, which a point file cannot hold (the readers refuse a "
                "quoted field over two lines, and a file with NUL as binary); remove it"
            )
    for line in comments:
        if "\x00" in str(line):
            raise InputError(
                f"comment {str(line)!r} holds a NUL character, which a point file cannot "
                "hold (the readers take the file for a binary one); remove it"
            )


def _texts(values) -> list[str]:
    return [str(v) for v in values]


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
    float64 (lossless round trip). See :class:`PointWriter` for files of any size.

    Parameters
    ----------
    ids : sequence
        One id per point.
    coords : numpy.ndarray, shape (n, len(columns))
        Coordinates.
    columns : sequence of str
        Coordinate column names.
    extra : dict of str to sequence, optional
        Further columns, after the coordinates.
    comments : sequence of str, default ()
        Lines written as ``# <line>`` before the header.

    Returns
    -------
    str

    Raises
    ------
    InputError
        As :meth:`PointWriter.write`.
    """
    import io

    buf = io.BytesIO()
    extra = dict(extra or {})
    with PointWriter(None, columns, extra=list(extra), comments=comments, stream=buf) as w:
        w.write(ids, coords, extra)
    return buf.getvalue().decode("utf-8")


def write_points(
    path: str | os.PathLike,
    ids: Sequence,
    coords: np.ndarray,
    columns: Sequence[str],
    *,
    extra: dict[str, Sequence] | None = None,
    comments: Sequence[str] = (),
) -> Path:
    """Write points as CSV, atomically (see :class:`PointWriter` for the layout).

    Parameters
    ----------
    path : str or os.PathLike
        Output file; replaced if it exists.
    ids : sequence
        One id per point.
    coords : numpy.ndarray, shape (n, len(columns))
        Coordinates.
    columns : sequence of str
        Coordinate column names.
    extra : dict of str to sequence, optional
        Further columns, after the coordinates.
    comments : sequence of str, default ()
        Lines written as ``# <line>`` before the header.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        As :meth:`PointWriter.write`; also what :func:`read_points` would refuse: an id
        with a line break (a quoted field over two lines) or a NUL character (a binary
        file), an empty or white-space-only id, two ids that read back as one (``"a"`` and
        ``" a"``: white space at the ends of an id is trimmed on reading), a line break or
        a NUL character in a text column of ``extra``, a NUL character in ``comments``;
        column names (``columns`` and those of ``extra``) that are empty, hold a line break
        or a NUL, or read back as one another or as ``id``.
    OutputError
        When the file cannot be written.
    """
    extra = dict(extra or {})
    ids = _id_array(ids)
    _check_ids_read_back(ids)  # a file for read_points: only ids it gives back
    _check_text_read_back(extra, comments)
    _check_header_read_back(["id", *map(str, columns), *map(str, extra)])
    with PointWriter(path, columns, extra=list(extra), comments=comments) as w:
        w.write(ids, coords, extra)
    return Path(path)
