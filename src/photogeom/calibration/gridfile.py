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
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from ..atomicfile import atomic_write_bytes
from ..errors import FileFormatError, InputError
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
    used only when unambiguous: one grid key with that text, one id with that text.

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


def save_grids(path: str | os.PathLike, grids: dict, *, std: bool = True) -> Path:
    """Write grids (``image id -> ResidualGrid``) to ``path`` atomically.

    ``.npz`` writes NumPy's archive, any other suffix JSON. ``std`` computes and stores the
    node standard deviations (about 0.1-0.2 s per image of 4000 nodes). Image ids keep
    their type (integers or text; see the module).

    Raises
    ------
    InputError
        An image id that is neither an integer nor text.
    """
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
        return atomic_write_bytes(path, buf.getvalue())
    images = []
    for st, arr in zip(stats, arrays):
        images.append({**st, **{n: _json_array(v) for n, v in arr.items()}})
    text = json.dumps({**meta, "images": images}, allow_nan=False) + "\n"
    return atomic_write_bytes(path, text.encode("utf-8"))


def _grid(st: dict, arr: dict, where: str) -> ResidualGrid:
    try:
        layout = GridLayout(int(st["width"]), int(st["height"]), float(st["spacing"]))
        nodes = np.asarray(arr["nodes"], dtype=float)
        if nodes.shape != (*layout.shape, 2):
            raise FileFormatError(
                f"{where}: nodes of shape {nodes.shape}, the layout needs {(*layout.shape, 2)}"
            )

        def num(key):
            v = st.get(key)
            return float("nan") if v is None else float(v)

        g = ResidualGrid(
            layout=layout,
            nodes=nodes,
            sigma0=num("sigma0"),
            redundancy=int(st["redundancy"]),
            sigma_obs=np.asarray(arr["sigma_obs"], dtype=float),
            sigma_constraint=num("sigma_constraint"),
            support=np.asarray(arr["support"], dtype=bool),
            counts=np.asarray(arr["counts"], dtype=np.int64),
            rms_before=num("rms_before"),
            rms_after=num("rms_after"),
            rms_cv_before=num("rms_cv_before"),
            rms_cv_after=num("rms_cv_after"),
            outliers=np.asarray(arr["outliers"], dtype=bool),
            vce_iterations=int(st.get("vce_iterations", 0)),
            border=str(st.get("border", "mean")),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"{where}: incomplete or malformed grid ({exc})") from None
    if arr.get("node_cofactor") is not None:
        g._std.append(np.asarray(arr["node_cofactor"], dtype=float))
    elif arr.get("node_std") is not None:  # a file from before the cofactors were stored
        sd = np.asarray(arr["node_std"], dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            g._std.append((sd / g.sigma0) ** 2)
    return g


def load_grids(path: str | os.PathLike) -> dict:
    """Read a grids file written by :func:`save_grids`: ``image id -> ResidualGrid``.

    Image ids come back with the type they were saved with (integers or text; older files:
    text).

    Raises
    ------
    FileFormatError
        Not a grids file, or a malformed one (the message names the image).
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{path}: no such grids file")
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                data = {k: z[k] for k in z.files if k != "meta"}
        except (OSError, ValueError, KeyError) as exc:
            raise FileFormatError(f"{path}: not a grids NPZ file ({exc})") from None
        _check(meta, path)
        out = {}
        for k, st in enumerate(meta["images"]):
            arr = {
                n: data[f"{n}_{k}"]
                for n in (
                    "nodes",
                    "node_std",
                    "node_cofactor",
                    "support",
                    "counts",
                    "sigma_obs",
                    "outliers",
                )
                if f"{n}_{k}" in data
            }
            _add(out, st, arr, path)
        return out
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{path}: not a grids JSON file ({exc})") from None
    _check(meta, path)
    out = {}
    for st in meta["images"]:
        _add(out, st, st, path)
    return out


def _add(out: dict, st: dict, arr: dict, path: Path) -> None:
    """Read one image's grid into ``out`` under its id (integer or text, as written)."""
    key = st.get("id") if isinstance(st, dict) else None
    if isinstance(key, bool) or not isinstance(key, (int, str)):
        raise FileFormatError(f"{path}: an image entry has no integer or text 'id' (found {key!r})")
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
