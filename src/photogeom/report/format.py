"""Number formatting and table rows of a :class:`~photogeom.adjust.Fit`, shared by the
console and HTML reports (so both show the same digits)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..adjust.fit import DEFAULT_ALPHA

#: Significance level of the data-snooping tests shown in reports for a fit that records none.
SNOOPING_ALPHA = DEFAULT_ALPHA


def snooping_alpha(fit) -> float:
    """Significance level of the tests shown for ``fit``: :attr:`photogeom.adjust.Fit.test_level`
    (the level its estimator recorded in ``extras["alpha"]``, else :data:`SNOOPING_ALPHA`).

    Parameters
    ----------
    fit : Fit
        Any fit (an object without ``test_level``: :data:`SNOOPING_ALPHA`).

    Returns
    -------
    float
        The level, in (0, 1) (unitless).
    """
    return float(getattr(fit, "test_level", SNOOPING_ALPHA))


RESIDUAL_CONVENTION = "v = computed - observed"


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def fmt_std(s: float) -> str:
    """A standard deviation with two significant digits ("-" when undefined)."""
    if not _finite(s):
        return "-"
    s = float(s)
    if s == 0.0:
        return "0"
    # two significant digits, without an exponent in the plain range (204 -> "200")
    return f"{float(f'{s:.2g}'):g}" if 1e-4 <= abs(s) < 1e6 else f"{s:.2e}"


def fmt_value(v: float, std: float | None = None) -> str:
    """A value with two digits beyond the leading digit of its standard deviation.

    Fixed-point while that needs at most 15 decimals (std >= 1e-13). A smaller standard
    deviation (exact or nearly exact data: the std is rounding noise) gives ``"0"`` for a
    value within one std of zero, else the value with the same digits in ``g`` notation
    (at most ten significant digits, trailing zeros dropped): ``9.9e-17 +- 1e-16`` is
    ``"0"``, ``1.23456e-20 +- 4e-22`` is ``"1.2346e-20"``, ``100 +- 9e-15`` is ``"100"``.
    Without a usable standard deviation: ten significant digits. A value that rounds to
    zero is shown without a sign ("0.0000", never "-0.0000").

    Parameters
    ----------
    v : float
        The value, any unit.
    std : float, optional
        Its standard deviation, unit of ``v``.

    Returns
    -------
    str
    """
    if not _finite(v):
        return "nan" if v is not None else "-"
    v = float(v)
    text = f"{v:.10g}"
    if std is not None and _finite(std) and float(std) > 0:
        s = float(std)
        decimals = 2 - math.floor(math.log10(s))
        if 0 <= decimals <= 15:
            text = f"{v:.{decimals}f}"
        elif decimals > 15:
            if abs(v) <= s:
                return "0"  # zero within a std at the level of rounding errors
            digits = math.floor(math.log10(abs(v))) + 1 + decimals
            text = f"{v:.{min(10, max(1, digits))}g}"
        else:
            text = f"{v:.{max(3, math.floor(math.log10(abs(v) + 1e-300)) + 1 + decimals)}g}"
    if text.startswith("-") and not text.strip("-0."):
        text = text[1:]  # -4e-9 +- 2.5e-5 is "0.0000000", -0.0 is "0"
    return text


def residual_decimals(values: np.ndarray) -> int:
    """Decimals that show residuals of this size with about three significant digits."""
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return 3
    rms = float(np.sqrt(np.mean(v * v)))
    return int(min(10, max(0, 2 - math.floor(math.log10(rms)))))


def fmt_fixed(x: float, decimals: int) -> str:
    """Fixed-point number, "-" when undefined."""
    if not _finite(x):
        return "-"
    text = f"{float(x):.{decimals}f}"
    if text.startswith("-") and not text.strip("-0."):
        text = text[1:]  # no "-0.000"
    return text


def fmt_stat(x: float, digits: int = 4) -> str:
    """A statistic (sigma0, RMSE) with ``digits`` significant digits."""
    if not _finite(x):
        return "-"
    return f"{float(x):.{digits}g}"


def fmt_sigma0(stats: dict) -> str:
    """sigma0 of :func:`photogeom.calibration.evaluate.adjustment_statistics` (unitless),
    four decimals."""
    return f"{stats['sigma0']:.4f}"


def fmt_redundancy(stats: dict) -> str:
    """The redundancy of :func:`photogeom.calibration.evaluate.adjustment_statistics`: a
    count, or the chain's effective redundancy (a real number, marked "(effective)")."""
    if stats["effective"]:
        return f"{stats['redundancy']:.1f} (effective)"
    return f"{stats['redundancy']:.0f}"


def fmt_duration(seconds: float) -> str:
    """A run time with three significant digits and never an exponent: milliseconds below
    one second (``"14.6 ms"``), else seconds (``"2.85 s"``, ``"1500 s"``); "-" when
    undefined.

    Parameters
    ----------
    seconds : float
        The duration (s).

    Returns
    -------
    str
    """
    if not _finite(seconds) or float(seconds) < 0:
        return "-"
    value, unit = float(seconds), "s"
    if value < 0.9995:  # what rounds to 1000 ms is shown as 1.00 s
        value, unit = value * 1e3, "ms"
    if value == 0.0:
        return f"0 {unit}"
    # decimals from the value rounded to three digits: 9.997 s is "10.0 s", not "10.00 s"
    decimals = max(0, 2 - math.floor(math.log10(float(f"{value:.3g}"))))
    return f"{value:.{decimals}f} {unit}"


def unit_suffix(unit: str) -> str:
    """`` [unit]`` or an empty string."""
    return f" [{unit}]" if unit else ""


def model_name(fit) -> str:
    """Readable name of the fitted model."""
    m = getattr(fit, "model", None)
    name = getattr(m, "name", "") or type(m).__name__
    return str(name)


@dataclass(frozen=True)
class ResidualTable:
    """Residual rows of control or check points, ready for display.

    ``columns`` are headings; ``rows`` are strings; ``flags`` marks cells whose snooping
    statistic exceeds its critical value (same shape as rows); ``n_points`` counts the
    points of the fit, also when ``rows`` shows only the worst of them.
    """

    columns: list[str]
    rows: list[list[str]]
    flags: list[list[bool]]
    footer: list[str]
    n_points: int = -1

    def __post_init__(self) -> None:
        if self.n_points < 0:
            object.__setattr__(self, "n_points", len(self.rows))


def parameter_rows(fit, angle_unit: str = "deg") -> list[tuple[str, str, str, str]]:
    """``(name, value, std, unit)`` strings, angles in ``angle_unit``. Where the a-posteriori
    standard deviation is undefined (redundancy 0) the a-priori one is shown, marked."""
    rows = []
    for name, value, std, unit, a_priori in fit.shown_parameter_table(angle_unit):
        shown = fmt_std(std) + (" (a priori)" if a_priori else "")
        rows.append((name, fmt_value(value, std), shown, unit or ""))
    return rows


def statistics_rows(fit) -> list[tuple[str, str]]:
    """``(label, value)`` strings of the adjustment statistics."""
    unit = getattr(fit, "residual_unit", "") or ""
    u = f" {unit}" if unit else ""
    n_par = len(fit.parameter_names)
    rows = [
        ("method", str(fit.method)),
        ("observations / unknowns", f"{fit.n_observations} / {n_par}"),
        ("redundancy r", str(fit.redundancy)),
        ("sigma0 a priori", fmt_stat(fit.sigma0_prior)),
    ]
    if _finite(fit.sigma0):
        rows.append(("sigma0 a posteriori", fmt_stat(fit.sigma0)))
    else:
        rows.append(("sigma0 a posteriori", "undefined (redundancy 0)"))
    n_pts = int(np.asarray(fit.residuals).shape[0]) if fit.residuals is not None else 0
    if n_pts:
        labels = axis_labels(fit)
        rows.append((f"RMSE per point ({n_pts} control)", fmt_stat(fit.rmse) + u))
        rows.append(
            (
                "RMS per axis",
                ", ".join(f"{lab} {fmt_stat(x)}" for lab, x in zip(labels, fit.rms_per_axis)) + u,
            )
        )
    if fit.check_residuals is not None and np.asarray(fit.check_residuals).size:
        labels = axis_labels(fit)
        n_chk = int(np.asarray(fit.check_residuals).shape[0])
        rows.append((f"check RMSE per point ({n_chk} check)", fmt_stat(fit.check_rmse) + u))
        rows.append(
            (
                "check RMS per axis",
                ", ".join(f"{lab} {fmt_stat(x)}" for lab, x in zip(labels, fit.check_rms_per_axis))
                + u,
            )
        )
    from ..adjust.fit import crs_rows

    rows.extend(crs_rows(fit))
    if fit.iterations:
        rows.append(
            (
                "iterations",
                f"{fit.iterations} ({'converged' if fit.converged else 'NOT converged'})",
            )
        )
    elif not fit.converged:
        rows.append(("convergence", "NOT converged"))
    if fit.message:
        rows.append(("message", str(fit.message)))
    if getattr(fit, "elapsed", 0.0):
        rows.append(("time", fmt_duration(fit.elapsed)))
    return rows


def axis_labels(fit) -> tuple[str, ...]:
    """Names of the residual columns (``v0, v1, ...`` if the fit has none)."""
    d = int(np.asarray(fit.residuals).shape[1]) if np.asarray(fit.residuals).ndim == 2 else 1
    labels = tuple(getattr(fit, "residual_labels", ()) or ())
    return labels if len(labels) == d else tuple(f"v{j}" for j in range(d))


def _snooping(fit, sigma: str):
    if fit.normalized_residuals is None or fit.redundancy <= (1 if sigma == "posterior" else 0):
        return None
    if sigma == "posterior" and not _finite(fit.sigma0):
        return None
    try:
        return fit.snooping(alpha=snooping_alpha(fit), sigma=sigma)
    except Exception:  # a statistic that cannot be formed is simply not shown
        return None


def _poorly_controlled(test, ids, labels, shape) -> str | None:
    """Footer naming the components whose redundancy number is below
    ``POORLY_CONTROLLED``: a gross error there hardly changes the residuals, so passing the
    test says little about it."""
    from ..adjust.snooping import POORLY_CONTROLLED, POWER

    if test is None or test.redundancy_numbers is None or test.mdb is None:
        return None
    poor = np.asarray(test.poorly_controlled, dtype=bool).reshape(shape)
    if not poor.any():
        return None
    red = np.asarray(test.redundancy_numbers, dtype=float).reshape(shape)
    mdb = np.asarray(test.mdb, dtype=float).reshape(shape)
    rows, cols = np.nonzero(poor)
    shown = [
        f"{ids[k]} {labels[j]} (r {red[k, j]:.2g}, "
        + (f"{mdb[k, j]:.0f} sigma)" if np.isfinite(mdb[k, j]) else "undetectable)")
        for k, j in zip(rows[:12], cols[:12])
    ]
    more = f" and {rows.size - 12} more" if rows.size > 12 else ""
    return (
        f"poorly controlled (redundancy number r below {POORLY_CONTROLLED:g}; a gross error "
        "there is largely absorbed by the parameters and may pass the tests; minimal "
        f"detectable error at alpha = {test.alpha:g}, power {POWER:.0%}, in standard deviations "
        f"of the observation): {', '.join(shown)}{more}"
    )


def residual_table(
    fit, *, check: bool = False, max_rows: int | None = None
) -> ResidualTable | None:
    """Rows of the control (or check) residuals with |v| and, for control points, the
    w-test (a-priori sigma0) and tau-test (a-posteriori sigma0) statistics per component.

    Parameters
    ----------
    fit : Fit
        The estimate.
    check : bool, default False
        The check points instead of the control points.
    max_rows : int, optional
        Rows at most: with more points, the ``max_rows`` with the largest test statistic
        (|w|, else |tau|; |v| for check points and fits without tests) are kept, largest
        first, and a footer line says so. None: every point, in the fit's order.

    Returns
    -------
    ResidualTable or None
        None when the fit has no such residuals.
    """
    res = fit.check_residuals if check else fit.residuals
    if res is None:
        return None
    res = np.asarray(res, dtype=float)
    if res.ndim == 1:
        res = res[:, None]
    if res.shape[0] == 0:
        return None
    ids = fit.check_ids if check else fit.ids
    if ids is None:
        ids = tuple(str(k) for k in range(1, res.shape[0] + 1))
    labels = axis_labels(fit)
    unit = getattr(fit, "residual_unit", "") or ""
    dec = residual_decimals(np.concatenate([np.asarray(fit.residuals, float).ravel(), res.ravel()]))
    # the unit in each residual heading (the w and tau statistics are unitless)
    cols = ["id", *(f"v_{lab}{unit_suffix(unit)}" for lab in labels)]
    norm = np.sqrt(np.sum(res * res, axis=1))
    if res.shape[1] > 1:
        cols.append(f"|v|{unit_suffix(unit)}")
    cells = [
        [str(pid), *(fmt_fixed(x, dec) for x in row)]
        + ([fmt_fixed(nv, dec)] if res.shape[1] > 1 else [])
        for pid, row, nv in zip(ids, res, norm)
    ]
    flags = [[False] * len(c) for c in cells]
    footer = [f"{RESIDUAL_CONVENTION}" + unit_suffix(unit)]
    if not check:
        w = _snooping(fit, "prior")
        tau = _snooping(fit, "posterior")
        for test, name, label in (
            (w, "w", "w-test (Baarda, sigma0 a priori)"),
            (tau, "tau", "tau-test (Pope, sigma0 a posteriori)"),
        ):
            if test is None:
                continue
            stat = np.asarray(test.statistic, dtype=float).reshape(res.shape)
            flagged = np.asarray(test.flagged, dtype=bool).reshape(res.shape)
            cols.extend(f"{name}_{lab}" for lab in labels)
            for k in range(res.shape[0]):
                cells[k].extend(fmt_fixed(x, 2) for x in stat[k])
                flags[k].extend(bool(f) for f in flagged[k])
            n_flag = int(flagged.sum())
            n_untested = int(np.sum(~np.isfinite(stat)))
            verdict = f"{n_flag} component(s) flagged" if n_flag else "no component flagged"
            if n_untested == stat.size:
                verdict = "no component could be tested (shown as -)"
            elif n_untested:
                verdict += f"; {n_untested} component(s) could not be tested (shown as -)"
            footer.append(
                f"{label}: critical value {test.critical_value:.3f} at alpha = {test.alpha:g}; "
                f"{verdict}"
            )
        poor = _poorly_controlled(w if w is not None else tau, ids, labels, res.shape)
        if poor:
            footer.append(poor)
        if w is not None and _finite(fit.sigma0) and fit.sigma0_prior > 0:
            ratio = fit.sigma0 / fit.sigma0_prior
            if ratio < 0.1 or ratio > 10:
                footer.append(
                    f"sigma0 a posteriori / a priori = {ratio:.3g}: the a-priori accuracy does not "
                    "match the data, so read the tau-test (or give realistic weights/sigmas)"
                )
    n_points = len(cells)
    if max_rows is not None and n_points > max_rows:
        test = None if check else (w if w is not None else tau)
        if test is not None:
            key = np.abs(np.asarray(test.statistic, dtype=float).reshape(res.shape))
            what = "|w|" if test is w else "|tau|"
        else:
            key, what = np.abs(res), "|v|"
        with np.errstate(invalid="ignore"):
            key = np.max(np.where(np.isfinite(key), key, -np.inf), axis=1)
        keep = np.argsort(-key, kind="stable")[: int(max_rows)]
        cells = [cells[k] for k in keep.tolist()]
        flags = [flags[k] for k in keep.tolist()]
        kind = "check" if check else "control"
        footer.insert(
            0,
            f"the {len(keep)} of {n_points} {kind} points with the largest {what} (largest "
            "first); the fit's JSON (Fit.to_dict, --json) holds all",
        )
    return ResidualTable(cols, cells, flags, footer, n_points)


def as_text_table(columns: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Plain-text table with right-aligned columns (first column left-aligned)."""
    widths = [len(c) for c in columns]
    for r in rows:
        for j, c in enumerate(r):
            widths[j] = max(widths[j], len(str(c)))

    def line(r):
        return "  ".join(
            (str(c).ljust(widths[j]) if j == 0 else str(c).rjust(widths[j]))
            for j, c in enumerate(r)
        )

    return "\n".join([line(columns), line(["-" * w for w in widths]), *(line(r) for r in rows)])


def textbook_rows(fit, angle_unit: str = "deg") -> list[tuple[str, str, str, str]]:
    """``(name, value, std, unit)`` of the textbook form of the fitted model, angles in
    ``angle_unit``.

    Uses ``fit.extras["textbook"]`` (name -> (value, std), radians) when the estimator
    propagated the covariance there, else ``fit.model.textbook()`` without standard
    deviations. Empty when there is no textbook form distinct from the parameters.
    """
    from ..units import display_angle, from_radians

    extras = getattr(fit, "extras", {}) or {}
    model = getattr(fit, "model", None)
    values: dict = {}
    units: dict = dict(extras.get("textbook_units", {}) or {})
    tb = extras.get("textbook")
    if isinstance(tb, dict) and tb:
        for name, val in tb.items():
            v, sd = val if isinstance(val, (tuple, list)) and len(val) == 2 else (val, None)
            values[name] = (v, sd)
    else:
        fn = getattr(model, "textbook", None)
        if not callable(fn):
            return []
        try:
            values = {k: (v, None) for k, v in fn().items()}
            units = units or dict(getattr(model, "textbook_units", {}) or {})
        except Exception:  # a model without a textbook form for these parameters
            return []
    if set(values) <= set(fit.parameter_names):
        return []  # the textbook form is the parametric form (e.g. projective)
    rows = []
    for name, (value, sd) in values.items():
        arr = np.asarray(value, dtype=float)
        if arr.ndim:
            continue
        v = float(arr)
        s = float(sd) if sd is not None and np.ndim(sd) == 0 else float("nan")
        unit = units.get(name, "")
        if unit == "rad":
            v, s, unit = (
                display_angle(from_radians(v, angle_unit), angle_unit, str(name)),
                float(from_radians(s, angle_unit)),
                angle_unit,
            )
        rows.append((str(name), fmt_value(v, s), fmt_std(s), unit))
    return rows


def helmert_rows(fit, convention: str = "position_vector") -> list[tuple[str, str, str, str]]:
    """``(name, value, std, unit)`` of the geodetic (EPSG) Helmert form of a 3D similarity:
    shifts, rotations in arc-seconds, scale difference in ppm; empty for other fits."""
    extras = getattr(fit, "extras", {}) or {}
    h = extras.get("helmert") or {}
    values = h.get(convention)
    if not values:
        return []
    units = h.get("units", {})
    rows = []
    for name, (v, sd) in values.items():
        rows.append((str(name), fmt_value(v, sd), fmt_std(sd), units.get(name, "")))
    return rows


#: Title of the Helmert table in the reports.
HELMERT_TITLE = "Helmert form (EPSG, position vector convention)"
