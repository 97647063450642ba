"""``correct_observations`` for a Block or for arrays per image (one public name)."""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import InputError
from .correction import correct_observations as correct_array_observations

__all__ = ["correct_observations"]


def correct_observations(observations, grids: Mapping):
    """Correct image coordinates with residual grids: ``uv + r(uv)`` (px).

    Parameters
    ----------
    observations : Block or mapping
        A :class:`~photogeom.bundle.Block`: a new block is returned whose observations are
        corrected (:func:`~photogeom.calibration.blocks.correct_block_observations`). A
        mapping ``image id -> uv (n, 2)``: a dict ``image id -> corrected uv``
        (:func:`~photogeom.calibration.correction.correct_observations`).
    grids : mapping
        ``image id -> ResidualGrid``.

    Returns
    -------
    Block or dict
        Of the kind of ``observations``.

    Raises
    ------
    InputError
        Neither a Block nor a mapping; an image without a grid (named); points outside an
        image.
    """
    if isinstance(observations, Mapping):
        return correct_array_observations(observations, grids)
    # the block level (and the bundle package it needs) is imported for a Block only
    from ..bundle.block import Block

    if isinstance(observations, Block):
        from .blocks import correct_block_observations

        return correct_block_observations(observations, grids)
    raise InputError(
        "correct_observations needs a photogeom.bundle.Block or a mapping image id -> uv "
        f"(n, 2), not {type(observations).__name__}"
    )
