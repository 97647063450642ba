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

from ..errors import InputError

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


def names() -> list[str]:
    """Names of the bundled point data sets."""
    return sorted(DESCRIPTIONS)


def path(name: str) -> Path:
    """Filesystem path of a bundled file: a data set name, a file name, ``rpc/<file>`` or a
    bundle-adjustment problem of :data:`BUNDLE_FILES`."""
    base = resources.files(_PACKAGE).joinpath("data")
    candidates = [f"{name}.csv", name]
    if name in RPC_FILES:
        candidates.insert(0, f"rpc/{RPC_FILES[name]}")
    if name in BUNDLE_FILES:
        candidates.insert(0, f"bundle/{BUNDLE_FILES[name]}")
    for cand in candidates:
        p = base.joinpath(cand)
        if p.is_file():
            return Path(str(p))
    known = ", ".join(names() + sorted(RPC_FILES) + sorted(BUNDLE_FILES))
    raise InputError(f"no bundled data set {name!r}; known: {known}")


def header(name: str) -> str:
    """The comment header of a bundled CSV (its source and meaning)."""
    lines = []
    for line in path(name).read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[1:].strip())
    return "\n".join(lines)


def load(name: str) -> dict[str, np.ndarray]:
    """Load a bundled CSV as a dict of columns (numbers as float arrays, text as str arrays)."""
    text = path(name).read_text(encoding="utf-8")
    body = "\n".join(line for line in text.splitlines() if line and not line.startswith("#"))
    reader = csv.DictReader(io.StringIO(body))
    rows = list(reader)
    out: dict[str, np.ndarray] = {}
    for col in reader.fieldnames or []:
        values = [r[col] for r in rows]
        try:
            out[col] = np.array([float(v) for v in values])
        except ValueError:
            out[col] = np.array(values)
    if "id" in out:
        out["id"] = np.array([_id_text(v) for v in out["id"]])
    return out


def _id_text(v) -> str:
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def point_pairs(name: str, kind: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ids, source (n, 3), target (n, 3))`` of a 3D point-pair data set.

    ``kind`` selects rows of ``afary2024_simulated`` (``"true"`` or ``"noisy"``).
    """
    t = load(name)
    mask = np.ones(len(t["id"]), dtype=bool)
    if "kind" in t:
        if kind is None:
            raise InputError(f"{name}: choose kind='true' or kind='noisy'")
        mask = t["kind"] == kind
    src = np.column_stack([t["x"], t["y"], t["z"]])[mask]
    dst = np.column_stack([t["X"], t["Y"], t["Z"]])[mask]
    return t["id"][mask], src, dst
