"""Evaluation of residual grids on arrays: residual statistics and the choice of spacing.

* :func:`residual_statistics` / :func:`compare_residuals` - RMS and mean length of image
  residuals per image and for the block, before and after the correction;
* :func:`adjustment_statistics` - sigma0 and the redundancy it is computed over, of the
  first adjustment and of the re-adjustment;
* :func:`min_max_normalise`, :func:`choose_spacing`, :func:`most_frequent_spacing` - the
  grid-size sweep: per test model, accuracy (the height step) and computing time are each
  normalised to [0, 1] (min-max over the spacings tried) and the spacing closest to the
  origin (equal weights) is chosen; the block's spacing is the most frequent choice.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .grid import check_spacing


def residual_statistics(residuals) -> dict:
    """Statistics of 2D residual vectors.

    Parameters
    ----------
    residuals : array_like, shape (n, 2)
        Finite residual vectors, px.

    Returns
    -------
    dict
        ``n``, ``rms`` (``sqrt(mean |v|^2)``, the per-point RMSE), ``mean_length``
        (``mean |v|``), ``rms_x``, ``rms_y`` (px; NaN for n = 0).

    Raises
    ------
    InputError
        For another shape or NaN/infinite values.
    """
    v = np.asarray(residuals, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2:
        raise InputError(f"residuals: expected shape (n, 2), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise InputError("residuals: NaN or infinite values")
    if v.shape[0] == 0:
        nan = float("nan")
        return {"n": 0, "rms": nan, "mean_length": nan, "rms_x": nan, "rms_y": nan}
    length = np.hypot(v[:, 0], v[:, 1])
    return {
        "n": int(v.shape[0]),
        "rms": float(np.sqrt(np.mean(length**2))),
        "mean_length": float(np.mean(length)),
        "rms_x": float(np.sqrt(np.mean(v[:, 0] ** 2))),
        "rms_y": float(np.sqrt(np.mean(v[:, 1] ** 2))),
    }


def compare_residuals(before: Mapping, after: Mapping) -> dict:
    """Residual statistics per image and for the block, before and after.

    Parameters
    ----------
    before, after : mapping
        ``image id -> residuals (n, 2)`` (px), the same images and counts in both.

    Returns
    -------
    dict
        ``{"images": {id: {"before": stats, "after": stats, "reduction_rms": float,
        "reduction_mean_length": float}}, "block": {...the same over all residuals...}}``;
        a reduction is ``1 - after / before``.
    """
    if set(before) != set(after):
        diff = set(before) ^ set(after)
        raise InputError(
            f"before and after differ in images: {', '.join(map(str, sorted(diff, key=str)[:10]))}"
        )
    images = {}
    all_b, all_a = [], []
    for key in before:
        b = np.asarray(before[key], dtype=float)
        a = np.asarray(after[key], dtype=float)
        if b.shape != a.shape:
            raise InputError(f"image {key}: before {b.shape} and after {a.shape} differ in shape")
        images[key] = _pair(b, a)
        all_b.append(b.reshape(-1, 2))
        all_a.append(a.reshape(-1, 2))
    block = _pair(
        np.concatenate(all_b) if all_b else np.zeros((0, 2)),
        np.concatenate(all_a) if all_a else np.zeros((0, 2)),
    )
    return {"images": images, "block": block}


def _pair(b: np.ndarray, a: np.ndarray) -> dict:
    sb, sa = residual_statistics(b), residual_statistics(a)

    def red(k):
        return 1.0 - sa[k] / sb[k] if sb[k] > 0 else float("nan")

    return {
        "before": sb,
        "after": sa,
        "reduction_rms": red("rms"),
        "reduction_mean_length": red("mean_length"),
    }


def adjustment_statistics(fit) -> dict:
    """sigma0 of an adjustment and the redundancy it is computed over.

    Parameters
    ----------
    fit : BundleFit
        A bundle adjustment or a re-adjustment with grids (:func:`readjust`,
        ``GridAdjustment.fit``).

    Returns
    -------
    dict
        ``sigma0`` (a-posteriori standard deviation of unit weight, ``sqrt(v'Pv / r)``,
        unitless), ``redundancy`` (``r``, unitless: the effective redundancy of the chain of
        first adjustment, grids and re-adjustment when the fit has one, else observations
        minus unknowns), ``effective`` (whether ``redundancy`` is the chain's), and
        ``observations`` and ``unknowns`` (scalar counts of the adjustment).
    """
    eff = getattr(fit, "effective_redundancy", None)
    return {
        "sigma0": float(fit.sigma0),
        "redundancy": float(eff["value"]) if eff is not None else float(fit.redundancy),
        "effective": eff is not None,
        "observations": int(fit.n_observations),
        "unknowns": int(fit.n_unknowns),
    }


def min_max_normalise(values, axis: int = -1) -> np.ndarray:
    """``(x - min) / (max - min)`` along ``axis``; 0 where all values are equal.

    Parameters
    ----------
    values : array_like
        Finite values.
    axis : int, default -1
        Axis along which to normalise.

    Returns
    -------
    numpy.ndarray
        In [0, 1], the shape of ``values``.

    Raises
    ------
    InputError
        For NaN or infinite values.
    """
    x = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(x)):
        raise InputError("min-max normalisation: NaN or infinite values")
    lo = x.min(axis=axis, keepdims=True)
    span = x.max(axis=axis, keepdims=True) - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(span > 0, (x - lo) / np.where(span > 0, span, 1.0), 0.0)


#: Normalised distances (and steps) closer than this are a tie in :func:`choose_spacing`.
TIE_TOLERANCE = 1e-12


#: How an error names the values of a non-numeric array (``dtype.kind``).
_KINDS = {"U": "text", "S": "text", "b": "booleans", "c": "complex numbers", "O": "objects"}


def _real_array(values, name: str) -> np.ndarray:
    """``values`` as a float array; text, booleans and other non-numbers refused by
    ``name`` (``numpy.asarray(..., dtype=float)`` converts ``"1.5"`` and ``True``)."""
    a = np.asarray(values)
    if a.dtype.kind not in "iuf":
        what = _KINDS.get(a.dtype.kind, f"{a.dtype.name} values")
        raise InputError(
            f"choose_spacing: {name} must be numbers, not {what}: {a.ravel()[:4].tolist()!r}"
        )
    return a.astype(float)


def choose_spacing(spacings: Sequence[float], step, time) -> dict:
    """The closest-to-origin spacing of each test model.

    Ties of the distance are broken by the smaller normalised step (the better accuracy),
    then by the smaller spacing, whatever the order of ``spacings``.

    Parameters
    ----------
    spacings : sequence of float, shape (s,)
        Grid spacings tried (px).
    step : array_like, shape (s,) or (models, s)
        Accuracy per spacing (the height step, GSD; smaller is better).
    time : array_like, the shape of ``step``
        Computing time per spacing (s).

    Returns
    -------
    dict
        ``spacing`` (models,), ``index`` (models,), ``step_norm``, ``time_norm`` and
        ``distance`` (models, s): ``sqrt(step_norm^2 + time_norm^2)``. One model: the
        arrays keep a leading axis of length 1.

    Raises
    ------
    InputError
        Fewer than two spacings, a spacing that is not a positive number of pixels
        (:func:`~photogeom.calibration.grid.check_spacing`), steps or times that are not
        numbers (text, booleans), NaN or infinite, or of other shapes.
    """
    if isinstance(spacings, (str, bytes)) or np.ndim(spacings) != 1:
        raise InputError(
            f"choose_spacing: spacings must be a list of numbers of pixels, not {spacings!r}"
        )
    g = np.array(
        [check_spacing(x, f"choose_spacing: spacings[{i}]") for i, x in enumerate(spacings)]
    )
    s = np.atleast_2d(_real_array(step, "step (GSD)"))
    t = np.atleast_2d(_real_array(time, "time (s)"))
    if g.size < 2:
        raise InputError("choose_spacing: give at least two spacings")
    if s.shape != t.shape or s.shape[1] != g.size:
        raise InputError(
            f"choose_spacing: step {s.shape} and time {t.shape} must both be "
            f"(models, {g.size}) for {g.size} spacings"
        )
    sn = min_max_normalise(s, axis=1)
    tn = min_max_normalise(t, axis=1)
    d = np.hypot(sn, tn)
    # ties (equal distances: with two spacings the normal case, both at distance 1) go to
    # the better accuracy, then to the smaller spacing: the choice does not depend on the
    # order the spacings are listed in
    tied = d <= d.min(axis=1, keepdims=True) + TIE_TOLERANCE
    key = np.where(tied, sn, np.inf)
    best = tied & (key <= key.min(axis=1, keepdims=True) + TIE_TOLERANCE)
    idx = np.argmin(np.where(best, g[None, :], np.inf), axis=1)
    return {"spacing": g[idx], "index": idx, "step_norm": sn, "time_norm": tn, "distance": d}


def most_frequent_spacing(chosen, distance=None) -> float:
    """The most frequent spacing among the models' choices.

    Ties are broken by the smaller sum of the models' normalised distances at the tied
    spacings when the choices come from :func:`choose_spacing` (pass its result dict as
    ``chosen``), else by the smaller spacing.

    Parameters
    ----------
    chosen : array_like or Mapping
        The spacing (px) chosen by each model, or the result dict of :func:`choose_spacing`
        (then ``distance`` is taken from it).
    distance : array_like, shape (models, s), optional
        Ignored unless ``chosen`` is a result dict (which supplies it).

    Returns
    -------
    float
        Spacing, px.

    Raises
    ------
    InputError
        When no choices are given.
    """
    if isinstance(chosen, Mapping):
        res = chosen
        chosen = res["spacing"]
        distance = res["distance"]
        spacings_idx = res["index"]
    else:
        spacings_idx = None
    c = np.asarray(chosen, dtype=float).ravel()
    if c.size == 0:
        raise InputError("most_frequent_spacing: no choices given")
    values, counts = np.unique(c, return_counts=True)
    top = values[counts == counts.max()]
    if top.size == 1 or distance is None or spacings_idx is None:
        return float(top.min())
    d = np.asarray(distance, dtype=float)
    col_of = {float(c[m]): int(spacings_idx[m]) for m in range(c.size)}
    sums = [d[:, col_of[float(v)]].sum() for v in top]
    return float(top[int(np.argmin(sums))])
