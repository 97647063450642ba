"""Shared helpers of the interchange readers and writers: text input, numbers, atomic output.

Readers are linear in their input: numbers are converted in one vectorised call and only an
error (a token that is not a number, a count that does not match) triggers a second, slower
pass that finds the line to name.
"""

from __future__ import annotations

import bz2
import os
import re
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from itertools import chain
from pathlib import Path

import numpy as np

from ..atomicfile import atomic_write_many
from ..errors import FileFormatError
from ..io.csvblocks import wide_unicode
from ..io.sources import device_message, input_kind, open_input
from ..numbers import decimal_comma_hint

_TOKEN = re.compile(r"\S+")
#: A number token. The digits before and after the point are separate runs (``\d+(\.\d*)?``,
#: not ``\d+\.?\d*``, where a run of n digits splits n ways and a failed match tries them
#: all): a long token that is not a number is refused in time linear in its length.
_NUMBER = re.compile(
    r"[+-]?(?:\d+(?:\.\d*)?(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf|infinity)"
)


#: Characters no block file can hold in an image name (or a CSV block in any id): NUL
#: (the end of a C string, where COLMAP's binary names end; text holding it is taken for
#: binary) and the line breaks of ``str.splitlines`` (the readers split lines there).
NO_NAME_CHARS = re.compile("[\x00\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")


def unwritable_name(ids) -> tuple[str, str] | None:
    """The first image name of ``ids`` that no block file can hold, and why.

    Parameters
    ----------
    ids : array-like
        Image ids as the block holds them (checked as Python strings: a numpy ``str``
        array would already have dropped trailing NUL characters).

    Returns
    -------
    (str, str) or None
        The name and why (``"is empty"``, ``"holds a NUL character"``, ``"holds the line
        break '\\n'"``); None when every name can be written.
    """
    values = ids.tolist() if hasattr(ids, "tolist") else list(ids)
    for name in map(str, values):
        if not name:
            return name, "is empty"
        bad = NO_NAME_CHARS.search(name)
        if bad is not None:
            c = bad.group()
            return name, "holds a NUL character" if c == "\x00" else f"holds the line break {c!r}"
    return None


#: Bytes of a text input looked at before the rest is read: its header (the size limit of
#: a BAL file), and whether it is binary.
HEAD_BYTES = 64 << 10
#: Bytes read (or decompressed) at a time.
_CHUNK = 1 << 20


def read_text(
    path: str | os.PathLike,
    what: str,
    *,
    limit: Callable[[str], tuple[int, str]] | None = None,
) -> str:
    """The text of ``path``: UTF-8 (a byte-order mark dropped; other bytes read as
    Latin-1), or UTF-16/32 with a byte-order mark or, for ASCII text, without one
    (:func:`photogeom.io.csvblocks.wide_unicode`). bzip2-compressed files are recognised by
    their magic bytes and decompressed as they are read; other files with NUL bytes are
    refused as binary.

    Parameters
    ----------
    path : str or os.PathLike
        A regular file or a pipe. Inside a :func:`photogeom.io.sources.pipe_reads` scope
        (every command) a pipe is read once: its bytes (as read, compressed or not; at most
        what ``limit`` allows, plus the chunk that went over it) are kept for any later
        read of it in the scope (:func:`photogeom.io.sources.open_input`). A device
        (``/dev/zero``) is refused.
    what : str
        What the file is (``"BAL file"``), for messages.
    limit : callable, optional
        ``limit(head) -> (bytes, message)``: given the text of the first
        :data:`HEAD_BYTES` bytes (decompressed) of an input longer than that, the most
        bytes the input may hold (decompressed) and the message of the
        :class:`FileFormatError` raised when it holds more. It may raise a
        :class:`FileFormatError` itself (a header that is not one). Without it, the input is
        read whole.

    Returns
    -------
    str
        The decoded text.

    Raises
    ------
    FileFormatError
        No such file, a folder, a device, no permission, a damaged bzip2 stream, binary
        content, UTF-16/32 text with bytes of another encoding, or more bytes than
        ``limit`` allows.
    """
    p = Path(path)
    with _input_errors(p, what):
        # a pipe is read once per command: from the bytes an earlier reader kept (grid
        # fit's format), or streamed and kept for the later readers
        with open_input(p) as fh:
            data = _read_limited(fh, p, what, limit)
    return _decode_text(data, p, what)


def read_binary(path: str | os.PathLike, what: str) -> bytes:
    """The bytes of a binary input (a regular file, or a pipe read once per command as in
    :func:`read_text`).

    Raises
    ------
    FileFormatError
        No such file, a folder, a device (``/dev/zero`` never ends), no permission.
    """
    p = Path(path)
    with _input_errors(p, what), open_input(p) as fh:
        return fh.read()


@contextmanager
def _input_errors(p: Path, what: str) -> Iterator[None]:
    """Refuse a device, and turn the errors of opening and reading ``p`` into
    :class:`FileFormatError` naming ``what``."""
    if input_kind(p) == "device":
        raise FileFormatError(device_message(p, what))
    try:
        yield
    except FileNotFoundError:
        raise FileFormatError(f"cannot read {what} {p}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"cannot read {what} {p}: it is a directory, not a file") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {what} {p}: {exc.strerror or exc}") from None


def _raw_chunks(fh) -> Iterator[bytes]:
    while chunk := fh.read(_CHUNK):
        yield chunk


def _bz2_chunks(raw: Iterator[bytes]) -> Iterator[bytes]:
    """The decompressed bytes of bzip2 data, at most :data:`_CHUNK` at a time (several
    concatenated streams, as ``pbzip2`` writes them, one after the other).

    Compressed bytes beyond twice the decompressed ones plus :data:`HEAD_BYTES` are refused
    (:class:`ValueError`): text compresses, so only streams that decompress to (almost)
    nothing get there, and the readers' bounds, on decompressed bytes, would never stop a
    stream of them that never ends (14 bytes each, read for ever)."""
    dec = bz2.BZ2Decompressor()
    fed = made = 0  # compressed bytes given to the decompressors, decompressed bytes
    for data in raw:
        while data or not (dec.eof or dec.needs_input):
            if dec.eof:  # the next stream
                dec = bz2.BZ2Decompressor()
            fed += len(data)
            out = dec.decompress(data, _CHUNK)
            data = dec.unused_data if dec.eof else b""
            fed -= len(data)
            made += len(out)
            if fed > 2 * made + HEAD_BYTES:
                raise ValueError(
                    f"its first {fed} bytes decompress to {made} bytes: empty bzip2 streams?"
                )
            if out:
                yield out
    if not dec.eof:
        raise EOFError("the data ends before the end-of-stream marker")


def _read_limited(fh, p: Path, what: str, limit) -> bytes:
    """The (decompressed) bytes of an open input, refused as binary from its head and, with
    ``limit``, beyond the size its head allows; see :func:`read_text`."""
    chunks = _raw_chunks(fh)
    first = next(chunks, b"")
    packed = first[:3] == b"BZh"
    if packed:
        chunks = _bz2_chunks(chain([first], chunks))
    else:
        chunks = chain([first], chunks)
    parts: list[bytes] = []
    total = 0
    head_seen = False
    bound: tuple[int, str] | None = None
    try:
        for chunk in chunks:
            parts.append(chunk)
            total += len(chunk)
            if not head_seen and total >= HEAD_BYTES:
                head_seen = True  # binary content is refused before the rest is read
                text = _decode_text(b"".join(parts)[:HEAD_BYTES], p, what, partial=True)
                if limit is not None:
                    bound = limit(text)
            if bound is not None and total > bound[0]:
                raise FileFormatError(bound[1])
    except (OSError, ValueError, EOFError) as exc:
        if not packed or isinstance(exc, FileFormatError):
            raise
        raise FileFormatError(
            f"{p}: a bzip2 file that cannot be decompressed ({exc}); the file is damaged "
            "or truncated"
        ) from None
    return b"".join(parts)


def _decode_text(data: bytes, p: Path, what: str, *, partial: bool = False) -> str:
    """Text of the bytes of an input (see :func:`read_text`); ``partial``: the bytes are the
    head of a longer input (a character cut at the end is dropped)."""
    errors = "ignore" if partial else "strict"
    wide = wide_unicode(data[:4096])
    if wide is not None:  # UTF-16/32 text (Windows tools, spreadsheets): read it
        name, bom = wide
        codec = name.lower() if bom else name.lower() + ("-le" if data[1:2] == b"\x00" else "-be")
        try:
            if partial:  # a character cut at the end of the head is dropped
                step = 4 if "32" in name else 2
                data = data[: len(data) // step * step]
            return data.decode(codec)
        except UnicodeDecodeError as exc:
            raise FileFormatError(
                f"cannot read {what} {p}: it begins as {name} text but byte {exc.start} is "
                f"not {name}; save it as UTF-8"
            ) from None
    if b"\x00" in data[:4096]:
        raise FileFormatError(f"cannot read {what} {p}: it is a binary file, not text")
    try:
        return data.decode("utf-8-sig", errors=errors)
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


def rotation_defects(R: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which matrices of a stack read from a file are no rotation, for the readers'
    refusals (Bundler's camera rotations, Metashape's transforms).

    Parameters
    ----------
    R : numpy.ndarray
        (k, 3, 3) matrices (finite; unitless).
    tolerance : float
        Largest ``max |R R' - I|`` read as a rotation (the digits the format holds).

    Returns
    -------
    bad : numpy.ndarray
        (k,) bool: off the orthonormal by more than ``tolerance``, or ``det R <= 0``.
    defect : numpy.ndarray
        (k,) ``max |R R' - I|`` of each.
    det : numpy.ndarray
        (k,) ``det R`` of each.
    """
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    defect = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    return (defect > tolerance) | ~(det > 0), defect, det


def token_starts(b: np.ndarray) -> np.ndarray:
    """Which bytes (uint8 array of UTF-8 text) begin a whitespace-separated token (bool)."""
    space = (b == 32) | ((b >= 9) & (b <= 13))
    starts = ~space
    starts[1:] &= space[:-1]
    return starts


def count_tokens(text: str) -> int:
    """Number of whitespace-separated tokens (vectorised over the bytes)."""
    b = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    return int(np.count_nonzero(token_starts(b)))


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
            raise FileFormatError(
                f"{label}, line {line}: {tok!r} is not a number{decimal_comma_hint(tok)}"
            )
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
    values, counts, _ = split_numeric_tokens(lines, line_numbers, label)
    return values, counts


def split_numeric_tokens(
    lines: list[str], line_numbers: list[int] | np.ndarray, label: str
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """As :func:`split_numeric_lines`, and the flat list of the tokens themselves (for
    integer ids that float64 cannot hold exactly, see :func:`exact_integers`)."""
    parts = [ln.split() for ln in lines]
    counts = np.fromiter(map(len, parts), dtype=np.int64, count=len(parts))
    flat = list(chain.from_iterable(parts))
    try:
        values = np.array(flat, dtype=np.float64) if flat else np.zeros(0)
    except ValueError:
        for ln_no, p in zip(line_numbers, parts):
            for t in p:
                if not _NUMBER.fullmatch(t.lower()):
                    raise FileFormatError(
                        f"{label}, line {ln_no}: {t!r} is not a number{decimal_comma_hint(t)}"
                    ) from None
        raise FileFormatError(f"{label}: a value is not a number") from None  # pragma: no cover
    return values, counts, flat


def _int64_text(t: str) -> bool:
    try:
        return -(2**63) <= int(t) < 2**63
    except ValueError:
        return False


#: Integers above this magnitude are not all exact in float64 (2^53).
EXACT_FLOAT_INT = 2**53


def exact_integers(
    values: np.ndarray,
    tokens: list[str],
    positions: np.ndarray,
    line_numbers: np.ndarray,
    label: str,
    field: str,
) -> np.ndarray:
    """The integers at ``positions`` of a flat value array, exact also beyond 2^53.

    Parameters
    ----------
    values : numpy.ndarray
        Flat float64 values (of :func:`split_numeric_tokens`).
    tokens : list of str
        The tokens the values were converted from.
    positions : numpy.ndarray of int
        Positions of the integer fields in ``values`` / ``tokens``.
    line_numbers : numpy.ndarray of int
        The line of each position (1-based), for errors.
    label : str
        The file, for errors.
    field : str
        The name of the field (e.g. ``POINT3D_ID``), for errors.

    Returns
    -------
    numpy.ndarray of int64
        The integers; a float64 value of magnitude 2^53 or more (where neighbouring
        integers share one float) is converted from its token instead.

    Raises
    ------
    FileFormatError
        A field that is not an integer, or one outside the 64-bit signed range.
    """
    v = values[positions]
    bad = np.flatnonzero(v != np.round(v))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(
            f"{label}, line {int(line_numbers[k])}: {field} {tokens[positions[k]]!r} is not an "
            "integer"
        )
    big = np.abs(v) >= EXACT_FLOAT_INT
    out = np.zeros(v.size, dtype=np.int64)
    out[~big] = v[~big].astype(np.int64)
    idx = np.flatnonzero(big)
    if idx.size:  # ids beyond 2^53: converted from their text (one numpy conversion)
        text = np.array([tokens[i] for i in positions[idx].tolist()], dtype=str)
        try:
            out[idx] = text.astype(np.int64)
        except (ValueError, OverflowError):
            k = next(k for k, t in enumerate(text.tolist()) if not _int64_text(t))
            raise FileFormatError(
                f"{label}, line {int(line_numbers[idx[k]])}: {field} {str(text[k])!r} is not an "
                "integer of the 64-bit signed range photogeom reads (|id| < 2^63, written in "
                "full digits, not with an exponent)"
            ) from None
    return out


def write_files_atomically(files: Mapping[Path, bytes]) -> None:
    """Write several files as one: each is its old or its complete new version, and either
    all are replaced or none is (:func:`photogeom.atomicfile.atomic_write_many`)."""
    atomic_write_many(list(files.items()))


def format_floats(values: np.ndarray) -> list[str]:
    """Shortest round-trip text of each float (``repr``), for writers."""
    return list(map(repr, np.asarray(values, dtype=float).ravel().tolist()))
