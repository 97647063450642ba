"""Shared helpers of the interchange readers and writers: text input, numbers, atomic output.

Readers are linear in their input: numbers are converted in one vectorised call and only an
error (a token that is not a number, a count that does not match) triggers a second, slower
pass that finds the line to name.
"""

from __future__ import annotations

import bz2
import os
import re
from collections.abc import Mapping
from itertools import chain
from pathlib import Path

import numpy as np

from ..atomicfile import atomic_write_many
from ..errors import FileFormatError

_TOKEN = re.compile(r"\S+")
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf|infinity)")


def read_text(path: str | os.PathLike, what: str) -> str:
    """The text of ``path`` (bzip2-compressed files are recognised by their magic bytes)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise FileFormatError(f"cannot read {what} {p}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"cannot read {what} {p}: it is a directory, not a file") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    if data[:3] == b"BZh":
        try:
            data = bz2.decompress(data)
        except (OSError, ValueError, EOFError) as exc:
            raise FileFormatError(
                f"{p}: a bzip2 file that cannot be decompressed ({exc}); the file is damaged "
                "or truncated"
            ) from None
    if b"\x00" in data[:4096]:
        raise FileFormatError(f"cannot read {what} {p}: it is a binary file, not text")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def token_line(text: str, index: int) -> tuple[int, str]:
    """Line number (1-based) and text of the whitespace-separated token number ``index``."""
    for k, m in enumerate(_TOKEN.finditer(text)):
        if k == index:
            return text.count("\n", 0, m.start()) + 1, m.group()
    return text.count("\n") + 1, ""


def _first_bad_token(text: str) -> tuple[int, int, str] | None:
    for k, m in enumerate(_TOKEN.finditer(text)):
        if not _NUMBER.fullmatch(m.group().lower()):
            return k, text.count("\n", 0, m.start()) + 1, m.group()
    return None


def count_tokens(text: str) -> int:
    """Number of whitespace-separated tokens (vectorised over the bytes)."""
    b = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    if b.size == 0:
        return 0
    space = (b == 32) | ((b >= 9) & (b <= 13))
    starts = ~space
    starts[1:] &= space[:-1]
    return int(np.count_nonzero(starts))


def numbers(text: str, label: str) -> np.ndarray:
    """All whitespace-separated numbers of ``text`` (float64), in one vectorised call.

    Raises :class:`FileFormatError` naming the line of the first token that is not a number.
    """
    try:
        values = np.fromstring(text, sep=" ")
        ok = values.size == count_tokens(text)
    except ValueError:
        ok = False
    if not ok:
        bad = _first_bad_token(text)
        if bad is not None:
            _, line, tok = bad
            raise FileFormatError(f"{label}, line {line}: {tok!r} is not a number")
        # every token matched the number pattern yet the fast path failed: parse slowly
        try:
            values = np.array(text.split(), dtype=float)
        except ValueError as exc:  # pragma: no cover - the pattern above is stricter
            raise FileFormatError(f"{label}: {exc}") from None
    return values


def split_numeric_lines(
    lines: list[str], line_numbers: list[int] | np.ndarray, label: str
) -> tuple[np.ndarray, np.ndarray]:
    """Numbers of each line (flat float64 array) and how many each line holds.

    One vectorised conversion; a token that is not a number is named with its line.
    """
    parts = [ln.split() for ln in lines]
    counts = np.fromiter(map(len, parts), dtype=np.int64, count=len(parts))
    flat = list(chain.from_iterable(parts))
    try:
        values = np.array(flat, dtype=np.float64) if flat else np.zeros(0)
    except ValueError:
        for ln_no, p in zip(line_numbers, parts):
            for t in p:
                if not _NUMBER.fullmatch(t.lower()):
                    raise FileFormatError(f"{label}, line {ln_no}: {t!r} is not a number") from None
        raise FileFormatError(f"{label}: a value is not a number") from None  # pragma: no cover
    return values, counts


def write_files_atomically(files: Mapping[Path, bytes]) -> None:
    """Write several files as one: each is its old or its complete new version, and either
    all are replaced or none is (:func:`photogeom.atomicfile.atomic_write_many`)."""
    atomic_write_many(list(files.items()))


def format_floats(values: np.ndarray) -> list[str]:
    """Shortest round-trip text of each float (``repr``), for writers."""
    return list(map(repr, np.asarray(values, dtype=float).ravel().tolist()))
