"""Reports: rich tables in the terminal and self-contained HTML with residual plots.

>>> from photogeom.report import Report, print_fit
>>> print_fit(fit)                                   # doctest: +SKIP
>>> rep = Report("Interior orientation")
>>> rep.add_fit(fit, points=source_xy)               # doctest: +SKIP
>>> rep.write("report.html")                         # doctest: +SKIP
"""

from .bundle import (
    add_bundle_fit,
    add_bundle_result,
    bundle_report,
    bundle_result_data,
    read_bundle_result,
    write_bundle_result,
)
from .console import fit_renderable, fit_text, print_fit, print_table
from .html import Report, figure_to_png
from .plots import nice_length, residual_figure

__all__ = [
    "Report",
    "add_bundle_fit",
    "add_bundle_result",
    "bundle_report",
    "bundle_result_data",
    "figure_to_png",
    "fit_renderable",
    "fit_text",
    "nice_length",
    "print_fit",
    "print_table",
    "read_bundle_result",
    "residual_figure",
    "write_bundle_result",
]
