"""Bundled example data sets (published data; each file's header says where it comes from).

>>> from photogeom import datasets
>>> datasets.names()                     # doctest: +SKIP
>>> table = datasets.load("lidar_wang2014")
>>> table["x"], table["X"], table["id"]  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError, PhotogeomError

_PACKAGE = "photogeom.datasets"

DESCRIPTIONS = {
    "lidar_wang2014": "18 point pairs from two terrestrial laser scans (absolute orientation)",
    "afary2024_simulated": "3 point pairs, error-free and noisy, large angles",
    "kraus_absolute_orientation": "3 point pairs, stereo model -> object (absolute orientation)",
    "lecture_fiducials": "8 fiducial marks, calibrated and machine coordinates",
    "lecture_two_images": "6 tie points on two images (2D similarity, affine, projective)",
}

RPC_FILES = {
    "quickbird": "quickbird_gdal_autotest.rpc.txt",
    "ikonos": "rpc_IKONOS.txt",
    "skysat": "skysat_l1a_RPC.TXT",
    "pleiades": "rpc_PLEIADES.xml",
    "worldview2": "rpc_WV2.xml",
}

#: Bundle-adjustment problems (see ``data/bundle/SOURCES.md``); read with
#: ``photogeom.bundle.read_bal(datasets.path(name))``.
BUNDLE_FILES = {
    "dubrovnik-3-7": "dubrovnik-3-7-pre.txt",
}


#: Columns of each bundled point data set (``load`` checks that they are all there). Columns
#: in :data:`TEXT_COLUMNS` hold text; every other column must hold a finite number in every row.
COLUMNS = {
    "lidar_wang2014": ("id", "x", "y", "z", "X", "Y", "Z"),
    "afary2024_simulated": ("kind", "id", "x", "y", "z", "X", "Y", "Z"),
    "kraus_absolute_orientation": ("id", "x", "y", "z", "X", "Y", "Z"),
    "lecture_fiducials": ("id", "role", "x", "y", "X", "Y"),
    "lecture_two_images": ("id", "x1", "y1", "x2", "y2"),
}

#: Columns of the bundled CSVs that hold text (all others are numbers).
TEXT_COLUMNS = frozenset({"id", "kind", "role"})

_REINSTALL = (
    "the installed copy of photogeom is damaged or incomplete: reinstall it "
    "(pip install --force-reinstall photogeom)"
)


def names() -> list[str]:
    """Names of the bundled point data sets.

    Returns
    -------
    list of str
        Sorted; each accepted by :func:`load`, :func:`header` and :func:`path`.
    """
    return sorted(DESCRIPTIONS)


def _data_dir() -> Path:
    """The folder of the bundled files."""
    return Path(str(resources.files(_PACKAGE).joinpath("data")))


def path(name: str) -> Path:
    """Filesystem path of a bundled file: a data set name, a file name, ``rpc/<file>`` or a
    bundle-adjustment problem of :data:`BUNDLE_FILES`.

    The file of a point data set (:func:`names`) is checked as :func:`load` checks it, so
    that a damaged copy is named as such whichever reader then reads it.

    Parameters
    ----------
    name : str
        Data set name (:func:`names`), ``RPC_FILES`` or ``BUNDLE_FILES`` key, file name or
        ``rpc/<file>``.

    Returns
    -------
    pathlib.Path
        The installed file.

    Raises
    ------
    InputError
        ``name`` is not a bundled data set or file (the message lists the known ones).
    PhotogeomError
        ``name`` is a known data set whose file is missing from the installation (the
        message names the file and says to reinstall).
    FileFormatError
        The file of a point data set is damaged (see :func:`load`).
    """
    p = _find(name)
    if name in DESCRIPTIONS:
        _read_table(p)
    return p


def _find(name: str) -> Path:
    """The bundled file of ``name`` (see :func:`path`), unchecked."""
    base = _data_dir()
    candidates = [f"{name}.csv", name]
    if name in RPC_FILES:
        candidates.insert(0, f"rpc/{RPC_FILES[name]}")
    if name in BUNDLE_FILES:
        candidates.insert(0, f"bundle/{BUNDLE_FILES[name]}")
    for cand in candidates:
        p = base / cand
        if p.is_file():
            return p
    if name in DESCRIPTIONS or name in RPC_FILES or name in BUNDLE_FILES:
        raise PhotogeomError(
            f"bundled data set {name!r}: its file {base / candidates[0]} is missing; {_REINSTALL}"
        )
    known = ", ".join(names() + sorted(RPC_FILES) + sorted(BUNDLE_FILES))
    raise InputError(f"no bundled data set {name!r}; known: {known}")


def _decoded_lines(p: Path) -> list[str]:
    """The lines of the bundled file ``p``, decoded as UTF-8 (a byte-order mark is skipped);
    a file that is not UTF-8 is a :class:`FileFormatError` naming it and the line."""
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise PhotogeomError(
            f"cannot read the bundled file {p} ({exc.strerror}); {_REINSTALL}"
        ) from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise FileFormatError(
            f"{p}, line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); {_REINSTALL}"
        ) from None
    return text.splitlines()


def header(name: str) -> str:
    """The comment header of a bundled CSV (its source and meaning).

    Parameters
    ----------
    name : str
        Data set name or file, as :func:`path` takes it.

    Returns
    -------
    str
        The ``#`` lines at the top of the file, without the ``#``, joined by newlines.

    Raises
    ------
    InputError
        For an unknown name (the message lists the known ones).
    """
    lines = []
    for line in _decoded_lines(_find(name)):
        if not line.startswith("#"):
            break
        lines.append(line[1:].strip())
    return "\n".join(lines)


def load(name: str) -> dict[str, np.ndarray]:
    """Load a bundled CSV as a dict of columns.

    Parameters
    ----------
    name : str
        A data set of :func:`names` (or a bundled CSV's file name).

    Returns
    -------
    dict of str to numpy.ndarray
        The columns of :data:`TEXT_COLUMNS` (``id``, ``kind``, ``role``) as str arrays, all
        others as float arrays.

    Raises
    ------
    FileFormatError
        The file is damaged: not UTF-8, no header or no rows, a row with more or fewer fields
        than the header, a cell that is not a finite number in a number column, or a column
        of :data:`COLUMNS` missing. The message names the file and the line.
    """
    return _read_table(_find(name))


def _read_table(p: Path) -> dict[str, np.ndarray]:
    """The checked columns of the bundled CSV ``p`` (see :func:`load`)."""
    lines = _decoded_lines(p)
    fields: list[str] | None = None
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(lines, start=1):
        if not line.strip() or line.startswith("#"):
            continue
        cells = [c.strip() for c in next(csv.reader(io.StringIO(line)))]
        if fields is None:
            fields = cells
            dup = sorted({c for c in cells if cells.count(c) > 1})
            if dup or "" in cells:
                raise FileFormatError(
                    f"{p}, line {lineno}: the header {line!r} has "
                    + (f"repeated columns {dup}" if dup else "an empty column name")
                    + f"; {_REINSTALL}"
                )
            continue
        if len(cells) != len(fields):
            raise FileFormatError(
                f"{p}, line {lineno}: {len(cells)} field(s) where the header has "
                f"{len(fields)} ({', '.join(fields)}); {_REINSTALL}"
            )
        rows.append((lineno, cells))
    if fields is None or not rows:
        raise FileFormatError(
            f"{p}: {'no header line' if fields is None else 'a header but no rows'}; {_REINSTALL}"
        )
    stem = p.name[: -len(".csv")] if p.name.endswith(".csv") else p.name
    missing = [c for c in COLUMNS.get(stem, ()) if c not in fields]
    if missing:
        raise FileFormatError(
            f"{p}: column(s) {', '.join(missing)} missing (the header has "
            f"{', '.join(fields)}; {stem} needs {', '.join(COLUMNS[stem])}); {_REINSTALL}"
        )
    out: dict[str, np.ndarray] = {}
    for j, col in enumerate(fields):
        values = [cells[j] for _, cells in rows]
        if col in TEXT_COLUMNS:
            out[col] = np.array(values)
            continue
        numbers = np.empty(len(values))
        for i, v in enumerate(values):
            try:
                numbers[i] = float(v)
            except ValueError:
                numbers[i] = np.nan
            if not np.isfinite(numbers[i]):
                raise FileFormatError(
                    f"{p}, line {rows[i][0]}: column {col!r} holds {v!r}, not a finite "
                    f"number; {_REINSTALL}"
                )
        out[col] = numbers
    return out


def point_pairs(name: str, kind: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ids, source (n, 3), target (n, 3))`` of a 3D point-pair data set.

    Parameters
    ----------
    name : str
        A data set with the columns ``id, x, y, z, X, Y, Z``.
    kind : {"true", "noisy"}, optional
        Selects rows of ``afary2024_simulated`` (the data sets with a ``kind`` column).

    Returns
    -------
    ids : numpy.ndarray
        Point ids.
    source, target : numpy.ndarray, shape (n, 3)
        The two coordinate sets, in the units the data set's header states.

    Raises
    ------
    FileFormatError
        The file is damaged (see :func:`load`) or lacks a point-pair column.
    InputError
        ``kind`` is missing or names no rows.
    """
    t = load(name)
    need = ("id", "x", "y", "z", "X", "Y", "Z")
    missing = [c for c in need if c not in t]
    if missing:
        raise FileFormatError(
            f"{_find(name)}: column(s) {', '.join(missing)} missing; a point-pair data set needs "
            f"{', '.join(need)}"
        )
    mask = np.ones(len(t["id"]), dtype=bool)
    if "kind" in t:
        kinds = sorted(set(t["kind"].tolist()))
        if kind not in kinds:
            raise InputError(
                f"{name}: choose kind= one of {', '.join(repr(k) for k in kinds)}"
                + ("" if kind is None else f" (not {kind!r})")
            )
        mask = t["kind"] == kind
    src = np.column_stack([t["x"], t["y"], t["z"]])[mask]
    dst = np.column_stack([t["X"], t["Y"], t["Z"]])[mask]
    return t["id"][mask], src, dst
