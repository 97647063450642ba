"""LAS/LAZ point clouds, chunk by chunk, with laspy (LAZ through the lazrs backend).

* :func:`cloud_info` - the header of a file: point count, format, scales and offsets, bounds,
  extra dimensions, CRS;
* :func:`read_cloud_xyz` - coordinates (n, 3) of a file or of a slice of it;
* :func:`iter_cloud_xyz` - coordinates chunk by chunk (memory bounded by the chunk);
* :func:`transform_cloud` - apply any transformation to a file, chunk by chunk, keeping the
  point format, every dimension (extra bytes too), the VLRs and the CRS record; scales kept,
  offsets recomputed for the moved coordinates; written atomically;
* :func:`cloud_dask_xyz` - a file's coordinates as a lazy ``dask.array`` (for
  :mod:`photogeom.distributed`).

laspy and lazrs are an optional extra: ``pip install "photogeom[cloud]"``.
"""

from __future__ import annotations

import functools
import os
import secrets
import shutil
import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError, OutputError, PhotogeomError
from ..records import ReadOnlyRecord
from .sources import device_message, input_kind, pipe_message

#: Points per chunk unless ``chunk_size=`` says otherwise (about 30-60 MB of records).
DEFAULT_CHUNK = 1_000_000
_INT32 = 2**31 - 1


def _laspy():
    try:
        import laspy
    except ImportError:  # pragma: no cover - depends on the installation
        raise PhotogeomError(
            "point clouds (LAS/LAZ) need laspy with the lazrs backend: "
            "pip install 'photogeom[cloud]'"
        ) from None
    return laspy


def _open_read(path, single_thread: bool = False, check_size: bool = True):
    """A laspy reader; ``single_thread`` decompresses LAZ on one thread (Dask workers: one
    core each) instead of lazrs's parallel decoder. A file shorter than its header says
    (:func:`_truncation`), whose scales and offsets give no coordinates
    (:func:`_bad_scaling`) or whose LASzip VLR lists no items (:func:`_bad_laszip_vlr`) is
    refused unless ``check_size`` is False. A pipe or a device is
    refused by name (:mod:`photogeom.io.sources`): a LAS/LAZ file is read with seeks."""
    laspy = _laspy()
    p = Path(path)
    kind = input_kind(p)
    if kind == "missing":
        raise InputError(f"point cloud {p} does not exist")
    if kind == "folder":
        raise InputError(f"point cloud {p} is a folder; give a LAS/LAZ file")
    if kind == "device":
        raise InputError(device_message(p, "point cloud"))
    if kind == "pipe":  # the header, the size check and every pass open the file again
        raise InputError(
            pipe_message(p, "point cloud", "a LAS/LAZ file is read with seeks, in chunks")
        )
    problem = _damaged_vlr_count(p)
    if problem:
        raise FileFormatError(problem)
    try:
        if single_thread:
            reader = laspy.open(p, laz_backend=laspy.LazBackend.Lazrs)
        else:
            reader = laspy.open(p)
    except laspy.errors.LaspyException as exc:
        raise FileFormatError(f"{p}: not a readable LAS/LAZ file ({exc})") from None
    except (OSError, ValueError, EOFError, MemoryError, struct.error, OverflowError) as exc:
        # a header cut short or damaged (a VLR count or length of gigabytes, a creation date
        # out of range), lazrs errors
        raise FileFormatError(
            f"{p}: not a readable LAS/LAZ file ({type(exc).__name__}: {exc}); is it "
            "complete? (an interrupted copy or download: copy it again)"
        ) from None
    version = reader.header.version
    if version.major != 1 or version.minor > MAX_LAS_MINOR:
        reader.close()
        raise FileFormatError(_bad_version(p, version.major, version.minor))
    if check_size:
        problem = (  # the LASzip VLR before lazrs decodes (it would panic)
            _bad_laszip_vlr(p, reader.header)
            or _truncation(p, reader.header)
            or _bad_scaling(p, reader.header)
        )
        if problem:
            reader.close()
            raise FileFormatError(problem)
    return reader


#: LASzip VLR: user id, record id, bytes before the item list, bytes per item.
_LASZIP_VLR = ("laszip encoded", 22204, 34, 6)


def _bad_laszip_vlr(path: Path, header) -> str | None:
    """Why the LASzip VLR of a LAZ header cannot describe the points, or None.

    A LASzip VLR holding no items made lazrs divide by zero when the first points were
    decoded: a Rust panic, which prints Rust's panic message (and, with
    ``RUST_BACKTRACE=1``, a backtrace) on the process's standard error before it reaches
    Python as a ``PanicException``; that output cannot be caught from Python (it is written
    by Rust's panic hook straight to file descriptor 2, by whatever thread panics), so the
    damage is refused from the header, before lazrs runs. The item count must be at least
    one and fit the record's length (34 bytes and 6 per item).
    """
    import struct

    user, record, fixed, per_item = _LASZIP_VLR
    for vlr in getattr(header, "vlrs", ()):
        if getattr(vlr, "user_id", "") != user or getattr(vlr, "record_id", None) != record:
            continue
        data = getattr(vlr, "record_data", None)
        if not isinstance(data, (bytes, bytearray)):
            return None  # laspy could not keep the bytes: lazrs names what it finds
        if len(data) < fixed:
            return (
                f"{path}: the LASzip VLR holds {len(data)} bytes, fewer than the {fixed} of "
                "its fixed part: the header is damaged (copy the file again)"
            )
        (items,) = struct.unpack_from("<H", data, fixed - 2)
        if items == 0 or len(data) != fixed + per_item * items:
            return (
                f"{path}: the LASzip VLR announces {items} compressed item(s) in "
                f"{len(data)} bytes (a point needs at least one item; {fixed} + {per_item} "
                "bytes per item): the header is damaged (copy the file again)"
            )
    return None


def _bad_scaling(path: Path, header) -> str | None:
    """Why the scales and offsets of a header cannot turn the stored integers into
    coordinates, or None: a scale of 0 (every coordinate equal to its offset), NaN or
    infinite values, or a scale so large that a 32-bit integer overflows to infinity. Such
    headers were read silently into constant or non-finite coordinates."""
    scales = np.asarray(header.scales, dtype=float)
    offsets = np.asarray(header.offsets, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        reach = np.abs(scales) * 2.0**31 + np.abs(offsets)
    bad = ~np.isfinite(reach) | (scales == 0)
    if not np.any(bad):
        return None
    k = int(np.flatnonzero(bad)[0])
    return (
        f"{path}: the header's {'XYZ'[k]} scale {float(scales[k])!r} and offset "
        f"{float(offsets[k])!r} cannot give coordinates (a scale must be finite and non-zero, "
        "and scale x 2^31 + offset finite): the header is damaged (copy the file again)"
    )


def _damaged_vlr_count(path: Path) -> str | None:
    """Why the version or the VLR count of the header cannot be right, or None.

    The version is checked before laspy reads the header: laspy reads the fields of the
    version the header names, so a damaged version (1.255) made it read past the header into
    a ``struct.error``. The VLRs (54 bytes each at least) lie between the header and the
    point data: laspy would otherwise read a damaged count of 2^31 VLRs one by one
    (minutes)."""
    with open(path, "rb") as f:
        raw = f.read(104)
    if len(raw) < 104 or raw[:4] != b"LASF":
        return None  # laspy reports it
    major, minor = raw[24], raw[25]
    if major != 1 or minor > MAX_LAS_MINOR:
        return _bad_version(path, major, minor)
    header_size, start, n_vlrs = struct.unpack_from("<HII", raw, 94)
    if n_vlrs * 54 > max(0, start - header_size):
        return (
            f"{path}: the header is damaged: it announces {n_vlrs} VLRs (54 bytes each at "
            f"least) between its end at byte {header_size} and the point data at byte "
            f"{start}; copy the file again"
        )
    # the VLRs lie in the file too: a damaged offset of the point data (4 GB) would let a
    # damaged count through, and laspy read millions of empty VLRs (minutes)
    size = path.stat().st_size
    if n_vlrs * 54 > max(0, size - header_size):
        return (
            f"{path}: the header is damaged: it announces {n_vlrs} VLRs (54 bytes each at "
            f"least) after its end at byte {header_size}, but the file has {size} bytes; "
            "copy the file again"
        )
    return None


#: Highest minor version of LAS 1.x read (laspy reads 1.0 to 1.4, and the fields of 1.5).
MAX_LAS_MINOR = 5


def _bad_version(path, major: int, minor: int) -> str:
    return (
        f"{path}: the header says LAS version {major}.{minor}; LAS versions are 1.0 to "
        "1.4: the header is damaged (copy the file again)"
    )


#: Most bytes one LAZ chunk may decompress to. LASzip, PDAL and laspy write chunks of
#: 50,000 points (a few MB); lazrs allocates a whole chunk before decoding it, so the chunk
#: size of a damaged header (10^9 points: 31 GB) aborted the process instead of failing.
MAX_LAZ_CHUNK_BYTES = 1 << 30


def _laz_fixed_chunk_size(header) -> int | None:
    """The chunk size (points) of the LASzip VLR, or None (variable chunks, no VLR): a
    ``uint32`` at byte 12 of the record (after compressor, coder, version and options)."""
    raw = next((v.record_data for v in header.vlrs if type(v).__name__ == "LasZipVlr"), None)
    if raw is None or len(raw) < 16:
        return None
    (size,) = struct.unpack_from("<I", bytes(raw), 12)
    return None if size == 0xFFFFFFFF else int(size)


def _huge_chunk(path: Path, points: int, rec: int, n: int) -> str | None:
    """Why a LAZ chunk of ``points`` records of ``rec`` bytes cannot be decoded, or None."""
    if points * rec <= MAX_LAZ_CHUNK_BYTES:
        return None
    return (
        f"{path}: its LAZ chunks hold {points} points each ({points * rec / 1e9:.3g} GB to "
        f"decompress at once, more than the {MAX_LAZ_CHUNK_BYTES >> 20} MiB photogeom decodes "
        f"at once; the header promises {n} points in all). LAZ writers use chunks of 50,000 "
        "points: the header or the chunk table is damaged (copy the file again), or "
        "re-compress the file with a standard chunk size"
    )


def _truncation(path: Path, header) -> str | None:
    """Why the file ``path`` is shorter than its ``header`` says, or None.

    Cheap (the file's size and, for LAZ, one 8-byte read): an uncompressed file must hold
    ``point_count`` records of ``point_format.size`` bytes from ``offset_to_point_data``; a
    LAZ file must reach its chunk table (the offset stored at the start of the point data;
    LAZ without a chunk table cannot be checked this way), and no chunk (the LASzip VLR's
    chunk size, the largest entry of the chunk table) may decompress to more than
    :data:`MAX_LAZ_CHUNK_BYTES`.
    """
    size = path.stat().st_size
    start = int(header.offset_to_point_data)
    n = int(header.point_count)
    fix = "the file was cut short (an interrupted copy or download?): copy it again"
    compressed = bool(getattr(header, "are_points_compressed", False))
    if not compressed:
        rec = int(header.point_format.size)
        need = start + n * rec
        if size < need:
            whole = max(0, (size - start) // rec) if rec else 0
            return (
                f"{path} is truncated: its header promises {n} points of {rec} bytes from "
                f"byte {start} (the file must be at least {need} bytes) but the file has "
                f"{size} bytes, {whole} whole point(s); {fix}"
            )
        return None
    if n == 0:
        return None
    rec = int(header.point_format.size)
    fixed = _laz_fixed_chunk_size(header)
    if fixed is not None and (problem := _huge_chunk(path, fixed, rec, n)):
        return problem
    if size < start + 8:
        return (
            f"{path} is truncated: its header promises {n} compressed points from byte "
            f"{start} but the file ends at byte {size}; {fix}"
        )
    with open(path, "rb") as f:
        f.seek(start)
        (table,) = struct.unpack("<q", f.read(8))
    if table > 0 and size < table + 8:
        return (
            f"{path} is truncated: its LAZ chunk table should start at byte {table} but the "
            f"file has {size} bytes (header: {n} points); {fix}"
        )
    if table > 0 and (problem := _damaged_chunk_table(path, start, table)):
        return problem
    chunks = _laz_chunk_points(path, header, start) if table > 0 else None
    held, biggest = chunks if chunks is not None else (None, 0)
    if problem := _huge_chunk(path, biggest, rec, n):
        return problem
    if held is not None and n > held:
        return (
            f"{path} is damaged: its header promises {n} points but its LAZ chunk table "
            f"holds at most {held}; the header or the table is corrupt: copy the file again"
        )
    return None


def _damaged_chunk_table(path: Path, start: int, table: int) -> str | None:
    """Why the head of a LAZ chunk table (version 0, number of chunks) cannot be right, or
    None. Each chunk holds at least one byte of the point data between ``start + 8`` and the
    table; lazrs allocates the entries of the announced count before reading them, so a
    damaged count (3 * 10^9) aborted the process (46 GB) instead of failing."""
    with open(path, "rb") as f:
        f.seek(table)
        version, count = struct.unpack("<II", f.read(8))
    room = table - (start + 8)
    if version != 0 or count > room:
        return (
            f"{path} is damaged: its LAZ chunk table at byte {table} says version {version} "
            f"and {count} chunks (LAZ tables are version 0, and the {room} bytes of point data "
            f"hold at most {max(room, 0)} chunks): copy the file again"
        )
    return None


def _laz_chunk_points(path: Path, header, start: int) -> tuple[int, int] | None:
    """The most points the chunk table of a LAZ file can hold (the sum of its chunks' point
    counts: exact for variable chunks, chunks x chunk size for fixed ones) and the point
    count of its largest chunk, or None when the table cannot be read (left to the reader
    to report)."""
    try:
        import lazrs

        raw = next(v.record_data for v in header.vlrs if type(v).__name__ == "LasZipVlr")
        with open(path, "rb") as f:
            f.seek(start)
            entries = lazrs.read_chunk_table(f, lazrs.LazVlr(bytes(raw)))
        counts = [int(e[0]) for e in entries]
        return sum(counts), max(counts, default=0)
    except Exception:  # no lazrs, no LASzip VLR, a table lazrs cannot read
        return None


def _read_error(reader, path, start: int, stop: int, exc: BaseException) -> FileFormatError:
    return FileFormatError(
        f"{path}: cannot read points {start}:{stop} of the {int(reader.header.point_count)} "
        f"points its header promises ({type(exc).__name__}: {exc}); the file is damaged or "
        "cut short (an interrupted copy or download?): copy it again"
    )


#: What a failed read of points may raise: any exception, and the ``PanicException`` of
#: lazrs (a Rust panic on damaged compressed data, e.g. a division by zero), which derives
#: from ``BaseException`` and would otherwise end the program in a traceback.
_NOT_READ = (KeyboardInterrupt, SystemExit, GeneratorExit)


def _read_range(reader, path, start: int, stop: int, chunk_size: int) -> Iterator:
    """laspy point records ``start:stop`` of an open ``reader``, at most ``chunk_size`` at a
    time; a read that fails or comes back short is a :class:`FileFormatError` naming the
    file and the counts (never fewer points than asked for without a word)."""
    pos = start
    try:
        if start:
            reader.seek(start)
    except _NOT_READ:
        raise
    except BaseException as exc:  # lazrs panics too (see _NOT_READ)
        raise _read_error(reader, path, start, stop, exc) from None
    while pos < stop:
        want = min(chunk_size, stop - pos)
        try:
            pts = reader.read_points(want)
        except _NOT_READ:
            raise
        except BaseException as exc:  # lazrs panics too (see _NOT_READ)
            raise _read_error(reader, path, pos, pos + want, exc) from None
        got = len(pts)
        if got < want:
            raise FileFormatError(
                f"{path}: the file ends after point {pos + got} but its header promises "
                f"{int(reader.header.point_count)} points (points {start}:{stop} asked for); "
                "it is cut short (an interrupted copy or download?): copy it again"
            )
        pos += got
        yield pts


@dataclass(frozen=True, eq=False)
class CloudInfo(ReadOnlyRecord):
    """What the header of a LAS/LAZ file says.

    Attributes
    ----------
    path : str
    point_count : int
    point_format : int
        LAS point data record format id.
    version : str
        LAS version, e.g. ``"1.4"``.
    compressed : bool
        LAZ.
    scales, offsets : numpy.ndarray, shape (3,)
        Stored integer ``X`` means ``X * scale + offset`` (m or the CRS unit).
    mins, maxs : numpy.ndarray, shape (3,)
        Bounds recorded in the header.
    dimensions : tuple of str
        Every dimension of a point record (standard and extra).
    extra_dimensions : tuple of str
        The extra-bytes dimensions.
    crs : str or None
        The CRS record (WKT or GeoTIFF keys) as WKT, None when the file has none.
    crs_name : str or None
        ``"EPSG:code (name)"`` or the CRS name.
    crs_error : str or None
        Why the file's CRS record could not be read (``crs`` is then None although the file
        has a record); None when it was read or there is none.
    vlrs : tuple of str
        The type names of the file's variable-length records, in file order.
    """

    path: str
    point_count: int
    point_format: int
    version: str
    compressed: bool
    scales: np.ndarray
    offsets: np.ndarray
    mins: np.ndarray
    maxs: np.ndarray
    dimensions: tuple[str, ...]
    extra_dimensions: tuple[str, ...]
    crs: str | None = None
    crs_name: str | None = None
    vlrs: tuple[str, ...] = field(default=())
    crs_error: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
            Every attribute by name; arrays as lists.
        """
        return {
            "path": self.path,
            "point_count": self.point_count,
            "point_format": self.point_format,
            "version": self.version,
            "compressed": self.compressed,
            "scales": self.scales.tolist(),
            "offsets": self.offsets.tolist(),
            "mins": self.mins.tolist(),
            "maxs": self.maxs.tolist(),
            "dimensions": list(self.dimensions),
            "extra_dimensions": list(self.extra_dimensions),
            "crs_name": self.crs_name,
            "crs": self.crs,
            "crs_error": self.crs_error,
            "vlrs": list(self.vlrs),
        }


def _header_crs(header) -> tuple[str | None, str | None, str | None]:
    """The header's CRS as (WKT, name, None); (None, None, None) without a CRS record;
    (None, None, reason) when a record is there but cannot be read."""
    try:
        crs = header.parse_crs()
    except Exception as exc:  # laspy / pyproj: a damaged or unknown record
        reason = " ".join(str(exc).split()) or type(exc).__name__
        return None, None, reason[:300]
    if crs is None:
        return None, None, None
    auth = crs.to_authority()
    return crs.to_wkt(), (f"{auth[0]}:{auth[1]} ({crs.name})" if auth else crs.name), None


def cloud_info(path, *, check_size: bool = True) -> CloudInfo:
    """Read the header of a LAS/LAZ file (no points are read).

    Parameters
    ----------
    path : str or path
        The LAS/LAZ file.
    check_size : bool
        Refuse a file shorter than its header says (``point_count`` records of the point
        format's size for LAS; the chunk table for LAZ), a cheap check of the file's size,
        and a header whose scales and offsets give no coordinates (a scale of 0, NaN or
        infinite values). False reads the header of such a file anyway.

    Returns
    -------
    CloudInfo

    Raises
    ------
    FileFormatError
        Not a LAS/LAZ file, or (``check_size``) a truncated one (the message names the file,
        the point count its header promises and the bytes present) or one with damaged
        scales or offsets.
    """
    with _open_read(path, check_size=check_size) as reader:
        h = reader.header
        wkt, name, crs_error = _header_crs(h)
        pf = h.point_format
        return CloudInfo(
            path=str(path),
            point_count=int(h.point_count),
            point_format=int(pf.id),
            version=f"{h.version.major}.{h.version.minor}",
            compressed=bool(h.are_points_compressed)
            if hasattr(h, "are_points_compressed")
            else str(path).lower().endswith(".laz"),
            scales=np.array(h.scales, dtype=float),
            offsets=np.array(h.offsets, dtype=float),
            mins=np.array(h.mins, dtype=float),
            maxs=np.array(h.maxs, dtype=float),
            dimensions=tuple(pf.dimension_names),
            extra_dimensions=tuple(pf.extra_dimension_names),
            crs=wkt,
            crs_name=name,
            vlrs=tuple(type(v).__name__ for v in h.vlrs),
            crs_error=crs_error,
        )


def _xyz(points) -> np.ndarray:
    out = np.empty((len(points), 3))
    out[:, 0] = points.x
    out[:, 1] = points.y
    out[:, 2] = points.z
    return out


def iter_cloud_xyz(path, chunk_size: int = DEFAULT_CHUNK) -> Iterator[np.ndarray]:
    """Coordinates of a LAS/LAZ file, ``chunk_size`` points at a time.

    Parameters
    ----------
    path : str or os.PathLike
        The LAS/LAZ file.
    chunk_size : int, default DEFAULT_CHUNK
        Points per chunk, >= 1.

    Yields
    ------
    numpy.ndarray, shape (m, 3)
        X, Y, Z in the file's CRS unit; ``m <= chunk_size``.

    Raises
    ------
    FileFormatError
        Naming the file, when it holds fewer points than its header says (see
        :func:`read_cloud_xyz`) or cannot be read.
    InputError
        For a ``chunk_size`` below 1.
    """
    chunk_size = _check_chunk(chunk_size)
    with _open_read(path) as reader:
        n = int(reader.header.point_count)
        for pts in _read_range(reader, path, 0, n, chunk_size):
            yield _xyz(pts)


def read_cloud_xyz(path, start: int = 0, stop: int | None = None) -> np.ndarray:
    """Coordinates (n, 3) of points ``start:stop`` of a LAS/LAZ file (all by default).

    Parameters
    ----------
    path : str or path
        The LAS/LAZ file.
    start, stop : int
        The range of points (``stop`` is limited to the header's point count).

    Returns
    -------
    numpy.ndarray, shape (stop - start, 3)
        Always as many rows as the range asks for.

    Raises
    ------
    FileFormatError
        The file is shorter than its header says (truncated) or its points cannot be
        decoded: the message names the file and the counts.
    """
    with _open_read(path) as reader:
        n = int(reader.header.point_count)
        stop = n if stop is None else min(int(stop), n)
        start = int(start)
        if not 0 <= start <= stop:
            raise InputError(f"point range {start}:{stop} outside 0:{n}")
        if not getattr(reader.header, "are_points_compressed", False):
            # the size check bounds the count by the file's size: one read into one array
            out = np.empty((stop - start, 3))
            i = 0
            for pts in _read_range(reader, path, start, stop, max(1, stop - start)):
                out[i : i + len(pts)] = _xyz(pts)
                i += len(pts)
            return out
        # LAZ: nothing bounds the header's count but the points themselves; read them a
        # chunk at a time, so a damaged count (2 x 10^9) fails on the first missing chunk
        # instead of allocating 50 GB first
        parts = [_xyz(pts) for pts in _read_range(reader, path, start, stop, DEFAULT_CHUNK)]
        return np.concatenate(parts) if parts else np.empty((0, 3))


def _check_chunk(chunk_size) -> int:
    c = int(chunk_size)
    if c < 1:
        raise InputError(f"chunk_size must be >= 1 point, got {chunk_size}")
    return c


def _as_apply(transform) -> Callable[[np.ndarray], np.ndarray]:
    """``apply`` of a transformation, of a Fit (its ``transform``), or a callable."""
    if hasattr(transform, "apply"):
        fn = transform.apply
    elif hasattr(transform, "transform") and hasattr(transform.transform, "apply"):
        fn = transform.transform.apply
    elif callable(transform):
        fn = transform
    else:
        raise InputError(
            "transform must be a photogeom transformation (an object with apply), a Fit, "
            f"or a function of (n, 3) points; got {type(transform).__name__}"
        )
    dim = getattr(transform, "dim", 3)
    if dim != 3:
        raise InputError(f"point clouds need a 3D transformation; this one is {dim}D")
    return fn


def _affine_like(transform) -> bool:
    """True when the transformation maps boxes into the box of their corners' images."""
    name = getattr(transform, "name", "")
    if not name and hasattr(transform, "transform"):
        name = getattr(transform.transform, "name", "")
    return name in ("similarity3d", "rigid3d", "affine3d") or bool(
        getattr(transform, "affine", False)
    )


def _corners(mins: np.ndarray, maxs: np.ndarray) -> np.ndarray:
    idx = np.array([[i >> k & 1 for k in range(3)] for i in range(8)], dtype=bool)
    return np.where(idx, maxs, mins)


def _new_offsets(
    lo: np.ndarray,
    hi: np.ndarray,
    scales: np.ndarray,
    what: str = "transformed coordinates",
    fix: str = "scales= / --scales",
) -> np.ndarray:
    """Offsets at the centre of the output bounds, rounded to a round number (a whole
    multiple of ``1000 * scale`` so that offsets stay readable), checked against int32."""
    centre = 0.5 * (lo + hi)
    step = scales * 1000.0
    off = np.round(centre / step) * step
    span = np.maximum(np.abs(hi - off), np.abs(lo - off)) / scales
    if np.any(span > _INT32):
        raise InputError(
            f"the {what} span {(hi - lo).tolist()} which the scales "
            f"{scales.tolist()} cannot store in 32-bit integers; pass larger scales "
            f"({fix})"
        )
    return off


def _cloud_destination(dst) -> tuple[Path, Path]:
    """:func:`photogeom.atomicfile._destination` for a LAS/LAZ output: a device or a named
    pipe (``/dev/null``, ``/dev/stdout``) is refused too, since a LAS/LAZ file is written
    with seeks and read back, and renaming over it would replace the device or pipe."""
    from ..atomicfile import _destination, _stream

    given, target = _destination(dst)
    if _stream(target):
        raise OutputError(
            f"cannot write {given}: it is a device or a named pipe; a LAS/LAZ output must be "
            "a file: give a file name"
        )
    check_cloud_suffix(given)
    return given, target


#: Name endings of the point-cloud files written (LAZ compressed), lower case.
CLOUD_SUFFIXES = (".las", ".laz")


def check_cloud_suffix(path, what: str = "output") -> None:
    """Refuse an output name that does not end in ``.las`` or ``.laz`` (any case): the file
    is LAS (LAZ when ``.laz``) whatever its name, so ``out.txt`` or ``out`` would hold a
    binary cloud under a name that says otherwise.

    Parameters
    ----------
    path : str or path
        Output file name.
    what : str, default "output"
        How the message names it (``"OUTPUT"`` in the command line).

    Raises
    ------
    InputError
        Naming the suffix found and the two accepted.
    """
    suffix = Path(path).suffix
    if suffix.lower() not in CLOUD_SUFFIXES:
        found = f"ends in {suffix!r}" if suffix else "has no suffix"
        raise InputError(
            f"{what} {path} {found}: a point cloud is written as LAS or LAZ, and its name "
            "must say which: give a name ending in .las (uncompressed) or .laz (compressed)"
        )


@contextmanager
def _atomic_target(dst: Path):
    """A temporary path beside ``dst``, fsynced and renamed over it when the ``with`` block
    succeeds (removed otherwise): the policy of :mod:`photogeom.atomicfile` (mode of a plain
    ``open``, symbolic links followed, read-only files refused, ``OutputError`` naming the
    file) for files written by a library that needs a path."""
    from ..atomicfile import _create_temporary, _failure, _fsync_directory, _take_over

    given, target = _cloud_destination(dst)
    directory = target.parent if str(target.parent) else Path(".")
    fd, tmp, old = _create_temporary(given, target)
    try:
        _take_over(fd, old)
        os.close(fd)
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
        _fsync_directory(directory)
    except PhotogeomError:
        _unlink(tmp)
        raise
    except OSError as exc:
        _unlink(tmp)
        raise _failure(given, exc) from exc
    except BaseException:
        _unlink(tmp)
        raise


def _unlink(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


@dataclass(frozen=True, eq=False)
class CloudTransformResult(ReadOnlyRecord):
    """What :func:`transform_cloud` wrote.

    Attributes
    ----------
    path : str
    point_count : int
    scales, offsets : numpy.ndarray, shape (3,)
        Of the output file.
    mins, maxs : numpy.ndarray, shape (3,)
        Bounds of the output points.
    crs_name : str or None
        CRS recorded in the output.
    chunks : int
        Chunks processed.
    passes : int
        Passes over the input (1, or 2 when the output bounds of a non-affine
        transformation had to be found first).
    """

    path: str
    point_count: int
    scales: np.ndarray
    offsets: np.ndarray
    mins: np.ndarray
    maxs: np.ndarray
    crs_name: str | None
    chunks: int
    passes: int


#: Metres per radian of a geographic axis (the WGS 84 semi-major axis): carries a coordinate
#: resolution between degrees and metres (1e-7 degree ~ 1.1 cm).
_METRES_PER_RADIAN = 6_378_137.0


def _metres_per_unit(crs) -> np.ndarray:
    """Metres per unit of the x/easting/longitude, y and height axes of ``crs`` (NaN where
    the CRS does not say: no height axis, an engineering CRS without units)."""
    out = np.full(3, np.nan)
    axes = list(getattr(crs, "axis_info", None) or [])
    for k, a in enumerate(axes[:3]):
        f = float(getattr(a, "unit_conversion_factor", np.nan) or np.nan)
        angular = k < 2 and bool(getattr(crs, "is_geographic", False))
        out[k] = f * _METRES_PER_RADIAN if angular else f
    return out


def unit_scales(scales, transform) -> np.ndarray:
    """The scales of a transformed copy: ``scales`` where the axis unit stays, else the same
    resolution in the target's unit, rounded to a power of ten.

    Parameters
    ----------
    scales : array_like (3,)
        The input file's scales (its coordinate resolution, in its CRS's units).
    transform : transformation
        A PROJ operation (with ``source_crs`` and ``target_crs``) changes units between
        metres, feet and degrees; other transformations keep the scales.

    Returns
    -------
    numpy.ndarray (3,)
        E.g. ``(0.01, 0.01, 0.01)`` metres to EPSG:4979 -> ``(1e-07, 1e-07, 0.01)``
        (1e-7 degree ~ 1.1 cm); from degrees to metres the reverse; 0.01 m to US survey
        feet 0.01 ft. The power of ten is at most ~12 % coarser than the input's
        resolution.
    """
    sc = np.array(scales, dtype=float)
    src, dst = getattr(transform, "source_crs", None), getattr(transform, "target_crs", None)
    if src is None or dst is None:
        return sc
    ratio = _metres_per_unit(src) / _metres_per_unit(dst)
    change = np.isfinite(ratio) & (np.abs(np.log10(np.where(ratio > 0, ratio, 1.0))) > 1e-3)
    # a power of ten at most ~12 % coarser than the input's resolution (0.0111 -> 0.01)
    sc[change] = 10.0 ** np.floor(np.log10(sc[change] * ratio[change]) + 0.05)
    return sc


def output_header(src_header, transform, scales=None, crs=None, bounds=None):
    """The header of a transformed copy: the source header (point format, version, VLRs,
    extra dimensions, CRS record) with the given or kept scales (carried into the target's
    unit by :func:`unit_scales` when a PROJ operation changes it), offsets recomputed from the
    output bounds (``bounds`` = (lo, hi), else the transformed corners of the source box of
    an affine-like transformation), and ``crs`` (a pyproj-readable CRS) replacing the CRS
    record when given (also a CRS record among the extended VLRs, EVLRs, is replaced: LAS 1.4
    allows the WKT there); ``crs=NO_CRS`` removes the record."""
    h = src_header.copy() if hasattr(src_header, "copy") else src_header
    sc = np.array(unit_scales(h.scales, transform) if scales is None else scales, dtype=float)
    if sc.shape != (3,) or not np.all(sc > 0):
        raise InputError(f"scales must be three positive numbers, got {scales}")
    if bounds is None:
        fn = _as_apply(transform)
        img = fn(_corners(np.array(h.mins), np.array(h.maxs)))
        bounds = (img.min(axis=0), img.max(axis=0))
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    h.scales = sc
    h.offsets = _new_offsets(lo, hi, sc)
    if crs == NO_CRS:  # the points leave the input's CRS for one nobody recorded
        h.vlrs = type(h.vlrs)(v for v in h.vlrs if type(v).__name__ not in _CRS_VLRS)
        evlrs = getattr(h, "evlrs", None)
        if evlrs:
            h.evlrs = type(evlrs)(v for v in evlrs if type(v).__name__ not in _CRS_VLRS)
    elif crs is not None:
        from ..crs import parse_crs

        # the record replaced in the encoding the global-encoding WKT bit announces: a LAS
        # 1.4 file that says "WKT" keeps WKT (laspy would write GeoTIFF keys for point
        # formats 0-5 and leave the bit set: the spec's readers then find no CRS)
        wkt = bool(getattr(h.global_encoding, "wkt", False)) and h.version.minor >= 4
        h.add_crs(parse_crs(crs, what="crs"), keep_compatibility=not wkt)
        evlrs = getattr(h, "evlrs", None)
        if evlrs:
            kept = type(evlrs)()
            kept.extend(v for v in evlrs if type(v).__name__ not in _CRS_VLRS)
            h.evlrs = kept
    return h


#: How the writer treats header and VLR text that is not ASCII (the spec's character set,
#: which real files do not always keep: a system identifier or a VLR description in UTF-8 or
#: Latin-1): text read from the input is copied byte for byte, new text gets '?'.
_COPY_TEXT = "replace"

#: laspy's classes of the records that hold a CRS (WKT or GeoTIFF keys).
#: ``crs`` of :func:`transform_cloud` that removes the CRS record of the output.
NO_CRS = ""

_CRS_VLRS = (
    "WktCoordinateSystemVlr",
    "GeoKeyDirectoryVlr",
    "GeoAsciiParamsVlr",
    "GeoDoubleParamsVlr",
)


def _quantise(
    values: np.ndarray,
    offset: float,
    scale: float,
    axis: str,
    what: str = "transformed",
    fix: str = "pass larger scales (scales= / --scales)",
) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        q = np.rint((values - offset) / scale)
    if not np.all(np.isfinite(q)) or np.any(np.abs(q) > _INT32):
        raise InputError(
            f"{what} {axis} coordinates do not fit the output scale/offset "
            f"({scale}/{offset}) or are not finite; {fix}"
        )
    return q.astype(np.int32)


def _rewrite(points, fn, scales, offsets) -> None:
    """Transform a chunk of points in place into the output scales and offsets."""
    out = fn(_xyz(points))
    if out.shape != (len(points), 3):
        raise InputError(f"the transformation returned shape {out.shape} for {len(points)} points")
    points.X = _quantise(out[:, 0], offsets[0], scales[0], "x")
    points.Y = _quantise(out[:, 1], offsets[1], scales[1], "y")
    points.Z = _quantise(out[:, 2], offsets[2], scales[2], "z")
    points.scales = scales
    points.offsets = offsets


def transform_cloud(
    src,
    dst,
    transform,
    chunk_size: int = DEFAULT_CHUNK,
    *,
    scales=None,
    crs=None,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str | None = None,
) -> CloudTransformResult:
    """Transform the points of a LAS/LAZ file into a new file, ``chunk_size`` points at a time.

    Parameters
    ----------
    src, dst : str or path
        Input and output LAS/LAZ files (compression from ``dst``'s suffix ``.laz``). ``dst``
        is written to a temporary file beside it and renamed when complete.
    transform : transformation
        Anything with ``apply((n, 3)) -> (n, 3)``: a photogeom transformation
        (``Similarity3D``, ``Affine3D``, ``Projective3D``, ``Polynomial3D``, ...), a
        ``Fit`` (its ``transform``), :class:`photogeom.crs.ProjTransform` (a PROJ
        coordinate operation; its target CRS is then recorded), or a function.
    chunk_size : int
        Points per chunk; memory use is proportional to it (~100 bytes per point), not to
        the file.
    scales : sequence of 3 floats, optional
        Output coordinate resolution; default: the input's, carried into the target CRS's
        unit when a PROJ operation changes it (metres to degrees: 0.01 -> 1e-7, ~1.1 cm;
        :func:`unit_scales`), so that the resolution stays what it was.
    crs : str, optional
        CRS to record in the output (EPSG code, WKT, PROJ string); default: the
        transformation's ``target_crs`` if it has one, else the input's record unchanged.
        ``NO_CRS`` (``""``) writes no record: the points are no longer in the input's CRS
        and their own is unknown.
    progress : callable(done, total), optional
        Called after each chunk with points done and total.
    scheduler : str, optional
        None (default): in this process, chunk after chunk. Otherwise the pieces of the file
        are Dask tasks (:func:`transform_cloud_dask`): ``"local"``, ``"local:N"``, a
        scheduler address, ``"threads"``; the output is the same.

    Returns
    -------
    CloudTransformResult
        What was written: the path, point count, bounds, scales, offsets and CRS.

    Raises
    ------
    InputError
        ``dst`` is ``src``.
    OutputError
        ``dst`` cannot be written: a folder, a read-only file, a missing folder, a device or
        a named pipe (``/dev/null``: a LAS/LAZ file is written with seeks and read back),
        refused before the first pass; a full disk while writing (nothing is left).

    Notes
    -----
    Kept: point format and LAS version, every dimension including extra bytes, all VLRs
    and EVLRs (LAS 1.4 extended VLRs, written after the points), the CRS record (unless
    replaced; also one among the EVLRs). Offsets are
    recomputed from the bounds of the output (the transformed corners of the input box for
    affine transformations; a first pass over the points for others), scales are kept, and
    coordinates are rounded to the scale like any LAS writer does.
    """
    if scheduler is not None:
        return transform_cloud_dask(
            src,
            dst,
            transform,
            chunk_size,
            scheduler=scheduler,
            scales=scales,
            crs=crs,
            progress=progress,
        )
    laspy = _laspy()
    chunk_size = _check_chunk(chunk_size)
    fn = _as_apply(transform)
    src = Path(src)
    dst = Path(dst)
    if dst.resolve() == src.resolve():
        raise InputError(f"output {dst} is the input file; write to a new file")
    _cloud_destination(dst)  # a folder, a read-only file, a device: refused before any pass
    if crs is None:
        crs = getattr(transform, "target_crs", None)
    passes = 1
    bounds = None
    with _open_read(src) as reader:
        n = int(reader.header.point_count)
        if not _affine_like(transform):
            lo = np.full(3, np.inf)
            hi = np.full(3, -np.inf)
            for pts in _read_range(reader, src, 0, n, chunk_size):
                out = fn(_xyz(pts))
                lo = np.minimum(lo, out.min(axis=0))
                hi = np.maximum(hi, out.max(axis=0))
            passes = 2
            bounds = (lo, hi) if n else (np.zeros(3), np.zeros(3))
        header = output_header(reader.header, transform, scales, crs, bounds)
    sc = np.array(header.scales, dtype=float)
    off = np.array(header.offsets, dtype=float)
    compress = dst.suffix.lower() == ".laz"
    chunks = 0
    done = 0
    with _atomic_target(dst) as tmp:
        with (
            _open_read(src) as reader,
            laspy.open(
                tmp,
                mode="w",
                header=header,
                do_compress=compress,
                encoding_errors=_COPY_TEXT,
            ) as writer,
        ):
            for pts in _read_range(reader, src, 0, n, chunk_size):
                _rewrite(pts, fn, sc, off)
                writer.write_points(pts)
                chunks += 1
                done += len(pts)
                if progress is not None:
                    progress(done, n)
            if header.evlrs:  # LAS 1.4 extended VLRs (e.g. the CRS WKT) follow the points
                writer.write_evlrs(header.evlrs)
    info = cloud_info(dst)
    return CloudTransformResult(
        str(dst),
        info.point_count,
        info.scales,
        info.offsets,
        info.mins,
        info.maxs,
        info.crs_name,
        chunks,
        passes,
    )


def write_cloud(
    path,
    xyz,
    *,
    scales=(0.001, 0.001, 0.001),
    offsets=None,
    crs=None,
    point_format: int = 6,
    version: str = "1.4",
    extra: dict | None = None,
) -> Path:
    """Write points (n, 3) to a new LAS/LAZ file (atomically), e.g. a generated test cloud.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write (``.laz``: compressed).
    xyz : array_like, shape (n, 3)
        Finite coordinates.
    scales : sequence of 3 floats
        The coordinate resolution (stored integer ``X`` means ``X * scale + offset``).
    offsets : sequence of 3 floats, optional
        Default: the centre of the points' bounds rounded to ``1000 * scale``, as
        :func:`transform_cloud` chooses them.
    crs : str, optional
        A CRS PROJ reads, recorded in the file.
    point_format, version
        LAS point format and version.
    extra : dict, optional
        Names to (n,) arrays written as extra-bytes dimensions (their dtype).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        Points not (n, 3); a NaN or infinite coordinate (naming its row: LAS stores
        integers); scales not three positive numbers; a point format that the LAS version
        does not have; extra dimensions with names of more than 32 bytes or names of the
        point format's own dimensions, or not one value per point; coordinates the scales
        (and offsets) cannot store in 32-bit integers (pass larger ``scales=``). Nothing is
        written then.
    """
    laspy = _laspy()
    xyz = np.asarray(xyz, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"points must have shape (n, 3), got {xyz.shape}")
    bad = ~np.all(np.isfinite(xyz), axis=1)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(
            f"points: row {k} is not finite ({', '.join(repr(float(v)) for v in xyz[k])}; "
            f"{int(bad.sum())} such row(s)): a LAS file stores finite coordinates only; "
            "remove those rows first"
        )
    sc = np.asarray(scales, dtype=float)
    if sc.shape != (3,) or not np.all(np.isfinite(sc) & (sc > 0)):
        raise InputError(f"scales= must be three positive numbers, got {scales!r}")
    fit = "pass larger scales (scales=)"
    if offsets is None:
        if len(xyz):
            off = _new_offsets(xyz.min(axis=0), xyz.max(axis=0), sc, "coordinates", "scales=")
        else:
            off = np.zeros(3)
    else:
        off = np.asarray(offsets, dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise InputError(f"offsets= must be three finite numbers, got {offsets!r}")
        fit = "pass larger scales (scales=) or offsets= nearer the points (or none)"
    ints = [_quantise(xyz[:, i], off[i], sc[i], a, "the", fit) for i, a in enumerate("xyz")]
    try:
        header = laspy.LasHeader(point_format=point_format, version=version)
    except (laspy.errors.LaspyException, ValueError, TypeError):
        from laspy.point.dims import VERSION_TO_POINT_FMT

        table = "; ".join(
            f"{v}: {min(f)}-{max(f)}" for v, f in sorted(VERSION_TO_POINT_FMT.items())
        )
        raise InputError(
            f"point_format={point_format!r} with version={version!r} is not a LAS point "
            f"format of that version; point formats by version: {table} (e.g. "
            "point_format=6, version='1.4', or point_format=3, version='1.2')"
        ) from None
    taken = {d.lower() for d in header.point_format.dimension_names}
    for name, values in (extra or {}).items():
        if not isinstance(name, str) or not 0 < len(name.encode("utf-8")) <= 32:
            raise InputError(
                f"extra= names dimensions of 1 to 32 bytes (a LAS extra-bytes name); "
                f"{str(name)[:40]!r} is not one"
            )
        if name.lower() in taken:
            raise InputError(
                f"extra={{{name!r}: ...}}: point format {point_format} already has a "
                f"dimension {name!r}; give the extra dimension another name"
            )
        v = np.asarray(values)
        if v.shape != (len(xyz),):
            raise InputError(
                f"extra={{{name!r}: ...}} has shape {v.shape}; it needs one value per point "
                f"({len(xyz)},)"
            )
        taken.add(name.lower())
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=v.dtype))
    header.scales = sc
    header.offsets = off
    if crs is not None:
        from ..crs import parse_crs

        header.add_crs(parse_crs(crs, what="crs"))
    las = laspy.LasData(header)
    las.X, las.Y, las.Z = ints
    for name, values in (extra or {}).items():
        las[name] = values
    p = Path(path)
    with _atomic_target(p) as tmp:
        with open(tmp, "wb") as fh:  # a stream: laspy then honours do_compress
            las.write(fh, do_compress=p.suffix.lower() == ".laz")
    return p


def cloud_dask_xyz(path, chunk_size: int = DEFAULT_CHUNK):
    """The coordinates of a LAS/LAZ file as a lazy ``dask.array``.

    One block per ``chunk_size`` points, each read (seeking in the file) when computed.

    Parameters
    ----------
    path : str or os.PathLike
        The LAS/LAZ file; every Dask worker must see it.
    chunk_size : int, default DEFAULT_CHUNK
        Points per block, >= 1.

    Returns
    -------
    dask.array.Array, shape (n, 3)
        X, Y, Z in the file's CRS unit (scaled and offset), float64.

    Raises
    ------
    InputError
        For a ``chunk_size`` below 1.
    FileFormatError
        When the file cannot be read as LAS/LAZ.
    """
    from ..distributed import _dask

    da, delayed = _dask()
    chunk_size = _check_chunk(chunk_size)
    n = cloud_info(path).point_count
    blocks = [
        da.from_delayed(
            delayed(read_cloud_xyz, pure=True)(str(path), i, min(i + chunk_size, n)),
            shape=(min(i + chunk_size, n) - i, 3),
            dtype=float,
        )
        for i in range(0, n, chunk_size)
    ]
    if not blocks:
        return da.zeros((0, 3), chunks=(1, 3))
    return da.concatenate(blocks, axis=0)


# --- the same job as Dask tasks ---------------------------------------------------------------

#: Points per chunk of laspy's LAZ writer (lazrs default); pieces written by separate tasks
#: are whole multiples of it so that their chunk tables join into one file.
LAZ_CHUNK = 50_000
_COPY_BLOCK = 1 << 24


def _piece_bounds(src: str, start: int, stop: int, transform, chunk_size: int):
    """Bounds (lo, hi) of the transformed points start:stop (first pass of a non-affine
    transformation)."""
    fn = _as_apply(transform)
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    with _open_read(src, single_thread=True) as reader:
        for pts in _read_range(reader, src, start, stop, chunk_size):
            out = fn(_xyz(pts))
            lo = np.minimum(lo, out.min(axis=0))
            hi = np.maximum(hi, out.max(axis=0))
    return lo, hi


def _write_piece(
    src: str, part: str, start: int, stop: int, transform, header, chunk_size: int, compress: bool
) -> int:
    """Transform points start:stop of ``src`` into the complete LAS/LAZ file ``part``."""
    laspy = _laspy()
    fn = _as_apply(transform)
    sc = np.array(header.scales, dtype=float)
    off = np.array(header.offsets, dtype=float)
    with (
        _open_read(src, single_thread=True) as reader,
        laspy.open(
            part,
            mode="w",
            header=header,
            do_compress=compress,
            laz_backend=laspy.LazBackend.Lazrs if compress else None,
            encoding_errors=_COPY_TEXT,
        ) as writer,
    ):
        for pts in _read_range(reader, src, start, stop, chunk_size):
            _rewrite(pts, fn, sc, off)
            writer.write_points(pts)
    return stop - start


def _laz_vlr(raw: bytes):
    """The LASzip VLR of a file's header bytes."""
    import lazrs

    pos = struct.unpack_from("<H", raw, 94)[0]
    for _ in range(struct.unpack_from("<I", raw, 100)[0]):
        uid = raw[pos + 2 : pos + 18].rstrip(b"\0")
        ln = struct.unpack_from("<H", raw, pos + 20)[0]
        if uid == b"laszip encoded":
            return lazrs.LazVlr(raw[pos + 54 : pos + 54 + ln])
        pos += 54 + ln
    raise FileFormatError("LAZ piece without a LASzip VLR")  # pragma: no cover


def _copy(fin, fout, nbytes: int) -> None:
    while nbytes > 0:
        block = fin.read(min(_COPY_BLOCK, nbytes))
        if not block:
            raise FileFormatError("a piece of the output ended early")  # pragma: no cover
        fout.write(block)
        nbytes -= len(block)


def _merge_pieces(parts: list[Path], out: Path, compress: bool) -> None:
    """Join complete LAS/LAZ files written with one header into one file: the header of the
    first with the counts, per-return counts and bounds of all; the point data one after the
    other (LAZ: the compressed chunks, and one chunk table for all)."""
    laspy = _laspy()
    heads = []
    for p in parts:
        with laspy.open(p) as r:
            heads.append(r.header)
    total = sum(int(h.point_count) for h in heads)
    by_return = np.sum(
        [np.asarray(h.number_of_points_by_return, dtype=np.int64) for h in heads if h.point_count],
        axis=0,
    )
    mins = np.min([h.mins for h in heads if h.point_count], axis=0)
    maxs = np.max([h.maxs for h in heads if h.point_count], axis=0)
    with open(parts[0], "rb") as f0:
        start = struct.unpack_from("<I", f0.read(100), 96)[0]
        f0.seek(0)
        raw = bytearray(f0.read(start))
    minor = raw[25]
    rec_len = struct.unpack_from("<H", raw, 105)[0]
    point_format = raw[104] & 0x3F  # LAZ sets bit 7 (and bit 6) of the point format byte
    if struct.unpack_from("<I", raw, 107)[0] or total == 0:
        legacy = total if total <= 0xFFFFFFFF and point_format < 6 else 0
        struct.pack_into("<I", raw, 107, legacy)
        if legacy:
            struct.pack_into("<5I", raw, 111, *[int(v) for v in by_return[:5]])
    struct.pack_into("<6d", raw, 179, maxs[0], mins[0], maxs[1], mins[1], maxs[2], mins[2])
    if minor >= 4:
        struct.pack_into("<Q", raw, 247, total)
        br = np.zeros(15, dtype=np.int64)
        br[: by_return.size] = by_return[:15]
        struct.pack_into("<15Q", raw, 255, *[int(v) for v in br])
    with open(out, "wb") as fo:
        fo.write(raw)
        if compress:
            import lazrs

            vlr = _laz_vlr(bytes(raw))
            fo.write(b"\0" * 8)  # offset to the chunk table, filled in below
            table = []
            for p, h in zip(parts, heads):
                if not h.point_count:
                    continue
                with open(p, "rb") as fi:
                    fi.seek(start)
                    entries = lazrs.read_chunk_table(fi, vlr)  # leaves fi at the first chunk
                    _copy(fi, fo, sum(int(e[1]) for e in entries))
                    table.extend(entries)
            at = fo.tell()
            lazrs.write_chunk_table(fo, table, vlr)
            fo.seek(start)
            fo.write(struct.pack("<q", at))
        else:
            for p, h in zip(parts, heads):
                with open(p, "rb") as fi:
                    fi.seek(start)
                    _copy(fi, fo, int(h.point_count) * rec_len)
        fo.flush()
        os.fsync(fo.fileno())


def transform_cloud_dask(
    src,
    dst,
    transform,
    chunk_size: int = DEFAULT_CHUNK,
    *,
    scheduler: str | None = None,
    scales=None,
    crs=None,
    progress: Callable[[int, int], None] | None = None,
) -> CloudTransformResult:
    """:func:`transform_cloud` as Dask tasks.

    Each task transforms a piece of the file into a complete LAS/LAZ file of its own
    (pieces are whole multiples of the LAZ chunk of 50 000 points), and the pieces are
    joined into ``dst`` without recompression (one chunk table). The output equals
    :func:`transform_cloud`'s point for point (same header fields, VLRs and integers; only
    the optional min/max statistics of extra-bytes descriptors, which laspy's writer
    updates per written chunk, can differ); the pieces take as much disk space as the
    output until they are joined.

    Parameters
    ----------
    src, dst : str or os.PathLike
        Input and output LAS/LAZ files (compression from ``dst``'s suffix); every worker
        must see ``src`` and the directory of ``dst`` (a shared file system on a real
        cluster).
    transform : transformation
        As in :func:`transform_cloud`.
    chunk_size : int, default DEFAULT_CHUNK
        Points per chunk within a piece.
    scheduler : str, optional
        As in :mod:`photogeom.distributed` (a local cluster by default).
    scales : sequence of 3 floats, optional
        Output coordinate resolution, as in :func:`transform_cloud`.
    crs : str, optional
        CRS to record in the output, as in :func:`transform_cloud`.
    progress : callable(done, total), optional
        Called with the points of finished pieces and the total.

    Returns
    -------
    CloudTransformResult

    Raises
    ------
    InputError
        When ``dst`` is ``src``, or the file has extended VLRs (EVLRs, LAS 1.4; use
        :func:`transform_cloud`).
    OutputError
        ``dst`` cannot be written (a folder, a read-only file, a missing folder: refused
        before any piece is computed; no room for the pieces or the output, a folder where
        no file may be made): one message naming ``dst``; the pieces are removed and an
        existing ``dst`` is left as it was.
    """
    from ..distributed import map_items

    chunk_size = _check_chunk(chunk_size)
    _as_apply(transform)
    src = Path(src)
    dst = Path(dst)
    if dst.resolve() == src.resolve():
        raise InputError(f"output {dst} is the input file; write to a new file")
    _cloud_destination(dst)  # a folder, a read-only file, no such folder: refused at once
    if crs is None:
        crs = getattr(transform, "target_crs", None)
    compress = dst.suffix.lower() == ".laz"
    with _open_read(src) as reader:
        n = int(reader.header.point_count)
        if getattr(reader.header, "number_of_evlrs", 0) or reader.evlrs:
            raise InputError(
                f"{src} has extended VLRs (EVLRs), which the joined pieces would drop; "
                "transform it without a scheduler"
            )
        src_header = reader.header
    piece = max(LAZ_CHUNK, -(-chunk_size // LAZ_CHUNK) * LAZ_CHUNK)
    ranges = [(i, min(i + piece, n)) for i in range(0, n, piece)] or [(0, 0)]
    passes = 1
    bounds = None
    if not _affine_like(transform):
        res = map_items(
            functools.partial(_bounds_item, str(src), transform, chunk_size),
            ranges,
            scheduler=scheduler,
            raise_on_failure=True,
        )
        lo = np.min([r[0] for r in res.results], axis=0)
        hi = np.max([r[1] for r in res.results], axis=0)
        bounds = (lo, hi) if n else (np.zeros(3), np.zeros(3))
        passes = 2
    header = output_header(src_header, transform, scales, crs, bounds)
    tmpdir = _pieces_folder(dst)
    try:
        parts = [tmpdir / f"piece-{k:06d}{dst.suffix}" for k in range(len(ranges))]
        items = [(str(p), a, b) for p, (a, b) in zip(parts, ranges)]

        def _progress(k: int, total: int) -> None:
            if progress is not None:
                progress(min(n, k * piece), n)

        done = map_items(
            functools.partial(_piece_item, str(src), transform, header, chunk_size, compress),
            items,
            scheduler=scheduler,
            progress=_progress,
        )
        tag = f"{PieceNotWritten.__name__}: "
        unwritten = [f.error for f in done.failures if f.error.startswith(tag)]
        if unwritten:  # disk full, ...: said of the output, not of a temporary piece
            raise OutputError(f"cannot write {dst}: {unwritten[0].removeprefix(tag)}")
        done.raise_failures()
        with _atomic_target(dst) as tmp:
            _merge_pieces(parts, tmp, compress)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    info = cloud_info(dst)
    return CloudTransformResult(
        str(dst),
        info.point_count,
        info.scales,
        info.offsets,
        info.mins,
        info.maxs,
        info.crs_name,
        len(ranges),
        passes,
    )


def _pieces_folder(dst: Path) -> Path:
    """A new folder for the pieces beside ``dst``, its name fitted to the file-name limit
    (a destination name that a plain ``open()`` accepts is accepted).

    Raises
    ------
    OutputError
        Naming ``dst`` when the folder cannot be made (a read-only folder, a full disk).
    """
    from ..atomicfile import _failure, _temporary_name

    given, target = _cloud_destination(dst)
    directory = target.parent if str(target.parent) else Path(".")
    for _ in range(100):
        folder = _temporary_name(directory, target.name, f".{secrets.token_hex(6)}.pieces")
        try:
            os.mkdir(folder, 0o700)
            return folder
        except FileExistsError:
            continue
        except OSError as exc:
            raise _failure(given, exc) from exc
    raise PhotogeomError(  # pragma: no cover - 100 collisions of 48 random bits
        f"cannot write {given}: no free temporary folder name"
    )


def _bounds_item(src, transform, chunk_size, rng):
    return _piece_bounds(src, rng[0], rng[1], transform, chunk_size)


class PieceNotWritten(Exception):
    """A worker could not write its piece (an ``OSError`` of the file system: disk full,
    ...); the message is the reason, which :func:`transform_cloud_dask` reports for the
    output file rather than for the temporary piece."""


def _piece_item(src, transform, header, chunk_size, compress, item):
    from ..atomicfile import _failure

    part, a, b = item
    try:
        return _write_piece(src, part, a, b, transform, header, chunk_size, compress)
    except PhotogeomError:  # the input (read errors are FileFormatError), the transformation
        raise
    except OSError as exc:
        reason = str(_failure(Path(part), exc)).removeprefix(f"cannot write {part}: ")
        raise PieceNotWritten(reason) from exc
