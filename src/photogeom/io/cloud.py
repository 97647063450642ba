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

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError, PhotogeomError

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


def _open_read(path):
    laspy = _laspy()
    p = Path(path)
    if not p.is_file():
        raise InputError(f"point cloud {p} does not exist")
    try:
        return laspy.open(p)
    except laspy.errors.LaspyException as exc:
        raise FileFormatError(f"{p}: not a readable LAS/LAZ file ({exc})") from None


@dataclass(frozen=True)
class CloudInfo:
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

    def to_dict(self) -> dict:
        """JSON-ready."""
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
            "vlrs": list(self.vlrs),
        }


def _header_crs(header) -> tuple[str | None, str | None]:
    try:
        crs = header.parse_crs()
    except Exception:
        crs = None
    if crs is None:
        return None, None
    auth = crs.to_authority()
    return crs.to_wkt(), (f"{auth[0]}:{auth[1]} ({crs.name})" if auth else crs.name)


def cloud_info(path) -> CloudInfo:
    """Read the header of a LAS/LAZ file (no points are read)."""
    with _open_read(path) as reader:
        h = reader.header
        wkt, name = _header_crs(h)
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
        )


def _xyz(points) -> np.ndarray:
    out = np.empty((len(points), 3))
    out[:, 0] = points.x
    out[:, 1] = points.y
    out[:, 2] = points.z
    return out


def iter_cloud_xyz(path, chunk_size: int = DEFAULT_CHUNK) -> Iterator[np.ndarray]:
    """Coordinates (m, 3) of a LAS/LAZ file, ``chunk_size`` points at a time."""
    chunk_size = _check_chunk(chunk_size)
    with _open_read(path) as reader:
        for pts in reader.chunk_iterator(chunk_size):
            yield _xyz(pts)


def read_cloud_xyz(path, start: int = 0, stop: int | None = None) -> np.ndarray:
    """Coordinates (n, 3) of points ``start:stop`` of a LAS/LAZ file (all by default)."""
    with _open_read(path) as reader:
        n = reader.header.point_count
        stop = n if stop is None else min(int(stop), n)
        start = int(start)
        if not 0 <= start <= stop:
            raise InputError(f"point range {start}:{stop} outside 0:{n}")
        if start:
            reader.seek(start)
        return _xyz(reader.read_points(stop - start))


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


def _new_offsets(lo: np.ndarray, hi: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """Offsets at the centre of the output bounds, rounded to a round number (a whole
    multiple of ``1000 * scale`` so that offsets stay readable), checked against int32."""
    centre = 0.5 * (lo + hi)
    step = scales * 1000.0
    off = np.round(centre / step) * step
    span = np.maximum(np.abs(hi - off), np.abs(lo - off)) / scales
    if np.any(span > _INT32):
        raise InputError(
            f"the transformed coordinates span {(hi - lo).tolist()} which the scales "
            f"{scales.tolist()} cannot store in 32-bit integers; pass larger scales "
            "(scales= / --scales)"
        )
    return off


@contextmanager
def _atomic_target(dst: Path):
    """A temporary path beside ``dst`` (same suffix) renamed over it on success."""
    directory = dst.parent if str(dst.parent) else Path(".")
    if not directory.is_dir():
        raise PhotogeomError(f"cannot write {dst}: directory {directory} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{dst.name}.", suffix=dst.suffix, dir=directory)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, dst)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


@dataclass(frozen=True)
class CloudTransformResult:
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


def output_header(src_header, transform, scales=None, crs=None, bounds=None):
    """The header of a transformed copy: the source header (point format, version, VLRs,
    extra dimensions, CRS record) with the given or kept scales, offsets recomputed from the
    output bounds (``bounds`` = (lo, hi), else the transformed corners of the source box of
    an affine-like transformation), and ``crs`` (a pyproj-readable CRS) replacing the CRS
    record when given."""
    h = src_header.copy() if hasattr(src_header, "copy") else src_header
    sc = np.array(h.scales if scales is None else scales, dtype=float)
    if sc.shape != (3,) or not np.all(sc > 0):
        raise InputError(f"scales must be three positive numbers, got {scales}")
    if bounds is None:
        fn = _as_apply(transform)
        img = fn(_corners(np.array(h.mins), np.array(h.maxs)))
        bounds = (img.min(axis=0), img.max(axis=0))
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    h.scales = sc
    h.offsets = _new_offsets(lo, hi, sc)
    if crs is not None:
        from ..crs import parse_crs

        h.add_crs(parse_crs(crs, what="crs"))
    return h


def _quantise(values: np.ndarray, offset: float, scale: float, axis: str) -> np.ndarray:
    q = np.rint((values - offset) / scale)
    if not np.all(np.isfinite(q)) or np.any(np.abs(q) > _INT32):
        raise InputError(
            f"transformed {axis} coordinates do not fit the output scale/offset "
            f"({scale}/{offset}) or are not finite; pass larger scales (scales= / --scales)"
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
        Output coordinate resolution; default: the input's.
    crs : str, optional
        CRS to record in the output (EPSG code, WKT, PROJ string); default: the
        transformation's ``target_crs`` if it has one, else the input's record unchanged.
    progress : callable(done, total), optional
        Called after each chunk with points done and total.

    Notes
    -----
    Kept: point format and LAS version, every dimension including extra bytes, all VLRs
    and EVLRs the writer supports, the CRS record (unless replaced). Offsets are
    recomputed from the bounds of the output (the transformed corners of the input box for
    affine transformations; a first pass over the points for others), scales are kept, and
    coordinates are rounded to the scale like any LAS writer does.
    """
    laspy = _laspy()
    chunk_size = _check_chunk(chunk_size)
    fn = _as_apply(transform)
    src = Path(src)
    dst = Path(dst)
    if dst.resolve() == src.resolve():
        raise InputError(f"output {dst} is the input file; write to a new file")
    if crs is None:
        crs = getattr(transform, "target_crs", None)
    passes = 1
    bounds = None
    with _open_read(src) as reader:
        n = int(reader.header.point_count)
        if not _affine_like(transform):
            lo = np.full(3, np.inf)
            hi = np.full(3, -np.inf)
            for pts in reader.chunk_iterator(chunk_size):
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
            laspy.open(tmp, mode="w", header=header, do_compress=compress) as writer,
        ):
            for pts in reader.chunk_iterator(chunk_size):
                _rewrite(pts, fn, sc, off)
                writer.write_points(pts)
                chunks += 1
                done += len(pts)
                if progress is not None:
                    progress(done, n)
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

    ``extra`` maps names to (n,) arrays written as extra-bytes dimensions (their dtype).
    """
    laspy = _laspy()
    xyz = np.asarray(xyz, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"points must have shape (n, 3), got {xyz.shape}")
    header = laspy.LasHeader(point_format=point_format, version=version)
    for name, values in (extra or {}).items():
        header.add_extra_dim(laspy.ExtraBytesParams(name=name, type=np.asarray(values).dtype))
    header.scales = np.array(scales, dtype=float)
    if offsets is None:
        offsets = np.floor(xyz.min(axis=0)) if len(xyz) else np.zeros(3)
    header.offsets = np.array(offsets, dtype=float)
    if crs is not None:
        from ..crs import parse_crs

        header.add_crs(parse_crs(crs, what="crs"))
    las = laspy.LasData(header)
    las.x = xyz[:, 0]
    las.y = xyz[:, 1]
    las.z = xyz[:, 2]
    for name, values in (extra or {}).items():
        las[name] = values
    p = Path(path)
    with _atomic_target(p) as tmp:
        las.write(tmp, do_compress=p.suffix.lower() == ".laz")
    return p


def cloud_dask_xyz(path, chunk_size: int = DEFAULT_CHUNK):
    """The coordinates of a LAS/LAZ file as a lazy ``dask.array`` (n, 3), one block per
    ``chunk_size`` points, each read (seeking in the file) when computed."""
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
