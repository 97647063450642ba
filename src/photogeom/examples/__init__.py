"""Registry of the bundled worked examples run by ``photogeom examples``.

Each part contributes a module with a list ``EXAMPLES`` of :class:`Example`; an example's
``run()`` computes on bundled data and returns a plain-text account (and, optionally,
fills an HTML :class:`~photogeom.report.Report`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Example:
    """One worked example.

    Attributes
    ----------
    name : str
        Short identifier (``photogeom examples run NAME``).
    title : str
        One-line description.
    run : callable
        ``run(report) -> str``: computes, returns text; adds sections to ``report`` if not None.
    """

    name: str
    title: str
    run: Callable[[object], str]


#: Modules that contribute examples (each defines ``EXAMPLES``).
_MODULES = ("transforms", "absolute", "rpc", "camera", "bundle", "grid")


def all_examples() -> list[Example]:
    """Every registered example, in registration order."""
    out: list[Example] = []
    for mod in _MODULES:
        out.extend(importlib.import_module(f"{__name__}.{mod}").EXAMPLES)
    return out


def get(name: str) -> Example:
    """The example called ``name``."""
    from ..errors import InputError

    for ex in all_examples():
        if ex.name == name:
            return ex
    raise InputError(f"no example {name!r}; run 'photogeom examples list' to see them")
