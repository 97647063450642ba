"""The tables of photogeom's HTML reports as text, for tests that compare them with the
console or JSON output of the same run."""

from __future__ import annotations

import html
import re


def table_rows(text: str) -> dict[str, list[str]]:
    """Table rows of an HTML report: first cell -> the other cells (text, tags removed,
    entities unescaped)."""
    rows = {}
    for row in re.findall(r"<tr>(.*?)</tr>", text, flags=re.S):
        cells = [
            html.unescape(re.sub(r"<[^>]+>", "", c)).strip()
            for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", row, flags=re.S)
        ]
        if cells:
            rows[cells[0]] = cells[1:]
    return rows
