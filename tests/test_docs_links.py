"""Links between the pages of README.md and docs/*.md reach a file and a heading.

A link ``docs/x.md#anchor`` whose heading was renamed still renders, and lands at the top
of the page: nothing says that the section it promised is gone. Anchors follow GitHub's
rules (the heading's text as rendered, lower case, characters other than letters, digits,
``-``, ``_`` and spaces dropped, spaces turned into ``-``; a repeated heading gets ``-1``,
``-2``, ...).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

pytestmark = pytest.mark.skipif(
    not (ROOT / "docs").is_dir(), reason="docs/ is not beside the tests"
)

_FENCE = re.compile(r"^```.*?^```", re.S | re.M)
_HEADING = re.compile(r"^#{1,6}[ \t]+(.+?)[ \t#]*$", re.M)
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading (without the suffix of a repeated one)."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link: its text
    text = re.sub(r"[`*]", "", text).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every anchor of ``page``'s headings (outside code blocks)."""
    seen: dict[str, int] = {}
    out = set()
    for m in _HEADING.finditer(_FENCE.sub("", page.read_text(encoding="utf-8"))):
        base = slug(m.group(1))
        n = seen.get(base, -1) + 1
        seen[base] = n
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_slug_follows_githubs_rules():
    assert slug("The CRS of results: `--crs` options") == "the-crs-of-results---crs-options"
    assert slug("The best any method can do (`field_bound`)") == (
        "the-best-any-method-can-do-field_bound"
    )
    assert slug("Whole blocks: fit, correct, re-adjust, steps") == (
        "whole-blocks-fit-correct-re-adjust-steps"
    )
    assert slug("Post-processing or in-adjustment? (simulator)") == (
        "post-processing-or-in-adjustment-simulator"
    )


def test_repeated_headings_are_numbered(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("# A\n\n## Speed\n\n```\n# Speed\n```\n\n## Speed\n", encoding="utf-8")
    assert anchors(page) == {"a", "speed", "speed-1"}


def test_every_internal_link_reaches_its_file_and_heading():
    problems = []
    cache: dict[Path, set[str]] = {}
    for page in PAGES:
        # code blocks blanked line for line, so that the line numbers stay the page's
        text = _FENCE.sub(lambda b: "\n" * b.group(0).count("\n"), page.read_text(encoding="utf-8"))
        for m in _LINK.finditer(text):
            link = m.group(1)
            if re.match(r"[a-z]+:", link):  # http:, https:, mailto:
                continue
            path, _, anchor = link.partition("#")
            target = (page.parent / path).resolve() if path else page.resolve()
            where = f"{page.name}:{text.count(chr(10), 0, m.start()) + 1}: {link}"
            if not target.exists():
                problems.append(f"{where} (no such file)")
            elif anchor and target.suffix == ".md":
                if target not in cache:
                    cache[target] = anchors(target)
                if anchor not in cache[target]:
                    problems.append(f"{where} (no such heading)")
    assert not problems, problems
