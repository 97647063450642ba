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

from .bias import MODELS as BIAS_MODELS
from .bias import refine_rpc
from .domain import DOMAIN_LIMIT, LocalizationWarning, RPCExtrapolationWarning
from .fitting import fit_rpc, fit_rpc_to_points
from .localization import LocalizationResult, LocalizationStatus, approximate_inverse
from .model import RPC, DirectModel
from .readers import read_rpc
from .stereo import RPCIntersection, intersect_rpc
from .writer import format_rpc, write_rpc

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
