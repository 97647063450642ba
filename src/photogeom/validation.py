"""Checks of array inputs shared by every layer (shape, finiteness, counts)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from .errors import InputError, PrecisionWarning, TooFewPointsError

#: A low-precision (float16/float32) coordinate array is reported (:class:`PrecisionWarning`)
#: when its resolution at its largest value exceeds this fraction of the spread of the points:
#: fewer than about six significant digits of the point configuration survive the rounding.
LOW_PRECISION_RELATIVE = 1e-6


def as_float64(values: object, name: str = "points", *, coordinates: bool = True) -> np.ndarray:
    """Return ``values`` as a float64 array; refuse what would be a silent wrong answer.

    * masked arrays with masked entries: :class:`InputError` (the hidden values would be
      used); a masked array without masked entries is read as its data;
    * complex values: :class:`InputError` (the imaginary part would be dropped);
    * float16 / float32 input is converted to float64 (every computation is in float64), with
      a :class:`PrecisionWarning` when the input's own resolution at its largest value is
      coarser than ``LOW_PRECISION_RELATIVE`` times the spread of its values (large offsets,
      e.g. UTM coordinates in float32, have been rounded before photogeom sees them);
      ``coordinates=False`` (weights, standard deviations) skips this check.
    """
    if isinstance(values, np.ma.MaskedArray):
        mask = np.ma.getmaskarray(values)
        if mask.any():
            rows = np.flatnonzero(mask.reshape(mask.shape[0], -1).any(axis=1)) if mask.ndim else []
            shown = ", ".join(str(int(i)) for i in rows[:10]) + (" ..." if len(rows) > 10 else "")
            raise InputError(
                f"{name}: masked array with {int(mask.sum())} masked value(s) (row index "
                f"{shown}); masked points are not dropped silently: remove those rows "
                "(e.g. a[~a.mask.any(axis=1)]) or fill the values"
            )
        values = np.ma.getdata(values)
    try:
        arr = np.asarray(values)
        if np.iscomplexobj(arr):
            raise InputError(
                f"{name}: complex values given; coordinates must be real numbers (the "
                "imaginary part would be discarded)"
            )
        low = arr.dtype.kind == "f" and arr.dtype.itemsize < 8
        dtype = arr.dtype
        arr = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{name}: cannot be read as numbers ({exc})") from exc
    if low and coordinates and arr.size:
        _check_resolution(arr, dtype, name)
    return arr


def _check_resolution(arr: np.ndarray, dtype: np.dtype, name: str) -> None:
    finite = arr[np.isfinite(arr)]
    if finite.size == 0:
        return
    big = float(np.max(np.abs(finite)))
    res = float(np.spacing(dtype.type(big)))
    cols = arr.reshape(arr.shape[0], -1) if arr.ndim > 1 else arr[:, None]
    with np.errstate(invalid="ignore"):
        spread = float(np.nanmax(np.nanmax(cols, axis=0) - np.nanmin(cols, axis=0)))
    if res > LOW_PRECISION_RELATIVE * spread:
        warnings.warn(
            f"{name}: {dtype.name} coordinates up to {big:.6g} have a resolution of {res:.3g} "
            f"(the points spread over {spread:.6g}): they were rounded to that before photogeom "
            "(which computes in float64) received them. Pass float64 coordinates, or reduce "
            f"them to a local origin before converting to {dtype.name}",
            PrecisionWarning,
            stacklevel=_caller_level(),
        )


def _caller_level() -> int:
    """``stacklevel`` for :func:`warnings.warn` called from the caller of this function that
    points at the first frame outside the photogeom package (the user's call)."""
    import os
    import sys

    pkg = os.path.dirname(os.path.abspath(__file__))
    frame = sys._getframe(2)
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(pkg):
        frame = frame.f_back
        level += 1
    return level


def as_points(
    values: object,
    dim: int | Sequence[int],
    name: str = "points",
    *,
    allow_single: bool = True,
    finite: bool = True,
) -> np.ndarray:
    """Return ``values`` as a float64 array of shape ``(n, dim)``.

    Parameters
    ----------
    values : array_like
        Coordinates, shape ``(n, dim)`` (or ``(dim,)`` for one point when
        ``allow_single``).
    dim : int or sequence of int
        Accepted coordinate dimension(s).
    name : str
        Name used in error messages.
    allow_single : bool
        Accept a single point of shape ``(dim,)`` and promote it to ``(1, dim)``.
    finite : bool
        Refuse NaN / infinite values. False checks the shape only, for callers that detect
        non-finite input later at no extra cost (e.g. in sums over the points).

    Raises
    ------
    InputError
        Wrong shape, NaN / infinite values (the message lists the first bad rows), masked
        entries or complex values (see :func:`as_float64`).
    """
    dims = (dim,) if isinstance(dim, int) else tuple(dim)
    if type(values) is np.ndarray and values.dtype == np.float64:
        arr = values
    else:
        arr = as_float64(values, name)
    if arr.ndim == 1 and allow_single and arr.shape[0] in dims:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] not in dims:
        want = " or ".join(f"(n, {d})" for d in dims)
        if allow_single:
            want += " (or " + " or ".join(f"({d},)" for d in dims) + " for one point)"
        hint = (
            "; one point per row: transpose the array"
            if arr.ndim == 2 and arr.shape[0] in dims
            else ""
        )
        raise InputError(
            f"{name}: expected an array of shape {want}, got shape {arr.shape}{hint}"
        )
    if finite:
        check_finite(arr, name)
    return arr


def as_points_single(
    values: object, dim: int | Sequence[int], name: str = "points", *, finite: bool = True
) -> tuple[np.ndarray, bool]:
    """``values`` as an ``(n, dim)`` float64 array and whether it was one point ``(dim,)``.

    The library's shape rule for functions of points: ``(n, dim)`` in gives ``n`` rows out
    (``(0, dim)`` gives none), one point ``(dim,)`` gives one result without the point axis.
    Pass the flag to :func:`one_or_many` on the way out.

    Parameters
    ----------
    values : array_like
        Coordinates, shape ``(n, dim)`` or ``(dim,)``.
    dim : int or sequence of int
        Accepted coordinate dimension(s).
    name : str
        Name used in error messages.
    finite : bool
        Refuse NaN / infinite values (see :func:`as_points`).

    Returns
    -------
    points : numpy.ndarray, shape (n, dim)
    single : bool
        True for one point given as ``(dim,)``.

    Raises
    ------
    InputError
        As :func:`as_points`: any other shape (a flat list of several points, a transposed
        ``(dim, n)`` array), NaN / infinite values, masked or complex entries.
    """
    arr = as_float64(values, name)
    return as_points(arr, dim, name, finite=finite), arr.ndim == 1


def one_or_many(out: np.ndarray, single: bool) -> np.ndarray:
    """``out[0]`` (the point axis dropped) when the input was one point, else ``out``."""
    return out[0] if single else out


def as_finite_scalar(value: object, name: str) -> float:
    """Return ``value`` as a finite float; :class:`InputError` naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: not a number ({value!r})") from exc
    if not np.isfinite(v):
        raise InputError(f"{name} is NaN or infinite")
    return v


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise :class:`InputError` naming the rows that hold NaN or infinite values."""
    finite = np.isfinite(arr)
    if not finite.all():
        bad = (
            np.flatnonzero(~finite.reshape(arr.shape[0], -1).all(axis=1))
            if arr.ndim > 1
            else (np.flatnonzero(~finite))
        )
        shown = ", ".join(str(int(i)) for i in bad[:10])
        more = " ..." if bad.size > 10 else ""
        raise InputError(
            f"{name}: {bad.size} row(s) contain NaN or infinite values (row index {shown}{more}); "
            "remove or fix them"
        )


#: Largest coordinate magnitude times sqrt(number of values) accepted by the estimators: sums
#: of squares and products of the coordinates (normal equations, scatter matrices) must stay
#: well inside the float64 range (1.8e308).
MAX_MAGNITUDE = 1e150


def check_finite_magnitude(arr: np.ndarray, name: str, what: str) -> None:
    """Refuse NaN / infinite values (:func:`check_finite`) and values so large that sums of
    their squares overflow float64: :class:`InputError` naming the scaling problem (one pass
    over the data: the largest magnitude, whose finiteness implies that of every value)."""
    if arr.size == 0:
        return
    # no temporary copy; the ufunc reductions directly (ndarray.max and np.max add Python-level
    # calls that cost as much as the reduction of a few points)
    big = max(float(np.maximum.reduce(arr, axis=None)), -float(np.minimum.reduce(arr, axis=None)))
    if not math.isfinite(big):
        check_finite(arr, name)
    if big * math.sqrt(arr.size) > MAX_MAGNITUDE:
        raise InputError(
            f"{what}: {name} coordinates up to {big:.3g} overflow float64 in the sums of "
            f"squares the estimate needs (limit {MAX_MAGNITUDE:.0e} / sqrt(number of values)); "
            "reduce them to a local origin or change their unit (scale them down)"
        )


def check_count(n: int, need: int, what: str, hint: str = "") -> None:
    """Raise :class:`TooFewPointsError` when ``n < need``."""
    if n < need:
        raise TooFewPointsError(what, n, need, hint)


def check_same_length(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    """Raise :class:`InputError` unless ``a`` and ``b`` have the same number of rows."""
    if a.shape[0] != b.shape[0]:
        raise InputError(
            f"{name_a} has {a.shape[0]} point(s) but {name_b} has {b.shape[0]}; "
            "they must correspond one to one"
        )


