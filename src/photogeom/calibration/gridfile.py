"""The grids file: fitted residual grids of many images, as NPZ or JSON.

Both forms hold, per image (in the order given): the id, the layout (``width``,
``height``, ``spacing``, ``shape = [ny, nx]``), the node values ``nodes`` (ny, nx, 2, px,
the modelled residual, computed minus observed, x then y), the node standard deviations
``node_std`` (ny, nx, px) with the cofactors they come from, ``node_cofactor = diag(N^-1)``
(ny, nx, px^2 per unit weight; both absent when not computed), the support map ``support``
(ny, nx, bool), the observation counts ``counts`` (ny, nx), the standard deviations of the
observations used ``sigma_obs`` (n,), the outlier mask ``outliers`` (n_input,) and the
statistics of :meth:`ResidualGrid.to_dict`. The cofactors are what is read back (so that
a sigma0 of 0 or NaN loses nothing); files without them give ``node_std / sigma0``.

* NPZ (``.npz``): ``meta`` is a JSON string (format name, version, convention and the list of
  per-image statistics with ``id``); the arrays are ``nodes_<k>``, ``node_std_<k>``,
  ``node_cofactor_<k>``, ``support_<k>``, ``counts_<k>``, ``sigma_obs_<k>``,
  ``outliers_<k>`` for the k-th image.
* JSON (any other suffix): ``{"format": "photogeom-residual-grids", "version": 1,
  "convention": ..., "images": [{"id": ..., <statistics>, "nodes": [[[x, y], ...], ...],
  "node_std": ..., "node_cofactor": ..., "support": ..., "counts": ..., "sigma_obs": ...,
  "outliers": ...}]}``. Numbers that are not finite (NaN: a sigma0 of a fit without
  redundancy and the standard deviations from it) are written as ``null`` and read back as
  NaN.

Image ids keep their type: an integer id is written as a JSON number, a text id as a
JSON string, and each is read back as it was written (files from before ids kept their type
hold text only; :func:`match_grid_ids` matches such text to integer ids).
"""

from __future__ import annotations

import io
import json
import os
import zipfile
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..atomicfile import atomic_write_bytes
from ..errors import FileFormatError, InputError
from ..io.jsonfile import parse_json_bytes
from ..io.sources import device_message, input_kind, pipe_bytes
from .grid import GridLayout, ResidualGrid

FORMAT = "photogeom-residual-grids"
VERSION = 1
CONVENTION = (
    "nodes: modelled image residual (computed minus observed, px); corrected "
    "coordinates = observed + field; node (0, 0) at the centre of the top-left pixel"
)


def _file_id(key) -> int | str:
    """An image id as the file holds it: integers as numbers, text as strings."""
    if isinstance(key, (bool, np.bool_)):
        pass
    elif isinstance(key, (int, np.integer)):
        return int(key)
    elif isinstance(key, str):
        return str(key)
    raise InputError(
        f"image id {key!r} is a {type(key).__name__}: a grids file holds integer or text "
        "image ids (those of a photogeom Block)"
    )


def _stats(key, grid: ResidualGrid) -> dict:
    return {"id": _file_id(key), **grid.to_dict()}


def match_grid_ids(ids: Iterable, grids: Mapping) -> tuple[dict, list]:
    """The grid key of each image id: the id itself, else the one key with the same text.

    The text match serves grids files written before image ids kept their type (text ids
    against a block's integer ids) and text ids (a CSV's) against integer grid ids. It is
    used only when unambiguous: one grid key with that text, one id with that text. A text
    id ``-0`` is the integer grid id 0, as a CSV block folder reads it.

    Parameters
    ----------
    ids : iterable
        Image ids (integers or text).
    grids : mapping
        ``image id -> ResidualGrid``.

    Returns
    -------
    dict, list
        ``id -> grid key`` of the ids matched, and the ids without a (unique) grid, in the
        order given.
    """
    ids = list(ids)
    by_text: dict = {}
    for key in grids:
        by_text.setdefault(str(key), []).append(key)
    texts: dict = {}
    for i in ids:
        texts[str(i)] = texts.get(str(i), 0) + 1
    found, missing = {}, []
    for i in ids:
        if i in grids:
            found[i] = i
            continue
        same = by_text.get(str(i), [])
        if not same and i == "-0":  # integer form: the integer 0 (never the text "0")
            same = [k for k in by_text.get("0", []) if isinstance(k, (int, np.integer))]
        if len(same) == 1 and texts[str(i)] == 1:
            found[i] = same[0]
        else:
            missing.append(i)
    return found, missing


def _arrays(grid: ResidualGrid, std: bool) -> dict:
    out = {
        "nodes": grid.nodes,
        "support": grid.support,
        "counts": grid.counts,
        "sigma_obs": grid.sigma_obs,
        "outliers": grid.outliers,
    }
    if grid.uv is not None:  # the positions fitted: readjust finds grids of its observations
        out["uv"] = grid.uv
    if std:
        try:
            out["node_cofactor"] = grid.node_cofactor
        except InputError:  # a grid read from a file without standard deviations
            pass
        else:
            out["node_std"] = grid.node_std
    return out


def _json_array(values) -> list:
    """Nested lists of an array, non-finite numbers as None (JSON null)."""
    a = np.asarray(values)
    if a.dtype.kind != "f":
        return a.tolist()
    obj = a.astype(object)
    obj[~np.isfinite(a)] = None
    return obj.tolist()


#: Where a grids file comes from, said when a path given as one is missing or a folder
#: (the command line says it in its words: ``photogeom grid fit ... -o``).
GRIDS_FILE_SOURCE = "(give the .npz or JSON file that save_grids writes)"


def save_grids(path: str | os.PathLike, grids: dict, *, std: bool = True) -> Path:
    """Write grids (``image id -> ResidualGrid``) to ``path`` atomically.

    ``.npz`` writes NumPy's archive, any other suffix JSON. ``std`` computes and stores the
    node standard deviations (about 0.1-0.2 s per image of 4000 nodes). Image ids keep
    their type (integers or text; see the module).

    Parameters
    ----------
    path : str or os.PathLike
        Output file; ``.npz`` or JSON (any other suffix).
    grids : dict
        ``image id -> ResidualGrid``.
    std : bool, default True
        Store the node standard deviations (px).

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    InputError
        An image id that is neither an integer nor text.
    OutputError
        The file cannot be written.
    """
    return atomic_write_bytes(path, grids_file_bytes(path, grids, std=std))


def grids_file_bytes(path: str | os.PathLike, grids: dict, *, std: bool = True) -> bytes:
    """The content :func:`save_grids` writes to ``path`` (NPZ for ``.npz``, else JSON), for
    writing it together with other files (:func:`photogeom.atomicfile.atomic_write_many`)."""
    path = Path(path)
    stats = [_stats(k, g) for k, g in grids.items()]
    arrays = [_arrays(g, std) for g in grids.values()]
    meta = {"format": FORMAT, "version": VERSION, "convention": CONVENTION}
    if path.suffix.lower() == ".npz":
        payload = {"meta": np.array(json.dumps({**meta, "images": stats}))}
        for k, arr in enumerate(arrays):
            for name, val in arr.items():
                payload[f"{name}_{k}"] = np.asarray(val)
        buf = io.BytesIO()
        np.savez_compressed(buf, **payload)
        return buf.getvalue()
    images = []
    for st, arr in zip(stats, arrays):
        images.append({**st, **{n: _json_array(v) for n, v in arr.items()}})
    text = json.dumps({**meta, "images": images}, allow_nan=False) + "\n"
    return text.encode("utf-8")


_ARRAYS = (
    "nodes", "node_std", "node_cofactor", "support", "counts", "sigma_obs", "outliers", "uv"
)  # fmt: skip
_NEEDED_STATS = ("width", "height", "spacing", "redundancy")
_NEEDED_ARRAYS = ("nodes", "support", "counts", "sigma_obs", "outliers")
_BORDERS = ("mean", "linear")


def _integer(st: dict, key: str, where: str) -> int:
    v = st[key]
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise FileFormatError(f"{where}: {key} is {v!r}, not a whole number")
    if not (np.isfinite(v) and float(v).is_integer()):
        raise FileFormatError(f"{where}: {key} is {v!r}, not a whole number")
    return int(v)


def _number(st: dict, key: str, where: str) -> float:
    """A statistic: a number, or NaN for null / absent (JSON has no NaN)."""
    v = st.get(key)
    if v is None:
        return float("nan")
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise FileFormatError(f"{where}: {key} is {v!r}, not a number")
    return float(v)


def _array(arr: dict, name: str, shape: tuple | None, kind: str, where: str) -> np.ndarray:
    """One stored array, checked: ``kind`` "f" (numbers, null = NaN), "b" (booleans, 0/1
    accepted), "u" (counts >= 0); ``shape`` exact, or None for any 1-D array."""
    v = arr[name]
    try:
        a = np.asarray(v, dtype=float) if kind == "f" else np.asarray(v)
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: {name} is not an array of numbers") from None
    want = "a list" if shape is None else f"shape {shape}"
    if (shape is None and a.ndim != 1) or (shape is not None and a.shape != shape):
        raise FileFormatError(
            f"{where}: {name} of shape {a.shape}, the grid needs {want}"
            + ("" if shape is None else f" ({shape[0]} x {shape[1]} nodes of the layout)")
        )
    if a.size and kind == "b":
        if a.dtype.kind in "iu" and np.isin(a, (0, 1)).all():
            a = a.astype(bool)
        if a.dtype.kind != "b":
            raise FileFormatError(f"{where}: {name} holds values other than true/false")
    elif a.size and kind == "u":
        if a.dtype.kind not in "iu" or (a < 0).any():
            raise FileFormatError(f"{where}: {name} holds values other than counts (0, 1, ...)")
    return a.astype({"f": float, "b": bool, "u": np.int64}[kind])


def _grid(st: dict, arr: dict, where: str) -> ResidualGrid:
    """One image's grid from its statistics and arrays; FileFormatError naming what is
    missing or malformed."""
    missing = [k for k in _NEEDED_STATS if k not in st]
    missing += [k for k in _NEEDED_ARRAYS if arr.get(k) is None]
    if missing:
        raise FileFormatError(f"{where}: incomplete grid, no {', '.join(missing)}")
    try:
        layout = GridLayout(
            _integer(st, "width", where), _integer(st, "height", where), float(st["spacing"])
        )
    except (TypeError, ValueError) as exc:  # InputError of the layout is a ValueError
        if isinstance(exc, FileFormatError):
            raise
        raise FileFormatError(f"{where}: not a valid grid layout ({exc})") from None
    shape = layout.shape
    if "shape" in st and st["shape"] != list(shape):
        raise FileFormatError(
            f"{where}: shape {st['shape']!r} does not fit the layout "
            f"({layout.width} x {layout.height} px, {layout.spacing:g} px: {list(shape)})"
        )
    border = st.get("border", "mean")
    if border not in _BORDERS:
        raise FileFormatError(f"{where}: border {border!r} is not one of {', '.join(_BORDERS)}")
    nodes = _array(arr, "nodes", (*shape, 2), "f", where)
    if not np.isfinite(nodes).all():
        raise FileFormatError(f"{where}: nodes hold NaN or infinite values")
    sigma_obs = _array(arr, "sigma_obs", None, "f", where)
    outliers = _array(arr, "outliers", None, "b", where)
    uv = None
    if arr.get("uv") is not None:  # the pixel positions of the fit (files before: none)
        n = outliers.size if outliers.size else sigma_obs.size
        uv = _array(arr, "uv", (n, 2), "f", where)
        if not np.isfinite(uv).all():
            raise FileFormatError(f"{where}: uv holds NaN or infinite values")
    g = ResidualGrid(
        layout=layout,
        nodes=nodes,
        sigma0=_number(st, "sigma0", where),
        redundancy=_integer(st, "redundancy", where),
        sigma_obs=sigma_obs,
        sigma_constraint=_number(st, "sigma_constraint", where),
        support=_array(arr, "support", shape, "b", where),
        counts=_array(arr, "counts", shape, "u", where),
        rms_before=_number(st, "rms_before", where),
        rms_after=_number(st, "rms_after", where),
        rms_cv_before=_number(st, "rms_cv_before", where),
        rms_cv_after=_number(st, "rms_cv_after", where),
        outliers=outliers,
        vce_iterations=_integer(
            {"vce_iterations": st.get("vce_iterations", 0)}, "vce_iterations", where
        ),
        border=border,
        uv=uv,
    )
    if arr.get("node_cofactor") is not None:
        g = replace(g, _std=[_array(arr, "node_cofactor", shape, "f", where)])
    elif arr.get("node_std") is not None:  # a file from before the cofactors were stored
        sd = _array(arr, "node_std", shape, "f", where)
        with np.errstate(invalid="ignore", divide="ignore"):
            g = replace(g, _std=[(sd / g.sigma0) ** 2])
    return g


def load_grids(path: str | os.PathLike) -> dict:
    """Read a grids file written by :func:`save_grids`: ``image id -> ResidualGrid``.

    Image ids come back with the type they were saved with (integers or text; older files:
    text).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npz`` or JSON grids file, or a pipe (read once; an NPZ is recognised by its
        content). A device (``/dev/zero``) is refused.

    Returns
    -------
    dict
        ``image id -> ResidualGrid``.

    Raises
    ------
    FileFormatError
        No such file, a folder, a device, not a grids file (or a damaged one: truncated,
        not a zip archive, not JSON), or a malformed entry: no id, missing values, arrays
        whose shape does not fit the layout (the message names the file and the image).
    """
    path = Path(path)
    kind = input_kind(path)
    if kind == "missing":
        raise FileFormatError(f"{path}: no such grids file {GRIDS_FILE_SOURCE}")
    if kind == "folder":
        raise FileFormatError(f"{path}: a folder, not a grids file {GRIDS_FILE_SOURCE}")
    if kind == "device":
        raise FileFormatError(device_message(path, "grids file"))
    raw = None
    if kind == "pipe":  # read once; an NPZ (a zip archive) is then read from memory
        try:
            raw = pipe_bytes(path, None)
        except OSError as exc:
            raise FileFormatError(f"{path}: cannot read the grids file ({exc.strerror})") from None
    source = path if raw is None else io.BytesIO(raw)
    npz = path.suffix.lower() == ".npz" or (raw is not None and raw[:4] == b"PK\x03\x04")
    if npz:
        if not zipfile.is_zipfile(source):
            raise FileFormatError(
                f"{path}: not a grids NPZ file (not a zip archive: truncated, or another "
                "format); write it again with save_grids or photogeom grid fit"
            )
        problem = _npz_array_too_large(path, source)
        if problem:
            raise FileFormatError(problem)
        if raw is not None:
            source.seek(0)  # np.load reads the zip magic where the checks above left off
        try:
            with np.load(source, allow_pickle=False) as z:
                meta = parse_json_bytes(str(z["meta"]).encode("utf-8"), str(path), allow_nan=True)
                data = {k: z[k] for k in z.files if k != "meta"}
        except (
            OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, MemoryError
        ) as exc:  # fmt: skip
            raise FileFormatError(
                f"{path}: not a readable grids NPZ file ({type(exc).__name__}: {exc}); "
                "write it again with save_grids or photogeom grid fit"
            ) from None
        _check(meta, path)
        out: dict = {}
        for k, st in enumerate(meta["images"]):
            arr = {n: data[f"{n}_{k}"] for n in _ARRAYS if f"{n}_{k}" in data}
            _add(out, k, st, arr, path)
        return out
    try:
        if raw is None:
            raw = path.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read the grids file ({exc.strerror})") from None
    try:  # bounded: deep nesting, huge integers and encodings are named, never a traceback
        meta = parse_json_bytes(raw, str(path), allow_nan=True)
    except FileFormatError as exc:
        raise FileFormatError(
            f"{exc} (not a grids JSON file: write it again with save_grids or photogeom grid fit)"
        ) from None
    _check(meta, path)
    out = {}
    for k, st in enumerate(meta["images"]):
        _add(out, k, st, st, path)
    return out


#: Most bytes a deflated member of an NPZ file can inflate to per byte stored (deflate's
#: limit is about 1032; a little more for the member's header).
_MAX_DEFLATE_RATIO = 1100


def _npz_array_too_large(path: Path, source: Path | io.BytesIO | None = None) -> str | None:
    """Why an array of the NPZ file ``path`` (read from ``source``: the path, or the bytes of
    a pipe) cannot be as large as its ``.npy`` header says, or None (also None for what
    :func:`numpy.load` reports itself).

    numpy allocates the array of the header's shape before it reads the data, so a 1 kB
    file whose header announced 10^10 values ended in a MemoryError (74.5 GiB) instead of a
    named error. A member holds at most its stored size (uncompressed) or
    :data:`_MAX_DEFLATE_RATIO` times it (deflated): a header announcing more is damage.
    """
    from numpy.lib import format as npy

    try:
        with zipfile.ZipFile(path if source is None else source) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as fh:
                    version = npy.read_magic(fh)
                    read = npy.read_array_header_1_0 if version == (1, 0) else (
                        npy.read_array_header_2_0)  # fmt: skip
                    shape, _fortran, dtype = read(fh, max_header_size=10_000)
                need = int(np.prod(shape, dtype=object)) * dtype.itemsize
                room = info.compress_size * (
                    1 if info.compress_type == zipfile.ZIP_STORED else _MAX_DEFLATE_RATIO
                )
                if need > room:
                    return (
                        f"{path}: array {info.filename[:-4]} announces shape {tuple(shape)} "
                        f"({need} bytes) but its member stores {info.compress_size} bytes: "
                        "the file is damaged; write it again with save_grids or photogeom "
                        "grid fit"
                    )
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, TypeError):
        return None  # reported by numpy.load below
    return None


def _add(out: dict, k: int, st, arr: dict, path: Path) -> None:
    """Read the k-th image's grid into ``out`` under its id (integer or text, as written)."""
    if not isinstance(st, dict):
        raise FileFormatError(
            f"{path}: image entry {k + 1} is {type(st).__name__} {st!r}, not an object with "
            "id, layout and arrays"
        )
    key = st.get("id")
    if isinstance(key, bool) or not isinstance(key, (int, str)):
        raise FileFormatError(
            f"{path}: image entry {k + 1} has no integer or text 'id' (found {key!r})"
        )
    if key in out:
        raise FileFormatError(f"{path}: image {key!r} appears twice")
    out[key] = _grid(st, arr, f"{path}, image {key}")


def _check(meta, path) -> None:
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise FileFormatError(f"{path}: not a photogeom residual-grids file")
    if meta.get("version") != VERSION:
        raise FileFormatError(f"{path}: grids file version {meta.get('version')} is not supported")
    if not isinstance(meta.get("images"), list):
        raise FileFormatError(f"{path}: the grids file has no image list")
