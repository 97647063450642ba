"""Which free unknowns of a bundle adjustment its observations leave undetermined.

A rank-deficient reduced camera system (a datum defect left, a part of the block hinged on
the rest by one or two points, calibration parameters the geometry cannot separate) need
not fail its Cholesky factorisation: rounding can leave its null directions a pivot of
order 1e-16 instead of zero, and the "covariances" of the unknowns along them are then
rounding noise times 1e15 (standard deviations of 3e4 m on a 12-image block whose two
halves share two tie points). The variance inflation factor of each unknown,
``VIF_k = Q_kk N_kk`` (``Q`` the inverse of the normal matrix, ``N_kk`` its diagonal; 1 for
an unknown uncorrelated with all others, ``1 / (1 - R_k^2)`` with ``R_k`` its multiple
correlation with them), tells them apart: along such a direction ``1 - R_k^2`` is rounding,
1e-16 to 1e-14 (factors of 9e14 to 2e15 on that block), while a determined but weak unknown
has a factor far below the bound (a focal length with all Brown terms on a flat nadir block
without GNSS, standard deviation 1e4 px: 5e10). It costs the diagonals of the covariance
blocks the statistics compute anyway and one pass over the Jacobian blocks (0.14 s of 52 s
on a simulated 500-image block of 75 000 observations).
"""

from __future__ import annotations

import numpy as np

from ..errors import DegenerateGeometryError
from .adjustment import NCAL, Problem, _sum_by
from .block import CALIBRATION_NAMES

#: Variance inflation factor (``Q_kk N_kk``, :mod:`photogeom.bundle.determined`) above which
#: a free unknown counts as undetermined: its multiple correlation with the other unknowns
#: is 1 to within 1e-12, about 5000 times the double-precision rounding, where the rounding
#: of a factorisation of n unknowns moves its variance by about ``VIF n 2.2e-16`` of itself
#: (percents at 1000 unknowns).
VIF_MAX = 1e12

#: Names of the local unknowns of an image: its projection centre, the components of its
#: rotation increment (reported as omega, phi, kappa) and its image-variant offsets.
LOCAL_NAMES = ("X0", "Y0", "Z0", "omega", "phi", "kappa", "f", "cx", "cy")


def inflation_factors(problem: Problem, lin, Q) -> tuple[np.ndarray, np.ndarray]:
    """Variance inflation factors ``Q_kk N_kk`` of the free camera-side unknowns.

    Parameters
    ----------
    problem : Problem
        The adjustment.
    lin : Linearization
        Its (undamped) linearisation: whitened Jacobian blocks ``A`` (n, 2, b), ``G`` (n, 2,
        NCAL), the priors' ``local_info`` (m, b, b) and ``global_info`` (g, g).
    Q : CovarianceBlocks or FoldedCovarianceBlocks
        Blocks of the inverse of the reduced camera system (the cameras' block of the
        inverse normal matrix).

    Returns
    -------
    tuple of numpy.ndarray
        ``(local, calibration)``: (m, b) per image and (groups * NCAL,) per camera group's
        calibration parameter, unitless; 0 for held unknowns.
    """
    m, ng = problem.m, problem.ng
    i = problem.obs_i
    cam = problem.block.image_camera[i]
    dl = _sum_by(i, np.einsum("ndc,ndc->nc", lin.A, lin.A), m)
    dl += np.einsum("lcc->lc", lin.local_info)
    dg = _sum_by(cam, np.einsum("ndc,ndc->nc", lin.G, lin.G), ng).ravel()
    dg += np.asarray(lin.global_info.diagonal()).ravel()
    local = np.where(problem.local_free, np.einsum("lcc->lc", Q.local) * dl, 0.0)
    qg = np.zeros(ng * NCAL)
    for gi in np.flatnonzero(problem.global_free.reshape(ng, NCAL).any(axis=1)).tolist():
        cols = np.arange(gi * NCAL, (gi + 1) * NCAL)  # groups with free parameters only
        qg[cols] = np.diag(Q.global_block(cols, cols))
    return local, np.where(problem.global_free, qg * dg, 0.0)


def undetermined_text(problem: Problem, local: np.ndarray, cal: np.ndarray, bound: float) -> str:
    """The unknowns whose variance inflation factors exceed ``bound``, in words: the
    images (worst first, at most five) with their parameters and the camera groups with
    their calibration parameters.

    Parameters
    ----------
    problem : Problem
        The adjustment.
    local, cal : numpy.ndarray
        :func:`inflation_factors`.
    bound : float
        The factor above which an unknown is named.

    Returns
    -------
    str
    """
    parts = []
    worst = local.max(axis=1)
    imgs = np.flatnonzero(worst > bound)
    imgs = imgs[np.argsort(-worst[imgs], kind="stable")]
    ids = problem.block.image_ids
    named = []
    for k in imgs[:5].tolist():  # images named, at most five
        cols = np.flatnonzero(local[k] > bound)
        cols = cols[np.argsort(-local[k, cols], kind="stable")]
        named.append(f"{ids[k]} ({', '.join(LOCAL_NAMES[c] for c in cols.tolist())})")
    if named:
        more = f" and {imgs.size - 5} more" if imgs.size > 5 else ""
        parts.append(f"image(s) {'; '.join(named)}{more}")
    groups = problem.block.camera_ids
    gcal = cal.reshape(problem.ng, NCAL)
    for gi in np.flatnonzero((gcal > bound).any(axis=1))[:5].tolist():
        names = [CALIBRATION_NAMES[c] for c in np.flatnonzero(gcal[gi] > bound).tolist()]
        parts.append(f"camera {groups[gi]} ({', '.join(names)})")
    return "; ".join(parts)


def advice(problem: Problem, cal: np.ndarray, bound: float) -> str:
    """What to do about undetermined unknowns: the datum and its links, and, where
    calibration parameters are among them, holding those (``free=`` without them)."""
    text = (
        "a part of the block linked to the rest by fewer than three tie points (its "
        "rotation about them, or its scale, is free: link it by more tie points, give it "
        "control points or GNSS positions, or adjust it as a block of its own), or control "
        "points and GNSS positions that fix fewer than seven datum elements"
    )
    weak = cal > bound
    if np.any(weak):
        free = problem.global_free.reshape(problem.ng, NCAL).any(axis=0)
        keep = free & ~weak.reshape(problem.ng, NCAL).any(axis=0)
        kept = [f"'{CALIBRATION_NAMES[c]}'" for c in np.flatnonzero(keep).tolist()]
        kept = ", ".join(kept) + ("," if len(kept) == 1 else "")  # a tuple of one
        hold = ", ".join(
            CALIBRATION_NAMES[c]
            for c in np.flatnonzero(weak.reshape(problem.ng, NCAL).any(axis=0)).tolist()
        )
        fix = f": free=({kept})" if kept else ""
        text = (
            f"calibration parameters the geometry cannot determine: hold {hold} (leave them "
            f"out of the free parameters{fix}; or add what separates them: oblique images, "
            "a second flying height, control points, points out to the image corners); or "
            + text
        )
    return text


def check_determined(problem: Problem, lin, Q) -> None:
    """Refuse statistics whose reduced camera system is singular to double precision.

    Parameters
    ----------
    problem : Problem
        The adjustment.
    lin : Linearization
        Its final, undamped linearisation.
    Q : CovarianceBlocks or FoldedCovarianceBlocks
        Blocks of the inverse of its reduced camera system.

    Raises
    ------
    DegenerateGeometryError
        Some free unknown has a variance inflation factor above :data:`VIF_MAX` (or not
        finite): the message names the images and parameters, the camera groups and
        calibration parameters, the largest factor and what to do.
    """
    local, cal = inflation_factors(problem, lin, Q)
    local = np.where(np.isfinite(local), local, np.inf)
    cal = np.where(np.isfinite(cal), cal, np.inf)
    top = max(float(local.max(initial=0.0)), float(cal.max(initial=0.0)))
    if top <= VIF_MAX:
        return
    raise DegenerateGeometryError(
        "the observations do not determine all free parameters: the normal equations are "
        f"singular to double precision (variance inflation factor up to {top:.2g}, above "
        f"{VIF_MAX:.0e}: the standard deviations would be rounding noise) at "
        f"{undetermined_text(problem, local, cal, VIF_MAX)}. Causes: "
        + advice(problem, cal, VIF_MAX)
    )


#: Marquardt damping (relative to the diagonal) of the system whose inverse names the
#: unknowns of a reduced camera system that does not factorise: it bounds their variance
#: inflation factors near its inverse, far above those of determined unknowns.
NAMING_DAMPING = 1e-10


def singular_error(problem: Problem, lin, exc: Exception) -> DegenerateGeometryError | None:
    """The error of a reduced camera system that does not factorise (or whose inverse
    does not form) at the solution, naming the unknowns it leaves free.

    They are the unknowns of the largest variance inflation factors (at least 1e-2 of the
    largest and 1e6) of the system damped by :data:`NAMING_DAMPING`; the cost is one more
    factorisation and the diagonal blocks of its inverse, on this failure only.

    Parameters
    ----------
    problem : Problem
        The adjustment.
    lin : Linearization
        Its final, undamped linearisation.
    exc : Exception
        The factorisation's error (its text is kept).

    Returns
    -------
    DegenerateGeometryError or None
        None when the damped system does not name them either.
    """
    from ..adjust.schur import covariance_blocks

    try:
        ne = problem.sys.normal_equations(lin, damping=NAMING_DAMPING)
        Q = covariance_blocks(ne, ne.factor(), pairs=False)
    except DegenerateGeometryError:
        return None
    local, cal = inflation_factors(problem, lin, Q)
    top = max(float(local.max(initial=0.0)), float(cal.max(initial=0.0)))
    if not (np.isfinite(top) and top > 1e6):
        return None
    bound = max(1e-2 * top, 1e6)
    return DegenerateGeometryError(
        f"the observations do not determine all free parameters at the solution ({exc}): "
        f"they leave free {undetermined_text(problem, local, cal, bound)}. Causes: "
        + advice(problem, cal, bound)
    )


def check_state_determined(problem: Problem, state) -> None:
    """Refuse a state of ``problem`` whose reduced camera system is singular: the bundle
    part of an adjustment that adds unknowns of its own (residual grids), whose own
    factorisation does not name the cause.

    Adding unknowns never determines the block's own: a defect of the bundle part is one
    of the joint system. The check is one linearisation (unit weights), one factorisation
    and the diagonal blocks of its inverse (:func:`check_determined`); with
    ``backend="cg"`` (no factor, a solve per unknown) it is not made.

    Parameters
    ----------
    problem : Problem
        The bundle adjustment of the block.
    state : _State
        Its unknowns at the solution.

    Raises
    ------
    DegenerateGeometryError
        As :func:`check_determined`, or as :func:`singular_error` where the factorisation
        fails.
    """
    from ..adjust.schur import covariance_blocks

    if problem.options.backend == "cg":
        return
    lin = problem.linearize(state, np.ones(problem.obs_i.size))
    ne = problem.sys.normal_equations(lin)
    try:
        Q = covariance_blocks(ne, ne.factor(), pairs=False)
    except DegenerateGeometryError as exc:
        named = singular_error(problem, lin, exc)
        raise (named or exc) from exc
    check_determined(problem, lin, Q)
