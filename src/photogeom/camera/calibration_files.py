"""Calibration files for other tools: Metashape XML, photogeom camera JSON, OpenCV YAML,
COLMAP ``cameras.txt``.

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
* ``.txt``: a COLMAP ``cameras.txt`` of one camera (``1 MODEL WIDTH HEIGHT PARAMS``, the
  smallest model that holds the calibration; as :mod:`photogeom.bundle.io_colmap`
  converts cameras). Exact only when ``k4 = b2 = 0``; no standard deviations.

All four are read by :func:`read_calibration` / :func:`read_calibration_file`, the format by
the content; OpenCV's ``cv2.FileStorage`` XML too. Terms without an exact Brown equivalent
(OpenCV's rational, thin-prism, tilt, fisheye or skew terms; COLMAP's other models) are
refused by name.
"""

from __future__ import annotations

import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError
from .metashape import MetashapeCalibration
from .metashape_export import SensorCalibration

#: File-name suffix -> calibration file format.
CALIBRATION_SUFFIXES = {
    ".xml": "metashape",
    ".json": "json",
    ".yaml": "opencv",
    ".yml": "opencv",
    ".txt": "colmap",
}
#: Calibration parameters, Metashape's names, in the order of ``photogeom.bundle``.
PARAMETERS = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")
#: Order of the parameters in Metashape's ``<covariance>``.
METASHAPE_ORDER = ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
#: Largest asymmetry of a covariance accepted, relative to ``sqrt(var_i var_j)``.
SYMMETRY_TOL = 1e-9
#: Terms of Metashape's ``<covariance>`` that photogeom's model has not (a calibration with
#: them non-zero is refused); their rows and columns are left out (the marginal covariance).
METASHAPE_EXTRA = ("p3", "p4")
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
        A file name ending in ``.xml``, ``.json``, ``.yaml``, ``.yml`` or ``.txt``.
    option : str, default "path"
        Name of the argument in the error message (a CLI option name in the CLI).

    Returns
    -------
    str
        ``"metashape"``, ``"json"``, ``"opencv"`` or ``"colmap"`` (a COLMAP ``cameras.txt``).

    Raises
    ------
    InputError
        For another suffix.
    """
    fmt = CALIBRATION_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(
            f"{option} {path}: the suffix names the format; end the name in .xml (Metashape "
            "calibration XML), .json (photogeom camera JSON), .yaml/.yml (OpenCV "
            "FileStorage) or .txt (COLMAP cameras.txt)"
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
    d = np.diagonal(C)
    if np.any(d < 0):
        i = int(np.flatnonzero(d < 0)[0])
        raise InputError(
            f"covariance: the variance of {names[i]} is negative ({float(d[i])!r}); a "
            "covariance matrix has variances >= 0 on its diagonal"
        )
    # symmetric to 1e-9 of the entries' scale (sqrt(var_i var_j) bounds |C_ij|)
    asym = np.abs(C - C.T) > SYMMETRY_TOL * np.sqrt(np.outer(d, d))
    if np.any(asym):
        i, j = (int(v) for v in np.argwhere(asym)[0])
        raise InputError(
            f"covariance is not symmetric: entry ({names[i]}, {names[j]}) is {float(C[i, j])!r} "
            f"but ({names[j]}, {names[i]}) is {float(C[j, i])!r}"
        )
    return names, C


def _std_of(
    std: Mapping[str, float] | None, cov: tuple[tuple[str, ...], np.ndarray] | None
) -> dict[str, float]:
    """Standard deviations of the estimated parameters (finite ones only), px / unitless:
    those of ``std``, and the square roots of the covariance's diagonal for the others.

    Raises
    ------
    InputError
        An unknown name or a negative value in ``std``; a value of ``std`` that is not the
        square root of the covariance's diagonal (relative 1e-9): the file would hold
        one of them silently replaced by the other.
    """
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
            if name in out and not math.isclose(v, out[name], rel_tol=1e-9):
                raise InputError(
                    f"std of {name} is {v!r} but the covariance gives {out[name]!r} (the "
                    "square root of its diagonal): give the standard deviations and the "
                    "covariance of one adjustment, or only one of them"
                )
            out[name] = v
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
        given; where both are given they must agree).

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
    fmt : {"metashape", "json", "opencv", "colmap"}
        The format (:func:`calibration_format` gives it from a file name).
    std, covariance
        As in :func:`calibration_json` (Metashape XML and OpenCV YAML use the covariance
        only; a COLMAP ``cameras.txt`` has no place for either); where both are given they
        must agree, in every format.

    Returns
    -------
    str
        The file's text.

    Raises
    ------
    InputError
        For an unknown format, ``k4``/``b2`` non-zero in OpenCV's or COLMAP's, or ``std``
        and ``covariance`` that disagree.
    """
    if std is not None and covariance is not None:  # they agree, whatever the format keeps
        _std_of(std, _checked_covariance(covariance))
    if fmt == "metashape":
        return metashape_xml_text(calibration, covariance)
    if fmt == "json":
        data = calibration_json(calibration, std=std, covariance=covariance)
        return json.dumps(data, indent=1, allow_nan=False) + "\n"
    if fmt == "opencv":
        return opencv_yaml_text(calibration, covariance)
    if fmt == "colmap":
        from ..bundle.io_colmap import colmap_camera_text

        return colmap_camera_text(calibration)
    raise InputError(
        f"unknown calibration format {fmt!r}; use 'metashape', 'json', 'opencv' or 'colmap'"
    )


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
        ``.xml`` (Metashape), ``.json`` (photogeom camera JSON), ``.yaml``/``.yml`` (OpenCV),
        ``.txt`` (COLMAP ``cameras.txt``, one camera, ``CAMERA_ID`` 1, the smallest of
        SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV that holds it).
    std : mapping name -> float, optional
        Standard deviations, px / unitless (NaN: held; JSON only).
    covariance : (names, matrix), optional
        Covariance of the free parameters, e.g. ``fit.calibration_covariance(group)``.

    Returns
    -------
    str
        The format written: ``"metashape"``, ``"json"``, ``"opencv"`` or ``"colmap"``.

    Raises
    ------
    InputError
        Another suffix; ``k4`` or ``b2`` non-zero for OpenCV or COLMAP; a value of ``std``
        that is not the square root of the covariance's diagonal (relative 1e-9).
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
            + ": a calibration file needs it in px with origin_px (InteriorOrientation."
            "digital(f, col_pp, row_pp, unit='px'); on the command line a camera given with "
            "--calibration, or with --principal-point and --unit px)"
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
    from ..io.sources import device_message, input_kind, read_input_bytes

    kind = input_kind(path)
    if kind == "device":
        raise FileFormatError(device_message(path, "the calibration"))
    if kind == "folder":
        raise FileFormatError(f"cannot read {path}: it is a folder; give a calibration file")
    try:
        data = read_input_bytes(path, limit)  # a pipe: read once, kept for later reads
    except OSError as exc:
        raise FileFormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if len(data) > limit:
        raise FileFormatError(
            f"{path}: more than {limit} bytes; a calibration file is a few kB: wrong file?"
        )
    return data


def metashape_covariance_from_xml(
    data: bytes | str, where: str = "calibration XML", sensor: int | str | None = None
) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The ``<covariance>`` of a Metashape calibration XML document, or None without one.

    Parameters
    ----------
    data : bytes or str
        The document: a calibration XML, or a camera export (root ``<document>``), whose
        sensor's ``<covariance>`` (beside its adjusted ``<calibration>``) is read.
    where : str, default "calibration XML"
        Its name in error messages.
    sensor : int or str, optional
        The sensor of a camera export, by id or label (needed when it has several).

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
        for the ``n`` names of ``<params>``, whose ``<params>`` name a term that is not
        Metashape's (or one twice), or whose matrix is not symmetric (to 1e-9 of
        ``sqrt(var_i var_j)``) or has a negative variance; each named.
    """
    from ..xmlsafe import parse_xml, root_tag

    if root_tag(data) in ("document", "chunk"):  # a camera export: the chosen sensor's
        from .metashape_export import read_sensor

        return read_sensor(data, where, sensor).covariance
    root = parse_xml(data, where)
    if sensor is not None:
        raise InputError(
            f"sensor {sensor!r}: {where} is a calibration XML of one camera (root "
            "<calibration>), not a camera export with sensors; leave the sensor out"
        )
    return covariance_from_element(root.find("covariance"), where)


def covariance_from_element(
    el: ET.Element | None, where: str
) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The covariance of a Metashape ``<covariance>`` element (None for None); see
    :func:`metashape_covariance_from_xml`."""
    from ..numbers import parse_decimal

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
    unknown = [name for name in names if name not in PARAMETERS + METASHAPE_EXTRA]
    if unknown:
        raise FileFormatError(
            f"{where}: <covariance><params> names {', '.join(unknown)}, not parameters of "
            f"Metashape's frame calibration ({' '.join(METASHAPE_ORDER + METASHAPE_EXTRA)})"
        )
    keep = [i for i, name in enumerate(names) if name in PARAMETERS]
    C = np.array(values, dtype=float).reshape(n, n)[np.ix_(keep, keep)]
    try:
        return _checked_covariance(([names[i] for i in keep], C))
    except InputError as exc:
        raise FileFormatError(f"{where}: <covariance>: {exc}") from exc


def read_metashape_covariance(
    path: str | os.PathLike, sensor: int | str | None = None
) -> tuple[tuple[str, ...], np.ndarray] | None:
    """The ``<covariance>`` of a Metashape calibration XML file or camera export (which
    :func:`read_metashape_xml` ignores), or None when the file has none.

    Parameters
    ----------
    path : str or os.PathLike
        The XML file.
    sensor : int or str, optional
        The sensor of a camera export, by id or label (needed when it has several).

    Returns
    -------
    (names, matrix) or None
        As :func:`metashape_covariance_from_xml`.

    Raises
    ------
    FileFormatError
        An unreadable file, or as :func:`metashape_covariance_from_xml`.
    """
    from .metashape import MAX_CAMERA_EXPORT_BYTES, check_xml_size

    data = _read_bytes(path, MAX_CAMERA_EXPORT_BYTES)
    check_xml_size(data, str(path))
    return metashape_covariance_from_xml(data, str(path), sensor)


#: OpenCV's distortion terms, in the order of its distortion vector.
OPENCV_DISTORTION = (
    "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tx", "ty",
)  # fmt: skip


def _fs_numbers(node, where: str, key: str) -> np.ndarray | None:
    """The numbers of a ``cv2.FileStorage`` node (a matrix, a sequence or a number), or None
    for a missing node."""
    if node.empty() or node.isNone():
        return None
    if node.isInt() or node.isReal():
        return np.array([node.real()])
    try:
        if node.isMap():  # !!opencv-matrix / type_id="opencv-matrix"
            m = node.mat()
            if m is not None:
                return np.asarray(m, dtype=float).reshape(-1)
        elif node.isSeq():
            items = [node.at(i) for i in range(node.size())]
            if all(it.isInt() or it.isReal() for it in items):
                return np.array([it.real() for it in items], dtype=float)
    except Exception:  # cv2.error: a map that is no matrix
        pass
    raise FileFormatError(f"{where}: {key} is not a matrix or list of numbers")


def opencv_calibration_from_text(
    data: bytes | str, where: str = "OpenCV calibration", image_size=None
) -> tuple[MetashapeCalibration, dict[str, float]]:
    """The calibration of an OpenCV ``cv2.FileStorage`` YAML or XML document.

    Reads what OpenCV's calibration samples and :func:`write_calibration` write:
    ``camera_matrix`` ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (px, the top-left pixel's
    centre at (0, 0)), ``distortion_coefficients`` (or ``dist_coeffs``) of 4, 5, 8, 12 or
    14 terms, ``image_width`` and ``image_height`` (px), and ``std_deviations_intrinsics``
    when present. Converted exactly by :meth:`MetashapeCalibration.from_opencv`
    (``f = fy``, ``b1 = fx - fy``, ``cx = cx_cv + 0.5 - w/2``, OpenCV ``p1, p2`` as
    Metashape's ``p2, p1``).

    Parameters
    ----------
    data : bytes or str
        The document: YAML (``%YAML``, or a mapping without it), XML
        (``<?xml``/``<opencv_storage>``) or FileStorage's JSON.
    where : str, default "OpenCV calibration"
        Its name in error messages.
    image_size : (int, int), optional
        ``(width, height)`` in px for a document without ``image_width``/``image_height``.

    Returns
    -------
    calibration : MetashapeCalibration
    std : dict
        Standard deviations (px; Metashape names) from ``std_deviations_intrinsics``
        (``cv2.calibrateCameraExtended``'s order ``fx, fy, cx, cy, k1, k2, p1, p2, k3, ...``):
        ``f`` from ``fy``, ``cx``, ``cy``, ``k1..k3``, ``p1, p2`` (zeros, held parameters, and
        ``b1``, which needs the covariance of ``fx`` and ``fy``, left out).

    Raises
    ------
    FileFormatError
        Not a FileStorage document; no ``camera_matrix`` or distortion vector; a fisheye
        calibration (``fisheye_model`` non-zero); a skew in the camera matrix; non-zero
        rational (k4..k6), thin-prism (s1..s4) or tilt (tx, ty) terms, named.
    InputError
        ``image_size`` given for a document that records the size.
    """
    import cv2

    text = data.decode("utf-8-sig", errors="replace") if isinstance(data, bytes) else data
    text = text.lstrip("\ufeff \t\r\n")
    if text.startswith("<") and not text.startswith("<?xml"):
        text = '<?xml version="1.0"?>\n' + text  # FileStorage tells XML by its declaration
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        ok = fs.isOpened()
    except Exception as exc:  # cv2.error (raised as SystemError by the bindings)
        cause = exc.__cause__ or exc
        raise FileFormatError(
            f"{where}: not an OpenCV FileStorage YAML/XML: {str(cause).strip()[-200:]}"
        ) from None
    if not ok:
        raise FileFormatError(f"{where}: not an OpenCV FileStorage YAML/XML")
    try:
        fisheye = _fs_numbers(fs.getNode("fisheye_model"), where, "fisheye_model")
        if fisheye is not None and np.any(fisheye != 0):
            raise FileFormatError(
                f"{where}: a fisheye calibration (fisheye_model: 1; cv2.fisheye's k1..k4 of the "
                "angle): the Brown model has no equivalent; calibrate with cv2.calibrateCamera"
            )
        K = _fs_numbers(fs.getNode("camera_matrix"), where, "camera_matrix")
        dist_key = "distortion_coefficients"
        dist = _fs_numbers(fs.getNode(dist_key), where, dist_key)
        if dist is None:
            dist_key = "dist_coeffs"
            dist = _fs_numbers(fs.getNode(dist_key), where, dist_key)
        size = [
            _fs_numbers(fs.getNode(k), where, k) for k in ("image_width", "image_height")
        ]
        sd_key = "std_deviations_intrinsics"
        sd = _fs_numbers(fs.getNode(sd_key), where, sd_key)
    finally:
        fs.release()
    if K is None or K.size != 9:
        raise FileFormatError(
            f"{where}: "
            + ("no camera_matrix" if K is None else f"camera_matrix has {K.size} entries, not 9")
            + " (an OpenCV calibration has camera_matrix, a 3x3 matrix, and "
            "distortion_coefficients)"
        )
    if dist is None:
        raise FileFormatError(
            f"{where}: no distortion_coefficients (or dist_coeffs); an OpenCV calibration has "
            "both camera_matrix and the distortion vector"
        )
    if dist.size not in (4, 5, 8, 12, 14):
        raise FileFormatError(
            f"{where}: {dist_key} has {dist.size} terms; OpenCV's distortion vectors have 4, 5, "
            "8, 12 or 14"
        )
    extra = [
        f"{n} = {v!r}" for n, v in zip(OPENCV_DISTORTION[5:], dist[5:].tolist()) if v != 0.0
    ]
    if extra:
        raise FileFormatError(
            f"{where}: {dist_key} has {', '.join(extra)}: OpenCV's rational (k4, k5, k6), "
            "thin-prism (s1..s4) and tilt (tx, ty) terms have no equivalent in photogeom's "
            "Brown model (k1..k4, p1, p2, b1, b2); only calibrations with them zero convert "
            "exactly"
        )
    if any(v is not None for v in size):
        if any(v is None or v.size != 1 for v in size):
            raise FileFormatError(f"{where}: give both image_width and image_height (px)")
        if image_size is not None:
            raise InputError(
                f"{where} records the image size (image_width, image_height); leave the image "
                "size out"
            )
        w, h = float(size[0][0]), float(size[1][0])
    elif image_size is None:
        raise FileFormatError(
            f"{where}: no image_width and image_height; give the image size (image_size, "
            "--image-size WIDTH,HEIGHT at the command line)"
        )
    else:
        w, h = (float(v) for v in image_size)
    if not (math.isfinite(w) and math.isfinite(h) and w == int(w) and h == int(h)):
        raise FileFormatError(f"{where}: image size {w:g} x {h:g} is not whole pixels")
    K = K.reshape(3, 3)
    if K[0, 1] != 0.0:
        raise FileFormatError(
            f"{where}: camera_matrix has a skew entry ({K[0, 1]!r}); OpenCV's projection "
            "(cv2.projectPoints, cv2.undistortPoints) ignores it, so the calibration has no "
            "exact Brown equivalent; set it to 0 if the camera was calibrated without skew"
        )
    try:
        calib = MetashapeCalibration.from_opencv(K, dist, int(w), int(h))
    except InputError as exc:
        raise FileFormatError(f"{where}: {exc}") from None
    std: dict[str, float] = {}
    if sd is not None and sd.size >= 9:
        _fx, fy_, cx_, cy_, k1_, k2_, p1_, p2_, k3_ = sd[:9].tolist()
        pairs = {"f": fy_, "cx": cx_, "cy": cy_, "k1": k1_, "k2": k2_, "k3": k3_,
                 "p1": p2_, "p2": p1_}  # fmt: skip
        std = {n: v for n, v in pairs.items() if math.isfinite(v) and v > 0}
    return calib, _std_of(std, None)


def colmap_calibration_from_text(
    text: str, where: str = "cameras.txt", image_size=None
) -> MetashapeCalibration:
    """The camera of a COLMAP ``cameras.txt`` holding one camera.

    Parameters
    ----------
    text : str
        The file's text; models SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV and
        FULL_OPENCV (k4 = k5 = k6 = 0), converted as :mod:`photogeom.bundle.io_colmap` does
        (``cx = cx_colmap - w/2``: COLMAP's principal point is absolute, from the image's
        top-left corner; ``f = fy``, ``b1 = fx - fy``; COLMAP ``p1, p2`` as Metashape's
        ``p2, p1``).
    where : str, default "cameras.txt"
        The file's name in error messages.
    image_size : None
        Must be None: the file records the size.

    Returns
    -------
    MetashapeCalibration

    Raises
    ------
    FileFormatError
        As :func:`photogeom.bundle.io_colmap.cameras_from_text`, or more than one camera.
    InputError
        ``image_size`` given.
    """
    from ..bundle.io_colmap import cameras_from_text

    cams, _ = cameras_from_text(text, where)
    if len(cams) != 1:
        ids = ", ".join(str(k) for k in list(cams)[:10])
        raise FileFormatError(
            f"{where}: {len(cams)} cameras (CAMERA_ID {ids}{', ...' if len(cams) > 10 else ''}); "
            "a calibration file holds one: keep the camera's line only"
        )
    if image_size is not None:
        raise InputError(
            f"{where} is a COLMAP cameras.txt, which records the image size (WIDTH, HEIGHT); "
            "leave the image size out"
        )
    return next(iter(cams.values()))


def read_calibration_file(
    path: str | os.PathLike, image_size=None, *, sensor: int | str | None = None
) -> tuple[MetashapeCalibration, dict[str, float], tuple[tuple[str, ...], np.ndarray] | None]:
    """A calibration with its standard deviations and covariance, from a Metashape XML, a
    camera JSON, an OpenCV FileStorage YAML/XML/JSON or a COLMAP ``cameras.txt`` of one camera
    (read once, so a pipe works; the format by its content,
    :func:`calibration_content_format`).

    Parameters
    ----------
    path : str or os.PathLike
        The file: a Metashape XML (:meth:`MetashapeCalibration.from_xml_string`, its
        ``<covariance>``), a camera JSON (:func:`calibration_from_json`), an OpenCV
        document (:func:`opencv_calibration_from_text`) or a COLMAP ``cameras.txt``
        (:func:`colmap_calibration_from_text`).
    image_size : (int, int), optional
        ``(width, height)`` in px for a camera JSON or OpenCV document that does not record
        it.
    sensor : int or str, optional
        For a Metashape camera export (File > Export > Export Cameras, root ``<document>``)
        with several sensors: the sensor's id or label (a single sensor is taken without
        it); see :func:`photogeom.camera.metashape_export.sensor_calibration`.

    Returns
    -------
    calibration, std, covariance
        As :func:`calibration_from_json` (for an XML, ``covariance`` its ``<covariance>``
        in the order of its ``<params>`` and ``std`` the square roots of its diagonal, px /
        unitless, or None and empty without one; for an OpenCV document the standard
        deviations of its
        ``std_deviations_intrinsics`` and no covariance; for a ``cameras.txt`` neither).

    Raises
    ------
    InputError
        ``image_size`` given for a file that records the size; ``sensor`` given for a file
        that is no camera export.
    FileFormatError
        An unreadable file, one of none of these formats, a calibration without an exact
        Brown equivalent (the terms named), or a camera export whose sensor cannot be read
        (as :func:`~photogeom.camera.metashape_export.sensor_calibration`).
    """
    return read_calibration_source(path, image_size, sensor=sensor)[:3]


def read_calibration_source(
    path: str | os.PathLike, image_size=None, *, sensor: int | str | None = None
) -> tuple[
    MetashapeCalibration,
    dict[str, float],
    tuple[tuple[str, ...], np.ndarray] | None,
    SensorCalibration | None,
]:
    """As :func:`read_calibration_file`, and the sensor read from a Metashape camera export.

    Parameters
    ----------
    path, image_size, sensor
        As :func:`read_calibration_file`.

    Returns
    -------
    calibration, std, covariance
        As :func:`read_calibration_file`.
    sensor : SensorCalibration or None
        For a camera export, the sensor read (its id, label and the class of the calibration
        read); None for other files.

    Raises
    ------
    InputError, FileFormatError
        As :func:`read_calibration_file`.
    """
    from ..io.jsonfile import MAX_JSON_BYTES, parse_json_bytes
    from ..xmlsafe import root_tag
    from .metashape import MAX_CAMERA_EXPORT_BYTES, check_xml_size

    where = str(path)
    data = _read_bytes(path, max(MAX_JSON_BYTES, MAX_CAMERA_EXPORT_BYTES))
    fmt = calibration_content_format(data)
    if fmt != "metashape" and len(data) > MAX_JSON_BYTES:
        raise FileFormatError(
            f"{path}: more than {MAX_JSON_BYTES} bytes; a calibration file is a few kB: wrong "
            "file?"
        )
    if sensor is not None and fmt != "metashape":
        raise InputError(
            f"sensor {sensor!r}: {where} is not a Metashape camera export (it has no sensors); "
            "leave the sensor out"
        )
    if fmt == "opencv":
        calib, std = opencv_calibration_from_text(data, where, image_size)
        return calib, std, None, None
    if fmt == "metashape":
        check_xml_size(data, where)  # the limits of read_metashape_xml, on every path
        if image_size is not None:
            raise InputError(
                f"{where} is a Metashape XML, which records the image size (<width>, "
                "<height>); leave the image size out"
            )
        if root_tag(data) in ("document", "chunk"):  # a camera export
            from .metashape_export import read_sensor

            read = read_sensor(data, where, sensor)  # calibration and covariance, one parse
            return read.calibration, _std_of(None, read.covariance), read.covariance, read
        calib = MetashapeCalibration.from_xml_string(data, source=where, sensor=sensor)
        cov = metashape_covariance_from_xml(data, where)
        return calib, _std_of(None, cov), cov, None
    if fmt == "json":
        obj = parse_json_bytes(data, where)
        if "camera_matrix" in obj and not any(k in obj for k in ("calibration", "interior")):
            # cv2.FileStorage's JSON (a .json written by OpenCV)
            calib, std = opencv_calibration_from_text(data, where, image_size)
            return calib, std, None, None
        return (*calibration_from_json(obj, where, image_size), None)
    if fmt == "colmap":
        from ..bundle._textio import _decode_text

        text = _decode_text(data, Path(where), "COLMAP cameras file")
        return colmap_calibration_from_text(text, where, image_size), {}, None, None
    raise FileFormatError(
        f"{where}: not a calibration file photogeom reads (Metashape calibration XML, camera "
        "JSON, OpenCV FileStorage YAML/XML/JSON, COLMAP cameras.txt)"
    )


def calibration_content_format(data: bytes) -> str | None:
    """The calibration format of a document by its first bytes: ``"opencv"``
    (``%YAML``, or XML whose root is ``<opencv_storage>``), ``"metashape"`` (other XML),
    ``"json"`` (``{``; a JSON with ``camera_matrix`` is OpenCV's, told by
    :func:`read_calibration_file` once parsed), ``"colmap"`` (a ``#`` comment or a
    ``CAMERA_ID`` digit), ``"opencv"`` again for a YAML mapping with ``camera_matrix`` but
    without ``%YAML``; else None."""
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "metashape"  # UTF-16 XML: Metashape's reader decodes it
    body = data.lstrip(b"\xef\xbb\xbf \t\r\n")
    head = body[:1]
    if body.startswith((b"%YAML", b"---")):
        return "opencv"
    if head == b"<":
        return "opencv" if b"<opencv_storage" in body[:4096] else "metashape"
    if head == b"{":
        return "json"
    if head == b"#" or head.isdigit():
        return "colmap"
    if re.match(rb"[A-Za-z_]\w*[ \t]*:", body) and b"camera_matrix" in body:
        return "opencv"  # a FileStorage YAML without its %YAML line
    return None


def read_calibration(path: str | os.PathLike) -> MetashapeCalibration:
    """Read a calibration: Metashape XML, photogeom camera JSON, OpenCV ``cv2.FileStorage``
    YAML/XML or a COLMAP ``cameras.txt`` of one camera (what :func:`write_calibration`
    writes, and the other tools' files), told apart by their content.

    Parameters
    ----------
    path : str or os.PathLike
        The file (see :func:`read_calibration_file`).

    Returns
    -------
    MetashapeCalibration
        The calibration (px), converted exactly.

    Raises
    ------
    FileFormatError
        An unreadable file, one of another format, a JSON without a calibration, a file
        without its image size (use :func:`read_calibration_file` with ``image_size``), or
        terms without an exact Brown equivalent: OpenCV's rational k4..k6, thin-prism s1..s4,
        tilt tx, ty, fisheye model or camera-matrix skew; COLMAP's other models or
        FULL_OPENCV's k4..k6; several COLMAP cameras.
    """
    return read_calibration_file(path)[0]
