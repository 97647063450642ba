"""One entry point for the block formats: read or write by path, the format named or found.

* a file: BAL (plain or bzip2);
* a folder with ``cameras.txt`` / ``images.txt`` / ``points3D.txt``: a COLMAP text model;
* a folder with ``images.csv`` / ``points.csv`` / ``observations.csv``: a CSV block.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import FileFormatError, InputError
from .block import Block
from .io_bal import read_bal, write_bal
from .io_colmap import read_colmap, write_colmap
from .io_csv import read_csv_block, write_csv_block

#: Names of the block formats.
FORMATS = ("bal", "colmap", "csv")


def detect_format(path: str | os.PathLike) -> str:
    """``"bal"``, ``"colmap"`` or ``"csv"`` for an existing file or folder (see the module
    docstring); :class:`FileFormatError` when it is none of them."""
    p = Path(path)
    if p.is_file():
        return "bal"
    if p.is_dir():
        if (p / "images.txt").is_file() or (p / "cameras.txt").is_file():
            return "colmap"
        if (p / "images.csv").is_file() or (p / "observations.csv").is_file():
            return "csv"
        raise FileFormatError(
            f"{p}: a folder with neither a COLMAP text model (cameras.txt, images.txt, "
            "points3D.txt) nor a CSV block (images.csv, points.csv, observations.csv)"
        )
    raise FileFormatError(f"{p}: no such file or folder")


def _check(kind: str) -> str:
    k = str(kind).lower()
    if k not in FORMATS:
        raise InputError(f"unknown block format {kind!r}; choose from {', '.join(FORMATS)}")
    return k


def read_block(path: str | os.PathLike, kind: str | None = None, **options) -> Block:
    """Read a block from a BAL file, a COLMAP text model or a CSV folder.

    ``kind`` (``"bal"``, ``"colmap"``, ``"csv"``) defaults to :func:`detect_format`;
    ``options`` go to :func:`read_bal`, :func:`read_colmap` or :func:`read_csv_block`.
    """
    k = detect_format(path) if kind is None else _check(kind)
    reader = {"bal": read_bal, "colmap": read_colmap, "csv": read_csv_block}[k]
    return reader(path, **options)


def write_block(block: Block, path: str | os.PathLike, kind: str | None = None, **options):
    """Write a block as a BAL file, a COLMAP text model or a CSV folder.

    Without ``kind``: an existing path's format (:func:`detect_format`), else BAL for names
    ending in ``.bal``, ``.txt`` or ``.bz2``; a new folder needs ``kind``. ``options`` go to
    :func:`write_bal`, :func:`write_colmap` or :func:`write_csv_block`.
    """
    p = Path(path)
    if kind is None:
        if p.exists():
            kind = detect_format(p)
        elif p.suffix.lower() in (".bal", ".txt", ".bz2"):
            kind = "bal"
        else:
            raise InputError(
                f"{p}: say which format to write (kind='colmap', 'csv' or 'bal'); only BAL "
                "files are recognised by their name (.bal, .txt, .bz2)"
            )
    k = _check(kind)
    writer = {"bal": write_bal, "colmap": write_colmap, "csv": write_csv_block}[k]
    return writer(block, p, **options)
