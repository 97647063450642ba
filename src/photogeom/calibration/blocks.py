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
from ..errors import DegenerateGeometryError, InputError
from .chain import PROBES, chain_redundancy
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


def readjust(
    block: Block,
    grids: Mapping,
    *,
    uncorrected=(),
    redundancy_probes: int = PROBES,
    redundancy_seed: int = 0,
    **options,
):
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
    redundancy_probes, redundancy_seed : int
        Random-sign probes (at least; more while the estimate's standard error is above
        1 % of it, up to 64) and their seed for the chain's effective redundancy, when the
        grids were fitted to these observations
        (:func:`~photogeom.calibration.chain.chain_redundancy`; computed exactly on very
        small blocks).
    **options
        Passed to :func:`photogeom.bundle_adjust` (``loss``, ``snooping``, ...);
        ``fix_exterior`` and ``free`` are set by this function and refused.

    Returns
    -------
    BundleFit
        When the grids were fitted to these same observations (found by their kept pixel
        positions): sigma0 over the chain's effective redundancy
        (``effective_redundancy``, see the notes; also the chi-square test's degrees of
        freedom) and a note that the standard deviations are in-sample; when the first
        adjustment of ``block`` cannot be linearised (a block not adjusted), sigma0 over the
        re-adjustment's own redundancy and a note saying so and why (:data:`NO_CHAIN_NOTE`).

    Notes
    -----
    Corrected with grids fitted to their own residuals, the observations have lost the
    part of their noise that the grids took up, and the cameras held were estimated from
    the same noise: over the re-adjustment's own redundancy (observations minus point
    unknowns) sigma0 comes out too small. It is computed instead over the redundancy of
    the whole chain, the first adjustment (``block.free``, its GNSS, IMU and control
    observations), the grid fit (linearised with the grids' final weights) and the
    re-adjustment: ``tr(M'M)`` for ``M = (I - H3)(I - G)(I - H1)`` (hat matrices of the two
    adjustments and the grids' smoothers, in the whitened observations), estimated with
    random-sign probes. On simulated blocks without any local field (2 x 4 images,
    ``local_field=0.0``, 100 draws of each camera and spacing) the mean of sigma0^2 is
    1.000-1.003 (FC300S) and 0.998-1.006 (ILCE-7RM2) for 100-2000 px grids, where over the
    plain redundancy it was 0.17-0.58 at 100-500 px (sigma0 0.41-0.76) and 0.81-0.92 at
    2000 px; the effective redundancy is 17-92 % of the plain count. Grids fitted in this
    process keep the factors of their normal equations while they live, and the chain
    solves with them (grids read from a file are factorised again): on the 250-image study
    block (120 tie points per image) the chain costs 0.9 s CPU at 500 px and 1.9 s at
    100 px, 0.6 and 0.3 times the grid fit (before, factorising every grid again: 2.0 and
    9.1 s). Grids with
    estimated weights (``sigma_constraint="vce"``) are smoothers that depend on the data;
    linearised with their final weights, the mean sigma0^2 over 30 draws differed from
    that of grids fitted with the same weights held by at most 0.0002 +- 0.0011.

    When ``block`` is the block of the final fit of
    :func:`~photogeom.calibration.adjust_with_grids` (``GridAdjustment.fit.block``, a copy
    of it or a CSV block folder written from it: its ``joint_adjustment`` record), the
    chain's first adjustment is that joint adjustment, with its
    calibration and grid nodes among the unknowns (before: the bundle adjustment of the
    final fit's block, and the mean sigma0^2 of 100 draws was 0.91 instead of 1.00). A
    block carrying the record whose observations, orientation or calibration differ from
    that final fit's takes its own bundle adjustment and a note says so. The joint estimate
    (``GridAdjustment.block``) with the joint adjustment's own grids (``GridAdjustment.grids``,
    node values bit for bit) is that final fit again: sigma0 over the
    chain of the joint adjustment and the re-adjustment, as ``GridAdjustment.fit``. With
    images left out of the correction (``uncorrected``) their residuals keep the grids'
    part of the joint fit and the chain says so (``joint_uncorrected`` of
    :func:`~photogeom.calibration.chain.chain_redundancy`); before, such a re-adjustment
    had no chain and no note (mean sigma0^2 0.74 over 6 draws of the 2 x 4 ILCE-7RM2 block
    with two of 8 images uncorrected, now 1.0). Other grids with the joint estimate (node
    values changed, grids of some images missing) get a note that sigma0 is over the
    re-adjustment's own redundancy (:data:`NOT_ITS_GRIDS_NOTE`).

    The standard deviations stay in-sample and too small: the re-adjustment holds the
    cameras as errorless, while they carry the first adjustment's errors. On the same
    simulated blocks the re-adjusted tie points' errors (against the truth) were 1.5-2.1
    times their standard deviations (mean squared ratio 2.3-4.2 per coordinate, 0.9-1.0
    after the first adjustment), at every spacing. The same grids applied to observations
    measured again (corrected images matched anew; ``sim.rematch``) give sigma0 1.01-1.26
    over the plain redundancy: valid, the grids' own error included.
    """
    fixed = sorted({"fix_exterior", "free"} & set(options))
    if fixed:
        raise InputError(
            f"readjust holds the exterior orientation and calibration fixed; do not pass "
            f"{', '.join(fixed)} (call photogeom.bundle_adjust on correct_observations(...) "
            "for another setting)"
        )
    corrected = correct_block_observations(block, grids, uncorrected=uncorrected)
    corrected.validate()  # the block's own errors first (e.g. a single image)
    chain, notes = None, ()
    joint = _joint_estimate(block)
    if joint and _its_grids(block, grids):
        from .in_adjustment import IN_ADJUSTMENT_NOTE

        # the final fit of adjust_with_grids again (images left uncorrected keep their
        # grids' part of the joint fit): the chain of the joint adjustment and this
        # re-adjustment, no grids after it
        final = corrected
        out = _uncorrected_ids(block, uncorrected)
        left = [k for k in block.image_ids.tolist() if k in out]
        if left:  # the final fit's block, every image corrected: the record's own
            final = correct_block_observations(block, grids)
        chain = chain_redundancy(
            final.replace(joint_adjustment=block.joint_adjustment),
            {},
            uncorrected=corrected.image_ids.tolist(),
            probes=redundancy_probes,
            seed=redundancy_seed,
            joint_uncorrected=left,
        )
        notes = (IN_ADJUSTMENT_NOTE,)
    elif _fitted_to_these_observations(block, grids, uncorrected):
        try:
            chain = chain_redundancy(
                block,
                grids,
                uncorrected=uncorrected,
                probes=redundancy_probes,
                seed=redundancy_seed,
            )
            notes = (IN_SAMPLE_NOTE,) if chain["note"] is None else (IN_SAMPLE_NOTE, chain["note"])
        except DegenerateGeometryError as exc:  # said in the result's notes
            notes = (f"{NO_CHAIN_NOTE}: {exc}",)
    elif joint:
        notes = (NOT_ITS_GRIDS_NOTE,)
    fit = _adjust_corrected(corrected, effective_redundancy=chain, **options)
    return replace(fit, notes=(*fit.notes, *notes)) if notes else fit


#: The note of :func:`readjust` when its grids were fitted to the observations it corrects.
IN_SAMPLE_NOTE = (
    "the grids were fitted to the residuals of these same observations: sigma0 is computed "
    "over the effective redundancy of the chain (first adjustment, grids, re-adjustment; "
    "see effective_redundancy), but the standard deviations are in-sample and too small "
    "(the cameras are held as errorless: on simulated blocks the points' errors were "
    "1.5-2.1 times their standard deviations); judge the precision on observations "
    "measured again (the corrected images matched anew)"
)


#: The note of :func:`readjust` when its grids were fitted to the observations it corrects
#: but the first adjustment of ``block`` cannot be linearised (a block not adjusted, whose
#: parameters its observations do not determine at its values), followed by the reason.
NO_CHAIN_NOTE = (
    "sigma0 and the standard deviations are in-sample and too small: the grids were fitted "
    "to the residuals of these same observations and took up part of their noise, and "
    "sigma0 is over the re-adjustment's own redundancy, because the effective redundancy "
    "of the chain needs the first adjustment of the block the grids were fitted to (adjust "
    "the block first, then fit the grids to its residuals)"
)


#: The note of :func:`readjust` when ``block`` is the joint estimate of
#: :func:`~photogeom.calibration.adjust_with_grids` but the grids are not its own.
NOT_ITS_GRIDS_NOTE = (
    "the block is the joint estimate of adjust_with_grids (GridAdjustment.block), but the "
    "grids are not that adjustment's own (their node values differ, or the grids of some "
    "images are missing): sigma0 is over the re-adjustment's own redundancy, without the "
    "chain of the joint adjustment, whose orientations and grids took up part of the "
    "noise (sigma0 too small); pass GridAdjustment.grids whole (uncorrected= leaves "
    "images out of the correction) for the joint adjustment's chain"
)


def _joint_estimate(block: Block) -> bool:
    """Whether ``block`` is the joint estimate of :func:`adjust_with_grids`
    (``GridAdjustment.block``: its record, its observations as given)."""
    rec = block.joint_adjustment
    if rec is None or not rec.grids_sha256:
        return False
    return rec.mismatch(block, estimate=True) is None


def _its_grids(block: Block, grids: Mapping) -> bool:
    """Whether ``grids`` are the own grids (node values bit for bit, one for every image)
    of the joint adjustment whose estimate ``block`` is."""
    from .in_adjustment import grids_digest

    return grids_digest(block, grids) == block.joint_adjustment.grids_sha256


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


def _adjust_corrected(corrected: Block, *, effective_redundancy=None, **options):
    """The adjustment of :func:`readjust` on observations already corrected: exterior
    orientation and Brown coefficients fixed, the points re-triangulated; sigma0 over
    ``effective_redundancy`` when given (:func:`~photogeom.calibration.chain.chain_redundancy`)."""
    from ..bundle.adjustment import adjust_block
    from ..bundle.options import BundleOptions

    opts = BundleOptions().updated(fix_exterior=True, free=(), **options)
    return adjust_block(corrected, opts, effective_redundancy=effective_redundancy)
