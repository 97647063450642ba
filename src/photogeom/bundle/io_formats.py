"""One entry point for the block formats: read or write by path, the format named or found.

* a file: BAL (plain or bzip2), or Bundler (``bundle.out``: its first line
  ``# Bundle file v0.3``; the image list goes with it);
* a folder with ``cameras.txt`` / ``images.txt`` / ``points3D.txt``: a COLMAP text model;
* a folder with ``cameras.bin`` / ``images.bin`` / ``points3D.bin``: a COLMAP binary model
  (``"colmap-bin"``);
* a folder with ``images.csv`` / ``points.csv`` / ``observations.csv``: a CSV block.
"""

from __future__ import annotations

import bz2
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..atomicfile import atomic_write_many
from ..errors import FileFormatError, InputError, LostRecordWarning, OutputError
from .block import Block
from .io_bal import bal_text, read_bal, write_bal
from .io_bundler import bundler_texts, is_bundler_file, read_bundler, write_bundler
from .io_colmap import (
    BINARY_FILES,
    TEXT_FILES,
    ColmapModelsDiffer,
    colmap_files,
    read_colmap,
    write_colmap,
)
from .io_csv import (
    csv_block_texts,
    read_csv_block,
    record_files,
    write_csv_block,
)

#: Names of the block formats.
FORMATS = ("bal", "colmap", "colmap-bin", "csv", "bundler")
#: Formats written as a folder of files (BAL and Bundler are one file).
FOLDER_FORMATS = ("colmap", "colmap-bin", "csv")
_NAMES = {"bal": "BAL file", "colmap": "COLMAP text model", "csv": "CSV block",
          "bundler": "Bundler file"}  # fmt: skip
_NAMES["colmap-bin"] = "COLMAP binary model"


def check_block_target(path: str | os.PathLike, kind: str, what: str | None = None) -> None:
    """Refuse a destination that a block in format ``kind`` cannot be written to, before
    anything is computed or written.

    Parameters
    ----------
    path : path-like
        Folder (``"colmap"``, ``"colmap-bin"``, ``"csv"``; created when missing) or file
        (``"bal"``, ``"bundler"``).
    kind : str
        ``"bal"``, ``"colmap"``, ``"colmap-bin"``, ``"csv"`` or ``"bundler"``.
    what : str, optional
        How the caller names the destination (e.g. a command-line option), put before the
        message.

    Raises
    ------
    OutputError
        A folder format onto an existing file (or under one), a BAL file onto a folder or
        into a folder that does not exist, a COLMAP text model into a folder holding a
        COLMAP binary model (COLMAP would read the old binary files), a binary model into a
        folder holding a text model.
    """
    p = Path(path)
    k = _check(kind)
    head = f"{what}: " if what else ""
    if k in FOLDER_FORMATS:
        if p.exists() and not p.is_dir():
            raise OutputError(
                f"{head}cannot write {p}: it is a file, not a folder; a {_NAMES[k]} is a "
                "folder of files: give a folder path (new or existing)"
            )
        # the other COLMAP model: COLMAP reads the binary one first, read_colmap neither
        other = {"colmap": (BINARY_FILES, "colmap-bin"), "colmap-bin": (TEXT_FILES, "colmap")}
        if k in other and p.is_dir():
            files, kind = other[k]
            stale = [f for f in files if (p / f).is_file()]
            if stale:
                why = (
                    "which COLMAP reads instead of the text files"
                    if k == "colmap"
                    else "which would stand beside the binary files with other numbers"
                )
                raise OutputError(
                    f"{head}cannot write a {_NAMES[k]} into {p}: it holds a {_NAMES[kind]} "
                    f"({', '.join(stale)}), {why}; give another folder, or remove the "
                    f"{stale[0][-4:]} files first"
                )
        up = p.parent
        while not up.exists() and up != up.parent:
            up = up.parent
        if up.exists() and not up.is_dir():
            raise OutputError(
                f"{head}cannot write {p}: {up} is a file, not a folder; give a folder path"
            )
    else:
        if p.is_dir():
            raise OutputError(
                f"{head}cannot write {p}: it is a folder; a {_NAMES[k].split()[0]} block is one "
                f"file: give a file name ({'.out' if k == 'bundler' else '.bal, .txt or .bz2'})"
            )
        if str(p.parent) and not p.parent.is_dir():
            raise OutputError(
                f"{head}cannot write {p}: folder {p.parent} does not exist; create it first"
            )


def block_files(
    block: Block, path: str | os.PathLike, kind: str, **options
) -> dict[Path, bytes]:
    """The files of ``block`` written as ``kind`` at ``path`` (nothing is written).

    Parameters
    ----------
    block : Block
    path : path-like
        The folder of a COLMAP or CSV block, the file of a BAL block (``.bz2``: compressed).
    kind : str
        ``"bal"``, ``"colmap"``, ``"colmap-bin"``, ``"csv"`` or ``"bundler"``.
    **options
        Options of :func:`write_bal`, :func:`write_colmap` or :func:`write_csv_block`.

    Returns
    -------
    dict of Path -> bytes
        Destination and content of every file, for :func:`write_files` (one batch with other
        outputs: all are written or none is).
    """
    p = Path(path)
    k = _check(kind)
    if k == "bal":
        data = bal_text(block, **options).encode("ascii")
        files = {p: bz2.compress(data) if p.suffix == ".bz2" else data}
    elif k == "bundler":  # the file and its image list
        out, names = bundler_texts(block, **options)
        files = {p: out.encode("ascii"), p.with_name(p.name + ".list.txt"): names.encode()}
    elif k in ("colmap", "colmap-bin"):
        model = colmap_files(block, **({"binary": True} if k == "colmap-bin" else {}), **options)
        files = {p / name: data for name, data in model.items()}
    else:
        texts = csv_block_texts(block, **options)
        files = {p / name: text.encode("utf-8") for name, text in texts.items()}
        files |= record_files(block, p)
    # after the texts: a block the format refuses gets the refusal alone, not the warning
    warn_lost_record(block, p, k)
    return files


def write_files(files: Mapping[Path, bytes], folders: Sequence[Path] = ()) -> list[Path]:
    """Write several files as one: every file is replaced, or none is changed.

    Parameters
    ----------
    files : mapping Path -> bytes
        Destinations and contents (:func:`photogeom.atomicfile.atomic_write_many`).
    folders : sequence of Path
        Folders to create first when missing (with missing parents); the folders created
        are removed again when a file cannot be written, so a failure leaves nothing behind.

    Raises
    ------
    OutputError
        A folder that is a file or cannot be created, a file that cannot be written.
    """
    made: list[Path] = []
    try:
        for folder in folders:
            missing = []
            d = Path(folder)
            while not d.exists() and d != d.parent:
                missing.append(d)
                d = d.parent
            if not d.is_dir():
                raise OutputError(
                    f"cannot write {folder}: {d} is a file, not a folder; give a folder path"
                )
            for m in reversed(missing):
                try:
                    m.mkdir()
                except OSError as exc:
                    raise OutputError(
                        f"cannot create folder {m}: {exc.strerror or exc}", exc.errno
                    ) from None
                made.append(m)
        written = atomic_write_many(list(files.items()))
    except BaseException:
        for m in reversed(made):  # empty again: the batch rolled its files back
            try:
                m.rmdir()
            except OSError:
                pass
        raise
    return written


def detect_format(path: str | os.PathLike) -> str:
    """The block format of an existing file (or pipe) or folder (see the module docstring).

    Parameters
    ----------
    path : path-like
        A BAL or Bundler file or pipe (Bundler: its first line ``# Bundle file``; a pipe
        is read once, whole, inside a :func:`photogeom.io.sources.pipe_reads` scope, every
        command's, and its bytes kept for the reader; outside every scope it is not read and
        taken for BAL, whose reader names ``kind='bundler'``), or a folder holding a COLMAP
        text or binary model or a CSV block.

    Returns
    -------
    str
        ``"bal"``, ``"colmap"``, ``"colmap-bin"``, ``"csv"`` or ``"bundler"``.

    Raises
    ------
    FileFormatError
        ``path`` does not exist or is a folder holding none of them (a folder holding both
        COLMAP models is ``"colmap-bin"``, COLMAP's choice: :func:`read_block` reads both
        and refuses them when they differ).
    """
    p = Path(path)
    if p.exists() and not p.is_dir():  # a file, or a pipe (read once); read_bal refuses devices
        return "bundler" if is_bundler_file(p) else "bal"
    if p.is_dir():
        if any((p / f).is_file() for f in BINARY_FILES):
            return "colmap-bin"  # with a text model too: read_block reads and compares both
        if any((p / f).is_file() for f in TEXT_FILES):
            return "colmap"
        if (p / "images.csv").is_file() or (p / "observations.csv").is_file():
            return "csv"
        raise FileFormatError(
            f"{p}: a folder with neither a COLMAP text model (cameras.txt, images.txt, "
            "points3D.txt) or binary model (cameras.bin, images.bin, points3D.bin) nor a CSV "
            "block (images.csv, points.csv, observations.csv)"
        )
    raise FileFormatError(f"{p}: no such file or folder")


def _check(kind: str) -> str:
    k = str(kind).lower()
    if k not in FORMATS:
        raise InputError(f"unknown block format {kind!r}; choose from {', '.join(FORMATS)}")
    return k


def read_block(path: str | os.PathLike, kind: str | None = None, **options) -> Block:
    """Read a block from a BAL or Bundler file, a COLMAP text or binary model or a CSV
    folder.

    Parameters
    ----------
    path : path-like
        The file or folder.
    kind : {"bal", "colmap", "colmap-bin", "csv", "bundler"}, optional
        The format (``"colmap"`` the text model, ``"colmap-bin"`` the binary one); default
        :func:`detect_format`.
    **options
        Keywords of :func:`read_bal`, :func:`read_colmap` or :func:`read_csv_block`.

    Returns
    -------
    Block
        The block, in photogeom's conventions (pixels from the centre of the first pixel).
    """
    k = detect_format(path) if kind is None else _check(kind)
    if k in ("colmap", "colmap-bin"):  # detected: both models compared (read_colmap)
        binary = None if kind is None else k == "colmap-bin"
        if binary is None:
            try:
                return read_colmap(path, **options)
            except ColmapModelsDiffer as exc:
                raise exc.chosen_by(
                    "pass kind='colmap-bin' to read the .bin files or kind='colmap' for the "
                    ".txt files, or remove one of the two"
                ) from None
        return read_colmap(path, binary=binary, **options)
    reader = {"bal": read_bal, "csv": read_csv_block, "bundler": read_bundler}[k]
    return reader(path, **options)


#: The warning of :func:`write_block` for the final fit's block of ``adjust_with_grids``
#: written in a format without a place for its record (``Block.joint_adjustment``).
LOST_RECORD = (
    "{path}: a {kind} has no place for the record of the joint adjustment with grids this "
    "block is the final fit of (Block.joint_adjustment): readjust on the block read back "
    "takes the bundle adjustment of that block as the first adjustment of its chain, whose "
    "redundancy is too large; write a CSV block folder to keep the record"
)


def warn_lost_record(block: Block, path: Path, kind: str) -> None:
    """Warn (:data:`LOST_RECORD`) when ``block`` carries the record of a joint adjustment
    with grids and format ``kind`` has no place for it."""
    if kind != "csv" and block.joint_adjustment is not None:
        warnings.warn(
            LOST_RECORD.format(path=path, kind=_NAMES[kind]), LostRecordWarning, stacklevel=3
        )


def write_block(block: Block, path: str | os.PathLike, kind: str | None = None, **options):
    """Write a block as a BAL or Bundler file, a COLMAP text or binary model or a CSV folder.

    Parameters
    ----------
    block : Block
        The block to write.
    path : path-like
        The file or folder.
    kind : {"bal", "colmap", "colmap-bin", "csv", "bundler"}, optional
        The format (``"colmap-bin"``: ``"colmap"`` with ``binary=True``). Without it: an
        existing path's format (:func:`detect_format`), else BAL for names ending in
        ``.bal``, ``.txt`` or ``.bz2``; a new folder needs ``kind``.
    **options
        Keywords of :func:`write_bal`, :func:`write_colmap` or :func:`write_csv_block`.

    Returns
    -------
    pathlib.Path
        The file or folder written.

    Warns
    -----
    LostRecordWarning
        The block carries the record of a joint adjustment with grids
        (``Block.joint_adjustment``) and the format is not a CSV folder, which alone holds it.
    """
    p = Path(path)
    if kind is None:
        if p.exists():
            kind = detect_format(p)
        elif p.suffix.lower() in (".bal", ".txt", ".bz2"):
            kind = "bal"
        elif p.suffix.lower() == ".out":
            kind = "bundler"
        else:
            raise InputError(
                f"{p}: say which format to write (kind='colmap', 'colmap-bin', 'csv' or "
                "'bal'); only BAL "
                "files are recognised by their name (.bal, .txt, .bz2)"
            )
    k = _check(kind)
    if k == "colmap-bin":
        options = {**options, "binary": True}
    writer = {"bal": write_bal, "csv": write_csv_block, "bundler": write_bundler}.get(
        k, write_colmap
    )
    written = writer(block, p, **options)
    warn_lost_record(block, p, k)  # after the writer: a refused block gets the refusal alone
    return written
