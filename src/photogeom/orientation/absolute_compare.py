"""The evaluation protocol of the absolute orientation methods on one data set.

For every method: the seven parameters, their differences to the converged Gauss-Markov
solution, the orthogonality defect of R and the time per solve (median of many repeats in
this process, parameters only: ``statistics=False``).
"""

from __future__ import annotations

import math
import statistics as _stats
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, PhotogeomError
from ..units import display_angle, from_radians
from .absolute import METHODS, AbsoluteOrientationFit, absolute_orientation, normalize_method
from .absolute_stats import transpose_angles

PARAMETERS = ("tx", "ty", "tz", "scale", "omega", "phi", "kappa")


@dataclass(frozen=True)
class MethodRow:
    """One method's line of the comparison.

    Attributes
    ----------
    method : str
    fit : AbsoluteOrientationFit or None
        None when the method failed (``error`` says why).
    values : dict
        ``tx, ty, tz`` (target units), ``scale``, ``omega, phi, kappa`` (``unit``,
        ``convention`` of the comparison).
    differences : dict
        ``values`` minus the reference method's (angles wrapped to +-half a turn).
    orthogonality_defect : float
    time_per_solve : float
        Median seconds per call (``statistics=False``).
    repeats : int
    error : str
    """

    method: str
    fit: AbsoluteOrientationFit | None
    values: dict = field(default_factory=dict)
    differences: dict = field(default_factory=dict)
    orthogonality_defect: float = math.nan
    time_per_solve: float = math.nan
    repeats: int = 0
    error: str = ""


@dataclass(frozen=True)
class MethodComparison:
    """Result of :func:`compare_absolute_methods`.

    Attributes
    ----------
    rows : tuple of MethodRow
        One per method compared, in the order asked.
    reference : str
        Method the differences refer to.
    convention : str
        Angle convention of the values (``"transposed"`` or ``"direct"``).
    unit : str
        Angle unit of the values.
    length_unit : str, default "m"
        Unit of the target coordinates (labels).
    """

    rows: tuple[MethodRow, ...]
    reference: str
    convention: str
    unit: str
    length_unit: str = "m"

    def row(self, method: str) -> MethodRow:
        """The row of ``method``.

        Parameters
        ----------
        method : str
            Method name or alias (normalised as in :func:`absolute_orientation`).

        Returns
        -------
        MethodRow

        Raises
        ------
        InputError
            For an unknown method name, or a known method that was not compared.
        """
        method = normalize_method(method)
        for r in self.rows:
            if r.method == method:
                return r
        raise InputError(
            f"method {method!r} was not compared; the rows are "
            f"{', '.join(r.method for r in self.rows)}"
        )

    def columns(self) -> list[str]:
        """Column headings of :meth:`table_rows` (units included).

        Returns
        -------
        list of str
            13 headings.
        """
        u, L = self.unit, self.length_unit
        return [
            "method", f"tx [{L}]", f"ty [{L}]", f"tz [{L}]", "scale",
            f"omega [{u}]", f"phi [{u}]", f"kappa [{u}]",
            f"max |d shift| [{L}]", "|d scale|", f"max |d angle| [{u}]",
            "orthogonality defect", "time per solve [us]",
        ]

    def table_rows(self) -> list[list]:
        """One list per method (None for values of a failed method).

        Returns
        -------
        list of list
            Rows of the 13 :meth:`columns`: shifts in :attr:`length_unit`, angles in
            :attr:`unit`, time per solve in microseconds.
        """
        out = []
        for r in self.rows:
            if r.fit is None:
                out.append([r.method] + [None] * 12)
                continue
            v, d = r.values, r.differences
            out.append([
                r.method, v["tx"], v["ty"], v["tz"], v["scale"], v["omega"], v["phi"],
                v["kappa"],
                max(abs(d["tx"]), abs(d["ty"]), abs(d["tz"])), abs(d["scale"]),
                max(abs(d["omega"]), abs(d["phi"]), abs(d["kappa"])),
                r.orthogonality_defect, r.time_per_solve * 1e6,
            ])
        return out

    def reference_std(self) -> dict:
        """Standard deviations of the reference method's parameters, in the units and angle
        convention of the table.

        Shifts in :attr:`length_unit`, the scale unitless, the angles in :attr:`unit` of
        :attr:`convention` (the direct convention's propagated from the transposed angles'
        covariance with :func:`~photogeom.orientation.absolute_stats.transpose_angles`).

        Returns
        -------
        dict
            ``tx, ty, tz, scale, omega, phi, kappa``; NaN each where undefined (the reference
            failed, or has no redundancy); empty when the reference failed.
        """
        ref = next((r for r in self.rows if r.method == self.reference), None)
        if ref is None or ref.fit is None:
            return {}
        fit = ref.fit
        names = list(fit.parameter_names)
        cov = np.asarray(getattr(fit, "covariance", None), dtype=float)
        if cov.shape != (len(names), len(names)):
            return {name: math.nan for name in PARAMETERS}
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        sd[~np.isfinite(np.diag(cov))] = np.nan
        out = {name: float(sd[names.index(name)]) for name in ("tx", "ty", "tz", "scale")}
        idx = [names.index(a) for a in ("omega", "phi", "kappa")]
        c_ang = cov[np.ix_(idx, idx)]
        if self.convention == "direct" and not fit.model.check:
            c_ang = np.full((3, 3), np.nan)  # raw closed form: the direct reading differs
        elif self.convention == "direct":
            _, jac = transpose_angles(*(float(fit.params[a]) for a in ("omega", "phi", "kappa")))
            c_ang = jac @ c_ang @ jac.T  # NaN at gimbal lock: the rule without a std
        with np.errstate(invalid="ignore"):
            s_ang = np.sqrt(np.clip(np.diag(c_ang), 0.0, None))
        s_ang[~np.isfinite(np.diag(c_ang))] = np.nan
        for a, v in zip(("omega", "phi", "kappa"), s_ang, strict=True):
            out[a] = float(from_radians(float(v), self.unit))
        return out

    def display_rows(self) -> list[list[str]]:
        """:meth:`table_rows` as text, with the digits the command line and the HTML
        report both show.

        Parameters have the digits of the parameter tables: two beyond the leading digit of
        the reference method's standard deviation (:meth:`reference_std`,
        :func:`photogeom.report.format.fmt_value`; Kraus' scale 8071.844 for a std of 0.30,
        not 8071.8438023223); without one, shifts and angles to 6 decimals and the scale
        to 10. The differences and the orthogonality defect have 3 significant digits
        (exponent form), an exact zero is ``0`` (the reference's differences to itself);
        the time to 0.1 us; "-" for the values of a failed method.

        Returns
        -------
        list of list of str
            Rows of the 13 :meth:`columns`.
        """
        from ..report.format import fmt_value

        def fmt(v, spec: str) -> str:
            if v is None or not math.isfinite(v):
                return "-"
            if spec.endswith("e") and v == 0.0:
                return "0"
            return format(float(v), spec)

        std = self.reference_std()

        def value(v, name: str, spec: str) -> str:
            s = std.get(name, math.nan)
            if v is None or not math.isfinite(v) or not (math.isfinite(s) and s > 0):
                return fmt(v, spec)
            return fmt_value(v, s)

        specs = [".2e"] * 4 + [".1f"]
        out = []
        for r in self.table_rows():
            params = [
                value(v, name, ".10f" if name == "scale" else ".6f")
                for v, name in zip(r[1:8], PARAMETERS, strict=True)
            ]
            out.append([r[0], *params, *(fmt(v, sp) for v, sp in zip(r[8:], specs, strict=True))])
        return out

    def to_text(self) -> str:
        """Plain-text table (differences are to the reference method), with the digits of
        :meth:`display_rows` (those of ``orient absolute --compare`` and the report).

        Returns
        -------
        str
        """
        head = (
            f"{'method':<16}{'scale':>16}{'omega':>12}{'phi':>12}{'kappa':>12}"
            f"{'|d shift|':>11}{'|d scale|':>11}{'|d angle|':>11}{'defect':>10}{'us/solve':>10}"
        )
        lines = [
            f"methods compared with the converged {self.reference} solution; angles in "
            f"{self.unit} ({self.convention} convention), shifts in {self.length_unit}",
            head,
        ]
        cells = {row[0]: row for row in self.display_rows()}
        for r in self.rows:
            if r.fit is None:
                lines.append(f"{r.method:<16}  failed: {r.error}")
                continue
            c = cells[r.method]
            lines.append(
                f"{r.method:<16}{c[4]:>16}{c[5]:>12}{c[6]:>12}{c[7]:>12}"
                f"{c[8]:>11}{c[9]:>11}{c[10]:>11}{c[11]:>10}{c[12]:>10}"
            )
        ref = self.row(self.reference)
        if ref.fit is not None:
            c = cells[ref.method]
            lines.append(f"{self.reference} shift: ({c[1]}, {c[2]}, {c[3]}) {self.length_unit}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready form.

        Returns
        -------
        dict
            ``reference``, ``convention``, ``angle_unit`` and ``methods``: per method its
            ``parameters``, ``differences_to_reference``, ``orthogonality_defect``,
            ``time_per_solve_s`` (None when not measured), ``repeats`` and ``error``.
        """
        return {
            "reference": self.reference,
            "convention": self.convention,
            "angle_unit": self.unit,
            "methods": [
                {
                    "method": r.method,
                    "error": r.error or None,
                    "parameters": r.values,
                    "differences_to_reference": r.differences,
                    "orthogonality_defect": (
                        r.orthogonality_defect if math.isfinite(r.orthogonality_defect) else None
                    ),
                    "time_per_solve_s": (
                        r.time_per_solve if math.isfinite(r.time_per_solve) else None
                    ),
                    "repeats": r.repeats,
                }
                for r in self.rows
            ],
        }


def _values(fit: AbsoluteOrientationFit, convention: str, unit: str) -> dict:
    w, p, k = fit.angles(convention, "rad")
    t = fit.translation
    return {
        "tx": float(t[0]),
        "ty": float(t[1]),
        "tz": float(t[2]),
        "scale": fit.scale,
        # printed values: one rule for every printed angle (units.display_angle)
        "omega": display_angle(from_radians(w, unit), unit, "omega"),
        "phi": display_angle(from_radians(p, unit), unit, "phi"),
        "kappa": display_angle(from_radians(k, unit), unit, "kappa"),
    }


def _time_per_solve(call, min_time: float, max_repeats: int) -> tuple[float, int]:
    call()  # warm-up
    times = []
    start = time.perf_counter()
    while len(times) < max_repeats and (
        len(times) < 5 or time.perf_counter() - start < min_time
    ):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return float(_stats.median(times)), len(times)


def compare_absolute_methods(
    source,
    target,
    methods: Sequence[str] = METHODS,
    *,
    reference: str = "gauss-markov",
    convention: str = "transposed",
    angle_unit: str = "deg",
    min_time: float = 0.05,
    max_repeats: int = 2000,
    timing: bool = True,
    length_unit: str = "m",
    **options,
) -> MethodComparison:
    """Run every method on one data set and compare it with the reference solution.

    Parameters
    ----------
    source, target : array_like, shape (n, 3)
    methods : sequence of str
        Methods to compare (default: all six).
    reference : str
        Method whose (converged) solution the differences refer to.
    convention, angle_unit : str
        Angle convention (``"transposed"`` / ``"direct"``) and unit (rad/deg/gon) of the table.
    min_time, max_repeats : float, int
        Each method is timed for at least ``min_time`` seconds (and 5 calls), at most
        ``max_repeats`` calls; the median is reported.
    timing : bool
        False skips the timing (faster, for tests).
    length_unit : str
        Unit of the target coordinates (labels).
    **options
        Passed to every :func:`absolute_orientation` call (e.g. ``with_scale``, ``weights``).

    Returns
    -------
    MethodComparison
        One row per method: its parameters, differences to ``reference``, orthogonality
        defect and time per solve (a method that fails has its error instead).
    """
    unit = angle_unit
    options["unit"] = length_unit
    methods = [normalize_method(m) for m in methods]
    reference = normalize_method(reference)
    if reference not in methods:
        methods.append(reference)
    fits: dict[str, AbsoluteOrientationFit | None] = {}
    errors: dict[str, str] = {}
    for m in methods:
        try:
            fits[m] = absolute_orientation(source, target, m, **options)
        except PhotogeomError as exc:
            fits[m] = None
            errors[m] = str(exc)
    ref_fit = fits[reference]
    ref_vals = _values(ref_fit, convention, unit) if ref_fit is not None else None
    half = float(from_radians(math.pi, unit))
    rows = []
    for m in methods:
        fit = fits[m]
        if fit is None:
            rows.append(MethodRow(m, None, error=errors[m]))
            continue
        vals = _values(fit, convention, unit)
        diffs = {}
        for k, v in vals.items():
            if ref_vals is None:
                diffs[k] = math.nan
                continue
            d = v - ref_vals[k]
            if k in ("omega", "phi", "kappa"):
                d = (d + half) % (2 * half) - half
            diffs[k] = d
        tps, reps = math.nan, 0
        if timing:
            tps, reps = _time_per_solve(
                lambda m=m: absolute_orientation(source, target, m, statistics=False, **options),
                min_time, max_repeats,
            )
        rows.append(MethodRow(m, fit, vals, diffs, fit.orthogonality_defect, tps, reps))
    return MethodComparison(tuple(rows), reference, convention, unit, length_unit)

