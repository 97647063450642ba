"""Residual grids of a whole block: fit from the adjusted block, correct, re-adjust.

The block-level face of the finite-element residual grids (05-residual-grid.md, "Public API
contract"):

* :func:`block_residuals` - the reprojection residuals (computed minus observed, px) of one
  block, grouped per image;
* :func:`fit_residual_grids` - one :class:`~photogeom.calibration.ResidualGrid` per image
  from the residuals of the block's **tie points** (by default; control points can be
  added with ``roles=("tie", "control")``; check points never enter: they are kept out of
  the adjustment and out of the grid so that they stay independent checks);
* :func:`correct_block_observations` - a new block whose observations (every role) are
  moved by the modelled residual, ``uv + r(uv)``;
* :func:`readjust` - the corrected block adjusted again with the exterior orientation and
  the Brown coefficients held at their first values: only the points move (the tie points
  are re-triangulated, the check points triangulated from the corrected observations).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from ..bundle.block import ROLES, Block
from ..bundle.residuals import reprojection_residuals
from ..errors import InputError
from .grid import (
    ResidualGrid,
    fit_grids,
    scaled_constraint_sigma,
)
from .gridfile import match_grid_ids

__all__ = [
    "block_residuals",
    "correct_block_observations",
    "fit_residual_grids",
    "readjust",
]


def _check_block(block, what: str) -> Block:
    if not isinstance(block, Block):
        raise InputError(f"{what} needs a photogeom.bundle.Block, got {type(block).__name__}")
    return block


def _roles(roles: Sequence[str] | str) -> tuple[str, ...]:
    roles = (roles,) if isinstance(roles, str) else tuple(roles)
    bad = [r for r in roles if r not in ROLES]
    if bad or not roles:
        raise InputError(f"roles must be a non-empty choice of {', '.join(ROLES)}, not {roles!r}")
    return roles


def block_residuals(
    block: Block, *, roles: Sequence[str] | str = ("tie",)
) -> dict[object, tuple[np.ndarray, np.ndarray]]:
    """Observed pixels and reprojection residuals per image.

    Parameters
    ----------
    block : Block
        An adjusted block (e.g. ``pg.bundle_adjust(...).block``).
    roles : sequence of str
        Point roles whose observations are used (default: tie points only).

    Returns
    -------
    dict
        ``image id -> (uv (n, 2), residuals (n, 2))`` in pixels, residuals computed minus
        observed, for every image of the block in block order (an image without
        observations of these roles gets empty arrays).
    """
    _check_block(block, "block_residuals")
    use = np.isin(block.role[block.obs_point], _roles(roles))
    r = reprojection_residuals(block)
    uv = block.observations.uv
    per_image = _rows_per_image(block, np.flatnonzero(use))
    return {
        iid: (uv[sel], r[sel]) for iid, sel in zip(block.image_ids.tolist(), per_image)
    }  # images, not points


def fit_residual_grids(
    block: Block,
    spacing: float = 100,
    *,
    roles: Sequence[str] | str = ("tie",),
    images: Sequence | None = None,
    sigma_obs: float | str = "block",
    sigma_constraint: float | str = "scaled",
    progress: bool | Callable[[int, int], None] = False,
    **options,
) -> dict[object, ResidualGrid]:
    """Fit one finite-element residual grid per image of an adjusted block.

    Parameters
    ----------
    block : Block
        The adjusted block: its reprojection residuals (computed minus observed, px) are
        the data, its cameras give each image's size.
    spacing : float
        Node spacing in pixels (the study: 100 px on the unstable camera, 70 px on the
        stable ones; 150-200 px chosen by the closest-to-origin rule).
    roles : sequence of str
        Point roles whose residuals are fitted: ``"tie"`` (the default) and ``"control"``;
        ``"check"`` is refused (see the module).
    images : sequence of image ids, optional
        Fit only these images (default: every image of the block).
    sigma_obs : "block" or float
        Standard deviations of the residuals (px): ``"block"`` takes each observation's
        a-priori sigma from the block (``block.observations.sigma``), a number one value
        for all.
    sigma_constraint : float, "scaled" or "vce"
        Standard deviation of the smoothness pseudo-observations (px). ``"scaled"`` (the
        default): ``0.1 px * (spacing / 100 px)^2``. A smooth field's departure from the
        mean of its neighbours grows with the square of the node spacing, so one sigma in
        pixels for every spacing stiffens coarse grids (on the simulator a 2000 px grid gave
        10 % of the 100 px grid's step reduction with 0.1 px, 42 % scaled); 0.1 px at 100 px
        suits observation sigmas of a few tenths of a pixel and a few hundred tie points per
        image (with 1 px a 100 px grid nearly interpolates the residuals, noise included).
        ``"vce"`` estimates it (variance components).
    progress : bool or callable
        ``True``: a progress bar (rich) on the terminal; a callable: called as
        ``progress(done, total)`` (images) before the first and after every image, as
        :func:`~photogeom.calibration.fit_grids` does.
    **options
        Passed to :func:`~photogeom.calibration.fit_grid` (``sigma_constraint`` - a number
        in px or ``"vce"`` -, ``border``, ``min_observations``, ``min_support``, ``folds``,
        ``snooping``, ...).

    Returns
    -------
    dict
        ``image id -> ResidualGrid`` in block order.

    Raises
    ------
    InputError
        Not a block, unknown roles or image ids, check points in ``roles``, a spacing of
        0, negative or larger than an image, residuals outside the image.
    TooFewPointsError
        An image with fewer residuals than ``min_observations`` (named; at any spacing):
        leave the image out with ``images=`` (and ``readjust(..., uncorrected=)``).
    """
    _check_block(block, "fit_residual_grids")
    roles = _roles(roles)
    if "check" in roles:
        raise InputError(
            f"roles={roles!r}: check points never enter a residual grid, so that they stay "
            "independent checks of the correction (they are kept out of the adjustment "
            "too); fit with roles=('tie',) or ('tie', 'control')"
        )
    sigma_constraint = scaled_constraint_sigma(sigma_constraint, spacing)
    per = block_residuals(block, roles=roles)
    if images is not None:
        want = list(images)
        unknown = [k for k in want if k not in per]
        if unknown:
            raise InputError(
                f"images: unknown image id(s) {', '.join(map(str, unknown[:5]))} "
                "(not in block.image_ids)"
            )
        per = {k: per[k] for k in want}
    sizes = block.image_sizes().astype(int)
    row = {iid: i for i, iid in enumerate(block.image_ids.tolist())}
    size_of = {k: (int(sizes[row[k], 0]), int(sizes[row[k], 1])) for k in per}
    if isinstance(sigma_obs, str):
        if sigma_obs != "block":
            raise InputError(f"sigma_obs must be 'block' or a number of pixels, not {sigma_obs!r}")
        sigma_obs = _sigmas_per_image(block, roles)  # each observation its own sigma
    return fit_grids(
        per,
        size_of,
        spacing,
        sigma_obs=sigma_obs,
        sigma_constraint=sigma_constraint,
        progress=progress,
        **options,
    )


def _sigmas_per_image(block: Block, roles) -> dict:
    use = np.isin(block.role[block.obs_point], _roles(roles))
    s = block.observations.sigma
    per_image = _rows_per_image(block, np.flatnonzero(use))
    return {iid: s[sel] for iid, sel in zip(block.image_ids.tolist(), per_image)}


def _rows_per_image(block: Block, rows: np.ndarray | None = None) -> list[np.ndarray]:
    """The rows of ``block``'s observations (of ``rows`` only, when given) grouped by image:
    one array per image of ``block.image_ids``, the rows in their order within it."""
    rows = np.arange(block.obs_image.size) if rows is None else rows
    order = rows[np.argsort(block.obs_image[rows], kind="stable")]
    counts = np.bincount(block.obs_image[rows], minlength=block.n_images)
    return np.split(order, np.cumsum(counts)[:-1])


def _uncorrected_ids(block: Block, uncorrected) -> set:
    """The image ids of ``uncorrected`` (ids of the block), unknown ids refused."""
    if isinstance(uncorrected, str | bytes) or not isinstance(uncorrected, Iterable):
        raise InputError(
            f"uncorrected must be a sequence of image ids, not {type(uncorrected).__name__}"
        )
    left = list(uncorrected)
    known = set(block.image_ids.tolist())
    unknown = [k for k in left if k not in known]
    if unknown:
        raise InputError(
            f"uncorrected: unknown image id(s) {', '.join(map(str, unknown[:5]))} "
            "(not in block.image_ids)"
        )
    return set(left)


def correct_block_observations(block: Block, grids: Mapping, *, uncorrected=()) -> Block:
    """A new block with every observation corrected by its image's grid: ``uv + r(uv)``.

    All roles are corrected (the local field displaces every measurement of an image). The
    result has the same ids, points and orientations; only ``observations.uv`` changes.
    A grid is found by the image id, else by its text when that is unambiguous (grids
    files written before image ids kept their type hold text ids).

    Parameters
    ----------
    block : Block
        The block whose observations (px) are corrected.
    grids : Mapping
        ``image id -> ResidualGrid``; each grid's image size must be its camera's.
    uncorrected : sequence of image ids
        Images left out of the correction: their observations are kept as they are and
        they need no grid (e.g. images with too few residuals for a grid, left out of
        :func:`fit_residual_grids` with ``images=``).

    Returns
    -------
    Block

    Raises
    ------
    InputError
        Images holding observations but no grid (named) and not ``uncorrected``, unknown
        ids in ``uncorrected``, or observations outside their image.
    """
    _check_block(block, "correct_observations")
    if not isinstance(grids, Mapping):
        raise InputError(
            f"grids must be a mapping image id -> ResidualGrid, not {type(grids).__name__}"
        )
    kept = _uncorrected_ids(block, uncorrected)
    counts, _ = block.observation_counts()
    ids = block.image_ids.tolist()
    key_of, _ = match_grid_ids(ids, grids)
    missing = [iid for iid, c in zip(ids, counts) if c and iid not in key_of and iid not in kept]
    if missing:
        raise InputError(
            f"no residual grid for image(s) {', '.join(map(str, missing[:10]))}"
            f"{' ...' if len(missing) > 10 else ''}: fit grids for every image of the block "
            "(fit_residual_grids) to correct its observations, or leave images out of the "
            "correction with uncorrected="
        )
    uv = block.observations.uv
    out = uv.copy()
    sizes = block.image_sizes().astype(int)
    for i, (iid, sel) in enumerate(zip(ids, _rows_per_image(block))):  # images, not points
        if sel.size == 0 or iid in kept:
            continue
        g = grids[key_of[iid]]
        if not isinstance(g, ResidualGrid):
            raise InputError(f"image {iid}: expected a ResidualGrid, got {type(g).__name__}")
        w, h = int(sizes[i, 0]), int(sizes[i, 1])
        if g.image_size != (w, h):
            raise InputError(
                f"image {iid}: the grid was fitted for a {g.image_size[0]} x {g.image_size[1]} "
                f"px image, the block's camera is {w} x {h} px: the grids are of another "
                "camera or block; fit the grids of this block (fit_residual_grids)"
            )
        try:
            out[sel] = g.correct(uv[sel])
        except InputError as exc:
            raise InputError(f"image {iid}: {exc}") from None
    return block.with_observations(uv=out)


def readjust(block: Block, grids: Mapping, *, uncorrected=(), **options):
    """Correct the observations with the grids and adjust again with the exterior
    orientation and the Brown coefficients held at their first values.

    Only the points move: tie (and control) points are re-triangulated by the adjustment,
    check points triangulated from their corrected observations afterwards. The datum is
    given by the fixed orientations (no datum check applies).

    Parameters
    ----------
    block : Block
        The adjusted block the grids were fitted to.
    grids : mapping
        ``image id -> ResidualGrid`` for every image with observations but those of
        ``uncorrected``.
    uncorrected : sequence of image ids
        Images whose observations are not corrected (no grid needed; see
        :func:`correct_block_observations`); they take part in the re-adjustment as they
        are.
    **options
        Passed to :func:`photogeom.bundle_adjust` (``loss``, ``snooping``, ...);
        ``fix_exterior`` and ``free`` are set by this function and refused.

    Returns
    -------
    BundleFit
        With a note when the grids were fitted to these same observations (found by their
        kept pixel positions): its sigma0 and standard deviations are then in-sample.

    Notes
    -----
    Corrected with grids fitted to their own residuals, the observations have lost the
    part of their noise that the grids took up, and the re-adjustment's redundancy does
    not count the grids' unknowns: sigma0 and every standard deviation scaled by it come
    out too small. On simulated blocks without any local field (2 x 4 images) sigma0 is
    0.98-1.01 after the first adjustment and 0.39-0.77 after 100-500 px grids (0.87-0.98
    at 2000 px). The same grids applied to observations measured again (corrected images
    matched anew; ``sim.rematch``) give 1.01-1.26: valid, the grids' own error included.
    """
    fixed = sorted({"fix_exterior", "free"} & set(options))
    if fixed:
        raise InputError(
            f"readjust holds the exterior orientation and calibration fixed; do not pass "
            f"{', '.join(fixed)} (call photogeom.bundle_adjust on correct_observations(...) "
            "for another setting)"
        )
    corrected = correct_block_observations(block, grids, uncorrected=uncorrected)
    fit = _adjust_corrected(corrected, **options)
    if _fitted_to_these_observations(block, grids, uncorrected):
        fit = replace(fit, notes=(*fit.notes, IN_SAMPLE_NOTE))
    return fit


#: The note of :func:`readjust` when its grids were fitted to the observations it corrects.
IN_SAMPLE_NOTE = (
    "sigma0 and the standard deviations are in-sample and too small: the grids were fitted "
    "to the residuals of these same observations and took up part of their noise, and the "
    "redundancy does not count the grids' unknowns; judge the precision on observations "
    "measured again (the corrected images matched anew)"
)


def _fitted_to_these_observations(block: Block, grids: Mapping, uncorrected) -> bool:
    """Whether a grid of ``grids`` was fitted to observations of ``block``: at least half
    of the pixel positions it kept are among its image's observed pixels, bit for bit
    (observations measured again differ by their fresh noise). Grids read without their
    positions (``uv`` None) say nothing."""
    kept = set(uncorrected)
    ids = block.image_ids.tolist()
    key_of, _ = match_grid_ids(ids, grids)
    uv = block.observations.uv
    for iid, sel in zip(ids, _rows_per_image(block)):  # images, not points
        g = grids[key_of[iid]] if iid in key_of and iid not in kept else None
        if g is None or g.uv is None or len(g.uv) == 0 or sel.size == 0:
            continue
        own = uv[sel]
        same = np.isin(g.uv[:, 0] + 1j * g.uv[:, 1], own[:, 0] + 1j * own[:, 1])
        if 2 * int(same.sum()) >= len(g.uv):
            return True
    return False


def _adjust_corrected(corrected: Block, **options):
    """The adjustment of :func:`readjust` on observations already corrected: exterior
    orientation and Brown coefficients fixed, the points re-triangulated."""
    from ..bundle.adjustment import bundle_adjust

    return bundle_adjust(corrected, fix_exterior=True, free=(), **options)
