"""Parsing XML from files that may be hostile.

One entry point, :func:`parse_xml`, for every XML reader of photogeom (RPC, Metashape), and
:func:`parse_xml_lines`, the same with the line of each element (for messages):

* bytes go to the parser untouched, so the document's encoding declaration (UTF-8, UTF-16
  with a byte-order mark, ISO-8859-1, ...) is honoured;
* a document type declaration (``<!DOCTYPE ...>``) is refused before the document is built:
  none of the formats read has one, and refusing it keeps entity expansion ("billion
  laughs") and external entities (XXE) out;
* every parser failure is a :class:`~photogeom.errors.FileFormatError` naming the file.
"""

from __future__ import annotations

from xml.etree import ElementTree
from xml.parsers import expat

from .errors import FileFormatError


class _PrologDone(Exception):
    """The first element was reached: the prolog holds no document type declaration."""


def _refuse_doctype(data: bytes | str, where: str) -> None:
    """Scan the prolog (up to the first element) for a document type declaration."""
    parser = expat.ParserCreate()

    def doctype(*_args) -> None:
        raise FileFormatError(
            f"{where}: XML with a document type declaration (<!DOCTYPE ...>) is refused "
            "(entities are never expanded); remove the declaration"
        )

    def first_element(*_args) -> None:
        raise _PrologDone

    parser.StartDoctypeDeclHandler = doctype
    parser.StartElementHandler = first_element
    try:
        parser.Parse(data, True)
    except _PrologDone:
        return
    except FileFormatError:
        raise
    except (expat.ExpatError, ValueError, LookupError):
        return  # reported by the real parse below


def parse_xml(data: bytes | str, where: str) -> ElementTree.Element:
    """The root element of an XML document; see the module docstring.

    Parameters
    ----------
    data : bytes or str
        The document; bytes keep the declared encoding.
    where : str
        Name used in error messages (the file).

    Raises
    ------
    FileFormatError
        Not well-formed, an unknown encoding, or a document type declaration.
    """
    _refuse_doctype(data, where)
    try:
        return ElementTree.fromstring(data)
    except ElementTree.ParseError as exc:
        raise FileFormatError(f"{where}: not well-formed XML ({exc}); truncated file?") from None
    except (ValueError, LookupError) as exc:  # e.g. an encoding the parser does not know
        raise FileFormatError(f"{where}: cannot read this XML ({exc})") from None


def parse_xml_lines(data: bytes | str, where: str) -> tuple[ElementTree.Element, dict[int, int]]:
    """The root element of an XML document and the line each element starts on.

    As :func:`parse_xml` (the same refusals and messages), built by the same parser (expat)
    driven here so that its position can be read at each element's start.

    Parameters
    ----------
    data : bytes or str
        The document; bytes keep the declared encoding.
    where : str
        Name used in error messages (the file).

    Returns
    -------
    root : xml.etree.ElementTree.Element
    lines : dict
        ``id(element)`` -> its line (1-based), for every element under ``root`` (valid while
        ``root`` is alive).

    Raises
    ------
    FileFormatError
        As :func:`parse_xml`.
    """
    _refuse_doctype(data, where)
    builder = ElementTree.TreeBuilder()
    lines: dict[int, int] = {}
    parser = expat.ParserCreate()
    parser.buffer_text = True

    def start(tag: str, attrs: dict) -> None:
        lines[id(builder.start(tag, attrs))] = parser.CurrentLineNumber

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    try:
        parser.Parse(data, True)
        root = builder.close()
    except expat.ExpatError as exc:
        raise FileFormatError(f"{where}: not well-formed XML ({exc}); truncated file?") from None
    except (ValueError, LookupError, AssertionError) as exc:  # encoding; no root element
        raise FileFormatError(f"{where}: cannot read this XML ({exc})") from None
    return root, lines


def root_tag(data: bytes | str) -> str | None:
    """The name of a document's first element, read from its start only (the prolog and the
    start tag), or None when there is none there or the start is not XML."""
    parser = expat.ParserCreate()
    found: list[str] = []

    def first_element(name: str, *_args) -> None:
        found.append(name)
        raise _PrologDone

    parser.StartElementHandler = first_element
    step = 4096
    try:
        for at in range(0, len(data), step):  # stops at the first element
            parser.Parse(data[at : at + step], False)
        parser.Parse(data[:0], True)
    except _PrologDone:
        pass
    except (expat.ExpatError, ValueError, LookupError):
        pass
    return found[0] if found else None
