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
import re
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from ..errors import FileFormatError, PhotogeomError

#: Largest JSON parameter file read (bytes).
MAX_JSON_BYTES = 16 << 20
#: Deepest nesting of arrays and objects accepted.
MAX_DEPTH = 64
#: Most digits of an integer accepted.
MAX_INT_DIGITS = 40

_T = TypeVar("_T")
_BRACKETS = re.compile(rb'[\[\]{}"\\]')


def _max_depth(data: bytes) -> int:
    """Deepest nesting of ``[``/``{`` outside strings (one pass over the bracket, quote and
    backslash characters; stops once :data:`MAX_DEPTH` is exceeded)."""
    if data.count(b"[") + data.count(b"{") <= MAX_DEPTH:
        return 0
    depth = deepest = 0
    in_string = False
    escaped_at = -1
    for m in _BRACKETS.finditer(data):
        i, c = m.start(), m.group()
        if in_string:
            if i == escaped_at:
                continue
            if c == b"\\":
                escaped_at = i + 1
            elif c == b'"':
                in_string = False
            continue
        if c == b'"':
            in_string = True
        elif c in (b"[", b"{"):
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > MAX_DEPTH:
                    break
        elif c in (b"]", b"}"):
            depth -= 1
    return deepest


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


def read_json_object(path: str | os.PathLike) -> dict:
    """The top-level JSON object of ``path``; see the module docstring.

    Raises
    ------
    FileFormatError
        Unreadable, too large, not UTF-8, not valid JSON, too deeply nested, a huge integer,
        NaN/Infinity, or a top level that is not an object.
    """
    where = str(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_JSON_BYTES + 1)
    except FileNotFoundError:
        raise FileFormatError(f"cannot read {where}: no such file") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {where}: {exc.strerror or exc}") from None
    if len(data) > MAX_JSON_BYTES:
        raise FileFormatError(
            f"{where}: more than {MAX_JSON_BYTES} bytes; a parameter file is a few kB: wrong file?"
        )
    if _max_depth(data) > MAX_DEPTH:
        raise FileFormatError(
            f"{where}: JSON nested more than {MAX_DEPTH} levels deep; not a parameter file"
        )
    text = _decode(data, where)
    try:
        obj = json.loads(text, parse_int=_parse_int, parse_constant=_parse_constant)
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{where}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:
        raise FileFormatError(f"{where}: not accepted: {exc}") from None
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
