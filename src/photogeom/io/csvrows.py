"""Rows of a point CSV formatted as text in compiled code, in worker threads, written in order.

The writing counterpart of :mod:`photogeom.io.csvblocks`. The columns of a chunk of rows
(text as pyarrow string arrays, numbers as float64 arrays) become CSV bytes through
pyarrow's kernels, which release the interpreter lock: slices of rows are formatted in a
few worker threads while the caller reads and computes the next chunk, and the bytes are
written in the order of the rows. At most a few slices are in flight, so memory stays that
of a few chunks whatever the number of rows.

Text of the values:

* numbers: the shortest text that reads back to the same float64 (pyarrow's conversion;
  ``1e+22``, ``2.5e-8``), integral values keep a ``.0`` (``3.0``, ``-0.0``), ``nan``,
  ``inf``, ``-inf``;
* text: written as it is, enclosed in double quotes (inner quotes doubled) when it holds a
  comma, a double quote or a line break, or begins with ``#`` (after blanks): a line that
  begins with an unquoted ``#`` is a comment to the readers, so an id such as ``#12`` would
  otherwise vanish from the file when it is read back.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Sequence
from itertools import pairwise

import numpy as np

#: Most rows per slice formatted by one task (chunks are cut into equal slices).
SLICE_ROWS = 1 << 14
#: Chunks with fewer rows are formatted at once in the calling thread (no threads started).
MIN_THREADED_ROWS = 1 << 12
#: Most worker threads. Formatting a row costs about twice its parsing, which one thread
#: does: more workers would wait for the reader and only hold memory.
MAX_WORKERS = 4
#: Characters that make a text field quoted (``#`` only at its start, after blanks).
_NEEDS_QUOTES = (b",", b'"', b"\n", b"\r", b"#")
#: Fields that are quoted: a comma, quote or line break anywhere, or a leading ``#`` (which
#: would make the line a comment when it is the first field).
_QUOTE_PATTERN = r'[,"\r\n]|^\s*#'


def _pa():
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    return pa, pc, pcsv


def float_text(values: np.ndarray):
    """Shortest round-trip text of float64 values (pyarrow string array); integral values
    keep a ``.0``."""
    pa, pc, _ = _pa()
    values = np.ascontiguousarray(values, dtype=np.float64)
    text = pc.cast(pa.array(values), pa.string())
    with np.errstate(invalid="ignore"):
        integral = np.isfinite(values) & (np.floor(values) == values)
    count = int(np.count_nonzero(integral))
    if count == 0:
        return text
    # integral values are written as digits ("3") or with an exponent ("1e+22")
    if count == values.shape[0]:
        if not pc.any(pc.match_substring(text, "e")).as_py():
            return pc.binary_join_element_wise(text, ".0", "")
        digits = pc.invert(pc.match_substring(text, "e"))
    else:
        where = np.flatnonzero(integral)
        sub_digits = pc.invert(pc.match_substring(pc.take(text, pa.array(where)), "e"))
        mask = np.zeros(values.shape[0], dtype=bool)
        mask[where[sub_digits.to_numpy(zero_copy_only=False)]] = True
        digits = pa.array(mask)
    return pc.if_else(digits, pc.binary_join_element_wise(text, ".0", ""), text)


def text_column(values):
    """Values of an extra column as a pyarrow string array: text as it is, integers as
    integers, floats by :func:`float_text`."""
    pa, pc, _ = _pa()
    if isinstance(values, (pa.Array, pa.ChunkedArray)):
        if isinstance(values, pa.ChunkedArray):
            values = values.combine_chunks()
        if pa.types.is_string(values.type) or pa.types.is_large_string(values.type):
            return values
        if pa.types.is_floating(values.type):
            return float_text(values.to_numpy(zero_copy_only=False))
        return pc.cast(values, pa.string())
    arr = np.asarray(values)
    if arr.dtype.kind in "iu":  # counts stay integers
        return pc.cast(pa.array(arr.astype(np.int64)), pa.string())
    if arr.dtype.kind == "f":
        return float_text(arr)
    if arr.dtype == object and len(arr) and all(isinstance(v, float | np.floating) for v in arr):
        return float_text(arr.astype(float))
    return pa.array([str(v) for v in values], pa.string())


def quoted(text):
    """``text`` (pyarrow string array) with the fields holding a comma, a quote or a line
    break, or beginning with ``#``, enclosed in quotes, inner quotes doubled (the CSV rule);
    a missing value (null) is an empty field."""
    _, pc, _ = _pa()
    if text.null_count:
        text = pc.fill_null(text, "")
    if len(text) == 0 or not _may_need_quotes(text):
        return text
    need = pc.match_substring_regex(text, _QUOTE_PATTERN)
    if not pc.any(need).as_py():
        return text
    enclosed = pc.binary_join_element_wise(
        '"', pc.replace_substring(text, '"', '""'), '"', ""
    )  # fmt: skip
    return pc.if_else(need, enclosed, text)


def _may_need_quotes(text) -> bool:
    """Whether the bytes of ``text`` hold a character that needs quotes (a fast search of
    the array's data, without a Python object per value)."""
    _, offsets, data = text.buffers()[:3]
    if data is None or len(text) == 0:
        return False
    start, stop = _byte_range(text, offsets)
    raw = data.slice(start, stop - start).to_pybytes()
    return any(c in raw for c in _NEEDS_QUOTES)


def _byte_range(text, offsets) -> tuple[int, int]:
    """First and end byte, in its data buffer, of a (sliced) string array."""
    import pyarrow as pa

    dtype = np.dtype(np.int64 if pa.types.is_large_string(text.type) else np.int32)
    ends = np.frombuffer(
        offsets, dtype=dtype, count=len(text) + 1, offset=text.offset * dtype.itemsize
    )
    return int(ends[0]), int(ends[-1])


def format_rows(texts: Sequence, numbers: np.ndarray, extras: Sequence, start: int, stop: int):
    """CSV bytes (a bytes-like object) of rows ``start:stop``, each line ended by ``\\n``.

    Parameters
    ----------
    texts : sequence of pyarrow string arrays
        Leading text columns (the ids).
    numbers : numpy.ndarray, shape (n, k)
        Number columns after them.
    extras : sequence
        Trailing columns (pyarrow arrays or numpy arrays), formatted by :func:`text_column`.
    start, stop : int
        Rows to format.
    """
    pa, pc, _ = _pa()
    if stop <= start:
        return b""
    cols = [quoted(t.slice(start, stop - start)) for t in texts]
    cols += [float_text(numbers[start:stop, j]) for j in range(numbers.shape[1])]
    cols += [quoted(text_column(e[start:stop])) for e in extras]
    if sum(_data_bytes(c) for c in cols) + 2 * len(cols) * (stop - start) >= 1 << 31:
        cols = [pc.cast(c, pa.large_string()) for c in cols]  # 32-bit offsets would overflow
    lines = pc.binary_join_element_wise(*cols, ",")
    lines = pc.binary_join_element_wise(lines, "\n", "")
    _, offsets, data = lines.buffers()[:3]
    start, stop = _byte_range(lines, offsets)
    return data.slice(start, stop - start)


def _data_bytes(text) -> int:
    data = text.buffers()[2]
    return 0 if data is None else data.size


def worker_count() -> int:
    """Worker threads for formatting: the CPUs this process may run on, at most
    :data:`MAX_WORKERS`."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - platforms without affinity
        n = os.cpu_count() or 1
    return max(1, min(n, MAX_WORKERS))


class OrderedRows:
    """Format chunks of rows in worker threads; hand their bytes to ``write`` in row order.

    Parameters
    ----------
    write : callable
        Called with each formatted slice (a bytes-like object), in the order of the rows,
        from the thread that calls :meth:`add` or :meth:`finish`.
    workers : int, optional
        Worker threads (default :func:`worker_count`); 1 formats in the calling thread.
    """

    def __init__(self, write: Callable, workers: int | None = None) -> None:
        self._write = write
        self.workers = worker_count() if workers is None else max(1, int(workers))
        self._pool = None
        self._pending: deque = deque()
        #: Slices in flight before the oldest is waited for.
        self.max_pending = 2 * self.workers

    def add(self, texts: Sequence, numbers: np.ndarray, extras: Sequence) -> None:
        """Queue rows (all columns of equal length); writes the slices that are done once
        more than a few are in flight."""
        n = numbers.shape[0]
        if self.workers == 1 or n < MIN_THREADED_ROWS:
            self.flush()
            self._write(format_rows(texts, numbers, extras, 0, n))
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.workers, thread_name_prefix="photogeom-csv")
        parts = -(-n // SLICE_ROWS)
        cuts = [n * k // parts for k in range(parts + 1)]
        for start, stop in pairwise(cuts):
            self._pending.append(
                self._pool.submit(format_rows, texts, numbers, extras, start, stop)
            )
            while len(self._pending) > self.max_pending:
                self._write(self._pending.popleft().result())

    def flush(self) -> None:
        """Write every queued slice."""
        while self._pending:
            self._write(self._pending.popleft().result())

    def close(self, *, discard: bool = False) -> None:
        """Stop the workers; queued slices are written first unless ``discard``."""
        try:
            if not discard:
                self.flush()
        finally:
            for f in self._pending:
                f.cancel()
            self._pending.clear()
            if self._pool is not None:
                self._pool.shutdown(wait=True)
                self._pool = None
