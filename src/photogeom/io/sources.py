"""What an input path names, for the readers: a regular file, a pipe, a folder or a device.

Inputs given on the command line may be pipes (``<(grep ... f.csv)``, ``... | photogeom ...
/dev/stdin``, a named pipe): a pipe can be read once, so a reader that opens its input
twice (a header first, the rest later) would wait for ever on the second open, or read
nothing. The readers either read a pipe once into memory, or, when the format needs seeks
(LAS/LAZ, rasters), refuse it with :func:`pipe_message`. A device (``/dev/zero``,
``/dev/urandom``) never ends: it is refused by every reader (:func:`device_message`) rather
than read until memory runs out.
"""

from __future__ import annotations

import io
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from typing import BinaryIO

from .._pipe_scope import kept_pipes, pipe_reads

#: The kinds :func:`input_kind` returns.
KINDS = ("file", "pipe", "folder", "device", "missing")

__all__ = [
    "KINDS",
    "device_message",
    "input_kind",
    "kept_pipe_bytes",
    "open_input",
    "pipe_bytes",
    "pipe_message",
    "pipe_reads",
    "read_input_bytes",
]


def input_kind(path: str | os.PathLike) -> str:
    """What ``path`` names, following links.

    Parameters
    ----------
    path : str or os.PathLike
        The input.

    Returns
    -------
    str
        ``"file"`` (a regular file; also when it cannot be examined, so that the reader's
        own ``open`` names the problem), ``"pipe"`` (a named or anonymous pipe, or a
        socket: input that can be read once), ``"folder"``, ``"device"`` (a character or
        block device) or ``"missing"``.
    """
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return "missing"
    except (OSError, ValueError):
        return "file"
    if stat.S_ISDIR(mode):
        return "folder"
    if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
        return "pipe"
    if stat.S_ISREG(mode):
        return "file"
    return "device"


def device_message(path: str | os.PathLike, what: str) -> str:
    """The refusal of a device as the input ``what`` (``/dev/zero`` never ends).

    Parameters
    ----------
    path : str or os.PathLike
        The device given.
    what : str
        The input it was given as, in the caller's words (``"the residuals CSV"``).

    Returns
    -------
    str
        The message: what the path is and what to give instead.
    """
    return (
        f"cannot read {what} {path}: it is a device, not a file (a device such as /dev/zero "
        "never ends); give a regular file or a pipe"
    )


def pipe_message(path: str | os.PathLike, what: str, why: str) -> str:
    """The refusal of a pipe as the input ``what`` of a format read with seeks.

    Parameters
    ----------
    path : str or os.PathLike
        The pipe given.
    what : str
        The input it was given as, in the caller's words (``"the LAS cloud"``).
    why : str
        Why the format needs a regular file (``"LAS is read with seeks"``).

    Returns
    -------
    str
        The message: what the path is, why, and to save the stream to a file.
    """
    return (
        f"cannot read {what} {path}: it is a pipe, and {why}; save the stream to a regular "
        "file and give that file"
    )


def _pipe_key(path: str | os.PathLike) -> tuple[str, int, int]:
    st = os.stat(path)
    return (os.path.abspath(path), st.st_dev, st.st_ino)


def _read_upto(path: str | os.PathLike, limit: int | None) -> bytes:
    """The bytes of ``path`` (a file or a pipe), at most ``limit + 1`` (None: all)."""
    with open(path, "rb") as fh:
        return fh.read() if limit is None else fh.read(limit + 1)


def _cut_message(read_to: int) -> str:
    return (
        f"the pipe was read once to {max(read_to, 0)} bytes and holds more; save the stream to a "
        "regular file and give that file"
    )


def pipe_bytes(path: str | os.PathLike, limit: int | None) -> bytes:
    """The content of the pipe ``path``, read once per :func:`pipe_reads` scope.

    Reads at most ``limit + 1`` bytes (so that the caller can tell a stream longer than
    ``limit`` from one of ``limit`` bytes; ``None``: the whole stream). Inside a
    :func:`pipe_reads` scope the first call keeps them and a later call for the same pipe
    returns what the first one read instead of waiting for a second writer; outside every
    scope each call reads the pipe.

    Parameters
    ----------
    path : str or os.PathLike
        A pipe (:func:`input_kind` gives ``"pipe"``).
    limit : int or None
        Most bytes the caller accepts (bytes); the caller refuses a longer result. None
        reads the whole stream.

    Returns
    -------
    bytes
        The pipe's content (up to ``limit + 1`` bytes).

    Raises
    ------
    OSError
        The pipe cannot be opened or read, or an earlier read of it in this scope stopped
        before the ``limit`` asked for now (its end was not kept).
    """
    kept = kept_pipes()
    if kept is None:
        return _read_upto(path, limit)
    key = _pipe_key(path)
    if key not in kept:
        kept[key] = (_read_upto(path, limit), limit)
    data, read_to = kept[key]
    cut = read_to is not None and len(data) > read_to
    if cut and (limit is None or limit > read_to):
        raise OSError(_cut_message(read_to))
    return data


def kept_pipe_bytes(path: str | os.PathLike) -> bytes | None:
    """What :func:`pipe_bytes` read from the pipe ``path`` in the current
    :func:`pipe_reads` scope, whole.

    Parameters
    ----------
    path : str or os.PathLike
        The pipe.

    Returns
    -------
    bytes or None
        The pipe's whole content; None when :func:`pipe_bytes` has not read it (or read only
        a part of it), or outside every scope.
    """
    kept = kept_pipes()
    if kept is None:
        return None
    try:
        key = _pipe_key(path)
    except (OSError, ValueError):
        return None
    data, read_to = kept.get(key, (None, None))
    if data is None or (read_to is not None and len(data) > read_to):
        return None
    return data


def read_input_bytes(path: str | os.PathLike, limit: int | None) -> bytes:
    """The bytes of a regular file or of a pipe (read once per scope, :func:`pipe_bytes`).

    Parameters
    ----------
    path : str or os.PathLike
        The input.
    limit : int or None
        Most bytes the caller accepts (bytes); at most ``limit + 1`` are read. None reads
        the whole input.

    Returns
    -------
    bytes
        The content, up to ``limit + 1`` bytes (the caller refuses a longer one).

    Raises
    ------
    OSError
        The input cannot be opened or read.
    """
    if input_kind(path) == "pipe":
        return pipe_bytes(path, limit)
    return _read_upto(path, limit)


class _KeepingReader:
    """A pipe's file object that keeps every byte read from it, and whether its end was
    reached (:func:`open_input`)."""

    def __init__(self, fh: BinaryIO) -> None:
        self._fh = fh
        self.chunks: list[bytes] = []
        self.ended = False

    def read(self, size: int = -1) -> bytes:
        data = self._fh.read(size)
        if data:
            self.chunks.append(data)
        if (not data and size != 0) or size is None or size < 0:
            self.ended = True  # an empty read, or one to the end
        return data

    def kept(self) -> tuple[bytes, int | None]:
        """The bytes read and the limit :func:`pipe_bytes` records them with: None when
        they are the whole stream; one byte less than their length when the stream was
        left before its end (so that a later read that needs the rest is refused)."""
        data = b"".join(self.chunks)
        return data, (None if self.ended else len(data) - 1)


@contextmanager
def open_input(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """A binary file object for a reader that streams its input (a regular file, or a pipe
    read once per :func:`pipe_reads` scope).

    A regular file (and anything :func:`input_kind` does not call a pipe) is opened as it
    is. Inside a :func:`pipe_reads` scope a pipe that an earlier reader read is served from
    the bytes kept then; a pipe read first here is streamed and every byte read is kept
    when the reader closes it, so that a later read of the same pipe in that scope (by any
    reader: :func:`pipe_bytes`, :func:`read_input_bytes`, this function) gets the same
    bytes instead of waiting for a new writer or reading what it wrote. The memory kept is
    the bytes read from the pipe (the compressed ones for a compressed stream), which the
    reader bounds with its own limit. Outside every scope a pipe is opened and nothing is
    kept.

    Parameters
    ----------
    path : str or os.PathLike
        The input.

    Yields
    ------
    BinaryIO
        An object with ``read(size)``.

    Raises
    ------
    OSError
        The input cannot be opened, or an earlier reader in this scope left the pipe before
        its end (its end was not kept).
    """
    kept = kept_pipes()
    if kept is None or input_kind(path) != "pipe":
        with open(path, "rb") as fh:
            yield fh
        return
    key = _pipe_key(path)
    if key in kept:
        data, read_to = kept[key]
        if read_to is not None and len(data) > read_to:
            raise OSError(_cut_message(read_to))
        yield io.BytesIO(data)
        return
    with open(path, "rb") as fh:
        reader = _KeepingReader(fh)
        try:
            yield reader  # type: ignore[misc]
        finally:
            kept[key] = reader.kept()
