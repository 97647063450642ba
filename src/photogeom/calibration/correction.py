"""Apply residual grids: correct image coordinates and resample images.

Sign convention. The grid models the image residual ``r = computed - observed`` (px). An
observation displaced by a local field ``d`` (``observed = ideal + d``) has ``r = -d``, so
the corrected observation is ``uv + r(uv)``: the displacement field subtracted.

Images are corrected by inverse mapping: the output pixel ``q`` takes the input value at
``q - r(q)`` (the field evaluated at the output pixel), resampled by OpenCV ``remap``
(bilinear or bicubic). A feature at ``p`` in the input then appears at ``p + r(p)`` up to
``|grad r| |r|`` (about 0.01 px for a 1 px field that changes by 1 px over 100 px). Only
the local field is removed: the Brown distortion of the camera stays in the image.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Literal

import numpy as np

from ..errors import InputError
from .grid import ResidualGrid, _as_uv

Interpolation = Literal["bilinear", "bicubic", "nearest"]
INTERPOLATIONS = ("bilinear", "bicubic", "nearest")
_CV_MAX = 32767  # OpenCV remap: image sides below SHRT_MAX


def correct_points(uv, grid: ResidualGrid) -> np.ndarray:
    """Corrected image coordinates ``uv + r(uv)``. See the module.

    Parameters
    ----------
    uv : array_like, shape (n, 2) or (2,)
        Observed pixels (col, row) inside the image.
    grid : ResidualGrid
        The grid of the image.

    Returns
    -------
    numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
        px.
    """
    return grid.correct(uv)


def correct_observations(per_image: Mapping, grids: Mapping) -> dict:
    """Correct the image coordinates of many images.

    Parameters
    ----------
    per_image : mapping
        ``image id -> uv (n, 2)`` observed pixel coordinates (any block, also points that
        were not in the fit); ``(2,)`` for one point.
    grids : mapping
        ``image id -> ResidualGrid``.

    Returns
    -------
    dict
        ``image id -> corrected uv (n, 2)`` (``(2,)`` for one point ``(2,)``), px.

    Raises
    ------
    InputError
        An image without a grid (named), or points outside an image.
    """
    missing = [k for k in per_image if k not in grids]
    if missing:
        raise InputError(
            f"no residual grid for image(s) {', '.join(map(str, missing[:10]))}"
            f"{' ...' if len(missing) > 10 else ''}: fit grids for every image to correct"
        )
    out = {}
    for key, uv in per_image.items():
        try:
            corrected = grids[key].correct(_as_uv(uv, f"image {key}: uv", "correcting them"))
            out[key] = corrected[0] if np.ndim(uv) == 1 else corrected
        except InputError as exc:
            msg = str(exc)
            raise InputError(msg if msg.startswith("image ") else f"image {key}: {msg}") from None
    return out


def _column_profiles(grid: ResidualGrid) -> tuple[np.ndarray, np.ndarray]:
    """Node rows interpolated to every pixel column: T (ny, width, 2) and the pixel-row
    weights are applied per band of rows."""
    L = grid.layout
    x = np.arange(L.width, dtype=float) / L.spacing
    j = np.minimum(np.floor(x).astype(np.int64), L.nx - 2)
    a = (x - j)[None, :, None]
    Z = grid.nodes
    return Z[:, j, :] * (1 - a) + Z[:, j + 1, :] * a, j


def field_at_pixels(grid: ResidualGrid, rows: slice | None = None) -> np.ndarray:
    """The modelled residual at every pixel centre.

    Separable evaluation: node rows interpolated to the pixel columns once, then linear
    between node rows, so the cost is two operations per pixel and component.

    Parameters
    ----------
    grid : ResidualGrid
        The grid of the image.
    rows : slice, optional
        Image rows to evaluate; default all.

    Returns
    -------
    numpy.ndarray, shape (rows, width, 2)
        Computed minus observed, px, float64.
    """
    L = grid.layout
    rows = rows or slice(0, L.height)
    T, _ = _column_profiles(grid)
    y = np.arange(L.height, dtype=float)[rows] / L.spacing
    i = np.minimum(np.floor(y).astype(np.int64), L.ny - 2)
    b = (y - i)[:, None, None]
    return T[i] * (1 - b) + T[i + 1] * b


def remap_maps(grid: ResidualGrid, rows: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The float32 maps of ``cv2.remap`` for the correction: ``q - r(q)`` for output
    pixels ``q`` in ``rows`` (all rows by default); each (rows, width)."""
    r = field_at_pixels(grid, rows)
    L = grid.layout
    rows = rows or slice(0, L.height)
    yy = np.arange(L.height, dtype=float)[rows][:, None]
    xx = np.arange(L.width, dtype=float)[None, :]
    return (xx - r[..., 0]).astype(np.float32), (yy - r[..., 1]).astype(np.float32)


def correct_image(
    image: np.ndarray,
    grid: ResidualGrid,
    *,
    interpolation: Interpolation = "bilinear",
    border: Literal["replicate", "constant", "reflect"] = "replicate",
    threads: int | None = None,
    chunk_rows: int = 64,
) -> np.ndarray:
    """Resample an image so that the residual field is built in (see the module).

    Parameters
    ----------
    image : numpy.ndarray, shape (height, width) or (height, width, channels)
        uint8, uint16, int16, float32 or float64; up to 4 channels.
    grid : ResidualGrid
        Fitted for an image of this size.
    interpolation : {"bilinear", "bicubic", "nearest"}
        ``"nearest"`` takes the nearest source pixel (no value is blended: for label,
        mask and palette-index images; the geometry then holds to half a pixel).
    border : {"replicate", "constant", "reflect"}
        Values for output pixels whose source lies outside the image.
    threads : int, optional
        Threads over chunks of rows (default: 2). The maps of each chunk are built and
        used at once, in one pair of buffers per thread, so the full-size maps are never
        held in memory.
    chunk_rows : int
        Rows per chunk (whole cell rows, at least this many).

    Returns
    -------
    numpy.ndarray
        Same shape and type as ``image``.
    """
    import cv2

    img = np.asarray(image)
    L = grid.layout
    if img.ndim not in (2, 3) or img.shape[:2] != (L.height, L.width):
        raise InputError(
            f"image of shape {img.shape} does not match the grid's image "
            f"({L.height} rows x {L.width} columns)"
        )
    if img.ndim == 3 and not 1 <= img.shape[2] <= 4:
        raise InputError(f"images with 1 to 4 channels are supported, not {img.shape[2]}")
    if img.dtype not in (np.uint8, np.uint16, np.int16, np.float32, np.float64):
        raise InputError(f"image type {img.dtype} is not supported (uint8, uint16, int16, float)")
    if max(L.width, L.height) >= _CV_MAX:
        raise InputError(f"images with a side of {_CV_MAX} px or more are not supported by remap")
    if interpolation not in INTERPOLATIONS:
        raise InputError(
            f"interpolation must be one of {', '.join(INTERPOLATIONS)}, not {interpolation!r}"
        )
    modes = {
        "replicate": cv2.BORDER_REPLICATE,
        "constant": cv2.BORDER_CONSTANT,
        "reflect": cv2.BORDER_REFLECT_101,
    }
    if border not in modes:
        raise InputError(f"border must be one of {', '.join(modes)}, not {border!r}")
    flag = {"bilinear": cv2.INTER_LINEAR, "bicubic": cv2.INTER_CUBIC}.get(
        interpolation, cv2.INTER_NEAREST
    )
    mode = modes[border]
    img = np.ascontiguousarray(img)
    out = np.empty_like(img)
    T, _ = _column_profiles(grid)
    T32 = T.astype(np.float32)
    dT = np.diff(T32, axis=0)  # (ny-1, width, 2)
    xs = np.arange(L.width, dtype=np.float32)
    g = L.spacing
    # bands: the pixel rows between two node rows (one band per cell row)
    edges = [min(L.height, int(np.ceil(k * g))) for k in range(L.ny)] + [L.height]
    bands = [(k, edges[k], edges[k + 1]) for k in range(L.ny - 1) if edges[k + 1] > edges[k]]
    if edges[L.ny - 1] < L.height:  # rows past the last node row: last cell extrapolates
        bands.append((L.ny - 2, edges[L.ny - 1], L.height))

    # chunks of whole bands, at least ``chunk_rows`` rows: few remap calls, small maps
    chunks, cur = [], []
    for band in bands:
        cur.append(band)
        if band[2] - cur[0][1] >= chunk_rows:
            chunks.append(cur)
            cur = []
    if cur:
        chunks.append(cur)

    ones = np.ones(L.width, np.float32)
    # the maps of a chunk go into buffers of the thread that remaps it, made once and used
    # for all its chunks: a pair per chunk was freshly mapped memory for every chunk where
    # the allocator returns large blocks to the system (Dask workers set
    # MALLOC_TRIM_THRESHOLD_): 26 500 page faults and 40 % of the CPU time for 12 Mpx
    longest = max(c[-1][2] - c[0][1] for c in chunks)
    local = threading.local()

    def run(chunk):
        c0, c1 = chunk[0][1], chunk[-1][2]
        if not hasattr(local, "maps"):
            local.maps = np.empty((2, longest, L.width), np.float32)
        mx, my = local.maps[:, : c1 - c0]
        for k, y0, y1 in chunk:
            # in a band the maps are linear in the row: [b, 1, y] times the rows of the two
            # node rows, one product that writes each map element once (einsum's own loop:
            # a BLAS product would start BLAS threads inside these threads)
            y = np.arange(y0, y1, dtype=np.float64)
            B = np.empty((y1 - y0, 3), np.float32)
            B[:, 0], B[:, 1], B[:, 2] = y / g - k, 1.0, y
            cx = np.stack([-dT[k, :, 0], xs - T32[k, :, 0]])
            cy = np.stack([-dT[k, :, 1], -T32[k, :, 1], ones])
            np.einsum("nk,kw->nw", B[:, :2], cx, out=mx[y0 - c0 : y1 - c0], optimize=False)
            np.einsum("nk,kw->nw", B, cy, out=my[y0 - c0 : y1 - c0], optimize=False)
        cv2.remap(img, mx, my, flag, dst=out[c0:c1], borderMode=mode)

    n_threads = 2 if threads is None else max(1, int(threads))
    if n_threads == 1:
        for chunk in chunks:
            run(chunk)
    else:
        with ThreadPoolExecutor(n_threads) as ex:
            list(ex.map(run, chunks))
    return out
