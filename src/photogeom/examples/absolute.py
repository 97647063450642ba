"""Worked examples of absolute orientation: every method on the bundled data sets.

* ``absolute-lidar`` - 18 point pairs of two terrestrial laser scans (Wang et al. 2014);
* ``absolute-afary`` - the closed-form paper's simulated three-point data, error-free and noisy,
  against the true transformation (s = 4, t = 250 m, 50/60/130 deg, direct convention);
* ``absolute-kraus`` - Kraus' textbook example (three pairs, model -> object), against the
  published angles -0.1854, -1.0920, 298.6799 gon (transposed convention).

Each prints the evaluation table (parameters, differences to the converged Gauss-Markov
solution, orthogonality defect, time per solve) and, for a report, adds the table and a plot.
"""

from __future__ import annotations

import numpy as np

from .. import datasets
from ..orientation import MethodComparison, compare_absolute_methods
from . import Example


def comparison_figure(cmp: MethodComparison):
    """Two panels: largest parameter differences to the reference (log scale) and time per
    solve (log scale), per method."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = [r for r in cmp.rows if r.fit is not None]
    names = [r.method for r in rows]
    tiny = 1e-17
    shift = [max(max(abs(r.differences[k]) for k in ("tx", "ty", "tz")), tiny) for r in rows]
    scale = [max(abs(r.differences["scale"]), tiny) for r in rows]
    angle = [max(max(abs(r.differences[k]) for k in ("omega", "phi", "kappa")), tiny)
             for r in rows]
    times = [r.time_per_solve * 1e6 for r in rows]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    y = np.arange(len(names))
    h = 0.27
    a1.barh(y - h, shift, h, label=f"shift [{cmp.length_unit}]")
    a1.barh(y, scale, h, label="scale")
    a1.barh(y + h, angle, h, label=f"angle [{cmp.unit}]")
    a1.set_xscale("log")
    a1.set_yticks(y, names)
    a1.invert_yaxis()
    a1.set_xlabel(f"largest |difference| to {cmp.reference} (1e-17 = equal)")
    a1.legend(fontsize=8, ncols=3, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    if all(np.isfinite(times)):
        a2.barh(y, times, color="0.5")
        a2.set_xscale("log")
        from matplotlib.ticker import NullFormatter

        a2.xaxis.set_minor_formatter(NullFormatter())  # minor labels overlapped each other
        a2.set_yticks(y, names)
        a2.invert_yaxis()
        a2.set_xlabel("time per solve [us] (median)")
    else:
        a2.axis("off")
    return fig


def add_comparison(report, cmp: MethodComparison, title: str) -> None:
    """Add the comparison table and its figure to an HTML report."""
    cols = cmp.columns()
    rows = cmp.display_rows()  # the digits 'orient absolute --compare' prints
    # two tables of at most 8 columns (as on the console): one page width, no scrolling
    report.add_table(
        title,
        cols[:8],
        [r[:8] for r in rows],
        note=f"parameters of every method; angles {cmp.unit} ({cmp.convention} convention)",
    )
    report.add_table(
        f"{title}: differences to the converged {cmp.reference} solution, speed",
        [cols[0], *cols[8:]],
        [[r[0], *r[8:]] for r in rows],
        note=f"differences to the converged {cmp.reference} solution; times: medians of "
        "repeated solves, parameters only",
    )
    report.add_figure(f"{title}: differences and speed", comparison_figure(cmp))
    for r in cmp.rows:
        if r.error:
            report.add_text(f"{r.method} failed", r.error)


def _run(name: str, kind: str | None, title: str, convention: str, unit: str, report,
         published=None) -> str:
    _, x, X = datasets.point_pairs(name, kind)
    cmp = compare_absolute_methods(x, X, convention=convention, angle_unit=unit, min_time=0.02)
    lines = [title, cmp.to_text()]
    if published is not None:
        lines.append(published(cmp))
    text = "\n".join(lines)
    if report is not None:
        add_comparison(report, cmp, title)
        if published is not None:
            report.add_text(f"{title}: published values", lines[-1])
    return text


def _lidar(report) -> str:
    return _run("lidar_wang2014", None, "18 laser-scan point pairs (Wang et al. 2014)",
                "transposed", "deg", report)


def _afary(report) -> str:
    def truth(cmp: MethodComparison) -> str:
        out = ["true transformation (direct convention): s = 4, t = (250, 250, 250) m, "
               "Omega/Phi/K = 50/60/130 deg"]
        for r in cmp.rows:
            if r.fit is not None:
                v = r.values
                out.append(
                    f"  {r.method:<16} s {v['scale']:.7f}  angles {v['omega']:.5f} "
                    f"{v['phi']:.5f} {v['kappa']:.5f} deg  t ({v['tx']:.4f}, {v['ty']:.4f}, "
                    f"{v['tz']:.4f}) m"
                )
        return "\n".join(out)

    parts = [
        _run("afary2024_simulated", kind, f"Afary (2024) simulated data, {kind}", "direct",
             "deg", report, published=truth)
        for kind in ("true", "noisy")
    ]
    return "\n\n".join(parts)


def _kraus(report) -> str:
    def published(cmp: MethodComparison) -> str:
        ref = cmp.row("gauss-markov").values
        k = ref["kappa"] % 400.0
        return (
            "published (Kraus 2007 via the Gauss-Helmert paper, transposed convention): "
            "omega -0.1854, phi -1.0920, kappa 298.6799 gon; ours: "
            f"{ref['omega']:.4f}, {ref['phi']:.4f}, {k:.4f} gon"
        )

    return _run("kraus_absolute_orientation", None, "Kraus (2007) absolute orientation",
                "transposed", "gon", report, published=published)


EXAMPLES = [
    Example("absolute-lidar", "Absolute orientation: all methods on 18 laser-scan pairs", _lidar),
    Example("absolute-afary", "Absolute orientation: closed-form paper's simulated data", _afary),
    Example("absolute-kraus", "Absolute orientation: Kraus' textbook example (gon)", _kraus),
]
