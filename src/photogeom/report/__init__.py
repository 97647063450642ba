"""Reports: rich tables in the terminal and self-contained HTML with residual plots.

>>> from photogeom.report import Report, print_fit
>>> print_fit(fit)                                   # doctest: +SKIP
>>> rep = Report("Interior orientation")
>>> rep.add_fit(fit, points=source_xy)               # doctest: +SKIP
>>> rep.write("report.html")                         # doctest: +SKIP
"""

from .console import fit_renderable, fit_text, print_fit, print_table
from .html import Report, figure_to_png
from .plots import nice_length, residual_figure

__all__ = [
    "Report",
    "figure_to_png",
    "fit_renderable",
    "fit_text",
    "nice_length",
    "print_fit",
    "print_table",
    "residual_figure",
]
