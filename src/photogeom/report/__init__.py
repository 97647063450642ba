"""Reports: rich tables in the terminal and self-contained HTML with residual plots.

>>> from photogeom.report import Report, print_fit
>>> print_fit(fit)                                   # doctest: +SKIP
>>> rep = Report("Interior orientation")
>>> rep.add_fit(fit, points=source_xy)               # doctest: +SKIP
>>> rep.write("report.html")                         # doctest: +SKIP
"""

# Imported on first use: the HTML report needs matplotlib, the console tables rich.
_LAZY = {
    "Report": "html",
    "figure_to_png": "html",
    "fit_renderable": "console",
    "fit_text": "console",
    "print_fit": "console",
    "print_table": "console",
    "nice_length": "plots",
    "residual_figure": "plots",
    "add_bundle_fit": "bundle",
    "add_bundle_result": "bundle",
    "bundle_report": "bundle",
    "bundle_result_data": "bundle_record",
    "read_bundle_result": "bundle_record",
    "write_bundle_result": "bundle_record",
}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'photogeom.report' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
