"""Writing RPCs as ``KEY: value`` text (IKONOS-style numbered keys or coefficient lists).

Numbers are written with Python's shortest round-trip representation, so reading the file
back gives exactly the same model. Offsets use the library's (and RPC00B's) pixel convention:
the centre of the first pixel is (0, 0). Image-to-ground polynomials (DIMAP) are written as
``LON_NUM_COEFF_1`` ... (the "extended IKONOS" form that rpcm also reads). An image-space
correction from bias compensation is written into the offsets and scales when that is exact
(shift, per-axis scale); other corrections must be re-fitted first. A known image size
(DIMAP, DigitalGlobe XML, GeoTIFF) is written as ``NUM_COLUMNS`` and ``NUM_ROWS``, which
:func:`~photogeom.rpc.read_rpc` reads back (GDAL and rpcm skip keys they do not know).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io.atomic import atomic_write_text
from .model import RPC
from .readers import IMAGE_SIZE_KEYS

_UNIT = {
    "LINE_OFF": "pixels", "SAMP_OFF": "pixels", "LAT_OFF": "degrees", "LONG_OFF": "degrees",
    "HEIGHT_OFF": "meters", "LINE_SCALE": "pixels", "SAMP_SCALE": "pixels",
    "LAT_SCALE": "degrees", "LONG_SCALE": "degrees", "HEIGHT_SCALE": "meters",
}  # fmt: skip

STYLES = ("ikonos", "lists")


def _num(v: float) -> str:
    return repr(float(v))


def format_rpc(rpc: RPC, style: str = "ikonos") -> str:
    """The text of :func:`write_rpc` (see there).

    Parameters
    ----------
    rpc : RPC
        The model; a foldable image-space correction is folded into its offsets.
    style : {"ikonos", "lists"}, default "ikonos"
        Text layout, as in :func:`write_rpc`.

    Returns
    -------
    str
        The file content, ending with a newline.

    Raises
    ------
    InputError
        Unknown style, or an image-space correction with cross terms (re-fit first).
    """
    if style not in STYLES:
        raise InputError(f"unknown RPC text style {style!r}; use one of {', '.join(STYLES)}")
    model = rpc.with_correction_folded()
    d = model.to_dict()
    lines = []
    for key, unit in _UNIT.items():
        lines.append(
            f"{key}: {_num(d[key])} {unit}" if style == "ikonos" else f"{key}: {_num(d[key])}"
        )
    vectors = [(k, d[k]) for k in ("LINE_NUM_COEFF", "LINE_DEN_COEFF", "SAMP_NUM_COEFF",
                                   "SAMP_DEN_COEFF")]  # fmt: skip
    if model.direct is not None:
        dm = model.direct
        vectors += [("LON_NUM_COEFF", dm.lon_num), ("LON_DEN_COEFF", dm.lon_den),
                    ("LAT_NUM_COEFF", dm.lat_num), ("LAT_DEN_COEFF", dm.lat_den)]  # fmt: skip
    for key, values in vectors:
        if style == "ikonos":
            lines.extend(f"{key}_{i}: {_num(v)}" for i, v in enumerate(values, start=1))
        else:
            lines.append(f"{key}: " + " ".join(_num(v) for v in values))
    if model.err_bias is not None:
        lines.append(f"ERR_BIAS: {_num(model.err_bias)}" + (" meters" if style == "ikonos" else ""))
    if model.err_rand is not None:
        lines.append(f"ERR_RAND: {_num(model.err_rand)}" + (" meters" if style == "ikonos" else ""))
    if model.image_size is not None:  # read back by read_rpc; other readers skip unknown keys
        for key, side in zip(IMAGE_SIZE_KEYS, model.image_size):
            lines.append(f"{key}: {int(side)}" + (" pixels" if style == "ikonos" else ""))
    return "\n".join(lines) + "\n"


def write_rpc(rpc: RPC, path: str | Path, style: str = "ikonos") -> Path:
    """Write an RPC as text, atomically.

    Parameters
    ----------
    rpc : RPC
    path : str or Path
    style : {"ikonos", "lists"}
        ``"ikonos"``: one key per coefficient (``LINE_NUM_COEFF_1: ...``) with units after the
        offsets and scales, as IKONOS ``_RPC.TXT`` files (readable by GDAL and rpcm);
        ``"lists"``: one line per coefficient vector (``LINE_NUM_COEFF: c1 c2 ... c20``), as
        GDAL's RPC metadata domain.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    InputError
        Unknown style, or an image-space correction with cross terms (re-fit first).
    """
    p = Path(path)
    atomic_write_text(p, format_rpc(rpc, style))
    return p
