"""Calibration files for other tools: Metashape XML, photogeom camera JSON, OpenCV YAML.

A frame-camera calibration (:class:`~photogeom.camera.metashape.MetashapeCalibration`, e.g.
one adjusted by :func:`photogeom.bundle.bundle_adjust`) is written, with its standard
deviations and covariance where the format has a place for them, as

* ``.xml``: Agisoft Metashape's calibration XML (``f``, ``cx``, ``cy`` in px, ``cx, cy``
  offsets from the image centre, ``b1``, ``b2`` in px, ``k1..k4``, ``p1``, ``p2`` in
  Metashape's order) with Metashape's ``<covariance>`` (``<params>`` the free parameters,
  ``<coeffs>`` their covariance row by row) when a covariance is given;
* ``.json``: photogeom's camera JSON, read by ``--camera`` of ``camera project``, ``orient
  resection`` and ``orient intersection`` (its ``interior``) and by :func:`read_calibration`
  (its ``calibration``, the Metashape terms), with ``std`` and ``covariance``;
* ``.yaml`` / ``.yml``: OpenCV's ``cv2.FileStorage`` YAML: ``image_width``,
  ``image_height``, ``camera_matrix`` ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (px, the
  top-left pixel's centre at (0, 0): ``cx = w/2 + cx_metashape - 0.5``, ``fx = f + b1``,
  ``fy = f``), ``distortion_coefficients`` ``(k1, k2, p1, p2, k3)`` (OpenCV's ``p1, p2``
  are Metashape's ``p2, p1``) and, with a covariance, ``std_deviations_intrinsics``
  ``(fx, fy, cx, cy, k1, k2, p1, p2, k3)`` as ``cv2.calibrateCameraExtended`` orders them
  (0 for parameters that were held). Exact only when ``k4 = b2 = 0``; otherwise refused.
"""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from .metashape import MetashapeCalibration

#: File-name suffix -> calibration file format.
CALIBRATION_SUFFIXES = {".xml": "metashape", ".json": "json", ".yaml": "opencv", ".yml": "opencv"}
#: Calibration parameters, Metashape's names, in the order of ``photogeom.bundle``.
PARAMETERS = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")
#: Order of the parameters in Metashape's ``<covariance>``.
METASHAPE_ORDER = ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
#: OpenCV intrinsics of ``std_deviations_intrinsics``, in OpenCV's order.
OPENCV_INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
#: ``d OpenCV intrinsic / d Metashape parameter`` (constant: the conversion is linear).
_OPENCV_FROM = {
    "fx": {"f": 1.0, "b1": 1.0},
    "fy": {"f": 1.0},
    "cx": {"cx": 1.0},
    "cy": {"cy": 1.0},
    "k1": {"k1": 1.0},
    "k2": {"k2": 1.0},
    "p1": {"p2": 1.0},
    "p2": {"p1": 1.0},
    "k3": {"k3": 1.0},
}


def calibration_format(path: str | os.PathLike, option: str = "path") -> str:
    """The calibration file format named by the suffix of ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        A file name ending in ``.xml``, ``.json``, ``.yaml`` or ``.yml``.
    option : str, default "path"
        Name of the argument in the error message (a CLI option name in the CLI).

    Returns
    -------
    str
        ``"metashape"``, ``"json"`` or ``"opencv"``.

    Raises
    ------
    InputError
        For another suffix.
    """
    fmt = CALIBRATION_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(
            f"{option} {path}: the suffix names the format; end the name in .xml (Metashape "
            "calibration XML), .json (photogeom camera JSON) or .yaml/.yml (OpenCV "
            "FileStorage)"
        )
    return fmt


def _checked_covariance(covariance) -> tuple[tuple[str, ...], np.ndarray] | None:
    if covariance is None:
        return None
    names, matrix = covariance
    names = tuple(str(n) for n in names)
    unknown = [n for n in names if n not in PARAMETERS]
    if unknown or len(set(names)) != len(names):
        raise InputError(
            f"covariance names {', '.join(names)}: give distinct calibration parameters "
            f"({', '.join(PARAMETERS)})"
        )
    C = np.asarray(matrix, dtype=float)
    if C.shape != (len(names), len(names)) or not np.all(np.isfinite(C)):
        raise InputError(
            f"covariance: a finite {len(names)} x {len(names)} matrix for the names "
            f"{', '.join(names) or '(none)'} is needed, got shape {C.shape}"
        )
    return names, C


def _std_of(
    std: Mapping[str, float] | None, cov: tuple[tuple[str, ...], np.ndarray] | None
) -> dict[str, float]:
    """Standard deviations of the estimated parameters (finite ones only), px / unitless."""
    out: dict[str, float] = {}
    if cov is not None:
        names, C = cov
        out.update({n: math.sqrt(max(float(C[i, i]), 0.0)) for i, n in enumerate(names)})
    for name, value in (std or {}).items():
        if name not in PARAMETERS:
            raise InputError(
                f"std: unknown calibration parameter {name!r} ({', '.join(PARAMETERS)})"
            )
        v = float(value)
        if math.isfinite(v):  # NaN: a parameter that was held (not estimated)
            if v < 0:
                raise InputError(f"std of {name} is negative ({v!r})")
            out.setdefault(name, v)
    return {n: out[n] for n in PARAMETERS if n in out}


def metashape_xml_text(
    calibration: MetashapeCalibration,
    covariance: tuple[Sequence[str], np.ndarray] | None = None,
) -> str:
    """Metashape calibration XML, with ``<covariance>`` when a covariance is given.

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration (px; coefficients unitless).
    covariance : (names, matrix), optional
        Free parameters (Metashape's names) and their covariance (px^2 for ``f, cx, cy,
        b1, b2``), e.g. ``BundleFit.calibration_covariance(group)``; written in Metashape's
        order (``f cx cy b1 b2 k1 k2 k3 k4 p1 p2``, the free ones).

    Returns
    -------
    str
        The document. photogeom's reader ignores ``<covariance>``; Metashape reads it.
    """
    text = calibration.to_xml_string()
    cov = _checked_covariance(covariance)
    if cov is None or not cov[0]:
        return text
    order = [i for n in METASHAPE_ORDER for i, m in enumerate(cov[0]) if m == n]
    names = [cov[0][i] for i in order]
    C = cov[1][np.ix_(order, order)]
    root = ET.fromstring(text)
    el = ET.SubElement(root, "covariance")
    ET.SubElement(el, "params").text = " ".join(names)
    ET.SubElement(el, "coeffs").text = " ".join(repr(float(v)) for v in C.ravel())
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def calibration_json(
    calibration: MetashapeCalibration,
    *,
    std: Mapping[str, float] | None = None,
    covariance: tuple[Sequence[str], np.ndarray] | None = None,
) -> dict:
    """photogeom's camera JSON of a calibration.

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration.
    std : mapping name -> float, optional
        Standard deviations (px for ``f, cx, cy, b1, b2``; NaN for held parameters, which
        are left out), e.g. ``BundleFit.calibration_std[group]``.
    covariance : (names, matrix), optional
        Covariance of the free parameters (its diagonal gives ``std`` where ``std`` is not
        given).

    Returns
    -------
    dict
        ``interior``: :meth:`InteriorOrientation.to_dict` (px, y up, origin at the image
        centre: ``x0 = cx``, ``y0 = -cy``), what ``--camera`` reads; ``calibration``: the
        Metashape terms (px); ``std``: standard deviations of the estimated Metashape
        parameters (px; ``x0``, ``y0`` of ``interior`` have those of ``cx``, ``cy``);
        ``covariance``: ``{"names", "matrix"}``; ``opencv``: camera matrix and distortion
        vector when the conversion is exact (``k4 = b2 = 0``).
    """
    cov = _checked_covariance(covariance)
    out: dict = {
        "interior": calibration.interior_orientation().to_dict(),
        "calibration": calibration.to_dict(),
        "unit": "px",
    }
    s = _std_of(std, cov)
    if s:
        out["std"] = s
    if cov is not None and cov[0]:
        out["covariance"] = {"names": list(cov[0]), "matrix": cov[1].tolist()}
    if calibration.k4 == 0.0 and calibration.b2 == 0.0:
        K, dist = calibration.to_opencv()
        out["opencv"] = {
            "image_size": [calibration.width, calibration.height],
            "camera_matrix": K.tolist(),
            "dist_coeffs": dist.tolist(),
        }
    return out


def _opencv_matrix(name: str, values: np.ndarray) -> str:
    rows, cols = values.shape
    data = ", ".join(repr(float(v)) for v in values.ravel())
    return (
        f"{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n"
        f"   data: [ {data} ]\n"
    )


def opencv_yaml_text(
    calibration: MetashapeCalibration,
    covariance: tuple[Sequence[str], np.ndarray] | None = None,
) -> str:
    """OpenCV ``cv2.FileStorage`` YAML of a calibration (see the module docstring).

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration; ``k4`` and ``b2`` must be zero.
    covariance : (names, matrix), optional
        Covariance of the free parameters: adds ``std_deviations_intrinsics`` (not when it
        names no parameter).

    Returns
    -------
    str
        The document (``%YAML:1.0``), numbers with 17 significant digits.

    Raises
    ------
    InputError
        When ``k4`` or ``b2`` is non-zero (OpenCV has no such terms).
    """
    K, dist = calibration.to_opencv()
    cov = _checked_covariance(covariance)
    text = (
        "%YAML:1.0\n---\n"
        f"image_width: {calibration.width}\nimage_height: {calibration.height}\n"
        + _opencv_matrix("camera_matrix", K)
        + _opencv_matrix("distortion_coefficients", dist.reshape(1, -1))
    )
    if cov is not None and cov[0]:  # nothing estimated: no standard deviations
        names, C = cov
        A = np.zeros((len(OPENCV_INTRINSICS), len(names)))
        for i, cv in enumerate(OPENCV_INTRINSICS):
            for j, n in enumerate(names):
                A[i, j] = _OPENCV_FROM[cv].get(n, 0.0)
        var = np.einsum("ij,jk,ik->i", A, C, A)
        text += _opencv_matrix("std_deviations_intrinsics", np.sqrt(np.maximum(var, 0.0))[None])
    return text


def calibration_text(
    calibration: MetashapeCalibration,
    fmt: str,
    *,
    std: Mapping[str, float] | None = None,
    covariance: tuple[Sequence[str], np.ndarray] | None = None,
) -> str:
    """The text of a calibration file in format ``fmt``.

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration.
    fmt : {"metashape", "json", "opencv"}
        The format (:func:`calibration_format` gives it from a file name).
    std, covariance
        As in :func:`calibration_json` (Metashape XML and OpenCV YAML use the covariance
        only).

    Returns
    -------
    str
        The file's text.

    Raises
    ------
    InputError
        For an unknown format, or ``k4``/``b2`` non-zero in OpenCV's.
    """
    if fmt == "metashape":
        return metashape_xml_text(calibration, covariance)
    if fmt == "json":
        data = calibration_json(calibration, std=std, covariance=covariance)
        return json.dumps(data, indent=1, allow_nan=False) + "\n"
    if fmt == "opencv":
        return opencv_yaml_text(calibration, covariance)
    raise InputError(f"unknown calibration format {fmt!r}; use 'metashape', 'json' or 'opencv'")


def write_calibration(
    calibration: MetashapeCalibration,
    path: str | os.PathLike,
    *,
    std: Mapping[str, float] | None = None,
    covariance: tuple[Sequence[str], np.ndarray] | None = None,
) -> str:
    """Write a calibration file, format by suffix (atomically: old or complete new file).

    Parameters
    ----------
    calibration : MetashapeCalibration
        The calibration (px).
    path : str or os.PathLike
        ``.xml`` (Metashape), ``.json`` (photogeom camera JSON), ``.yaml``/``.yml`` (OpenCV).
    std : mapping name -> float, optional
        Standard deviations, px / unitless (NaN: held; JSON only).
    covariance : (names, matrix), optional
        Covariance of the free parameters, e.g. ``fit.calibration_covariance(group)``.

    Returns
    -------
    str
        The format written: ``"metashape"``, ``"json"`` or ``"opencv"``.

    Raises
    ------
    InputError
        Another suffix; ``k4`` or ``b2`` non-zero for OpenCV.
    OutputError
        The file cannot be written (nothing is changed then).
    """
    from ..atomicfile import atomic_write_text

    fmt = calibration_format(path)
    atomic_write_text(path, calibration_text(calibration, fmt, std=std, covariance=covariance))
    return fmt


def calibration_from_json(
    data: Mapping, where: str | os.PathLike = "camera JSON", image_size=None
) -> tuple[MetashapeCalibration, dict[str, float], tuple[tuple[str, ...], np.ndarray] | None]:
    """The calibration of a camera JSON object, with its standard deviations and covariance.

    Parameters
    ----------
    data : Mapping
        The JSON object: with ``calibration`` (Metashape terms, px), as
        :func:`calibration_json` writes it, or with an ``interior`` in px (the ``--camera``
        files of ``orient resection --output-params``, ``orient relative --output-cameras``,
        also inside ``model_parameters``), or a bare interior orientation.
    where : str or os.PathLike, default "camera JSON"
        Name of the file in error messages.
    image_size : (int, int), optional
        ``(width, height)`` in px, for an interior orientation that does not record it.

    Returns
    -------
    calibration : MetashapeCalibration
    std : dict
        Standard deviations (Metashape names, px) of a file written by
        :func:`calibration_json` or of the parameters an ``orient resection --calibrate``
        estimated (``x0, y0`` as ``cx, cy``); empty otherwise.
    covariance : (names, matrix) or None
        Likewise (the sign of ``y0``'s covariances turned for ``cy``).

    Raises
    ------
    FileFormatError
        No calibration in ``data``, or one that cannot be a Metashape calibration (not in
        px, without pixel geometry or image size).
    """
    from ..io.jsonfile import build_from_json
    from .interior import InteriorOrientation

    where = str(where)
    cal = data.get("calibration")
    if isinstance(cal, Mapping):
        terms = {k: v for k, v in cal.items() if k != "model"}
        calib = build_from_json(lambda d: MetashapeCalibration(**d), terms, where, "calibration")

        def extras(d: dict):
            std = _std_of(d.get("std") or {}, None)
            cov = d.get("covariance")
            return std, None if cov is None else _checked_covariance(
                (cov["names"], cov["matrix"])
            )

        std, cov = build_from_json(extras, dict(data), where, "std or covariance")
        return calib, std, cov
    outer = data
    if isinstance(data.get("model_parameters"), Mapping):
        data = data["model_parameters"]
    interior = data.get("interior") if isinstance(data.get("interior"), Mapping) else None
    if interior is None and "f" in data:
        interior = data
    if interior is None:
        raise FileFormatError(
            f"{where}: no calibration found (expected 'calibration' or 'interior', as written by "
            "write_calibration, 'bundle adjust --output-calibration' or 'orient resection "
            "--output-params')"
        )
    io = build_from_json(InteriorOrientation.from_dict, interior, where, "interior orientation")
    if io.unit != "px" or io.origin_px is None:
        raise FileFormatError(
            f"{where}: the interior orientation is in {io.unit}"
            + (" without pixel geometry (origin_px)" if io.origin_px is None else "")
            + ": a calibration file needs it in px with origin_px (a camera of a pixel "
            "calibration: --calibration, --principal-point and --unit px)"
        )
    if image_size is None and io.image_size is None:
        raise FileFormatError(
            f"{where}: the interior orientation records no image size; give it (image_size, "
            "--image-size WIDTH,HEIGHT at the command line)"
        )
    calib = build_from_json(
        lambda _: MetashapeCalibration.from_interior_orientation(io, image_size), {}, where,
        "interior orientation",
    )
    cov = build_from_json(_resection_covariance, dict(outer), where, "parameters or covariance")
    return calib, _std_of(None, cov), cov


#: Interior-orientation names of a self-calibrating resection -> Metashape's, and the sign
#: (``cy = -y0 + const``: the image y axis is up, Metashape's rows down).
_FROM_INTERIOR = {
    "f": ("f", 1.0), "x0": ("cx", 1.0), "y0": ("cy", -1.0), "b1": ("b1", 1.0),
    "b2": ("b2", 1.0), "k1": ("k1", 1.0), "k2": ("k2", 1.0), "k3": ("k3", 1.0),
    "k4": ("k4", 1.0), "p1": ("p1", 1.0), "p2": ("p2", 1.0),
}


def _resection_covariance(data: dict) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The covariance of the calibrated interior parameters of an ``orient resection
    --output-params`` file (``parameters`` by name, ``covariance`` in their order), in
    Metashape's names and signs; None when nothing was calibrated."""
    params, cov = data.get("parameters"), data.get("covariance")
    if not isinstance(params, Mapping) or cov is None:
        return None
    order = list(params)
    C = np.asarray(cov, dtype=float)
    if C.shape != (len(order), len(order)):
        raise ValueError(f"covariance of shape {C.shape} for {len(order)} parameters")
    idx = [i for i, n in enumerate(order) if n in _FROM_INTERIOR]
    if not idx:
        return None
    sign = np.array([_FROM_INTERIOR[order[i]][1] for i in idx])
    names = [_FROM_INTERIOR[order[i]][0] for i in idx]
    return _checked_covariance((names, C[np.ix_(idx, idx)] * np.outer(sign, sign)))


def _read_bytes(path: str | os.PathLike, limit: int) -> bytes:
    """The bytes of a calibration file, read once (a pipe gives its content once)."""
    from ..io.sources import device_message, input_kind

    kind = input_kind(path)
    if kind == "device":
        raise FileFormatError(device_message(path, "the calibration"))
    if kind == "folder":
        raise FileFormatError(f"cannot read {path}: it is a folder; give a calibration file")
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise FileFormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if len(data) > limit:
        raise FileFormatError(
            f"{path}: more than {limit} bytes; a calibration file is a few kB: wrong file?"
        )
    return data


def metashape_covariance_from_xml(
    data: bytes | str, where: str = "calibration XML"
) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The ``<covariance>`` of a Metashape calibration XML document, or None without one.

    Parameters
    ----------
    data : bytes or str
        The document.
    where : str, default "calibration XML"
        Its name in error messages.

    Returns
    -------
    (names, matrix) or None
        The parameters of ``<params>`` (Metashape's names) and their covariance from
        ``<coeffs>`` (row by row; px^2 for ``f, cx, cy, b1, b2``). Terms photogeom's model
        has not (``p3``, ``p4``) are left out.

    Raises
    ------
    FileFormatError
        Not XML, or a ``<covariance>`` whose ``<coeffs>`` are not ``n x n`` finite numbers
        for the ``n`` names of ``<params>``.
    """
    from ..numbers import parse_decimal
    from ..xmlsafe import parse_xml

    el = parse_xml(data, where).find("covariance")
    if el is None:
        return None
    names = (el.findtext("params") or "").split()
    try:
        values = [parse_decimal(t) for t in (el.findtext("coeffs") or "").split()]
    except ValueError:
        raise FileFormatError(f"{where}: <covariance><coeffs> holds a non-number") from None
    n = len(names)
    if len(values) != n * n or not all(math.isfinite(v) for v in values):
        raise FileFormatError(
            f"{where}: <covariance> has {len(values)} finite <coeffs> for {n} <params>; "
            f"expected {n * n}"
        )
    keep = [i for i, name in enumerate(names) if name in PARAMETERS]
    C = np.array(values, dtype=float).reshape(n, n)[np.ix_(keep, keep)]
    try:
        return _checked_covariance(([names[i] for i in keep], C))
    except InputError as exc:
        raise FileFormatError(f"{where}: <covariance>: {exc}") from exc


def read_metashape_covariance(
    path: str | os.PathLike,
) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The ``<covariance>`` of a Metashape calibration XML file (which
    :func:`read_metashape_xml` ignores), or None when the file has none.

    Parameters
    ----------
    path : str or os.PathLike
        The XML file.

    Returns
    -------
    (names, matrix) or None
        As :func:`metashape_covariance_from_xml`.

    Raises
    ------
    FileFormatError
        An unreadable file, or as :func:`metashape_covariance_from_xml`.
    """
    from .metashape import MAX_XML_BYTES

    return metashape_covariance_from_xml(_read_bytes(path, MAX_XML_BYTES), str(path))


def read_calibration_file(
    path: str | os.PathLike, image_size=None
) -> tuple[MetashapeCalibration, dict[str, float], tuple[tuple[str, ...], np.ndarray] | None]:
    """A calibration with its standard deviations and covariance, from a Metashape XML or a
    camera JSON (read once, so a pipe works; the format by its content).

    Parameters
    ----------
    path : str or os.PathLike
        The file: a document starting with ``<`` is a Metashape XML
        (:meth:`MetashapeCalibration.from_xml_string`, its ``<covariance>``), one starting
        with ``{`` a camera JSON (:func:`calibration_from_json`).
    image_size : (int, int), optional
        ``(width, height)`` in px for a camera JSON that does not record it.

    Returns
    -------
    calibration, std, covariance
        As :func:`calibration_from_json` (for an XML, ``std`` is empty and ``covariance``
        its ``<covariance>`` or None).

    Raises
    ------
    InputError
        ``image_size`` given for a Metashape XML (which records the size).
    FileFormatError
        An unreadable file, one that is neither, an OpenCV YAML (written, not read).
    """
    from ..io.jsonfile import MAX_JSON_BYTES, parse_json_bytes

    where = str(path)
    data = _read_bytes(path, MAX_JSON_BYTES)
    head = data.lstrip(b"\xef\xbb\xbf \t\r\n")[:1]
    if head == b"<" or data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        if image_size is not None:
            raise InputError(
                f"{where} is a Metashape XML, which records the image size (<width>, "
                "<height>); leave the image size out"
            )
        return (
            MetashapeCalibration.from_xml_string(data, source=where),
            {},
            metashape_covariance_from_xml(data, where),
        )
    if head == b"{":
        obj = parse_json_bytes(data, where)
        return calibration_from_json(obj, where, image_size)
    hint = (
        " (an OpenCV YAML is written, not read: read it with cv2.FileStorage and "
        "MetashapeCalibration.from_opencv)"
        if data.lstrip().startswith((b"%YAML", b"---"))
        else ""
    )
    raise FileFormatError(
        f"{where}: neither a Metashape calibration XML nor a camera JSON{hint}"
    )


def read_calibration(path: str | os.PathLike) -> MetashapeCalibration:
    """Read a calibration written by :func:`write_calibration` (Metashape XML or JSON).

    Parameters
    ----------
    path : str or os.PathLike
        A Metashape calibration XML or a photogeom camera JSON
        (:func:`calibration_from_json`), told apart by their content.

    Returns
    -------
    MetashapeCalibration

    Raises
    ------
    FileFormatError
        An unreadable file, an OpenCV YAML (read it with ``cv2.FileStorage`` and
        :meth:`MetashapeCalibration.from_opencv`), or a JSON without a calibration.
    """
    return read_calibration_file(path)[0]
