"""Standard deviations given to the public API say in which unit they are.

A ``sigma`` without a unit leaves the reader to guess between pixels, millimetres and metres,
and a guess that is off by the pixel size weights an adjustment wrongly without any error.
Every parameter of the public callables (the scanner of ``test_docstrings.py``) whose name
says it is a standard deviation (``sigma``, ``sigma_*``, ``*_sigma``) and that takes numbers
names its unit in its description, or refers to the function whose description does
("As in ...").
"""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import test_docstrings as scanner

#: Words that name a unit (or say that the unit is that of some coordinates).
UNIT = re.compile(
    r"\b(m|mm|px|pixels?|metres?|meters?|deg|degrees?|rad|radians?|gon|arc-?seconds?|"
    r"units?|unitless|dimensionless)\b",
    re.I,
)


def _entries(block: str) -> dict[str, str]:
    """``{entry line: description}`` of a numpy-style section."""
    lines = block.splitlines()
    filled = [ln for ln in lines if ln.strip()]
    if not filled:
        return {}
    indent = min(len(ln) - len(ln.lstrip()) for ln in filled)
    out: dict[str, str] = {}
    head = None
    for ln in lines:
        if ln.strip() and len(ln) - len(ln.lstrip()) == indent:
            head = ln.strip()
            out[head] = ""
        elif head is not None:
            out[head] += " " + ln.strip()
    return out


def _is_sigma(name: str) -> bool:
    return name == "sigma" or name.startswith("sigma_") or name.endswith("_sigma")


def unitless_sigmas() -> list[str]:
    """``"callable: entry"`` of every standard-deviation parameter without a unit."""
    out = []
    for key, obj in scanner.public_callables().items():
        docs = [inspect.getdoc(obj) or ""]
        if inspect.isclass(obj) and "__init__" in vars(obj) and obj.__init__.__doc__:
            docs.append(inspect.getdoc(obj.__init__))
        for doc in docs:
            secs = scanner._sections(doc)
            block = secs.get("Parameters", "") + secs.get("Other Parameters", "")
            for head, desc in _entries(block).items():
                names, _, kind = head.partition(" : ")
                if not any(_is_sigma(n.strip().lstrip("*")) for n in names.split(",")):
                    continue
                if kind.lstrip().startswith("{") or re.search(r"\bbool\b", kind):
                    continue  # a choice ("prior" / "posterior") or a switch, not a number
                if UNIT.search(desc) or re.search(r"\bAs in\b", desc):
                    continue
                out.append(f"{key}: {head}")
    return out


def test_scanner_flags_a_sigma_without_unit(monkeypatch):
    def f(xy, sigma=None, gnss_sigma=None, sigma_px=None):
        """Do it.

        Parameters
        ----------
        xy : array_like (n, 2)
            Image coordinates, mm.
        sigma : float, optional
            Standard deviation of the image coordinates.
        gnss_sigma : array_like (m, 3), optional
            Standard deviations of the projection centres.
        sigma_px : float
            Standard deviation, pixels.

        Returns
        -------
        float
            Nothing, m.
        """
        return 0.0

    monkeypatch.setattr(scanner, "public_callables", lambda: {"f": f})
    assert unitless_sigmas() == [
        "f: sigma : float, optional",
        "f: gnss_sigma : array_like (m, 3), optional",
    ]


def test_public_standard_deviations_name_their_unit():
    # absolute_orientation_batch (sigma_source, sigma_target), estimate_affine_camera,
    # estimate_dlt, space_resection_batch, orient_strip (sigma), Block.from_arrays
    # (point_sigma, gnss_sigma) described their standard deviations without a unit
    bad = unitless_sigmas()
    assert not bad, "standard deviations without a unit:\n" + "\n".join(bad)
