"""The calibration of one sensor of an Agisoft Metashape camera export.

Metashape's File > Export > Export Cameras (format "Agisoft XML") writes a ``<document>``
whose ``<chunk>`` holds ``<sensors>`` (the cameras: one ``<sensor id=".." label=".."
type="frame">`` per calibration group) and ``<cameras>`` (the images and their poses). A
sensor has its image size (``<resolution width=".." height=".."/>``), properties, bands and
up to two calibrations of the same form as a calibration XML: ``<calibration type="frame"
class="initial">`` (the values before the alignment, e.g. a precalibration) and ``<calibration
type="frame" class="adjusted">`` (the values the alignment estimated), each with its own
``<resolution>``, ``<f>``, ``<cx>``, ``<cy>``, ``<b1>``, ``<b2>``, ``<k1>``..``<k4>``,
``<p1>``, ``<p2>``; beside them, in the sensor, the ``<covariance>`` of the adjusted
calibration (``<params>`` the estimated terms, ``<coeffs>`` their covariance row by row).

:func:`sensor_calibration` reads one sensor's calibration (the adjusted one, else the
initial one) and the covariance, with the checks of the calibration XML's readers. The
images' poses (``<cameras>``) are not read.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from ..errors import FileFormatError
from .metashape import MetashapeCalibration, MetashapeXMLWarning

#: Metashape's camera types (``<sensor type="..">``) other than "frame", with the model they
#: name; photogeom has none of them (its frame camera is the Brown model).
OTHER_SENSOR_TYPES = {
    "fisheye": "the equidistant fisheye model",
    "equidistant_fisheye": "the equidistant fisheye model",
    "equisolid_fisheye": "the equisolid fisheye model",
    "spherical": "the spherical (equirectangular) panorama",
    "cylindrical": "the cylindrical panorama",
    "rpc": "the rational polynomial (RPC) model of a satellite image",
}
#: The clause of the error that asks for a sensor; the command line writes it in its words.
CHOOSE_SENSOR = "choose one with sensor= (its id or label)"
#: Sensors listed in an error at most.
LISTED_SENSORS = 20


@dataclass(frozen=True)
class SensorCalibration:
    """The calibration of one sensor of a Metashape camera export.

    Attributes
    ----------
    sensor_id : str
        The sensor's ``id``.
    label : str
        Its ``label`` (empty when it has none).
    calibration_class : str
        ``"adjusted"`` (estimated by the alignment) or ``"initial"`` (before it), the
        ``class`` of the ``<calibration>`` read.
    calibration : MetashapeCalibration
        The calibration (px; coefficients unitless).
    covariance : (names, matrix) or None
        The ``<covariance>`` of the adjusted calibration (Metashape's names in the order of
        ``<params>``; px^2 for ``f, cx, cy, b1, b2``), None without one or for the initial
        calibration.
    """

    sensor_id: str
    label: str
    calibration_class: str
    calibration: MetashapeCalibration
    covariance: tuple[tuple[str, ...], np.ndarray] | None


def _line(el: ET.Element | None, lines: dict[int, int] | None) -> str:
    """`` (line N)`` of an element, empty when unknown."""
    n = None if el is None or lines is None else lines.get(id(el))
    return "" if n is None else f" (line {n})"


def _name(sensor: ET.Element) -> str:
    label = sensor.get("label")
    return f'<sensor id="{sensor.get("id", "")}"' + (f' label="{label}">' if label else ">")


def _describe(sensor: ET.Element) -> str:
    classes = [c.get("class") or "calibration" for c in sensor.findall("calibration")]
    state = ", ".join(classes) if classes else "no calibration"
    return (
        f"{sensor.get('id', '?')} {sensor.get('label', '')!r} ({sensor.get('type', '?')}: {state})"
    )


def _listing(sensors: list[ET.Element]) -> str:
    shown = "; ".join(_describe(s) for s in sensors[:LISTED_SENSORS])
    return shown + ("; ..." if len(sensors) > LISTED_SENSORS else "")


def _sensors(root: ET.Element, where: str) -> list[ET.Element]:
    """The ``<sensor>`` elements of the one chunk of a camera export."""
    chunks = [root] if root.tag == "chunk" else root.findall("chunk")
    with_sensors = [c for c in chunks if c.find("sensors") is not None]
    if len(with_sensors) > 1:
        labels = ", ".join(repr(c.get("label", c.get("id", "?"))) for c in with_sensors)
        raise FileFormatError(
            f"{where}: a Metashape camera export with {len(with_sensors)} chunks ({labels}); "
            "export the cameras of one chunk (File > Export > Export Cameras exports the "
            "active chunk)"
        )
    sensors = with_sensors[0].find("sensors").findall("sensor") if with_sensors else []
    if not sensors:
        raise FileFormatError(
            f"{where}: a Metashape <{root.tag}> without <chunk><sensors><sensor>: not a camera "
            "export (File > Export > Export Cameras, Agisoft XML) or a calibration XML (root "
            "<calibration>)"
        )
    return sensors


def _choose(sensors: list[ET.Element], sensor: int | str | None, where: str) -> ET.Element:
    if sensor is None:
        if len(sensors) == 1:
            return sensors[0]
        raise FileFormatError(
            f"{where}: a Metashape camera export with {len(sensors)} sensors "
            f"({_listing(sensors)}); {CHOOSE_SENSOR}"
        )
    key = str(sensor)
    if isinstance(sensor, int) or key.startswith("id:"):  # an id only
        key = key.removeprefix("id:")
        found = [s for s in sensors if s.get("id") == key]
    elif key.startswith("label:"):  # a label only
        key = key.removeprefix("label:")
        found = [s for s in sensors if s.get("label") == key]
    else:
        found = [s for s in sensors if key in (s.get("id"), s.get("label"))]
    if len(found) == 1:
        return found[0]
    if not found:
        raise FileFormatError(
            f"{where}: no sensor with id or label {key!r}; the sensors (id 'label') are "
            f"{_listing(sensors)}"
        )
    ids = {s.get("id") for s in found}
    raise FileFormatError(
        f"{where}: {len(found)} sensors have the id or label {key!r} ({_listing(found)}); "
        + (
            f"write id:{key} for the sensor of that id or label:{key} for the one of that label"
            if key in ids and len(ids) == len(found)
            else "choose one by its id"
        )
    )


def read_sensor(
    data: bytes | str, where: str, sensor: int | str | None = None, *, strict: bool = False
) -> SensorCalibration:
    """:func:`sensor_calibration` of a camera export's text, the messages naming lines.

    Parameters
    ----------
    data : bytes or str
        The document (bytes in the encoding it declares).
    where : str
        Its name in messages (the file).
    sensor : int or str, optional
        The sensor's ``id`` or ``label``; needed when the chunk has several sensors.
    strict : bool, default False
        Refuse unknown tags in the ``<calibration>``.

    Returns
    -------
    SensorCalibration

    Raises
    ------
    FileFormatError
        As :func:`photogeom.xmlsafe.parse_xml` and :func:`sensor_calibration`.
    """
    from ..xmlsafe import parse_xml_lines

    root, lines = parse_xml_lines(data, where)
    return sensor_calibration(root, where, sensor, strict=strict, lines=lines)


def sensor_calibration(
    root: ET.Element,
    where: str,
    sensor: int | str | None = None,
    *,
    strict: bool = False,
    lines: dict[int, int] | None = None,
) -> SensorCalibration:
    """The calibration and covariance of one sensor of a parsed Metashape camera export.

    Parameters
    ----------
    root : xml.etree.ElementTree.Element
        The document's root, ``<document>`` (or ``<chunk>``), as
        :func:`photogeom.xmlsafe.parse_xml` gives it.
    where : str
        The document's name in messages (the file).
    sensor : int or str, optional
        The sensor's ``id`` or ``label``; needed when the chunk has several sensors. An int,
        or a text ``"id:ID"``, matches ids only; ``"label:LABEL"`` labels only; other text
        either (refused when it is one sensor's id and another's label).
    strict : bool, default False
        Refuse unknown tags in the ``<calibration>`` (else they are ignored with a
        ``MetashapeXMLWarning``), as :func:`photogeom.camera.read_metashape_xml`.
    lines : dict, optional
        ``id(element)`` -> line, as :func:`photogeom.xmlsafe.parse_xml_lines` gives it: the
        messages then name the line of the element refused.

    Returns
    -------
    SensorCalibration
        The adjusted calibration with its covariance; the initial calibration (and no
        covariance) for a sensor without an adjusted one, with a ``MetashapeXMLWarning``.
        The image size is the calibration's ``<resolution>``, else the sensor's.

    Raises
    ------
    FileFormatError
        Several chunks with sensors, or none; several sensors and no ``sensor``, or a
        ``sensor`` that names none or several (the sensors are listed); a sensor of another
        camera type (fisheye, spherical, cylindrical, RPC: named) or without a
        ``<calibration>``; two calibrations of one class; a ``<covariance>`` without an
        adjusted calibration; a calibration or covariance refused as in a calibration XML
        (each named with its sensor).

    Warns
    -----
    MetashapeXMLWarning
        When the initial calibration is read (the sensor has no adjusted one).
    """
    from .calibration_files import covariance_from_element

    chosen = _choose(_sensors(root, where), sensor, where)
    name = f"{where}: {_name(chosen)}{_line(chosen, lines)}"
    kind = chosen.get("type", "frame")
    if kind != "frame":
        model = OTHER_SENSOR_TYPES.get(kind, "a camera model")
        raise FileFormatError(
            f"{name} is a {kind!r} camera ({model}): photogeom reads frame cameras only "
            '(type="frame", the Brown model)'
        )
    calibrations: dict[str, ET.Element] = {}
    for el in chosen.findall("calibration"):
        cls = el.get("class", "adjusted")  # a lone calibration without class: the sensor's
        if cls not in ("adjusted", "initial"):
            raise FileFormatError(
                f"{name}: <calibration class={cls!r}>{_line(el, lines)}; Metashape writes "
                'class "adjusted" or "initial"'
            )
        if cls in calibrations:
            raise FileFormatError(
                f"{name}: two <calibration class={cls!r}> elements"
                f"{_line(calibrations[cls], lines)}{_line(el, lines).replace(' (', ' and (')}"
            )
        calibrations[cls] = el
    if not calibrations:
        raise FileFormatError(
            f"{name} has no <calibration> (a camera Metashape has not calibrated: align the "
            "photos, or load a calibration in Tools > Camera Calibration, then export again)"
        )
    cls = "adjusted" if "adjusted" in calibrations else "initial"
    res = chosen.find("resolution")
    size = None if res is None else (res.get("width"), res.get("height"))
    if size is not None and None in size:
        raise FileFormatError(f"{name}: <resolution> needs both width and height (px)")
    line = _line(calibrations[cls], lines)
    source = f'{where}: {_name(chosen)} <calibration class="{cls}">{line}'
    calib = MetashapeCalibration._from_calibration_element(
        calibrations[cls], strict=strict, source=source, size=size
    )
    cov_el = chosen.find("covariance")
    if cls == "initial":
        if cov_el is not None:
            raise FileFormatError(
                f"{name}: a <covariance>{_line(cov_el, lines)} but no adjusted calibration; "
                "Metashape writes the covariance of the calibration its alignment estimated"
            )
        warnings.warn(
            f"{name} has no adjusted calibration: its initial one (before any alignment) was read",
            MetashapeXMLWarning,
            stacklevel=3,
        )
    cov = covariance_from_element(cov_el, f"{where}: {_name(chosen)}{_line(cov_el, lines)}")
    return SensorCalibration(
        sensor_id=chosen.get("id", ""),
        label=chosen.get("label", ""),
        calibration_class=cls,
        calibration=calib,
        covariance=cov,
    )
