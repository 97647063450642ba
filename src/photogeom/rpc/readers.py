"""Readers of RPC files; the format is detected from the content.

Formats:

* **KEY: value text** -- IKONOS / GeoEye / SkySat ``_RPC.TXT`` with numbered coefficient keys
  (``LINE_NUM_COEFF_1: ...`` to ``_20``) and units after the values (``pixels``,
  ``degrees``, ``meters``), or one key per coefficient vector with the 20 values on one line
  (as GDAL's RPC metadata domain). Extended files with ``LON_NUM_COEFF``/``LAT_NUM_COEFF``
  (image-to-ground polynomials) are read too. ``#`` starts a comment line.
* **RPB** -- DigitalGlobe/Maxar ``.RPB`` (``lineOffset = ...;``, ``lineNumCoef = (...);``).
* **OSSIM keyword list** -- ``.geom`` files of OSSIM and the Orfeo ToolBox with an
  ``ossimRpcModel`` (``line_off: ...``, ``line_num_coeff_00`` .. ``_19``, 0-based;
  ``polynomial_format`` A or B, A reordered to B): :func:`read_ossim_geom`.
* **DIMAP XML** -- Pleiades / SPOT 6-7 ``RPC_*.XML``: v2 (``Inverse_Model`` = ground to image,
  ``Direct_Model`` = image to ground) and v3 / Pleiades Neo (``GroundtoImage_Values``,
  ``ImagetoGround_Values``). DIMAP v2 counts pixels from 1 (the centre of the first pixel is
  (1, 1)); the validity domain's ``FIRST_COL``/``FIRST_ROW`` (default 1) is subtracted from
  ``SAMP_OFF``/``LINE_OFF`` so that the model uses the library's convention (first pixel
  centre at (0, 0)), as GDAL does.
* **DigitalGlobe/Maxar XML** -- WorldView ``.XML`` with an ``RPB/IMAGE`` block
  (``LINEOFFSET``, ``LINENUMCOEFList/LINENUMCOEF``, ...); pixel convention as RPB (0-based).
* **GeoTIFF / NITF** -- the ``RPC`` metadata domain read through ``rasterio`` (optional
  extra ``photogeom[geotiff]``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from ..errors import FileFormatError, InputError
from ..io.sources import (
    device_message,
    input_kind,
    pipe_bytes,
    pipe_message,
    read_input_bytes,
)
from ..numbers import decimal_comma_hint, parse_decimal
from ..xmlsafe import parse_xml
from . import polynomial as poly
from .model import GDAL_COEFF_KEYS, GDAL_KEYS, RPC, DirectModel

_UNITS = {
    "pixel", "pixels", "px", "degree", "degrees", "deg", "meter", "meters", "metre",
    "metres", "m",
}  # fmt: skip

#: Keys of the image size (columns, rows) in ``KEY: value`` text written by photogeom.
IMAGE_SIZE_KEYS = ("NUM_COLUMNS", "NUM_ROWS")

_OFFSET_SCALE_KEYS = tuple(GDAL_KEYS.values())
_COEFF_KEYS = tuple(GDAL_COEFF_KEYS.values())
_DIRECT_KEYS = ("LON_NUM_COEFF", "LON_DEN_COEFF", "LAT_NUM_COEFF", "LAT_DEN_COEFF")

_RPB_KEYS = {
    "errBias": "ERR_BIAS",
    "errRand": "ERR_RAND",
    "lineOffset": "LINE_OFF",
    "sampOffset": "SAMP_OFF",
    "latOffset": "LAT_OFF",
    "longOffset": "LONG_OFF",
    "heightOffset": "HEIGHT_OFF",
    "lineScale": "LINE_SCALE",
    "sampScale": "SAMP_SCALE",
    "latScale": "LAT_SCALE",
    "longScale": "LONG_SCALE",
    "heightScale": "HEIGHT_SCALE",
    "lineNumCoef": "LINE_NUM_COEFF",
    "lineDenCoef": "LINE_DEN_COEFF",
    "sampNumCoef": "SAMP_NUM_COEFF",
    "sampDenCoef": "SAMP_DEN_COEFF",
}
_RPB_LOWER = {k.lower(): v for k, v in _RPB_KEYS.items()}

#: Largest RPC text or RPB file read (bytes); an RPC is a few kB.
MAX_TEXT_BYTES = 1 << 20
#: Largest XML file read (bytes): WorldView metadata may carry long attitude/ephemeris lists.
MAX_XML_BYTES = 64 << 20

FORMATS = (
    "KEY: value text (IKONOS-style _RPC.TXT or coefficient lists), DigitalGlobe .RPB, "
    "OSSIM/Orfeo ToolBox keyword list (.geom, ossimRpcModel), "
    "DIMAP XML (Pleiades/SPOT), DigitalGlobe/Maxar XML with an RPB block (WorldView), "
    "GeoTIFF/NITF RPC metadata (with rasterio)"
)


# --- building from a mapping ------------------------------------------------------------------


def _numbers(value: object, key: str, where: str) -> list[float]:
    """A value (number, string, or list) as a list of floats; units are skipped."""
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, str):
        tokens = value.replace(",", " ").split()
    else:
        try:
            tokens = list(value)  # type: ignore[arg-type]
        except TypeError as exc:
            raise FileFormatError(f"{where}: {key} has an unreadable value {value!r}") from exc
    out = []
    for tok in tokens:
        if isinstance(tok, (bytes, bytearray)):
            tok = bytes(tok).decode("latin-1")
        if isinstance(tok, str) and tok.strip().lower() in _UNITS:
            continue
        try:
            out.append(parse_decimal(tok) if isinstance(tok, str) else float(tok))
        except (TypeError, ValueError):
            raise FileFormatError(
                f"{where}: {key} holds {tok!r}, which is not a number; write it as an ASCII "
                "decimal number (digits, '.', an exponent; no '_' digit grouping)"
            ) from None
    return out


def _comma_hint(value: object) -> str:
    """The decimal-comma hint when a value read as several numbers has one (``1234,5``)."""
    if isinstance(value, str):
        for tok in value.split():
            hint = decimal_comma_hint(tok)
            if hint:
                return hint
    return ""


def _scalar(d: Mapping[str, object], key: str, where: str) -> float:
    if key not in d:
        raise FileFormatError(
            f"{where}: missing key {key} (truncated or not an RPC file?); an RPC needs "
            + ", ".join(_OFFSET_SCALE_KEYS)
            + " and the four coefficient vectors"
        )
    vals = _numbers(d[key], key, where)
    if not vals:
        raise FileFormatError(f"{where}: key {key} has no value")
    if len(vals) != 1:
        raise FileFormatError(
            f"{where}: key {key} holds {len(vals)} values, expected one{_comma_hint(d[key])}"
        )
    return vals[0]


def _vector(d: Mapping[str, object], key: str, where: str, required: bool = True):
    """20 coefficients from ``key`` (one list) or ``key_1`` .. ``key_20``."""
    if key in d:
        if any(k.startswith(f"{key}_") and k[len(key) + 1 :].isdigit() for k in d):
            raise FileFormatError(
                f"{where}: {key} is given both as a list and as numbered keys {key}_1 ...; keep one"
            )
        vals = _numbers(d[key], key, where)
        if len(vals) != poly.N_TERMS:
            raise FileFormatError(
                f"{where}: {key} has {len(vals)} coefficient(s), an RPC00B polynomial has "
                f"exactly {poly.N_TERMS}{_comma_hint(d[key])}"
            )
        return vals
    numbered: dict[int, str] = {}
    prefix = f"{key}_"
    for k in d:
        if not k.startswith(prefix):
            continue
        digits = k[len(prefix) :]
        if not digits.isascii() or not digits.isdigit():
            continue
        stripped = digits.lstrip("0")
        if len(stripped) > 6:  # no int() of a number with thousands of digits
            raise FileFormatError(
                f"{where}: {k[:60]}... found, but an RPC00B polynomial has exactly "
                f"{poly.N_TERMS} coefficients ({key}_1 .. {key}_{poly.N_TERMS})"
            )
        i = int(stripped or "0")
        if i in numbered:
            raise FileFormatError(
                f"{where}: {numbered[i]} and {k} both give coefficient {i} of {key}; keep one"
            )
        numbered[i] = k
    if not numbered:
        if not required:
            return None
        raise FileFormatError(
            f"{where}: missing key {key} (neither {key} with 20 values nor {key}_1 .. "
            f"{key}_20); truncated or not an RPC file?"
        )
    extra = sorted(i for i in numbered if not 1 <= i <= poly.N_TERMS)
    if extra:
        raise FileFormatError(
            f"{where}: {key}_{extra[0]} found, but an RPC00B polynomial has exactly "
            f"{poly.N_TERMS} coefficients ({key}_1 .. {key}_{poly.N_TERMS})"
        )
    missing = [i for i in range(1, poly.N_TERMS + 1) if i not in numbered]
    if missing:
        shown = ", ".join(f"{key}_{i}" for i in missing[:5]) + (" ..." if len(missing) > 5 else "")
        raise FileFormatError(
            f"{where}: missing key(s) {shown} ({len(numbered)} of {poly.N_TERMS} coefficients "
            "present; truncated file?)"
        )
    out = []
    for i in range(1, poly.N_TERMS + 1):
        vals = _numbers(d[numbered[i]], numbered[i], where)
        if len(vals) != 1:
            what = "no value" if not vals else f"{len(vals)} values"
            raise FileFormatError(
                f"{where}: key {numbered[i]} has {what}, expected one number"
                f"{_comma_hint(d[numbered[i]])}"
            )
        out.append(vals[0])
    return out


def _optional_error(d: Mapping[str, object], key: str, where: str) -> float | None:
    if key not in d:
        return None
    vals = _numbers(d[key], key, where)
    if len(vals) != 1:
        raise FileFormatError(
            f"{where}: {key} holds {len(vals)} values, expected one number (-1 when unknown)"
        )
    if not np.isfinite(vals[0]):
        raise FileFormatError(
            f"{where}: {key} is {vals[0]!r}; give a finite error in metres, or -1 when unknown"
        )
    if vals[0] < 0:  # -1 means "unknown" in RPC00B
        return None
    return vals[0]


def _optional_image_size(d: Mapping[str, object], where: str) -> tuple[int, int] | None:
    """``(columns, rows)`` from ``NUM_COLUMNS`` and ``NUM_ROWS`` (pixels), None without."""
    given = [k for k in IMAGE_SIZE_KEYS if k in d]
    if not given:
        return None
    if len(given) == 1:
        other = IMAGE_SIZE_KEYS[1 - IMAGE_SIZE_KEYS.index(given[0])]
        raise FileFormatError(
            f"{where}: {given[0]} is given without {other}; give both (the image size in "
            "pixels) or neither"
        )
    cols, rows = (_image_side(_scalar(d, k, where), k, where) for k in IMAGE_SIZE_KEYS)
    return cols, rows


def rpc_from_mapping(
    d: Mapping[str, object],
    source: str = "dictionary",
    where: str | None = None,
    **extra,
) -> RPC:
    """Build an :class:`RPC` from GDAL-style keys (case-insensitive).

    Parameters
    ----------
    d : mapping
        ``LINE_OFF``, ..., ``HEIGHT_SCALE`` (numbers or strings), ``LINE_NUM_COEFF``, ...
        (20 values as a list or a space-separated string, or numbered keys ``_1`` .. ``_20``),
        optional ``ERR_BIAS``, ``ERR_RAND``, ``LON_NUM_COEFF``, ... (image-to-ground) and
        ``NUM_COLUMNS``, ``NUM_ROWS`` (the image size in pixels, as :func:`write_rpc` writes
        it; both or neither).
    source : str
        Format name stored in the model.
    where : str, optional
        Name used in error messages (file name).
    **extra
        Further :class:`RPC` fields (``image_size``, ``notes``, ...).
    """
    where = where or source
    up = {str(k).strip().upper(): v for k, v in d.items()}
    values = {name: _scalar(up, key, where) for name, key in GDAL_KEYS.items()}
    coeffs = {name: _vector(up, key, where) for name, key in GDAL_COEFF_KEYS.items()}
    direct_vecs = [_vector(up, key, where, required=False) for key in _DIRECT_KEYS]
    present = [v is not None for v in direct_vecs]
    direct = None
    if all(present):
        direct = DirectModel(*direct_vecs)
    elif any(present):
        missing = [k for k, p in zip(_DIRECT_KEYS, present) if not p]
        raise FileFormatError(
            f"{where}: incomplete image-to-ground polynomials: missing {', '.join(missing)}"
        )
    if "IMAGE_CORRECTION" in up and "correction" not in extra:
        raw = up["IMAGE_CORRECTION"]
        if not isinstance(raw, str):
            raw = " ".join(str(v) for v in np.ravel(np.asarray(raw, dtype=object)))
        vals = _numbers(raw, "IMAGE_CORRECTION", where)
        if len(vals) != 6:
            raise FileFormatError(f"{where}: IMAGE_CORRECTION needs 6 values, got {len(vals)}")
        extra["correction"] = np.reshape(vals, (2, 3))
    if extra.get("image_size") is None:
        extra["image_size"] = _optional_image_size(up, where)
    extra.setdefault("err_bias", _optional_error(up, "ERR_BIAS", where))
    extra.setdefault("err_rand", _optional_error(up, "ERR_RAND", where))
    try:
        return RPC(**values, **coeffs, direct=direct, source=source, **extra)
    except InputError as exc:
        raise FileFormatError(f"{where}: {exc}") from exc


# --- text formats --------------------------------------------------------------------------

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_SEPARATOR = re.compile(r"[:=]")


def parse_key_value_text(text: str, where: str) -> dict[str, str]:
    """``KEY: value`` (or ``KEY=value``) lines -> dict; ``#`` lines are comments.

    Linear in the length of the text (no pattern that backtracks over a line). A key given
    twice is refused.
    """
    out: dict[str, str] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        sep = _SEPARATOR.search(s)
        name = s[: sep.start()].rstrip() if sep else ""
        if sep is None or _NAME.fullmatch(name) is None:
            raise FileFormatError(
                f"{where}, line {lineno}: expected 'KEY: value', found {s[:60]!r}"
            )
        key = name.upper()
        if key in out:
            raise FileFormatError(f"{where}, line {lineno}: key {key} appears twice")
        out[key] = s[sep.end() :].strip()
    return out


def read_key_value_text(text: str, where: str) -> RPC:
    """Read IKONOS-style or coefficient-list ``KEY: value`` text."""
    d = parse_key_value_text(text, where)
    numbered = any(k.startswith("LINE_NUM_COEFF_") for k in d)
    source = "KEY: value text, numbered coefficients" if numbered else "KEY: value text, lists"
    return rpc_from_mapping(d, source=source, where=where)


# --- OSSIM keyword lists (.geom) ---------------------------------------------------------------

#: OSSIM keyword (ossimRpcModel) -> GDAL key, offsets, scales and errors.
_OSSIM_KEYS = {
    "line_off": "LINE_OFF", "samp_off": "SAMP_OFF", "lat_off": "LAT_OFF",
    "long_off": "LONG_OFF", "height_off": "HEIGHT_OFF", "line_scale": "LINE_SCALE",
    "samp_scale": "SAMP_SCALE", "lat_scale": "LAT_SCALE", "long_scale": "LONG_SCALE",
    "height_scale": "HEIGHT_SCALE", "bias_error": "ERR_BIAS", "rand_error": "ERR_RAND",
}  # fmt: skip
#: RPC00A term order in RPC00B positions: the A polynomial's term i is B's term OSSIM_A_TO_B[i]
#: (A: 1 L P H LP LH PH LPH L2 P2 H2 L3 L2P L2H LP2 P3 P2H LH2 PH2 H3; B: as the spec).
OSSIM_A_TO_B = (0, 1, 2, 3, 4, 5, 6, 10, 7, 8, 9, 11, 14, 17, 12, 15, 18, 13, 16, 19)
_OSSIM_LINE = re.compile(r"[ \t]*([A-Za-z0-9_.]+)[ \t]*:(.*)")
_OSSIM_HINT = re.compile(
    r"^[ \t]*(?:[A-Za-z0-9_]+\.)*(?:type[ \t]*:[ \t]*ossim[A-Za-z]*RpcModel\b"
    r"|line_num_coeff_00[ \t]*:)",
    re.M | re.I,
)


def read_ossim_geom(text: str, where: str) -> RPC:
    """Read the RPC of an OSSIM keyword list (``.geom``, as written by OSSIM and the Orfeo
    ToolBox for an ``ossimRpcModel`` and its vendor subclasses).

    Keys ``line_off`` ... ``height_scale``, ``bias_error``, ``rand_error``,
    ``polynomial_format`` (``A``: RPC00A term order, reordered to RPC00B here; ``B``) and
    ``line_num_coeff_00`` .. ``_19`` (0-based), ``line_den_coeff_``, ``samp_num_coeff_``,
    ``samp_den_coeff_``; a prefix before the keys (``projection.line_off``) is allowed.
    Other keys (sensor, image size, support data) are ignored; ``//`` and ``#`` start
    comment lines. Offsets are taken as they are (OSSIM, like RPC00B, puts the centre of
    the first pixel at (0, 0)).

    Parameters
    ----------
    text : str
        The file's text.
    where : str
        The file's name, for messages.

    Returns
    -------
    RPC
        ``source`` names the format and the polynomial format.

    Raises
    ------
    FileFormatError
        A line that is not ``key: value``, a key given twice, another model type, a
        polynomial format other than A or B, missing keys (named), numbers that cannot be
        read.
    """
    d: dict[str, str] = {}
    seen: dict[str, int] = {}
    types: list[str] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith(("//", "#")):
            continue
        m = _OSSIM_LINE.fullmatch(s)
        if m is None:
            raise FileFormatError(
                f"{where}, line {lineno}: expected 'keyword: value' (OSSIM keyword list), "
                f"found {s[:60]!r}"
            )
        key = m.group(1).rsplit(".", 1)[-1].lower()
        value = m.group(2).strip()
        if key == "type":  # also of other objects in the list (datum, support data, ...)
            types.append(value)
            continue
        if key in seen and (key in _OSSIM_KEYS or key == "polynomial_format" or "coeff_" in key):
            raise FileFormatError(
                f"{where}, line {lineno}: keyword {key} appears twice (first on line "
                f"{seen[key]})"
            )
        seen.setdefault(key, lineno)
        d[key] = value
    if types and not any(re.fullmatch(r"ossim[A-Za-z]*RpcModel", t) for t in types):
        raise FileFormatError(
            f"{where}: an OSSIM geometry of type {types[0][:60]!r}, not an RPC model "
            "(type: ossimRpcModel)"
        )
    fmt = d.get("polynomial_format", "").upper()
    if fmt not in ("A", "B"):
        raise FileFormatError(
            f"{where}: polynomial_format is {d.get('polynomial_format')!r}; an OSSIM RPC "
            "keyword list needs polynomial_format: A (RPC00A) or B (RPC00B)"
        )
    mapping: dict[str, object] = {_OSSIM_KEYS[k]: v for k, v in d.items() if k in _OSSIM_KEYS}
    for vector in ("line_num_coeff", "line_den_coeff", "samp_num_coeff", "samp_den_coeff"):
        keys = [f"{vector}_{i:02d}" for i in range(20)]
        missing = [k for k in keys if k not in d]
        if missing:
            raise FileFormatError(
                f"{where}: missing {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}"
                f" (an OSSIM RPC has {vector}_00 .. {vector}_19)"
            )
        values = [_numbers(d[k], k, where) for k in keys]
        bad = [k for k, v in zip(keys, values) if len(v) != 1]
        if bad:
            raise FileFormatError(f"{where}: {bad[0]} holds {len(values[keys.index(bad[0])])} "
                                  "values, expected one number")
        coeffs = np.array([v[0] for v in values])
        if fmt == "A":
            coeffs = coeffs[np.argsort(OSSIM_A_TO_B)]  # B's term j is A's term argsort[j]
        mapping[vector.upper()] = coeffs.tolist()
    for key in ("ERR_BIAS", "ERR_RAND"):
        if key in mapping and _numbers(mapping[key], key, where) == [0.0]:
            del mapping[key]  # OSSIM writes 0 for "not given"
    return rpc_from_mapping(
        mapping, source=f"OSSIM keyword list (.geom), polynomial format {fmt}", where=where
    )


_RPB_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _rpb_assignments(text: str, where: str) -> dict[str, str]:
    """The ``name = value;`` statements of an RPB file that carry RPC values (GDAL names).

    One pass over the statements (split at ``;``); ``BEGIN_GROUP``/``END_GROUP`` lines
    and ``END;`` are skipped. A value in parentheses may span lines. An RPC key given twice
    (e.g. two ``IMAGE`` groups) is refused.
    """
    d: dict[str, str] = {}
    first_line: dict[str, int] = {}
    lineno = 1
    for stmt in text.split(";"):
        start_line = lineno
        lineno += stmt.count("\n")
        lines = [ln.strip() for ln in stmt.split("\n")]
        # drop group markers and blank lines before the assignment
        k = 0
        while k < len(lines) and (
            not lines[k] or lines[k].upper().startswith(("BEGIN_GROUP", "END_GROUP"))
        ):
            k += 1
        if k == len(lines):
            continue
        body = " ".join(lines[k:])
        name, eq, value = body.partition("=")
        name = name.strip()
        if not eq or _RPB_NAME.fullmatch(name) is None:
            continue  # "END" and other non-assignments
        mapped = _RPB_LOWER.get(name.lower())
        if mapped is None:
            continue
        where_line = f"{where}, line {start_line + k}"
        if mapped in d:
            raise FileFormatError(
                f"{where_line}: {name} given again (first on line {first_line[mapped]}); "
                "an RPB file has one IMAGE group with each key once"
            )
        value = value.strip()
        if value.startswith("("):
            if not value.endswith(")"):
                raise FileFormatError(f"{where_line}: {name} = ( ... without the closing ')'")
            value = value[1:-1]
        d[mapped] = value
        first_line[mapped] = start_line + k
    return d


def read_rpb(text: str, where: str) -> RPC:
    """Read a DigitalGlobe ``.RPB`` file."""
    d = _rpb_assignments(text, where)
    if not d:
        raise FileFormatError(f"{where}: no RPB assignments (lineOffset = ...;) found")
    for key in _COEFF_KEYS:
        if key not in d:
            rpb = next(k for k, v in _RPB_KEYS.items() if v == key)
            raise FileFormatError(f"{where}: missing key {rpb} ({key}); truncated RPB file?")
    try:
        return rpc_from_mapping(d, source="RPB", where=where)
    except FileFormatError as exc:
        msg = str(exc)
        for rpb, gdal in _RPB_KEYS.items():
            msg = msg.replace(f"missing key {gdal} ", f"missing key {rpb} ({gdal}) ")
        raise FileFormatError(msg) from exc


# --- XML formats ------------------------------------------------------------------------------


def _strip_ns(root: ElementTree.Element) -> None:
    for el in root.iter():
        if isinstance(el.tag, str) and "}" in el.tag:
            el.tag = el.tag.split("}", 1)[1]


def _find_any(root: ElementTree.Element, tag: str) -> ElementTree.Element | None:
    """The element ``tag`` anywhere below ``root``; refused when there are several."""
    found = None
    for el in root.iter(tag):
        if found is not None:
            raise FileFormatError(
                f"XML element {tag} appears more than once: one RPC per file is read; "
                "split the file"
            )
        found = el
    return found


def _find_one(el: ElementTree.Element, path: str, where: str) -> ElementTree.Element | None:
    nodes = el.findall(path)
    if len(nodes) > 1:
        raise FileFormatError(
            f"{where}: XML element {path} appears {len(nodes)} times; it must be given once"
        )
    return nodes[0] if nodes else None


def _xml_text(el: ElementTree.Element | None, path: str, where: str) -> str:
    node = None if el is None else _find_one(el, path, where)
    if node is None or node.text is None or not node.text.strip():
        raise FileFormatError(f"{where}: missing XML element {path}")
    return node.text.strip()


def _xml_number(el: ElementTree.Element, path: str, where: str) -> float:
    """One finite number from the element ``path`` (units after it are skipped)."""
    vals = _numbers(_xml_text(el, path, where), path, where)
    if len(vals) != 1 or not np.isfinite(vals[0]):
        shown = "no number" if not vals else ", ".join(repr(v) for v in vals[:3])
        raise FileFormatError(
            f"{where}: XML element {path} holds {shown}; expected one finite number"
        )
    return vals[0]


#: Largest image side accepted from a file (pixels); larger values are a corrupt file.
MAX_IMAGE_SIDE = 10**7


def _image_side(value: float, what: str, where: str) -> int:
    if not 1 <= value <= MAX_IMAGE_SIDE or value != round(value):
        raise FileFormatError(
            f"{where}: {what} = {value:g} is not an image size in pixels (a whole number from "
            f"1 to {MAX_IMAGE_SIDE})"
        )
    return round(value)


def _xml_coeffs(el: ElementTree.Element, prefix: str, where: str, block: str) -> list[float]:
    vals = []
    for i in range(1, poly.N_TERMS + 1):
        node = _find_one(el, f"{prefix}_{i}", f"{where} ({block})")
        if node is None or node.text is None or not node.text.strip():
            raise FileFormatError(
                f"{where}: missing XML element {block}/{prefix}_{i} (an RPC00B polynomial has "
                f"{poly.N_TERMS} coefficients)"
            )
        vals.extend(_numbers(node.text, f"{prefix}_{i}", where))
    if el.find(f"{prefix}_{poly.N_TERMS + 1}") is not None:
        raise FileFormatError(
            f"{where}: {block}/{prefix}_{poly.N_TERMS + 1} found; an RPC00B polynomial has "
            f"exactly {poly.N_TERMS} coefficients"
        )
    return vals


def read_dimap(root: ElementTree.Element, where: str) -> RPC:
    """Read the ``Rational_Function_Model`` of a DIMAP (v2 or v3) document."""
    rfm = _find_any(root, "Rational_Function_Model")
    g = rfm.find("Global_RFM") if rfm is not None else None
    if g is None:
        raise FileFormatError(f"{where}: DIMAP file without Rational_Function_Model/Global_RFM")
    inverse = g.find("Inverse_Model")
    forward = g.find("Direct_Model")
    version = "v2"
    if inverse is None:
        inverse = g.find("GroundtoImage_Values")
        forward = g.find("ImagetoGround_Values")
        version = "v3"
    if inverse is None:
        raise FileFormatError(
            f"{where}: DIMAP Global_RFM has neither Inverse_Model (v2) nor GroundtoImage_Values "
            "(v3): no ground-to-image polynomials"
        )
    block = "Inverse_Model" if version == "v2" else "GroundtoImage_Values"
    d: dict[str, object] = {key: _xml_coeffs(inverse, key, where, block) for key in _COEFF_KEYS}
    if forward is not None:
        if version == "v2":
            names = {
                "LON_NUM_COEFF": "SAMP_NUM_COEFF",
                "LON_DEN_COEFF": "SAMP_DEN_COEFF",
                "LAT_NUM_COEFF": "LINE_NUM_COEFF",
                "LAT_DEN_COEFF": "LINE_DEN_COEFF",
            }
        else:
            names = {k: k for k in _DIRECT_KEYS}
        fblock = "Direct_Model" if version == "v2" else "ImagetoGround_Values"
        for key, tag in names.items():
            d[key] = _xml_coeffs(forward, tag, where, fblock)
    validity = g.find("RFM_Validity")
    if validity is None:
        raise FileFormatError(f"{where}: missing XML element Global_RFM/RFM_Validity")
    for key in _OFFSET_SCALE_KEYS:
        d[key] = _xml_text(validity, key, f"{where} (RFM_Validity)")
    domain = _find_any(g, "Direct_Model_Validity_Domain")
    if domain is None:
        domain = _find_any(root, "ImagetoGround_Validity_Domain")
    first_col = first_row = 1.0
    image_size = None
    notes = []
    if domain is not None:
        dwhere = f"{where} ({domain.tag})"
        if _find_one(domain, "FIRST_COL", dwhere) is not None:
            first_col = _xml_number(domain, "FIRST_COL", dwhere)
        if _find_one(domain, "FIRST_ROW", dwhere) is not None:
            first_row = _xml_number(domain, "FIRST_ROW", dwhere)
        has_last = [_find_one(domain, t, dwhere) is not None for t in ("LAST_COL", "LAST_ROW")]
        if all(has_last):
            last_col = _xml_number(domain, "LAST_COL", dwhere)
            last_row = _xml_number(domain, "LAST_ROW", dwhere)
            image_size = (
                _image_side(last_col - first_col + 1, "LAST_COL - FIRST_COL + 1", dwhere),
                _image_side(last_row - first_row + 1, "LAST_ROW - FIRST_ROW + 1", dwhere),
            )
    if first_col or first_row:
        vwhere = f"{where} (RFM_Validity)"
        d["SAMP_OFF"] = _scalar(d, "SAMP_OFF", vwhere) - first_col
        d["LINE_OFF"] = _scalar(d, "LINE_OFF", vwhere) - first_row
        notes.append(
            f"DIMAP pixel origin: first pixel centre at (col {first_col:g}, row {first_row:g}); "
            f"SAMP_OFF and LINE_OFF reduced by {first_col:g} and {first_row:g} to the "
            "convention first pixel centre = (0, 0)"
        )
    return rpc_from_mapping(
        d, source=f"DIMAP {version} XML", where=where, image_size=image_size, notes=tuple(notes)
    )


def read_dg_xml(root: ElementTree.Element, where: str) -> RPC:
    """Read the ``RPB/IMAGE`` block of a DigitalGlobe/Maxar (WorldView, QuickBird) XML file."""
    rpb = _find_any(root, "RPB")
    image = rpb.find("IMAGE") if rpb is not None else None
    if image is None:
        raise FileFormatError(f"{where}: XML without RPB/IMAGE block")
    tags = {
        "LINE_OFF": "LINEOFFSET", "SAMP_OFF": "SAMPOFFSET", "LAT_OFF": "LATOFFSET",
        "LONG_OFF": "LONGOFFSET", "HEIGHT_OFF": "HEIGHTOFFSET", "LINE_SCALE": "LINESCALE",
        "SAMP_SCALE": "SAMPSCALE", "LAT_SCALE": "LATSCALE", "LONG_SCALE": "LONGSCALE",
        "HEIGHT_SCALE": "HEIGHTSCALE",
    }  # fmt: skip
    d: dict[str, object] = {k: _xml_text(image, t, f"{where} (RPB/IMAGE)") for k, t in tags.items()}
    for key in _COEFF_KEYS:
        tag = key.replace("_COEFF", "COEF").replace("_", "")
        d[key] = _xml_text(image, f"{tag}List/{tag}", f"{where} (RPB/IMAGE)")
    for key, tag in (("ERR_BIAS", "ERRBIAS"), ("ERR_RAND", "ERRRAND")):
        node = _find_one(image, tag, f"{where} (RPB/IMAGE)")
        if node is not None and node.text and node.text.strip():
            d[key] = node.text.strip()
    image_size = None
    imd = _find_any(root, "IMD")
    iwhere = f"{where} (IMD)"
    if (
        imd is not None
        and _find_one(imd, "NUMROWS", iwhere) is not None
        and _find_one(imd, "NUMCOLUMNS", iwhere) is not None
    ):
        image_size = (
            _image_side(_xml_number(imd, "NUMCOLUMNS", iwhere), "NUMCOLUMNS", iwhere),
            _image_side(_xml_number(imd, "NUMROWS", iwhere), "NUMROWS", iwhere),
        )
    return rpc_from_mapping(d, source="DigitalGlobe XML (RPB block)", where=where,
                            image_size=image_size)  # fmt: skip


def read_xml(text: bytes | str, where: str) -> RPC:
    """Read a DIMAP or DigitalGlobe XML RPC file (bytes: the declared encoding is used)."""
    root = parse_xml(text, where)
    _strip_ns(root)
    try:
        has_dimap = _find_any(root, "Rational_Function_Model") is not None
        has_rpb = not has_dimap and _find_any(root, "RPB") is not None
    except FileFormatError as exc:
        raise FileFormatError(f"{where}: {exc}") from None
    try:
        if has_dimap:
            return read_dimap(root, where)
        if has_rpb:
            return read_dg_xml(root, where)
    except FileFormatError as exc:
        if str(exc).startswith("XML element"):
            raise FileFormatError(f"{where}: {exc}") from None
        raise
    raise FileFormatError(
        f"{where}: XML file without a known RPC block (DIMAP Rational_Function_Model or "
        "DigitalGlobe RPB)"
    )


# --- raster files --------------------------------------------------------------------------


def read_raster_tags(path: Path) -> RPC:
    """Read the ``RPC`` metadata domain of a GeoTIFF/NITF through ``rasterio``."""
    try:
        import rasterio
    except ImportError as exc:
        raise FileFormatError(
            f"{path}: reading RPC tags of raster files needs rasterio; install the extra "
            "'photogeom[geotiff]' (pip install rasterio), or give the RPC sidecar file"
        ) from exc
    import warnings

    try:
        with warnings.catch_warnings():
            # a file without geotransform warns in rasterio; the missing RPCs are reported below
            warnings.simplefilter(
                "ignore", getattr(rasterio.errors, "NotGeoreferencedWarning", Warning)
            )
            with rasterio.open(path) as src:
                tags = src.tags(ns="RPC")
                size = (src.width, src.height)
    except Exception as exc:  # rasterio raises its own RasterioIOError family
        raise FileFormatError(f"{path}: cannot open as a raster ({exc})") from exc
    if not tags:
        raise FileFormatError(f"{path}: the raster has no RPC metadata")
    return rpc_from_mapping(
        tags, source="raster RPC metadata (GDAL)", where=str(path), image_size=size
    )


# --- detection ---------------------------------------------------------------------------------

_RASTER_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+", b"NITF", b"NSIF")
_RASTER_SUFFIX = {".tif", ".tiff", ".ntf", ".nitf", ".jp2"}


_RPB_HINT = re.compile(r"\blineOffset[ \t]*=|BEGIN_GROUP[ \t]*=[ \t]*IMAGE", re.I)
_TEXT_LINE = re.compile(r"^[ \t]*[A-Za-z][A-Za-z0-9_]*[ \t]*[:=]", re.M)
_TEXT_HINT = re.compile(r"(LINE|SAMP|LAT|LONG|HEIGHT)_(OFF|SCALE|NUM_COEFF|DEN_COEFF)", re.I)


def decode_text(data: bytes) -> str:
    """Text of a file: UTF-8 (a byte-order mark is dropped) or UTF-16 with a byte-order mark;
    bytes that are not UTF-8 are replaced (they can only be part of a value, which is then
    reported as not a number)."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16", errors="replace")
    return data.decode("utf-8", errors="replace").removeprefix("\ufeff")


def detect_format(path: Path, head: bytes) -> str:
    """``"raster"``, ``"xml"``, ``"rpb"``, ``"ossim"``, ``"text"`` or ``"unknown"``.

    Every pattern is anchored to one line (``[ \\t]``, not ``\\s``), so the detection is
    linear in the head it looks at.
    """
    if head.startswith(_RASTER_MAGIC) or (
        path.suffix.lower() in _RASTER_SUFFIX and not head.lstrip().startswith(b"<")
    ):
        return "raster"
    text = decode_text(head).lstrip("\ufeff \t\r\n")
    if text.startswith("<"):
        return "xml"
    if _RPB_HINT.search(text):
        return "rpb"
    if _OSSIM_HINT.search(text):
        return "ossim"
    if _TEXT_LINE.search(text) and _TEXT_HINT.search(text):
        return "text"
    return "unknown"


def read_rpc(path: str | Path) -> RPC:
    """Read an RPC file of any supported format (detected from the content).

    Parameters
    ----------
    path : str or pathlib.Path
        IKONOS-style ``_RPC.TXT``, ``KEY: value`` text, DigitalGlobe ``.RPB``, OSSIM / Orfeo
        ToolBox ``.geom`` keyword lists (``ossimRpcModel``), DIMAP XML,
        DigitalGlobe/Maxar XML or a GeoTIFF with RPC tags (needs the ``geotiff`` extra).
        The text and XML formats may come from a pipe (read once per
        :func:`photogeom.io.sources.pipe_reads` scope: a command that reads it again gets
        the same bytes); a raster may not (GDAL reads it with seeks), nor may a device.

    Returns
    -------
    RPC
        Offsets/scales in px, deg and m; ``source`` names the file.

    Raises
    ------
    FileFormatError
        No such file, a folder, a device, a raster from a pipe, an empty or too large file,
        unknown format, missing keys (named), coefficient vectors that do not have 20
        values, keys without a value, numbers that cannot be read.
    """
    p = Path(path)
    source = input_kind(p)
    if source == "missing":
        raise FileFormatError(f"{p}: no such file")
    if source == "folder":
        raise FileFormatError(f"{p}: a folder, not an RPC file")
    if source == "device":
        raise FileFormatError(device_message(p, "RPC file"))
    try:
        if source == "pipe":
            # read once per command (io.sources.pipe_reads): a second read of the pipe in
            # the command, by this reader or another, gets the same bytes
            data = pipe_bytes(p, max(MAX_XML_BYTES, MAX_TEXT_BYTES))
            head, size = data[:65536], len(data)
        else:
            size = p.stat().st_size
            with open(p, "rb") as fh:
                head = fh.read(65536)
        if not head.strip() and size <= len(head):
            raise FileFormatError(f"{p}: the file is empty")
        kind = detect_format(p, head)
        if kind == "unknown":
            raise FileFormatError(f"{p}: not a known RPC file format; supported: {FORMATS}")
        if kind == "raster" and source == "pipe":
            raise FileFormatError(
                pipe_message(p, "the raster", "GDAL reads a GeoTIFF or NITF with seeks")
            )
        if kind == "raster":
            data = b""
        else:
            limit = MAX_XML_BYTES if kind == "xml" else MAX_TEXT_BYTES
            if source != "pipe":
                if size > limit:
                    raise FileFormatError(
                        f"{p}: {size} bytes is too large for an RPC file of this kind (at "
                        f"most {limit} bytes; an RPC is a few kB): wrong file?"
                    )
                data = read_input_bytes(p, limit)
            if len(data) > limit:
                raise FileFormatError(f"{p}: more than {limit} bytes; wrong file?")
    except OSError as exc:
        raise FileFormatError(f"cannot read {p}: {exc.strerror or exc}") from None
    where = str(p)
    if kind == "raster":
        return read_raster_tags(p)
    if not data.strip():
        raise FileFormatError(f"{p}: the file is empty")
    if kind == "xml":
        return read_xml(data, where)
    text = decode_text(data)
    if kind == "rpb":
        return read_rpb(text, where)
    if kind == "ossim":
        return read_ossim_geom(text, where)
    if kind == "text":
        return read_key_value_text(text, where)
    raise FileFormatError(f"{p}: not a known RPC file format; supported: {FORMATS}")
