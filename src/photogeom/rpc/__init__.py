"""Rational polynomial camera (RPC) models for satellite images.

>>> import photogeom as pg
>>> rpc = pg.RPC.from_file(pg.datasets.path("ikonos"))
>>> col, row = rpc.project(-56.17, -34.90, 30.0)        # degrees, degrees, metres
>>> lon, lat = rpc.localize(col, row, 30.0)

Pixel ``(0, 0)`` is the centre of the first (top-left) pixel (RPC00B convention; GDAL's RPC
transformer reports ``(col + 0.5, row + 0.5)``). Modules: :mod:`.model` (the model,
projection), :mod:`.polynomial` (the 20 cubic terms), :mod:`.readers`, :mod:`.writer`,
:mod:`.localization`, :mod:`.fitting` (terrain-independent and terrain-dependent fits),
:mod:`.bias` (bias compensation), :mod:`.stereo` (intersection), :mod:`.domain` (warnings).
"""

from .domain import DOMAIN_LIMIT, LocalizationWarning, RPCExtrapolationWarning
from .localization import LocalizationResult, LocalizationStatus, approximate_inverse
from .model import RPC, DirectModel
from .readers import read_rpc
from .stereo import RPCIntersection, intersect_rpc
from .writer import format_rpc, write_rpc

#: Names imported on first use: fitting and bias compensation need the adjustment engine
#: (scipy), projecting and localising do not.
_DEFERRED = {
    "BIAS_MODELS": (".bias", "MODELS"),
    "refine_rpc": (".bias", "refine_rpc"),
    "fit_rpc": (".fitting", "fit_rpc"),
    "fit_rpc_to_points": (".fitting", "fit_rpc_to_points"),
}


def __getattr__(name: str):
    if name in _DEFERRED:
        import importlib

        module, attr = _DEFERRED[name]
        value = getattr(importlib.import_module(module, __name__), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_DEFERRED))


__all__ = [
    "BIAS_MODELS",
    "DOMAIN_LIMIT",
    "RPC",
    "DirectModel",
    "LocalizationResult",
    "LocalizationStatus",
    "LocalizationWarning",
    "RPCExtrapolationWarning",
    "RPCIntersection",
    "approximate_inverse",
    "fit_rpc",
    "fit_rpc_to_points",
    "format_rpc",
    "intersect_rpc",
    "read_rpc",
    "refine_rpc",
    "write_rpc",
]
