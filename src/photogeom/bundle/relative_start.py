"""Start values of a :class:`Block` without GNSS/IMU: relative orientations, strips, GCPs.

:func:`start_from_relative_orientation` feeds the block's cameras, observations and control
points to :func:`photogeom.orientation.block_start` (relative orientation of consecutive
images, strip formation, absolute orientation to the GCPs) and returns a new block with
every image's exterior orientation and the tie points' coordinates replaced by the result;
tie points no model reached are triangulated with the new cameras. Pixels are converted to
the image system of each camera's ``interior_orientation()`` (its distortion is removed by
the relative orientation).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..orientation.strip import BlockStart, block_start
from .block import Block

__all__ = ["start_from_relative_orientation"]


def start_from_relative_orientation(
    block: Block,
    strips: Sequence[Sequence],
    *,
    method: str = "independent",
    sigma: float | None = None,
    min_common: int = 3,
    seed: int | None = 0,
) -> tuple[Block, BlockStart]:
    """Exterior orientations and tie points of ``block`` from relative orientations and GCPs.

    Parameters
    ----------
    block : Block
        Cameras (calibrations), image observations and control points (role ``"control"``,
        their surveyed coordinates) are used; the current exterior orientations and tie
        points are ignored.
    strips : sequence of sequences of image ids
        Each strip in flight order.
    method, min_common, seed
        As in :func:`photogeom.orientation.block_start`.
    sigma : float, optional
        A-priori standard deviation of the image coordinates in pixels for the relative
        orientations' w-tests. Default None: the tau-test against the noise each relative
        orientation estimates, which tolerates a start calibration that is not yet exact
        (the block's own sigmas would flag every match then).

    Returns
    -------
    (Block, BlockStart)
        The block with the new start values, and the strips, models and fits behind them.
        Images in no strip keep their exterior orientation, and tie points that no model
        reached and the new cameras cannot intersect (e.g. seen in one image of the strips)
        keep their coordinates.

    Raises
    ------
    InputError
        Unknown image ids in ``strips``, or an image listed twice.
    TooFewPointsError
        Fewer than three control points observed in the strips' images (a block read from
        a BAL or Bundler file or a COLMAP model holds none), before any relative
        orientation is computed; a strip that cannot be oriented (see
        :func:`photogeom.orientation.block_start`).
    """
    known = set(block.image_ids.tolist())
    listed = [i for s in strips for i in s]
    missing = [i for i in listed if i not in known]
    if missing:
        raise InputError(f"strips: unknown image id(s) {', '.join(map(str, missing[:10]))}")
    if len(set(listed)) != len(listed):
        raise InputError("strips: an image is listed twice")
    interiors = {}
    observations: dict = {}
    obs = block.observations
    row = {i: k for k, i in enumerate(block.image_ids.tolist())}
    for iid in listed:
        k = row[iid]
        io = block.image_calibration(k).interior_orientation()
        interiors[iid] = io
        sel = np.flatnonzero(block.obs_image == k)
        xy = io.pixel_to_image(obs.uv[sel])
        observations[iid] = dict(zip(obs.point_ids[sel].tolist(), xy))
    control = {
        p: x
        for p, x, r in zip(block.point_ids.tolist(), block.surveyed_xyz, block.role)
        if r == "control"
    }
    start = block_start(
        strips,
        interiors,
        observations,
        control,
        method=method,
        sigma=sigma,
        min_common=min_common,
        seed=seed,
    )
    exterior = block.exterior.copy()
    for iid, e in start.exteriors.items():
        exterior[row[iid]] = e.parameters
    xyz = block.xyz.copy()
    tie = block.role == "tie"
    reached = np.zeros(len(xyz), dtype=bool)
    for k, (p, t) in enumerate(zip(block.point_ids.tolist(), tie)):
        if t and p in start.points:
            xyz[k] = start.points[p]
            reached[k] = True
    new = block.replace(exterior=exterior, xyz=xyz)
    rest = np.flatnonzero(tie & ~reached)
    if rest.size:
        from .triangulate import triangulate

        tri = triangulate(new, block.point_ids[rest], images=listed)
        ok = np.asarray(tri.ok, dtype=bool)
        xyz[rest[ok]] = tri.xyz[ok]
        new = block.replace(exterior=exterior, xyz=xyz)
    return new, start
