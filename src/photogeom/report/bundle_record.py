"""The result record of a bundle adjustment: what :mod:`photogeom.report.bundle` renders.

:func:`bundle_result_data` (the summary of ``BundleFit.to_dict()`` plus what the figures
need), :func:`write_bundle_result` and :func:`read_bundle_result`. Kept apart from the
figures so that ``photogeom bundle adjust`` without ``--report`` does not import matplotlib;
every name is also available from :mod:`photogeom.report.bundle`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

#: Identifies a saved result record (``"format"``) and its layout (``"version"``).
RESULT_FORMAT = "photogeom-bundle-result"
RESULT_VERSION = 1
#: Rows of the image, calibration-group, flagged and poorly controlled observation tables at
#: most.
MAX_ROWS = 50
#: Flagged observations kept in the record at most.
MAX_FLAGGED = 200
#: Sensor cells with fewer observations are drawn pale (their mean is noisy).
MIN_CELL_COUNT = 5
#: Camera groups drawn with their own sensor panel and heat map at most.
MAX_GROUP_PANELS = 4

_CAL_NAMES = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")
_CAL_UNIT = {n: ("px" if n in ("f", "cx", "cy", "b1", "b2") else "1") for n in _CAL_NAMES}


# --- the result record ---------------------------------------------------------------------------


def _nan(v) -> float:
    return math.nan if v is None else float(v)


def _sensor_grid(fit, cells: int) -> list[dict]:
    """Mean residual vector per cell of a regular grid over the image frame, per camera
    group (or pooled per image size when there are many groups)."""
    from ..adjust.fit import _jsonable

    b = fit.block
    rows = fit.in_adjustment & np.isfinite(fit.residuals).all(axis=1)
    uv = b.observations.uv[rows]
    v = fit.residuals[rows]
    img = b.obs_image[rows]
    group = b.image_camera[img]
    sizes = b.image_sizes()[img]
    cams = b.camera_ids.tolist()
    if len(cams) <= MAX_GROUP_PANELS:
        keys = [(f"camera {cams[g]}", group == g) for g in range(len(cams))]
    else:
        uniq = np.unique(b.image_sizes(), axis=0)
        keys = [
            (
                f"images of {int(w)} x {int(h)} px (pooled over camera groups)",
                (sizes[:, 0] == w) & (sizes[:, 1] == h),
            )
            for w, h in uniq
        ]
    out = []
    for label, sel in keys:
        if not sel.any():
            continue
        w, h = (float(x) for x in sizes[sel][0])
        nx = int(cells)
        ny = max(1, round(cells * h / w))
        # pixel centres run from -0.5 to w - 0.5 (centre of the top-left pixel at 0, 0)
        cx = np.clip(((uv[sel, 0] + 0.5) / w * nx).astype(int), 0, nx - 1)
        cy = np.clip(((uv[sel, 1] + 0.5) / h * ny).astype(int), 0, ny - 1)
        cell = cy * nx + cx
        n = np.bincount(cell, minlength=nx * ny)
        su = np.bincount(cell, weights=v[sel, 0], minlength=nx * ny)
        sv = np.bincount(cell, weights=v[sel, 1], minlength=nx * ny)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.column_stack([su / n, sv / n])
        vs = v[sel]
        out.append(
            _jsonable(
                {
                    "label": label,
                    "width": w,
                    "height": h,
                    "nx": nx,
                    "ny": ny,
                    "count": n,
                    "mean": mean,
                    "n_observations": int(sel.sum()),
                    "n_images": int(np.unique(img[sel]).size),
                    "rms": float(np.sqrt(np.mean(np.einsum("nd,nd->n", vs, vs)))),
                }
            )
        )
    return out


def _point_histogram(fit, bins: int = 30) -> dict | None:
    if fit.point_std is None:
        return None
    s = fit.point_std[fit.block.role != "check"]
    s = s[np.isfinite(s).all(axis=1)]
    if s.size == 0:
        return None
    top = float(np.quantile(s, 0.995))
    if not top > 0:
        top = float(s.max()) or 1.0
    edges = np.linspace(0.0, top, bins + 1)
    counts = {a: np.histogram(np.clip(s[:, k], 0, top), edges)[0] for k, a in enumerate("XYZ")}
    above = {a: int(np.sum(s[:, k] > top)) for k, a in enumerate("XYZ")}
    return {
        "edges": edges.tolist(),
        "counts": {a: c.tolist() for a, c in counts.items()},
        "above": above,
        "rms": np.sqrt(np.mean(s**2, axis=0)).tolist(),
        "median": np.median(s, axis=0).tolist(),
        "max": s.max(axis=0).tolist(),
        "n": int(s.shape[0]),
    }


def _flagged(fit) -> tuple[list[dict], int]:
    if fit.snooping is None:
        return [], 0
    w = np.abs(fit.snooping["w"])
    mx = np.nanmax(np.where(np.isfinite(w), w, -1.0), axis=1)
    crit = fit.snooping["critical_value"]
    rows = np.flatnonzero(mx > crit)
    rows = rows[np.argsort(-mx[rows], kind="stable")]
    o = fit.block.observations
    out = [
        {
            "image": o.image_ids[k].item(),
            "point": o.point_ids[k].item(),
            "w": float(mx[k]),
            "v": [float(fit.residuals[k, 0]), float(fit.residuals[k, 1])],
            "sigma": float(o.sigma[k]),
        }
        for k in rows[:MAX_FLAGGED]
    ]
    return out, int(rows.size)


def _poorly_controlled(fit) -> tuple[list[dict], int]:
    """The poorly controlled observations (a redundancy number below
    :data:`~photogeom.adjust.snooping.POORLY_CONTROLLED` in u or v), the least controlled
    first: image and point id, the redundancy numbers and minimal detectable biases of u and v
    (a-priori sigmas) and the sigma (px); at most :data:`MAX_FLAGGED`, and their count."""
    from ..adjust.snooping import POORLY_CONTROLLED

    sn = fit.snooping
    if sn is None or sn.get("redundancy_numbers") is None or sn.get("mdb") is None:
        return [], 0
    red = np.asarray(sn["redundancy_numbers"], dtype=float)
    mdb = np.asarray(sn["mdb"], dtype=float)
    with np.errstate(invalid="ignore"):
        least = np.nanmin(np.where(np.isfinite(red), red, np.inf), axis=1)
    rows = np.flatnonzero(least < POORLY_CONTROLLED)
    rows = rows[np.argsort(least[rows], kind="stable")]
    o = fit.block.observations
    out = [
        {
            "image": o.image_ids[k].item(),
            "point": o.point_ids[k].item(),
            "r": [float(red[k, 0]), float(red[k, 1])],
            "mdb": [float(mdb[k, 0]), float(mdb[k, 1])],
            "sigma": float(o.sigma[k]),
        }
        for k in rows[:MAX_FLAGGED].tolist()
    ]
    return out, int(rows.size)


def _spread(name: str, sigma, unit: str) -> dict | None:
    """One row of :func:`_a_priori`: the count, median, least and largest of the finite
    ``sigma`` (None when there are none)."""
    s = np.asarray(sigma, dtype=float)
    s = s[np.isfinite(s)]
    if not s.size:
        return None
    return {
        "observations": name,
        "n": int(s.size),
        "median": float(np.median(s)),
        "min": float(s.min()),
        "max": float(s.max()),
        "unit": unit,
    }


def _a_priori(fit, unit: str, angle_unit: str) -> list[dict]:
    """The a-priori standard deviations of the adjustment's observations (its stochastic
    model): image observations by the role of their point (px), the control points' surveyed
    coordinates and the GNSS positions (``unit``) per axis, the IMU attitudes per angle
    (``angle_unit``)."""
    from ..units import from_radians

    b = fit.block
    obs_role = b.role[b.obs_point]
    rows = [
        _spread(
            f"image observations of {role} points", b.observations.sigma[obs_role == role], "px"
        )
        for role in ("tie", "control", "check")
    ]
    ctl = b.role == "control"
    rows += [
        _spread(f"control points {a}", b.point_sigma[ctl, k], unit) for k, a in enumerate("XYZ")
    ]
    gnss = np.isfinite(b.gnss).all(axis=1)
    rows += [_spread(f"GNSS {a}0", b.gnss_sigma[gnss, k], unit) for k, a in enumerate("XYZ")]
    imu = np.isfinite(b.imu).all(axis=1)
    rows += [
        _spread(f"IMU {a}", from_radians(b.imu_sigma[imu, k], angle_unit), angle_unit)
        for k, a in enumerate(("omega", "phi", "kappa"))
    ]
    return [r for r in rows if r is not None]


def bundle_result_data(fit, *, unit: str = "m", angle_unit: str = "deg", cells: int = 10) -> dict:
    """The JSON-ready record of a bundle adjustment that :func:`add_bundle_result` renders.

    Parameters
    ----------
    fit : BundleFit
    unit : str
        Name of the object-space length unit (labels only; the block's coordinates are not
        converted).
    angle_unit : {"deg", "gon", "rad"}
        Unit of the exterior orientation angles and their standard deviations.
    cells : int
        Cells of the sensor grid across the image width (rows follow the aspect ratio).

    Returns
    -------
    dict
        ``fit.to_dict(angle_unit)`` plus ``format``, ``version``, ``unit``, ``block`` (counts),
        per image ``camera`` and ``n_obs``, ``calibration_correlation`` (names and matrix per
        group), ``sensor_grid``, ``point_precision`` (histogram of the point standard
        deviations, or None), ``flagged`` (at most 200 observations, largest |w| first) and
        ``n_flagged``, ``poorly_controlled`` (at most 200 observations with a redundancy
        number below 0.1, the least controlled first: ``image``, ``point``, ``r`` and
        ``mdb`` of u and v, ``sigma``), ``n_poorly_controlled`` and ``a_priori`` (the
        a-priori standard deviations: per group of observations ``observations``, ``n``,
        ``median``, ``min``, ``max`` and ``unit``: image observations by their point's role in
        px, control points and GNSS per axis in ``unit``, IMU per angle in ``angle_unit``).
        NaN is written as None (JSON null).
    """
    from ..adjust.fit import _jsonable

    if int(cells) != cells or not 1 <= cells <= 200:
        raise InputError(f"cells must be an integer from 1 to 200, not {cells!r}")
    b = fit.block
    d = fit.to_dict(angle_unit)
    per_img, _ = b.observation_counts()
    in_adj = np.bincount(b.obs_image[fit.in_adjustment], minlength=b.n_images)
    cams = b.camera_ids.tolist()
    for k, row in enumerate(d["images"]):
        row["camera"] = cams[b.image_camera[k]]
        row["n_obs"] = int(in_adj[k])
        row["n_obs_all"] = int(per_img[k])
    flagged, n_flagged = _flagged(fit)
    poor, n_poor = _poorly_controlled(fit)
    d.update(
        {
            "format": RESULT_FORMAT,
            "version": RESULT_VERSION,
            "unit": unit,
            "block": {
                "n_camera_groups": len(cams),
                "n_images": b.n_images,
                "n_points": b.n_points,
                "n_tie": int(np.sum(b.role == "tie")),
                "n_control": int(np.sum(b.role == "control")),
                "n_check": int(np.sum(b.role == "check")),
                "n_image_observations": b.n_observations,
                "has_gnss": bool(np.isfinite(b.gnss).all(axis=1).any()) if b.n_images else False,
                "has_imu": bool(np.isfinite(b.imu).all(axis=1).any()) if b.n_images else False,
            },
            "calibration_correlation": {
                str(g): {"names": list(names), "matrix": np.asarray(R)}
                for g, (names, R) in fit.calibration_correlation.items()
            },
            "sensor_grid": _sensor_grid(fit, int(cells)),
            "point_precision": _point_histogram(fit),
            "flagged": flagged,
            "n_flagged": n_flagged,
            "poorly_controlled": poor,
            "n_poorly_controlled": n_poor,
            "correlation_threshold": fit.correlation_threshold,
            "a_priori": _a_priori(fit, unit, angle_unit),
        }
    )
    return _jsonable(d)


def write_bundle_result(data: Mapping, path: str | os.PathLike) -> Path:
    """Write a result record (from :func:`bundle_result_data`) as JSON, atomically.

    Parameters
    ----------
    data : Mapping
        The record (no NaN: undefined values are None).
    path : str or os.PathLike
        Output file; replaced if it exists.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    OutputError
        When the file cannot be written.
    """
    from ..io.atomic import atomic_write_text

    return atomic_write_text(path, json.dumps(data, indent=1, allow_nan=False) + "\n")


def read_bundle_result(path: str | os.PathLike) -> dict:
    """Read a result record written by :func:`write_bundle_result` (or ``--result``).

    Parameters
    ----------
    path : str or os.PathLike
        The JSON file.

    Returns
    -------
    dict

    Raises
    ------
    InputError
        When the file does not exist.
    FileFormatError
        When it cannot be read (a folder, a device, no permission), is not JSON (UTF-8, or
        UTF-16/32; nested more than 64 levels, an integer of more than 40 digits and NaN are
        refused), is not a bundle adjustment result record, or lacks an entry the report needs (or
        holds one of the wrong kind): the message names the entries and how to write the
        record again.
    """
    from ..io.jsonfile import parse_json_bytes
    from ..io.sources import device_message, input_kind, read_input_bytes

    p = Path(path)
    if input_kind(p) == "device":  # /dev/zero never ends: it was read until memory ran out
        raise FileFormatError(device_message(p, "result record"))
    try:
        raw = read_input_bytes(p, None)  # a file, or a pipe read once per command
    except FileNotFoundError:
        raise InputError(f"no file {p}") from None
    except OSError as exc:  # a folder, no permission, ...
        raise FileFormatError(f"cannot read {p}: {exc.strerror or exc}") from None
    try:  # bounded: deep nesting, huge integers, UTF-16/32 and a byte-order mark handled
        data = parse_json_bytes(raw, str(p))
    except FileFormatError as exc:
        raise FileFormatError(
            f"{exc}; not JSON photogeom reads as a bundle adjustment result (write one with "
            "'photogeom bundle adjust ... --result FILE.json')"
        ) from None
    if not isinstance(data, dict) or data.get("format") != RESULT_FORMAT:
        raise FileFormatError(
            f'{p}: not a bundle adjustment result (expected "format": "{RESULT_FORMAT}"; '
            "write one with 'photogeom bundle adjust ... --result FILE.json')"
        )
    if data.get("version") != RESULT_VERSION:
        raise FileFormatError(
            f"{p}: result version {data.get('version')!r}; this photogeom reads version "
            f"{RESULT_VERSION}"
        )
    missing = [k for k in _RECORD_ENTRIES if k not in data]
    wrong = [
        k for k, kind in _RECORD_ENTRIES.items() if k in data and not isinstance(data[k], kind)
    ]
    if missing or wrong:
        what = [f"no {', '.join(missing)}"] if missing else []
        what += [f"{k} is not {_KIND_WORDS[_RECORD_ENTRIES[k]]}" for k in wrong]
        raise FileFormatError(
            f"{p}: an incomplete or damaged bundle adjustment result ({'; '.join(what)}); "
            "write it again with 'photogeom bundle adjust ... --result FILE.json'"
        )
    return data


_NUMBER = (int, float, type(None))  # NaN is written as null
#: Entries the report needs, with their JSON kind (checked by :func:`read_bundle_result`).
_RECORD_ENTRIES: dict[str, type | tuple[type, ...]] = {
    "converged": bool, "message": str, "unit": str, "angle_unit": str, "redundancy": int,
    "sigma0": _NUMBER, "sigma0_prior": _NUMBER, "rmse_px": _NUMBER, "gsd": _NUMBER,
    "block": dict, "chi2": dict, "calibration": dict, "calibration_std": dict,
    "calibration_correlation": dict, "images": list,
}  # fmt: skip
_KIND_WORDS = {bool: "true/false", str: "text", int: "an integer", _NUMBER: "a number or null",
               dict: "an object", list: "a list"}  # fmt: skip
