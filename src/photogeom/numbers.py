"""Strict reading of numbers written as text in files.

Python's :func:`float` reads more than a decimal number: ``"3_500.5"`` (digit grouping of
Python source) and non-ASCII digits (``"\\u0663"``, an Arabic-Indic three) are accepted
too. Files from other programs never mean those, so every reader of numbers in text files
(CSV columns, Metashape XML tags, RPC text) uses the one rule here: ASCII decimal numbers
with an optional sign, fraction and exponent (``-12``, ``.5``, ``1e-3``, ``+1.2E+03``),
and the words ``inf``/``infinity``/``nan`` (any case, signed) that the readers then accept
or refuse themselves (PyArrow reads the same set in CSV columns).
"""

from __future__ import annotations

import re

__all__ = ["decimal_comma_hint", "is_decimal_number", "parse_decimal"]


def is_decimal_number(text: str) -> bool:
    """Whether ``text`` is a decimal number (surrounding white space allowed).

    Parameters
    ----------
    text : str
        The text of one number.

    Returns
    -------
    bool
        True for what :func:`float` reads, except text with ``_`` or non-ASCII characters.
    """
    if not isinstance(text, str) or "_" in text or not text.isascii():
        return False
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_decimal(text: str) -> float:
    """The value of a decimal number written as text (see :func:`is_decimal_number`).

    Parameters
    ----------
    text : str
        The text of one number.

    Returns
    -------
    float
        Its value; ``inf`` and ``nan`` are returned as such (the caller decides).

    Raises
    ------
    ValueError
        ``text`` is not a decimal number (the caller names the file and the place).
    """
    if not is_decimal_number(text):
        raise ValueError(f"not a decimal number: {text!r}")
    return float(text)


#: A number written with a decimal comma (and perhaps '.' grouping thousands): 1,5  -3,25e2
#: 1.234,5 -- what spreadsheets write in German, French, ... locales.
_DECIMAL_COMMA = re.compile(r"[+-]?(?:\d{1,3}(?:\.\d{3})+|\d+),\d+(?:[eE][+-]?\d+)?")


def decimal_comma_hint(text: str) -> str:
    """A hint to append to "not a number" errors when ``text`` has a decimal comma.

    Parameters
    ----------
    text : str
        The text of the cell that is not a decimal number.

    Returns
    -------
    str
        ``""``, or a clause (starting with ``"; "``) saying that decimal commas are not read
        and how to export the file instead.
    """
    if not isinstance(text, str) or _DECIMAL_COMMA.fullmatch(text.strip()) is None:
        return ""
    return (
        "; it has a decimal comma, which photogeom does not read: write numbers with a "
        "decimal point (1.5, not 1,5), e.g. export the file with '.' as the decimal separator"
    )
