"""Columnar, block-wise reading of delimited text (the engine under the point-CSV reader).

A file is read in blocks of whole lines (a few MiB each); each block is parsed by pyarrow's
CSV reader into columns, so reading is linear in the file size, runs at the speed of compiled
code and holds one block of text at a time. Comment lines (``#``) and blank lines may appear
anywhere; the delimiter is taken from the header line (comma, else semicolon, else tab, else
runs of white space).

What Python's csv module would accept silently and this reader refuses, with the line
number:

* a quote that opens a field and is not closed on the same line (a quoted field spanning
  lines would swallow the rows after it);
* a field longer than :data:`MAX_FIELD_BYTES`;
* a line with more or fewer fields than the header.

Line numbers of data rows are found again by a second pass over the file, which only the
error paths (and messages naming points) take.
"""

from __future__ import annotations

import csv
import io
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileFormatError
from ..numbers import decimal_comma_hint, is_decimal_number
from .sources import input_kind, pipe_bytes

#: Bytes of text parsed at a time.
BLOCK_BYTES = 8 << 20
#: Blocks at least this large are parsed by several threads.
THREADED_BLOCK_BYTES = 4 << 20
#: Longest field accepted (a point id or a number is a few dozen bytes).
MAX_FIELD_BYTES = 128 * 1024
#: Longest line accepted.
MAX_LINE_BYTES = 16 << 20

_LINE_END = re.compile(rb"\r\n|\n|\r")
_LINE_SPLIT = re.compile(r"\r\n|\n|\r")
#: Inputs up to this size are parsed in Python by the whole-table readers (no pyarrow import).
SMALL_BYTES = 256 << 10
_BLANK_LINE = re.compile(rb"(?m)^[ \t]+\r?$")
_RUNS_OF_SPACE = re.compile(rb"[ \t]+")
_EDGE_TABS = re.compile(rb"(?m)^\t|\t(?=\r?$)")


#: Byte-order marks of the Unicode encodings wider than UTF-8 (UTF-32 first: its
#: little-endian mark begins with UTF-16's).
_WIDE_BOMS = (
    (b"\xff\xfe\x00\x00", "UTF-32"),
    (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"),
    (b"\xfe\xff", "UTF-16"),
)


def wide_unicode(head: bytes) -> tuple[str, bool] | None:
    """The encoding of text in UTF-16 or UTF-32 (a spreadsheet's "Unicode text", Windows
    tools), and whether it has a byte-order mark, or None.

    Without a mark, ASCII text in UTF-16 is recognised by its pattern: a NUL in every
    second byte of the first bytes, and nowhere else.

    Parameters
    ----------
    head : bytes
        The first bytes of the file (a few kB).

    Returns
    -------
    tuple of (str, bool) or None
        ``("UTF-16", True)``, ``("UTF-32", False)``, ...; None for other bytes.
    """
    for bom, name in _WIDE_BOMS:
        if head.startswith(bom):
            return name, True
    a = np.frombuffer(head[: len(head) - len(head) % 4], dtype=np.uint8)
    if a.size < 4:
        return None
    if np.all(a[1::4] == 0) and np.all(a[2::4] == 0) and np.all(a[3::4] == 0) and a[0::4].all():
        return "UTF-32", False
    for nul, text in ((a[1::2], a[0::2]), (a[0::2], a[1::2])):
        if np.all(nul == 0) and text.all():
            return "UTF-16", False
    return None


def wide_unicode_message(label: str, head: bytes, what: str) -> str | None:
    """The refusal of a UTF-16/32 file read as UTF-8 text (naming the fix), or None."""
    wide = wide_unicode(head)
    if wide is None:
        return None
    name, bom = wide
    how = "with a byte-order mark" if bom else "without a byte-order mark"
    return (
        f"cannot read {label}: it is {name} text ({how}); photogeom reads {what} as UTF-8: "
        "save it as UTF-8 (in a spreadsheet: 'CSV UTF-8'; in an editor: encoding UTF-8)"
    )


def _pa():
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    return pa, pc, pcsv


@dataclass
class Block:
    """Columns of one block of rows.

    Attributes
    ----------
    first_row : int
        Index (0-based, among all data rows) of the block's first row.
    n_rows : int
    strings : dict of str -> pyarrow.Array
        The string columns asked for, white space trimmed.
    numbers : dict of str -> numpy.ndarray
        The number columns asked for (float64).
    bytes_done : int
        Bytes of the file read so far (for progress display).
    """

    first_row: int
    n_rows: int
    strings: dict
    numbers: dict
    bytes_done: int


class DelimitedText:
    """A delimited text file (or text) opened for block-wise reading.

    Parameters
    ----------
    path : path-like, optional
        File to read.
    data : bytes, optional
        Text to read instead of a file (UTF-8).
    block_bytes : int
        Bytes per block.

    Attributes
    ----------
    header : tuple of str
        Column names.
    comments : tuple of str
        Comment lines before the header (without ``#``); comment lines further down are
        added while blocks are read.
    size : int
        Size of the input in bytes.
    """

    def __init__(
        self,
        path: str | os.PathLike | None = None,
        data: bytes | None = None,
        *,
        block_bytes: int = BLOCK_BYTES,
    ) -> None:
        self.path = Path(path) if path is not None else None
        self.label = str(self.path) if self.path is not None else "point table"
        self._data = data
        self.block_bytes = int(block_bytes)
        self.comments: list[str] = []
        if data is None and input_kind(self.path) == "pipe":
            # a pipe (`<(cat f.csv)`, `... | photogeom ... /dev/stdin`) can be read once: the
            # header, the blocks and the diagnostics each open the input, and a command may
            # read the file again (its '# crs:' line, a second set of columns), so its bytes
            # are kept for the whole command (io.sources.pipe_reads; in Python, by this object)
            try:
                data = self._data = pipe_bytes(self.path, None)
            except OSError as exc:
                raise FileFormatError(f"cannot read {self.path}: {exc.strerror or exc}") from None
        if data is None:
            self.size = _stat_size(self.path)
        else:
            self.size = len(data)
        self._read_header()

    # -- opening --------------------------------------------------------------------------

    def _open(self):
        if self._data is not None:
            return io.BytesIO(self._data)
        p = self.path
        try:
            return open(p, "rb")
        except FileNotFoundError:
            raise FileFormatError(f"cannot read {p}: no such file") from None
        except IsADirectoryError:
            raise FileFormatError(f"cannot read {p}: it is a directory, not a CSV file") from None
        except PermissionError:
            raise FileFormatError(f"cannot read {p}: permission denied") from None
        except OSError as exc:
            raise FileFormatError(f"cannot read {p}: {exc.strerror or exc}") from None

    def _lines_raw(self) -> Iterator[tuple[int, bytes]]:
        """(line number, line without its end) over the whole input, BOM removed."""
        with self._open() as fh:
            first = True
            for k, line in enumerate(_split_lines(fh), start=1):
                if first:
                    first = False
                    if line.startswith(b"\xef\xbb\xbf"):
                        line = line[3:]
                yield k, line

    def _read_header(self) -> None:
        with self._open() as fh:
            try:
                head = fh.read(4096)
            except IsADirectoryError:
                raise FileFormatError(
                    f"cannot read {self.label}: it is a directory, not a CSV file"
                ) from None
            except OSError as exc:
                raise FileFormatError(f"cannot read {self.label}: {exc.strerror or exc}") from None
        wide = wide_unicode_message(self.label, head, "CSV files")
        if wide:
            raise FileFormatError(wide)
        if b"\x00" in head:
            raise FileFormatError(
                f"cannot read {self.label}: it looks like a binary file, not a CSV text file"
            )
        for number, line, end in self._head_lines():
            if len(line) > MAX_LINE_BYTES:
                raise FileFormatError(
                    f"{self.label}, line {number}: the line is longer than {MAX_LINE_BYTES} bytes"
                )
            text = _decode(line).strip()
            if not text:
                continue
            if text.startswith("#"):
                self.comments.append(text[1:].strip())
                continue
            self.header_line = number
            self._body_offset = end
            self._parse_header(text, number)
            return
        raise FileFormatError(
            f"{self.label}: no header line and no data (the file is empty or all comments)"
        )

    def _head_lines(self) -> Iterator[tuple[int, bytes, int]]:
        """(line number, line, byte offset after its end) from the start of the input."""
        with self._open() as fh:
            buf = fh.read(1 << 16)
            pos = 3 if buf.startswith(b"\xef\xbb\xbf") else 0
            base = 0  # file offset of buf[0]
            number = 0
            while True:
                m = _LINE_END.search(buf, pos)
                if m is None or (m.group() == b"\r" and m.end() == len(buf)):
                    more = fh.read(1 << 16)
                    if more:
                        if pos > MAX_LINE_BYTES:
                            buf, base, pos = buf[pos:], base + pos, 0
                        buf += more
                        if len(buf) - pos > MAX_LINE_BYTES + (1 << 16):
                            raise FileFormatError(
                                f"{self.label}, line {number + 1}: the line is longer than "
                                f"{MAX_LINE_BYTES} bytes"
                            )
                        continue
                    if pos >= len(buf):
                        return
                    number += 1
                    yield number, buf[pos:], base + len(buf)
                    return
                number += 1
                yield number, buf[pos : m.start()], base + m.end()
                pos = m.end()

    def _parse_header(self, text: str, number: int) -> None:
        if "," in text:
            self.delimiter = ","
        elif ";" in text:
            self.delimiter = ";"
        elif "\t" in text:
            self.delimiter = "\t"
        else:
            self.delimiter = " "
        if self.delimiter == " ":
            names = text.split()
        else:
            names = self._split_line(text, number)
        header = tuple(n.strip() for n in names)
        if any(not h for h in header):
            raise FileFormatError(
                f"{self.label}, line {number}: {empty_column(header, self.delimiter)}: "
                f"{_shorten(text)!r}"
            )
        counts: dict[str, int] = {}
        for h in header:
            counts[h] = counts.get(h, 0) + 1
        dup = sorted(h for h, c in counts.items() if c > 1)
        if dup:
            raise FileFormatError(
                f"{self.label}: column name(s) {', '.join(dup[:20])} appear more than once in "
                "the header"
            )
        if all(_is_number(h) for h in header):
            raise FileFormatError(
                f"{self.label}, line {number}: the first line holds numbers, not column names; "
                "a header line such as 'id,x,y' is required"
            )
        self.header = header

    def _split_line(self, text: str, number: int) -> list[str]:
        """Fields of one line (csv rules, strict quoting), refusing what spans lines."""
        if self.delimiter == " ":
            return text.split()
        try:
            rows = list(
                csv.reader([text], delimiter=self.delimiter, skipinitialspace=True, strict=True)
            )
        except csv.Error as exc:
            if "field larger than field limit" in str(exc):
                naive = text.split(self.delimiter)  # to name the column (quotes ignored)
                k = next((i for i, f in enumerate(naive) if len(f) > MAX_FIELD_BYTES), None)
                raise self._long_field(number, k) from None
            raise FileFormatError(
                f'{self.label}, line {number}: a quote (") opens a field that is not closed '
                "on the same line; a quoted field cannot span lines (close the quote or "
                "remove it)"
            ) from None
        fields = rows[0] if rows else []
        k = next((i for i, f in enumerate(fields) if len(f) > MAX_FIELD_BYTES), None)
        if k is not None:
            raise self._long_field(number, k)
        return [f.strip() for f in fields]

    def _long_field(self, number: int, k: int | None) -> FileFormatError:
        header = getattr(self, "header", ())
        where = f"column {header[k]}" if k is not None and k < len(header) else "a field"
        return FileFormatError(
            f"{self.label}, line {number}: {where} holds a field longer than {MAX_FIELD_BYTES} "
            "bytes; point files hold ids and numbers"
        )

    # -- data -----------------------------------------------------------------------------

    def _raw_blocks(self) -> Iterator[tuple[bytes, int]]:
        """Blocks of whole lines after the header: (bytes, bytes read so far)."""
        with self._open() as fh:
            fh.seek(self._body_offset)
            done = self._body_offset
            rest = b""
            while True:
                chunk = fh.read(self.block_bytes)
                done += len(chunk)
                if not chunk:
                    if rest:
                        yield rest, done
                    return
                buf = rest + chunk
                cut = max(buf.rfind(b"\n"), buf.rfind(b"\r"))
                if cut < 0:
                    if len(buf) > MAX_LINE_BYTES:
                        raise FileFormatError(
                            f"{self.label}: a line is longer than {MAX_LINE_BYTES} bytes"
                        )
                    rest = buf
                    continue
                rest = buf[cut + 1 :]
                yield buf[: cut + 1], done

    def _clean(self, block: bytes) -> bytes:
        """UTF-8 text with only data lines (comments and blank lines taken out)."""
        if not block.isascii():
            try:
                block.decode("utf-8")
            except UnicodeDecodeError:
                block = block.decode("latin-1").encode("utf-8")
        if b"\r" in block:
            block = block.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        if b"#" in block or (_indented(block) and _BLANK_LINE.search(block) is not None):
            keep = []
            for line in block.split(b"\n"):
                s = line.strip()
                if not s:
                    continue
                if s.startswith(b"#"):
                    self.comments.append(s[1:].strip().decode("utf-8"))
                    continue
                keep.append(line)
            block = b"\n".join(keep) + b"\n" if keep else b""
        if self.delimiter == " " and block:
            block = _EDGE_TABS.sub(b"", _RUNS_OF_SPACE.sub(b"\t", block))
        return block

    def blocks(
        self,
        strings: Sequence[str] = (),
        numbers: Sequence[str] = (),
        *,
        arrow: bool = True,
    ) -> Iterator[Block]:
        """Blocks of the columns asked for.

        Parameters
        ----------
        strings : sequence of str
            Columns read as text (white space trimmed).
        numbers : sequence of str
            Columns read as float64.
        arrow : bool
            ``True``: string columns are pyarrow arrays. ``False``: they are lists of str,
            and an input of at most :data:`SMALL_BYTES` is parsed in Python, without
            importing pyarrow (a command on a few points starts faster); the rules and the
            error messages are the same.

        Raises
        ------
        FileFormatError
            A malformed line (field count, unclosed quote, overlong field) or a number column
            holding text; the message names the line and the column.
        """
        strings, numbers = list(strings), list(numbers)
        if not arrow and self.size <= SMALL_BYTES:
            yield from self._python_blocks(strings, numbers)
            return
        for block in self._arrow_blocks(strings, numbers):
            if not arrow:
                block.strings = {c: v.to_pylist() for c, v in block.strings.items()}
            yield block

    def _python_blocks(self, strings: list[str], numbers: list[str]) -> Iterator[Block]:
        """One block parsed line by line (small inputs)."""
        with self._open() as fh:
            fh.seek(self._body_offset)
            data = fh.read()
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
        where = {c: self.header.index(c) for c in dict.fromkeys([*strings, *numbers])}
        out_s: dict[str, list] = {c: [] for c in strings}
        out_n: dict[str, list] = {c: [] for c in numbers}
        n_fields = len(self.header)
        for k, line in enumerate(_LINE_SPLIT.split(text), start=self.header_line + 1):
            stripped = line.strip()
            if not stripped:
                continue
            if stripped.startswith("#"):
                self.comments.append(stripped[1:].strip())
                continue
            fields = self._split_line(stripped, k)
            if len(fields) != n_fields:
                raise FileFormatError(
                    f"{self.label}, line {k}: {len(fields)} field(s) but the header has "
                    f"{n_fields} ({_names(self.header)})"
                )
            for c in strings:
                out_s[c].append(fields[where[c]])
            for c in numbers:
                v = fields[where[c]]
                if not _arrow_number(v):
                    shown = "an empty field" if v == "" else repr(_shorten(v))
                    raise FileFormatError(
                        f"{self.label}, line {k}: column {c} holds {shown}, not a number"
                        + decimal_comma_hint(v)
                    )
                out_n[c].append(float(v))
        n = len(out_s[strings[0]]) if strings else len(out_n[numbers[0]]) if numbers else 0
        arrays = {c: np.array(v, dtype=np.float64) for c, v in out_n.items()}
        yield Block(0, n, out_s, arrays, self.size)

    def _arrow_blocks(self, strings: list[str], numbers: list[str]) -> Iterator[Block]:
        pa, pc, pcsv = _pa()
        row = 0
        delim = "\t" if self.delimiter == " " else self.delimiter
        # a block of a few MiB is parsed in pieces by threads; a small block (streamed jobs,
        # whose writer formats in threads of its own) by one thread, which allocates less
        read_opts = pcsv.ReadOptions(
            column_names=list(self.header), use_threads=self.block_bytes >= THREADED_BLOCK_BYTES
        )
        parse_opts = pcsv.ParseOptions(
            delimiter=delim,
            quote_char=False if self.delimiter == " " else '"',
            newlines_in_values=False,
            ignore_empty_lines=True,
        )

        def convert(types):
            return pcsv.ConvertOptions(
                column_types=types,
                include_columns=list(types),
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
                null_values=[],
                true_values=[],
                false_values=[],
            )

        fast_types = {c: pa.string() for c in strings}
        fast_types.update({c: pa.float64() for c in numbers})
        all_text = {c: pa.string() for c in self.header}
        for raw, done in self._raw_blocks():
            block = self._clean(raw)
            if not block:
                continue
            table = None
            if b'"' not in block and _lines_at_most(block, MAX_FIELD_BYTES):
                try:
                    table = pcsv.read_csv(
                        pa.BufferReader(block), read_options=read_opts, parse_options=parse_opts,
                        convert_options=convert(fast_types),
                    )  # fmt: skip
                except pa.ArrowInvalid:
                    table = None
            if table is None:
                try:
                    table = pcsv.read_csv(
                        pa.BufferReader(block), read_options=read_opts, parse_options=parse_opts,
                        convert_options=convert(all_text),
                    )  # fmt: skip
                except pa.ArrowInvalid:
                    self._diagnose(row)
                    raise  # pragma: no cover - _diagnose raises
                self._check_text(table, row)
            n = table.num_rows
            out_s = {}
            for c in strings:
                col = table.column(c)
                if col.num_chunks != 1:
                    col = col.combine_chunks()
                else:
                    col = col.chunk(0)
                out_s[c] = _trim(pc, col)
            out_n = {}
            for c in numbers:
                col = table.column(c)
                if col.type == pa.float64():
                    out_n[c] = col.to_numpy()
                else:
                    out_n[c] = self._to_float(pc, pa, col, c, row)
            yield Block(row, n, out_s, out_n, done)
            row += n

    def _check_text(self, table, first_row: int) -> None:
        """Refuse quoted fields with line breaks and overlong fields (all columns)."""
        _, pc, _ = _pa()
        for name in table.column_names:
            col = table.column(name)
            if len(col) == 0:
                continue
            broken = pc.any(pc.match_substring(col, "\n")).as_py()
            long = pc.max(pc.binary_length(col)).as_py() > MAX_FIELD_BYTES
            if broken or long:
                self._diagnose(first_row)

    def _to_float(self, pc, pa, col, name: str, first_row: int) -> np.ndarray:
        col = _trim(pc, col.combine_chunks() if col.num_chunks != 1 else col.chunk(0))
        try:
            return pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            pass
        values = col.to_pylist()
        for k, v in enumerate(values):
            if not _arrow_number(v):
                line = self.line_numbers([first_row + k])[0]
                shown = "an empty field" if v == "" else repr(_shorten(v))
                raise FileFormatError(
                    f"{self.label}, line {line}: column {name} holds {shown}, not a number"
                    + decimal_comma_hint(v)
                )
        raise FileFormatError(  # pragma: no cover - the loop finds the cell
            f"{self.label}: column {name} holds text that is not a number"
        )

    def _diagnose(self, first_row: int) -> None:
        """Find and name the malformed line at or after data row ``first_row``."""
        n_fields = len(self.header)
        row = -1
        for number, line in self._data_lines():
            row += 1
            if row < first_row:
                continue
            text = _decode(line)
            fields = self._split_line(text.strip(), number)
            if len(fields) != n_fields:
                raise FileFormatError(
                    f"{self.label}, line {number}: {len(fields)} field(s) but the header has "
                    f"{n_fields} ({_names(self.header)})"
                )
        raise FileFormatError(  # pragma: no cover - every parser failure has a line
            f"{self.label}: the file cannot be parsed as delimited text"
        )

    def _data_lines(self) -> Iterator[tuple[int, bytes]]:
        """(line number, line) of the data lines (no comments, blank lines or header)."""
        for number, line in self._lines_raw():
            if number <= self.header_line:
                continue
            s = line.strip()
            if not s or s.startswith(b"#"):
                continue
            yield number, line

    def line_numbers(self, rows: Sequence[int]) -> list[int]:
        """Line numbers (1-based) of data rows ``rows`` (0-based); a pass over the file."""
        want = sorted(set(int(r) for r in rows))
        found: dict[int, int] = {}
        if not want:
            return []
        k = 0
        row = -1
        for number, _ in self._data_lines():
            row += 1
            if row == want[k]:
                found[row] = number
                k += 1
                if k == len(want):
                    break
        return [found.get(int(r), -1) for r in rows]


def _indented(block: bytes) -> bool:
    """Whether a line of ``block`` starts with a space or a tab (cheap test)."""
    # a search for a single byte is fast; "\n " is slow (line ends are everywhere)
    if block[:1] in (b" ", b"\t"):
        return True
    return (b" " in block and b"\n " in block) or (b"\t" in block and b"\n\t" in block)


def empty_column(header: Sequence[str], delimiter: str) -> str:
    """The refusal of a header with an empty column name (``header`` its names, split at
    ``delimiter``), naming the column and the fix: a separator at the end of the line (a
    spreadsheet's empty column) is to be removed, another empty name to be given."""
    k = next(j for j, h in enumerate(header) if not h)
    sep = {"\t": "tab", " ": "space"}.get(delimiter, repr(delimiter))
    if k == len(header) - 1 and k > 0:
        return (
            f"the header ends in a separator ({sep}): its column {k + 1} has no name; "
            "remove the separator at the end of the lines (a spreadsheet writes one for an "
            "empty column), or name the column"
        )
    return f"the header has an empty column name (column {k + 1}): name it, or remove it"


def _lines_at_most(block: bytes, limit: int) -> bool:
    """Whether every line of ``block`` (its end included) has at most ``limit`` bytes.

    From a line start, the last line end within the next ``limit`` bytes closes every line
    begun before it; one backward search per ``limit`` bytes of text.
    """
    pos, n = 0, len(block)
    while n - pos > limit:
        end = block.rfind(b"\n", pos, pos + limit)
        if end < 0:
            return False
        pos = end + 1
    return True


def _trim(pc, col):
    return pc.utf8_trim_whitespace(col)


def _arrow_number(v: str) -> bool:
    """Whether pyarrow reads ``v`` as a float64 (Python's float() also takes "1_0" and
    non-ASCII digits): :func:`photogeom.numbers.is_decimal_number`, the rule of every reader."""
    return is_decimal_number(v)


def _split_lines(fh) -> Iterator[bytes]:
    """Lines of a binary file without their ends (``\\n``, ``\\r\\n`` or ``\\r``)."""
    rest = b""
    while True:
        chunk = fh.read(1 << 20)
        if not chunk:
            break
        buf = rest + chunk
        tail = b""
        if buf.endswith(b"\r"):  # a \r\n may be split between two reads
            buf, tail = buf[:-1], b"\r"
        if b"\r" in buf:
            buf = buf.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        parts = buf.split(b"\n")
        rest = parts.pop() + tail
        yield from parts
        if len(rest) > MAX_LINE_BYTES:
            raise FileFormatError(f"a line is longer than {MAX_LINE_BYTES} bytes")
    if rest:
        yield rest.rstrip(b"\r")


def _decode(line: bytes) -> str:
    try:
        return line.decode("utf-8")
    except UnicodeDecodeError:
        return line.decode("latin-1")


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _shorten(s: str, n: int = 60) -> str:
    return s if len(s) <= n else s[:n] + "..."


def _names(header: Sequence[str], limit: int = 30) -> str:
    shown = ", ".join(header[:limit])
    return shown + (f" ... ({len(header)} in all)" if len(header) > limit else "")


def _stat_size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0
