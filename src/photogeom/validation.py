"""Checks of array inputs shared by every layer (shape, finiteness, counts)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .errors import InputError, TooFewPointsError


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
        Wrong shape, or NaN / infinite values (the message lists the first bad rows).
    """
    dims = (dim,) if isinstance(dim, int) else tuple(dim)
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot be read as numbers ({exc})") from exc
    if arr.ndim == 1 and allow_single and arr.shape[0] in dims:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] not in dims:
        want = " or ".join(f"(n, {d})" for d in dims)
        raise InputError(f"{name}: expected an array of shape {want}, got shape {arr.shape}")
    if finite:
        check_finite(arr, name)
    return arr


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


def as_weights(weights: object, n: int, name: str = "weights") -> np.ndarray | None:
    """Return per-point positive weights of shape ``(n,)`` or ``None``."""
    if weights is None:
        return None
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape[0] != n:
        raise InputError(f"{name}: {w.shape[0]} value(s) for {n} point(s)")
    check_finite(w, name)
    if np.any(w <= 0):
        raise InputError(f"{name}: every weight must be > 0 (found {w.min():g})")
    return w
