"""Reading the JSON parameter files of the command line (transformations, cameras).

The files may come from anywhere, so the reader is strict and bounded:

* at most :data:`MAX_JSON_BYTES` bytes; UTF-8 (UTF-16 and UTF-32 are recognised by their
  byte pattern, as JSON allows); any other encoding is refused with the fix;
* ``NaN``/``Infinity`` (not JSON) and integers of more than :data:`MAX_INT_DIGITS` digits
  are refused; nesting deeper than :data:`MAX_DEPTH` is refused before parsing;
* the top level must be an object; :func:`build_from_json` turns a missing entry or an entry
  of the wrong type or shape into a :class:`~photogeom.errors.FileFormatError` that names
  the file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np

from ..errors import FileFormatError, PhotogeomError

#: Largest JSON parameter file read (bytes).
MAX_JSON_BYTES = 16 << 20
#: Deepest nesting of arrays and objects accepted.
MAX_DEPTH = 64
#: Most digits of an integer accepted.
MAX_INT_DIGITS = 40

_T = TypeVar("_T")


def _max_depth(data: bytes) -> int:
    """Deepest nesting of ``[``/``{`` outside strings, with array operations (no loop, no
    backtracking pattern).

    A quote opens or closes a string unless an odd number of backslashes precedes it; a
    bracket is inside a string when an odd number of such quotes precedes it.
    """
    if data.count(b"[") + data.count(b"{") <= MAX_DEPTH:
        return 0
    a = np.frombuffer(data, dtype=np.uint8)
    # only brackets, quotes and backslashes matter: work on their positions
    pos = np.flatnonzero(np.isin(a, np.frombuffer(b'[]{}"\\', dtype=np.uint8)))
    c = a[pos]
    backslash = c == ord("\\")
    # a backslash run continues only over adjacent positions
    adjacent = np.concatenate([[False], np.diff(pos) == 1])
    count = np.cumsum(backslash, dtype=np.int32)
    start = np.where(backslash & adjacent, 0, count - backslash)
    run = count - np.maximum.accumulate(start)  # backslashes in the run ending here
    before = np.concatenate([[0], run[:-1]]) * adjacent  # the run right before this byte
    quote = (c == ord('"')) & (before % 2 == 0)
    inside = np.cumsum(quote, dtype=np.int32) % 2 == 1
    step = (c == ord("[")).astype(np.int32) + (c == ord("{"))
    step -= (c == ord("]")).astype(np.int32) + (c == ord("}"))
    step[inside] = 0
    return int(np.cumsum(step).max(initial=0))


def _decode(data: bytes, where: str) -> str:
    try:
        return data.decode(json.detect_encoding(data))
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{where}: not UTF-8 text (byte {exc.start}); JSON files are UTF-8: re-save the "
            "file as UTF-8"
        ) from None


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {len(text)} digits (at most {MAX_INT_DIGITS})")
    return int(text)


def _parse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number; write null or a finite number")


def _keep_constant(name: str) -> float:
    return float(name)


def parse_json_bytes(data: bytes, where: str, *, allow_nan: bool = False) -> object:
    """The JSON value of ``data`` (the bytes of a file), parsed with the bounds of the module
    docstring except the size (the caller bounds what it reads).

    Parameters
    ----------
    data : bytes
        The file's content: UTF-8 (a byte-order mark is dropped), or UTF-16 / UTF-32.
    where : str
        The file, for messages.
    allow_nan : bool, default False
        Read ``NaN``/``Infinity`` as floats (files of photogeom's own writers that predate
        their refusal) instead of refusing them.

    Returns
    -------
    object
        The parsed value (any JSON type).

    Raises
    ------
    FileFormatError
        Not UTF-8/16/32, not valid JSON, nested more than :data:`MAX_DEPTH` levels, an
        integer of more than :data:`MAX_INT_DIGITS` digits, or (unless ``allow_nan``)
        ``NaN``/``Infinity``.
    """
    if _max_depth(data) > MAX_DEPTH:
        raise FileFormatError(
            f"{where}: JSON nested more than {MAX_DEPTH} levels deep; not a file photogeom "
            "writes or reads: wrong file?"
        )
    text = _decode(data, where)
    constant = _keep_constant if allow_nan else _parse_constant
    try:
        return json.loads(text, parse_int=_parse_int, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{where}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:
        raise FileFormatError(f"{where}: not accepted: {exc}") from None


def read_json_object(path: str | os.PathLike) -> dict:
    """The top-level JSON object of ``path``; see the module docstring.

    Raises
    ------
    FileFormatError
        Unreadable, too large, not UTF-8, not valid JSON, too deeply nested, a huge integer,
        NaN/Infinity, or a top level that is not an object.
    """
    where = str(path)
    from .sources import read_input_bytes

    try:
        data = read_input_bytes(path, MAX_JSON_BYTES)  # a pipe: read once, kept
    except FileNotFoundError:
        raise FileFormatError(f"cannot read {where}: no such file") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {where}: {exc.strerror or exc}") from None
    if len(data) > MAX_JSON_BYTES:
        raise FileFormatError(
            f"{where}: more than {MAX_JSON_BYTES} bytes; a parameter file is a few kB: wrong file?"
        )
    obj = parse_json_bytes(data, where)
    if not isinstance(obj, dict):
        raise FileFormatError(
            f"{where}: expected a JSON object {{...}}, found {type(obj).__name__}"
        )
    return obj


def build_from_json(
    build: Callable[[dict], _T], data: dict, where: str | os.PathLike, what: str
) -> _T:
    """``build(data)``, with the errors of a malformed entry reported against the file.

    photogeom's own errors get the file name in front; a missing entry (``KeyError``) or
    an entry of the wrong type or shape (``TypeError``, ``ValueError``, ``IndexError``,
    ``AttributeError``, ``OverflowError`` raised while building) becomes a
    :class:`~photogeom.errors.FileFormatError` naming the file and ``what`` was read.
    """
    where = str(Path(where))
    try:
        return build(data)
    except PhotogeomError as exc:
        raise FileFormatError(f"{where}: {exc}") from exc
    except KeyError as exc:
        raise FileFormatError(f"{where}: {what} without the entry {exc.args[0]!r}") from exc
    except (TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise FileFormatError(
            f"{where}: {what} with an entry of the wrong type or shape ({exc})"
        ) from exc
