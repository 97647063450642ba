"""A block's coordinate reference system: GNSS positions from another CRS into the block's
frame, adjusted coordinates back into any CRS.

A block is adjusted in Cartesian coordinates: a local east-north-up frame
(``"enu:lat0,lon0,h0"``, see :class:`photogeom.crs.LocalFrame`), geocentric coordinates, a
projected CRS or an engineering (site) system; ``Block.crs`` records which. GNSS receivers
give WGS 84 (``EPSG:4979``: longitude, latitude in degrees, ellipsoidal height in metres).
:func:`gnss_into_block_crs` brings such positions into the block's system (PROJ for the CRS,
photogeom's closed formulas for the ENU frame), and :func:`positions_in` / :func:`points_in`
take the adjusted projection centres and points back into any CRS.
"""

from __future__ import annotations

import numpy as np

from ..crs import (
    LocalFrame,
    cartesian_crs,
    frame_from_text,
    points_between,
    transform_points,
)
from ..errors import InputError
from .block import Block

__all__ = ["gnss_into_block_crs", "points_in", "positions_in"]

#: WGS 84 geographic 3D: longitude, latitude (degrees), ellipsoidal height (m).
WGS84_3D = "EPSG:4979"


def gnss_into_block_crs(
    block: Block,
    gnss_crs,
    *,
    crs=None,
    allow_ballpark: bool = False,
) -> Block:
    """The block with its GNSS positions converted from ``gnss_crs`` into its own system.

    Parameters
    ----------
    block : Block
        ``block.gnss`` (m, 3) holds positions in ``gnss_crs``, x/easting/longitude first
        (``lon, lat, h`` for ``EPSG:4979``); NaN rows (images without GNSS) stay NaN.
    gnss_crs : str
        CRS of the GNSS positions (EPSG code, WKT, PROJ string, ``"enu:lat0,lon0,h0"``).
    crs : str, optional
        System of the block's object coordinates (exterior orientations, points); default
        ``block.crs``. Without either: a local ENU frame at the centre of the GNSS positions
        (``LocalFrame.at_centroid``) - then the block's starting coordinates must be in that
        frame, and a block with control or check points is refused (their system is not
        known).
    allow_ballpark : bool
        Accept an approximate PROJ datum shift (refused by default).

    Returns
    -------
    Block
        GNSS positions in the block's system, ``crs`` recorded. The GNSS standard deviations
        are kept: they are taken along the axes of the block's system (east, north, up of
        a local frame; a receiver's horizontal and vertical sigmas).
    """
    has = np.all(np.isfinite(block.gnss), axis=1)
    if not np.any(has):
        raise InputError("the block has no GNSS positions to convert (gnss_crs / --gnss-crs)")
    target = crs if crs is not None else block.crs
    if crs is not None and block.crs is not None and not _same(crs, block.crs):
        raise InputError(
            f"the block records the CRS {block.crs}, not {crs}: give the CRS of its coordinates "
            "(they are not converted)"
        )
    gn = block.gnss[has]
    if target is None:
        if np.any(block.role != "tie"):
            raise InputError(
                "the block's control/check points are in a system it does not record: name it "
                "(crs=, --crs; the '# crs:' line of points.csv), e.g. the enu:LAT,LON,H frame "
                "they were converted to with 'photogeom crs convert --to enu --origin'"
            )
        lon, lat, h = transform_points(gn, gnss_crs, WGS84_3D, allow_ballpark=allow_ballpark).T
        target = LocalFrame.at_centroid(lat, lon, h).to_text()
    cartesian_crs(target, what="block crs")
    out = block.gnss.copy()
    out[has] = points_between(gn, gnss_crs, target, allow_ballpark=allow_ballpark)
    return block.replace(gnss=out, crs=target)


def _same(a, b) -> bool:
    fa, fb = frame_from_text(a), frame_from_text(b)
    if fa is not None or fb is not None:
        return fa == fb
    from ..crs import parse_crs

    return parse_crs(a) == parse_crs(b)


def _block_crs(block: Block) -> str:
    if block.crs is None:
        raise InputError(
            "the block records no CRS: its coordinates cannot be converted (name it with "
            "crs= / --crs)"
        )
    return block.crs


def positions_in(block: Block, crs, *, allow_ballpark: bool = False) -> np.ndarray:
    """Projection centres of ``block`` (e.g. ``BundleFit.block``) in another CRS.

    Parameters
    ----------
    block : Block
        A block that records the CRS of its coordinates (``block.crs``).
    crs : str
        The CRS to convert to: EPSG code, WKT, PROJ string or ``enu:LAT,LON,H``.
    allow_ballpark : bool
        Accept an approximate ("ballpark") datum shift; refused by default.

    Returns
    -------
    numpy.ndarray, shape (m, 3)
        One row per image, x/easting/longitude first, in the units of ``crs`` (``lon, lat``
        in degrees and ``h`` in m for ``EPSG:4979``).
    """
    return points_between(
        block.exterior[:, :3], _block_crs(block), crs, allow_ballpark=allow_ballpark
    )


def points_in(block: Block, crs, *, allow_ballpark: bool = False) -> np.ndarray:
    """Object points of ``block`` in another CRS (as :func:`positions_in` converts).

    Parameters
    ----------
    block : Block
        A block that records the CRS of its coordinates (``block.crs``).
    crs : str
        The CRS to convert to: EPSG code, WKT, PROJ string or ``enu:LAT,LON,H``.
    allow_ballpark : bool
        Accept an approximate ("ballpark") datum shift; refused by default.

    Returns
    -------
    numpy.ndarray, shape (p, 3)
        One row per point of ``block.point_ids``, x/easting/longitude first, in the units
        of ``crs``.
    """
    return points_between(block.xyz, _block_crs(block), crs, allow_ballpark=allow_ballpark)
