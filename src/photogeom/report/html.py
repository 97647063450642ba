"""Self-contained HTML reports: tables, text and figures (PNG embedded as base64)."""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write_text
from . import format as F
from .invocation import cli_command
from .plots import residual_figure

_CSS = """
body{font-family:-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;margin:2em auto;
max-width:68em;padding:0 1.5em;color:#1d2733;line-height:1.45}
h1{border-bottom:3px solid #1f5fa8;padding-bottom:.2em}
h2{border-bottom:1px solid #c8d3df;padding-bottom:.15em;margin-top:2.2em;color:#1f5fa8}
h3{margin-top:1.6em;color:#22364d}
h4{margin:1.1em 0 .3em 0;font-size:1em;color:#4a5a6c}
table{border-collapse:collapse;margin:.4em 0 .8em 0;font-size:.92em}
th,td{padding:.22em .75em;border-bottom:1px solid #e3e8ee}
th{background:#eef3f8;text-align:right;font-weight:600}
th:first-child,td:first-child{text-align:left}
td{text-align:right;font-family:"DejaVu Sans Mono",Menlo,Consolas,monospace;font-size:.95em;
white-space:nowrap}
td.text{font-family:inherit;text-align:left;white-space:normal}
td.flag{background:#fbe3e1;color:#a01d12;font-weight:600}
table.stats td:first-child{font-family:inherit;color:#4a5a6c}
table.stats td{text-align:left}
div.tbl{max-width:100%;overflow-x:auto}
pre{background:#f5f7fa;border:1px solid #e3e8ee;padding:.7em;overflow-x:auto;font-size:.88em}
p.note{color:#4a5a6c;font-size:.9em;margin:.2em 0}
p.warn{color:#a01d12}
nav{background:#f5f7fa;border:1px solid #e3e8ee;padding:.5em 1.2em;font-size:.92em}
nav ul{margin:.2em 0;padding-left:1.2em}
img{max-width:100%;height:auto;border:1px solid #e3e8ee}
footer{margin-top:3em;border-top:1px solid #c8d3df;color:#6b7b8c;font-size:.85em}
.grid{display:flex;flex-wrap:wrap;gap:2em;align-items:flex-start}
"""

#: Rows of a residual table in :meth:`Report.add_fit` at most: with more points, those with the
#: largest test statistic (|w|, else |tau|, else |v|), largest first, and a note.
MAX_RESIDUAL_ROWS = 100

_CONVENTIONS = (
    "Residuals are computed minus observed (v = A x - L), in the target system. "
    "sigma0 is the a-posteriori standard deviation of unit weight, sqrt(v'Pv / r), undefined "
    "when the redundancy r is 0; standard deviations of parameters are sqrt of the diagonal "
    "of sigma0^2 Qxx. RMSE is per point, sqrt(sum |v_i|^2 / n_points); RMS per axis is "
    "sqrt(mean v^2) of one coordinate. Check points do not enter the estimate. "
    "Angles are labelled with their unit."
)


def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _slug(text: str, used: set[str]) -> str:
    base = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"
    slug, k = base, 2
    while slug in used:
        slug, k = f"{base}-{k}", k + 1
    used.add(slug)
    return slug


def figure_to_png(fig, dpi: int = 110) -> bytes:
    """PNG bytes of a matplotlib figure (closed afterwards if pyplot manages it).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    dpi : int, default 110
        Resolution, dots per inch.

    Returns
    -------
    bytes
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:
        plt.close(fig)
    return buf.getvalue()


class Report:
    """An HTML report assembled section by section, written as one self-contained file.

    The file has inline CSS and figures embedded as base64 PNG: it can be mailed or archived
    alone. ``write`` replaces the target atomically (never a half-written file).

    Parameters
    ----------
    title : str
        Title of the document (``<h1>`` and ``<title>``).
    subtitle : str, optional
        A line under the title.

    Attributes
    ----------
    command : str or None
        The command line that made the report
        (:func:`photogeom.report.invocation.cli_command`), shown under the title; None (not
        shown) outside the command line.

    Examples
    --------
    >>> rep = Report("Interior orientation")
    >>> rep.add_text("Data", "Eight fiducial marks, four control and four check.")
    >>> rep.add_fit(fit, points=source_xy)                  # doctest: +SKIP
    >>> rep.write("report.html")                            # doctest: +SKIP
    """

    def __init__(self, title: str, subtitle: str | None = None) -> None:
        self.title = str(title)
        self.subtitle = subtitle
        self.command = cli_command()
        self._blocks: list[tuple[int, str, str, str]] = []  # (level, heading, anchor, html)
        self._used: set[str] = set()

    # --- structure ---------------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._blocks)

    @property
    def headings(self) -> list[str]:
        """Headings of all sections and chapters, in order."""
        return [b[1] for b in self._blocks]

    def truncate(self, n: int) -> None:
        """Drop the sections added after the first ``n``.

        Take ``n = len(report)`` before a step that may fail: a step that failed then leaves
        none of its sections half-way in the report.

        Parameters
        ----------
        n : int
            Sections to keep.
        """
        del self._blocks[int(n) :]

    def _add(self, level: int, heading: str | None, body: str) -> None:
        anchor = _slug(heading, self._used) if heading else ""
        self._blocks.append((level, heading or "", anchor, body))

    def add_heading(self, title: str, text: str | None = None) -> None:
        """Start a chapter (a top-level heading; sections added after it belong to it).

        Parameters
        ----------
        title : str
            Heading.
        text : str, optional
            Paragraphs under the heading (separated by blank lines).
        """
        body = "" if not text else "".join(f"<p>{_esc(p)}</p>" for p in _paragraphs(text))
        self._add(2, title, body)

    def add_text(self, heading: str | None, text: str, *, pre: bool | None = None) -> None:
        """A section of text.

        Parameters
        ----------
        heading : str or None
            Section heading; None: no heading.
        text : str
            Paragraphs separated by blank lines (HTML-escaped).
        pre : bool, optional
            Show preformatted; default: when the text has aligned columns.
        """
        if pre is None:
            pre = bool(re.search(r"\S {2,}\S", text)) or "\n  " in text
        body = (
            f"<pre>{_esc(text.rstrip())}</pre>"
            if pre
            else "".join(f"<p>{_esc(p)}</p>" for p in _paragraphs(text))
        )
        self._add(3, heading, body)

    def add_table(
        self,
        title: str | None,
        columns: Sequence[str],
        rows: Sequence[Sequence],
        *,
        note: str | None = None,
    ) -> None:
        """A table; numbers are printed with up to 10 significant digits.

        Parameters
        ----------
        title : str or None
            Section heading.
        columns : sequence of str
            Column headings (units in them).
        rows : sequence of sequences
            Cells (numbers, text, None).
        note : str, optional
            A note under the table.
        """
        self._add(3, title, _table_html(columns, [[_cell(c) for c in r] for r in rows], note=note))

    def add_figure(self, title: str | None, figure, *, caption: str | None = None) -> None:
        """A matplotlib figure, embedded as PNG.

        Parameters
        ----------
        title : str or None
            Section heading (also the image's alternative text).
        figure : matplotlib.figure.Figure
            The figure (closed afterwards if pyplot manages it).
        caption : str, optional
            Caption under the figure.
        """
        self._add(3, title, _img_html(figure_to_png(figure), title or "figure", caption))

    def add_residual_plot(
        self,
        title: str | None,
        points_xy,
        residuals_xy,
        ids: Sequence | None = None,
        unit: str = "",
        labels: tuple[str, str] = ("x", "y"),
        **kwargs,
    ) -> None:
        """Residual vectors at their points with a labelled scale arrow and the ids.

        Parameters
        ----------
        title : str or None
            Section heading.
        points_xy : array_like, shape (n, 2)
            Positions of the residuals.
        residuals_xy : array_like, shape (n, 2)
            Residual vectors (computed minus observed), in ``unit``.
        ids : sequence, optional
            Point labels.
        unit : str, default ""
            Unit of the residuals (scale arrow).
        labels : (str, str), default ("x", "y")
            Axis labels.
        **kwargs
            Passed to :func:`~photogeom.report.plots.residual_figure` (``check_points``,
            ``check_residuals``, ``check_ids``, ``y_down``, ``point_unit``, ``name``).
        """
        fig = residual_figure(points_xy, residuals_xy, ids, unit=unit, labels=labels, **kwargs)
        self._add(3, title, _img_html(figure_to_png(fig), title or "residuals", None))

    def add_fit(
        self,
        fit,
        title: str | None = None,
        angle_unit: str = "deg",
        points=None,
        *,
        check_points=None,
        point_labels: tuple[str, str] | None = None,
        point_unit: str | None = None,
        y_down: bool = False,
        description: str | None = None,
    ) -> None:
        """A full account of a :class:`~photogeom.adjust.Fit`.

        Shows the parameters with standard deviations and units, the adjustment statistics
        (sigma0 a priori / a posteriori, redundancy, RMSE and RMS per axis), the residual
        table (v = computed - observed) with data-snooping statistics when available, the
        check-point table and RMSE, notes, and - when ``points`` gives the (n, 2) positions
        of the residual rows - a residual vector plot (``check_points`` adds the check points).
        A residual table of more than :data:`MAX_RESIDUAL_ROWS` points shows the
        :data:`MAX_RESIDUAL_ROWS` with the largest |w| (else |tau|, else |v|), largest first,
        and says so; the statistics and the plot use every point.

        Parameters
        ----------
        fit : Fit
            The estimate.
        title : str, optional
            Section heading; default the model name and method.
        angle_unit : str, default "deg"
            Unit of the angle parameters.
        points : array_like, shape (n, 2), optional
            Positions of the residual rows, for the plot.
        check_points : array_like, shape (k, 2), optional
            Positions of the check points, for the plot.
        point_labels : (str, str), optional
            Axis labels of the plot; default the fit's first two axis labels.
        point_unit : str, optional
            Unit of the positions (axis labels); default the residual unit.
        y_down : bool, default False
            Draw the second axis downwards (pixel systems).
        description : str, optional
            Paragraphs shown before the tables.
        """
        title = title or f"{F.model_name(fit)} ({fit.method})"
        parts: list[str] = []
        if description:
            parts.append("".join(f"<p>{_esc(p)}</p>" for p in _paragraphs(description)))
        prows = F.parameter_rows(fit, angle_unit)
        stats = F.statistics_rows(fit)
        left = "<h4>Parameters</h4>" + _table_html(
            ["parameter", "value", "std. dev.", "unit"],
            [list(r) for r in prows],
            text_cols={3},
            note=_std_note(fit, prows),
        )
        right = "<h4>Adjustment</h4>" + _table_html(
            ["quantity", "value"], [list(r) for r in stats], cls="stats", header=False
        )
        parts.append(f'<div class="grid"><div>{left}</div><div>{right}</div></div>')
        tb = F.textbook_rows(fit, angle_unit)
        if tb:
            parts.append(
                "<h4>Textbook form</h4>"
                + _table_html(
                    ["parameter", "value", "std. dev.", "unit"],
                    [list(r) for r in tb],
                    text_cols={3},
                )
            )
        hm = F.helmert_rows(fit)
        if hm:
            parts.append(
                f"<h4>{html.escape(F.HELMERT_TITLE)}</h4>"
                + _table_html(
                    ["parameter", "value", "std. dev.", "unit"],
                    [list(r) for r in hm],
                    text_cols={3},
                )
            )
        ctab = F.residual_table(fit, max_rows=MAX_RESIDUAL_ROWS)
        if ctab is not None:
            parts.append(
                f"<h4>Control point residuals ({ctab.n_points})</h4>"
                + _table_html(ctab.columns, ctab.rows, flags=ctab.flags)
                + "".join(f'<p class="note">{_esc(n)}</p>' for n in ctab.footer)
            )
        ktab = F.residual_table(fit, check=True, max_rows=MAX_RESIDUAL_ROWS)
        if ktab is not None:
            parts.append(
                f"<h4>Check point residuals ({ktab.n_points}, not in the estimate)</h4>"
                + _table_html(ktab.columns, ktab.rows)
                + "".join(f'<p class="note">{_esc(n)}</p>' for n in ktab.footer)
            )
        for note in fit.notes:
            parts.append(f'<p class="note">note: {_esc(note)}</p>')
        if not fit.converged:
            parts.append(
                '<p class="warn">The iteration did NOT converge; do not trust these numbers.</p>'
            )
        if points is not None:
            labels = point_labels or tuple(F.axis_labels(fit)[:2])
            if len(labels) < 2:
                labels = ("x", "y")
            chk = None
            if check_points is not None and fit.check_residuals is not None:
                chk = dict(
                    check_points=check_points,
                    check_residuals=np.asarray(fit.check_residuals)[:, :2],
                    check_ids=fit.check_ids,
                )
            fig = residual_figure(
                points,
                np.asarray(fit.residuals)[:, :2],
                fit.ids,
                unit=fit.residual_unit,
                labels=labels,
                y_down=y_down,
                point_unit=point_unit,
                **(chk or {}),
            )
            dims = np.asarray(fit.residuals).shape[1]
            cap = (
                "Residual vectors (first two components) at the points."
                if dims > 2
                else "Residual vectors at the points."
            )
            parts.append(_img_html(figure_to_png(fig), f"residuals of {title}", cap))
        self._add(3, title, "".join(parts))

    # --- output ------------------------------------------------------------------------------

    def to_html(self) -> str:
        """The complete HTML document.

        Returns
        -------
        str
        """
        from .. import __version__

        now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
        out = [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            f"<title>{_esc(self.title)}</title><style>{_CSS}</style></head><body>",
            f"<h1>{_esc(self.title)}</h1>",
        ]
        if self.subtitle:
            out.append(f'<p class="note">{_esc(self.subtitle)}</p>')
        out.append(f'<p class="note">photogeom {_esc(__version__)} &middot; {_esc(now)}</p>')
        if self.command:
            out.append(f'<p class="note">command: <code>{_esc(self.command)}</code></p>')
        if sum(1 for b in self._blocks if b[1]) >= 4:
            out.append(self._toc())
        for level, heading, anchor, body in self._blocks:
            if heading:
                out.append(f'<section><h{level} id="{anchor}">{_esc(heading)}</h{level}>')
            else:
                out.append("<section>")
            out.append(body)
            out.append("</section>")
        out.append(f"<footer><p>{_esc(_CONVENTIONS)}</p></footer></body></html>")
        return "\n".join(out)

    def _toc(self) -> str:
        items: list[str] = ["<nav><strong>Contents</strong><ul>"]
        open_sub = False
        for level, heading, anchor, _ in self._blocks:
            if not heading:
                continue
            if level == 2:
                if open_sub:
                    items.append("</ul></li>")
                    open_sub = False
                items.append(f'<li><a href="#{anchor}">{_esc(heading)}</a><ul>')
                open_sub = True
            else:
                items.append(f'<li><a href="#{anchor}">{_esc(heading)}</a></li>')
        if open_sub:
            items.append("</ul></li>")
        items.append("</ul></nav>")
        return "".join(items).replace("<ul></ul>", "")

    def write(self, path: str | os.PathLike) -> Path:
        """Write the report atomically to ``path`` (``.html``) and return the path.

        Parameters
        ----------
        path : str or os.PathLike
            Output file; replaced if it exists.

        Returns
        -------
        pathlib.Path

        Raises
        ------
        OutputError
            When the file cannot be written.
        """
        return atomic_write_text(path, self.to_html())


# ------------------------------------------------------------------------------------------------


def _std_note(fit, rows) -> str:
    """The note under a parameter table: where its standard deviations come from."""
    if np.isfinite(fit.sigma0):
        return "std. dev. from sigma0 a posteriori"
    if any(r[2].endswith("(a priori)") for r in rows):
        # the table shows numbers: saying "undefined" above them contradicted them
        return (
            "std. dev. a priori (from sigma0 a priori; redundancy 0: no a-posteriori "
            "sigma0 to scale them)"
        )
    return "std. dev. undefined: redundancy 0 (no a-posteriori sigma0)"


def _paragraphs(text: str) -> list[str]:
    return [p.strip() for p in re.split(r"\n\s*\n", str(text)) if p.strip()]


def _cell(c) -> str:
    if isinstance(c, (bool, np.bool_)):
        return str(bool(c))
    if isinstance(c, (int, np.integer)):
        return str(int(c))
    if isinstance(c, (float, np.floating)):
        return F.fmt_value(float(c))
    return str(c)


def _is_numeric_text(s: str) -> bool:
    return bool(re.fullmatch(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|-|nan|inf|-inf", s.strip()))


def _table_html(
    columns: Sequence[str],
    rows: Sequence[Sequence[str]],
    *,
    flags: Sequence[Sequence[bool]] | None = None,
    note: str | None = None,
    cls: str | None = None,
    header: bool = True,
    text_cols: set[int] | None = None,
    numeric_cols: set[int] | None = None,
) -> str:
    # a wide table scrolls inside its box instead of widening the page
    out = ['<div class="tbl">', f'<table class="{cls}">' if cls else "<table>"]
    if header:
        out.append("<tr>" + "".join(f"<th>{_esc(c)}</th>" for c in columns) + "</tr>")
    for i, row in enumerate(rows):
        cells = []
        for j, c in enumerate(row):
            classes = []
            numeric = bool(numeric_cols and j in numeric_cols)
            if (
                j > 0
                and not numeric
                and ((text_cols and j in text_cols) or not _is_numeric_text(str(c)))
            ):
                classes.append("text")
            if flags is not None and i < len(flags) and j < len(flags[i]) and flags[i][j]:
                classes.append("flag")
            attr = f' class="{" ".join(classes)}"' if classes else ""
            cells.append(f"<td{attr}>{_esc(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table></div>")
    if note:
        out.append(f'<p class="note">{_esc(note)}</p>')
    return "".join(out)


def _img_html(png: bytes, alt: str, caption: str | None) -> str:
    data = base64.b64encode(png).decode("ascii")
    cap = f'<p class="note">{_esc(caption)}</p>' if caption else ""
    return f'<figure><img alt="{_esc(alt)}" src="data:image/png;base64,{data}">{cap}</figure>'
