"""Variance-component estimation (Förstner / Helmert, iterated) for the bundle adjustment.

Groups: image observations of tie points, image observations of control points, control
point coordinates, GNSS positions, IMU attitudes. For each group k with whitened residuals
``v_k`` and redundancy contribution ``r_k = n_k - tr(P_k J Q J')`` the variance factor is
updated as ``f_k <- f_k * v_k'P_k v_k / r_k`` and the adjustment repeated until every ratio
is 1 within the tolerance (a group whose ratio jumps across 1, as Huber's loss makes it
where an image point's residual crosses the loss scale, is bisected between the factors
around its root, :func:`_bound_root`). With a robust loss ``v_k'P_k v_k`` holds the
robust weights and ``r_k`` is the group's share of the Stein redundancy
(:func:`photogeom.bundle.robust.stein_redundancy`), from the adjustment weighted by the
score slopes, less the part of ``v_k'P_k v_k`` that cancels only over all groups
(:func:`_cross_terms`; for GNSS, IMU, the control points and their image observations,
the tie points' image observations taking the rest): the expectation of ``v_k'P_k v_k`` over
the group's variance factor under normal errors. The estimated standard
deviation of a group is its a-priori one times ``sqrt(f_k)``. A group without redundancy,
or whose iterated estimate runs to zero (its redundancy contribution collapsing, or its
ratio staying below 1 down to factor 0), keeps its a-priori sigmas and is listed
in ``not_estimated``.
"""

from __future__ import annotations

import numpy as np

from ..adjust.variance_components import update_variance_factors
from ..camera.frame_kernel import opk_from_increment_jacobian
from ._angles import opk_from_rotations
from .adjustment import levenberg_marquardt
from .robust import (
    influence_factors,
    point_trace_shares,
    score_slopes,
)

#: Stop when every group's ratio v'Pv / r is within this of 1.
TOLERANCE = 0.01
MAX_ROUNDS = 20
#: A group whose redundancy contribution falls below this share of its first-round value
#: is collapsing: the iterated estimate of its variance runs to zero.
COLLAPSE = 1e-3
#: A group whose redundancy contribution has fallen below this share of its first round's,
#: with its factor falling, is tested for a ratio that stays below 1 down to factor 0
#: (:func:`_inestimable`).
SMALL_SHARE = 0.1
#: ... and held when that ratio extrapolated to factor 0 is below this: the straight line
#: through two rounds underestimates it where the ratio curves up toward factor 0 (by
#: 0.02 over 12 rounds of a group whose sigma factor was still falling at 0.24), and groups
#: whose estimate runs to zero come out at 0.69-0.83.
EXTRAPOLATED_BELOW = 0.95
#: A redundancy contribution at most this is none (nothing controls the group).
NO_REDUNDANCY = 1e-6
#: Step of the difference quotient of the robust cross terms (:func:`_cross_terms`).
CROSS_STEP = 0.125


def _inestimable(names, vtpv, red, first_red, held, factors=None, previous=None) -> dict:
    """Groups (not yet held) whose variance cannot be estimated, with the reason.

    No redundancy from the start (nothing else controls them), or an iterated estimate of
    the group's variance running to zero, its ratio ``rho = v'Pv / r`` below 1: its
    redundancy contribution collapsed below :data:`COLLAPSE` of its first round's, or fell
    below :data:`SMALL_SHARE` of it and the ratio, extrapolated to factor 0, stays below 1
    (below :data:`EXTRAPOLATED_BELOW`).
    A group much more precise than what controls it has ``r_k`` and ``v_k'P_k v_k`` both
    proportional to its factor ``f_k`` plus terms of order ``f_k^2``, so ``rho(f) = rho_0 +
    b f`` for small ``f``; ``rho_0`` and ``b`` from this round and the previous one. With
    ``rho_0 < 1`` and ``rho`` below 1 no factor between 0 and ``f_k`` has ratio 1: every
    round multiplies the factor by about ``rho_0`` and the estimate runs to zero
    geometrically (``rho_0`` 0.69 for least squares, 0.82 with Huber's loss on a 6-image
    block, where :data:`COLLAPSE` alone held the group after 18 and 30 rounds, beyond the 20
    allowed with the robust loss). With ``rho_0 > 1`` the ratio reaches 1 at a smaller
    factor, however slowly: that group is estimated. The straight line through two rounds
    is only the ratio's tangent, and where the ratio curves up toward factor 0 its value
    at 0 is below the true one: with Huber's loss a group whose ratio still climbed toward
    1 (sigma factor 0.24 after 20 rounds, 0.41 with least squares on the same draw) had
    ``rho_0`` 0.987 at variance factor 0.08, hence the margin of
    :data:`EXTRAPOLATED_BELOW`.

    Parameters
    ----------
    names : list of str
        The groups.
    vtpv, red : numpy.ndarray
        Per group ``v_k'P_k v_k`` and redundancy contribution ``r_k`` of this round.
    first_red : dict
        Per group ``r_k`` of the first round.
    held : dict
        Groups already held at their a-priori sigmas.
    factors : dict, optional
        Per group the variance factor ``f_k`` of this round.
    previous : dict, optional
        Per group ``(ratio, f_k)`` of the previous round (without a group held between).

    Returns
    -------
    dict
        Group -> reason.
    """
    factors = factors or {}
    previous = previous or {}
    out = {}
    for k, q, r in zip(names, vtpv, red):
        if k in held:
            continue
        low = q < (1 - TOLERANCE) * r
        toward_zero = False
        if low and k in previous and k in factors and r < SMALL_SHARE * first_red[k]:
            rho1, f1 = previous[k]
            f, rho = factors[k], q / r
            if f < f1:
                rho0 = rho - f * (rho - rho1) / (f - f1)  # the ratio extrapolated to f = 0
                toward_zero = rho0 < EXTRAPOLATED_BELOW
        if first_red[k] <= NO_REDUNDANCY:
            out[k] = "no redundancy: no other observations control this group"
        elif r <= NO_REDUNDANCY or (low and (r < COLLAPSE * first_red[k] or toward_zero)):
            out[k] = (
                "its iterated estimate runs to zero (residuals much smaller than its "
                f"redundancy of {first_red[k]:.3g} expects: too few observations to estimate "
                "its variance)"
            )
    return out


def _prior_cofactor_traces(problem, run, Q, Qpp) -> dict:
    """Per prior group (GNSS, IMU, control) ``tr(N_k Q)``: the trace of its whitened
    observations' cofactors ``A_k Q A_k'`` for the inverse normal matrix ``Q`` (camera
    blocks ``Q``, point blocks ``Qpp``)."""
    _, _, _, _, _, parts = problem.prior_terms(run.state)
    gf = problem.group_factor
    out = {}
    if "gnss" in parts:
        k = problem.has_gnss
        w = 1.0 / (problem.block.gnss_sigma[k] ** 2 * gf["gnss"])
        out["gnss"] = float((w * np.einsum("kii->ki", Q.local[k][:, :3, :3])).sum())
    if "imu" in parts:
        k = problem.has_imu
        s = problem.block.imu_sigma[k] * np.sqrt(gf["imu"])
        J = opk_from_increment_jacobian(opk_from_rotations(run.state.M[k])) / s[:, :, None]
        out["imu"] = float(np.einsum("kai,kij,kaj->", J, Q.local[k][:, 3:6, 3:6], J))
    if "control" in parts:
        c = problem.control
        w = 1.0 / (problem.control_sigma**2 * gf["control"])
        out["control"] = float((w * np.einsum("kii->ki", Qpp[c])).sum())
    return out


def _contributions(problem, run):
    """Per group ``(v_k'P_k W_k v_k, r_k)``: its weighted square sum and the redundancy
    whose expectation times the group's variance factor is that sum's expectation."""
    from .result import statistics_pass

    opts = problem.options
    # per image point v'PWv and its Stein redundancy (robust.stein_redundancy): with the
    # squared loss 2 - tr(J Q J'); with a robust loss d_i (2 - tr C_i) in the adjustment
    # weighted by the score slopes d_i, plus the point's share of the full derivative's
    # trace; the prior groups' redundancy from that adjustment too
    lin1 = problem.linearize(run.state, np.ones(problem.obs_i.size))
    e2 = np.einsum("nd,nd->n", lin1.r, lin1.r)
    r_img = run.weights * e2
    d = score_slopes(opts.loss, opts.scale, e2)
    _, _, _, Q, Qpp, Cobs = statistics_pass(problem, run.state, d, pairs=True, cofactors=True)
    red_img = d * (2.0 - np.einsum("ndd->n", Cobs))
    prior_tr = _prior_cofactor_traces(problem, run, Q, Qpp)
    n_prior = {
        "gnss": 3.0 * int(problem.has_gnss.sum()),
        "imu": 3.0 * int(problem.has_imu.sum()),
        "control": 3.0 * problem.control.size,
    }
    red_prior = {k: n_prior[k] - t for k, t in prior_tr.items()}
    if opts.loss != "squared":
        per_obs, per_point = point_trace_shares(
            opts.loss, opts.scale, lin1.r, lin1.P, problem.obs_j, lin1.point_info
        )
        red_img = red_img + per_obs
        if "control" in red_prior:
            red_prior["control"] += float(np.sum(per_point))
    ctrl = problem.obs_is_control
    red_tie, red_ctrl = float(red_img[~ctrl].sum()), float(red_img[ctrl].sum())
    if opts.loss != "squared":
        cross_ctrl, cross_prior = _cross_terms(problem, run, d, Cobs, prior_tr)
        for k, x in cross_prior.items():
            red_prior[k] -= x
        # the cross terms add up to zero over all groups: the tie points' image
        # observations (the largest group, whose own first-order term is least accurate:
        # points of two rays) take the rest, the total staying the Stein redundancy
        rest = sum(cross_prior.values())
        if np.any(~ctrl):
            red_ctrl -= cross_ctrl
            red_tie += rest + cross_ctrl
        else:
            red_ctrl += rest
    out = {}
    if np.any(~ctrl):
        out["image_tie"] = (float(r_img[~ctrl].sum()), red_tie)
    if np.any(ctrl):
        out["image_control"] = (float(r_img[ctrl].sum()), red_ctrl)
    _, _, _, _, _, parts = problem.prior_terms(run.state)
    for k in ("gnss", "imu", "control"):
        if k in parts:
            out[k] = (float((parts[k] ** 2).sum()), float(red_prior[k]))
    return out


def _cross_terms(problem, run, d, Cobs, prior_tr):
    """The part of the robust ``v_k'P_k W_k v_k`` of the control points' image observations
    and of each prior group (GNSS, IMU, control) that its share of the Stein redundancy
    misses, in variance-factor units.

    With ``v = eps - A delta`` (``delta`` the error of the estimate) a group's ``psi_k'v_k =
    psi_k'eps_k - psi_k'A_k delta``. Stein's identity gives the first term's expectation
    (the group's share of :func:`~photogeom.bundle.robust.stein_redundancy`); the second
    adds up to zero over the groups (``A'psi = 0``) but not within one. To first order, with
    ``H = A'DA`` the normal matrix weighted by the score slopes, ``B = H + J'(S - D)J`` the
    one whose image points are weighted by the scores' spreads ``S`` instead and ``Sigma =
    H^-1 B H^-1`` the covariance of the estimate, its expectation is ``tr(H^-1 B_k) - tr(H_k
    Sigma)``: for a prior group (weight 1) ``tr(N_k (H^-1 - Sigma))``, positive since the
    spread of a robust score is below its slope; for image point ``i`` ``d_i tr(J_i (H^-1 -
    Sigma) J_i') + (spread_i - slope_i) tr(J_i H^-1 J_i')``. ``H^-1 - Sigma = -H^-1 J'(S -
    D)J H^-1`` is the derivative of ``(H + t J'(S - D)J)^-1`` at ``t = 0``, taken as its
    difference quotient at ``t =`` :data:`CROSS_STEP` (one more factorisation; the
    quotient's error is below ``t (1 - spread / slope)`` of the term). ``spread`` and
    ``slope`` are the expectations of :func:`~photogeom.bundle.robust.influence_factors` at
    each image point's residual variance ``1 - h_i`` (its leverage in the slope-weighted
    adjustment, variance factor 1: the fixed point of the iteration). Without these terms
    the control points' factor came out 0.76 (Huber) and 0.58 (Cauchy) against 0.95 for
    least squares on the same draws.

    Returns
    -------
    (control_images, per_prior_group) : float, dict
    """
    from .result import statistics_pass

    opts = problem.options
    dd = np.clip(d, 1e-12, None)
    tr_d = np.einsum("ndd->n", Cobs) / dd  # tr(J_i H^-1 J_i')
    h = np.clip(0.5 * tr_d, 0.0, 1.0)
    slope, spread = influence_factors(opts.loss, opts.scale, 1.0 - h)
    wt = np.clip(d + CROSS_STEP * (spread - slope), 1e-12, None)
    _, _, _, Qt, Qppt, Ct = statistics_pass(problem, run.state, wt, pairs=True, cofactors=True)
    tr_t = np.einsum("ndd->n", Ct) / wt  # tr(J_i (H + t J'(S - D)J)^-1 J_i')
    c = problem.obs_is_control
    diff = (tr_t[c] - tr_d[c]) / CROSS_STEP  # tr(J_i (H^-1 - Sigma) J_i')
    cross_ctrl = float(np.sum(d[c] * diff + (spread[c] - slope[c]) * tr_d[c]))
    t_tr = _prior_cofactor_traces(problem, run, Qt, Qppt)
    cross_prior = {k: (t_tr[k] - prior_tr[k]) / CROSS_STEP for k in prior_tr}
    return cross_ctrl, cross_prior


def _bound_root(k: str, trail: list, bounds: dict) -> dict:
    """Bounds ``(lo, hi)`` of the root of ``v'Pv = r`` in a group's factor: set when its
    ratio has jumped across 1, outside :data:`TOLERANCE`, in each of its last two updates
    (the iteration alternating around the root), narrowed after that by each new ratio.

    A group's ratio ``v'Pv / r`` need not be continuous in its factor: with Huber's loss an
    image point's score slope (:func:`~photogeom.bundle.robust.score_slopes`) drops from 1
    to 1/2 where its residual crosses the loss scale, and its share of the group's
    redundancy with it (in a control points' image group of redundancy 38 the ratio jumps
    from 0.981 to 1.019). The plain update then alternates between two factors around the
    root for the remaining rounds, never within the tolerance. Only a repeated crossing
    sets the bounds: a single one is also the first rounds' overshoot, whose factors bound
    the root only for the other groups' factors of then.
    """
    bounds = dict(bounds)
    f, q = trail[-1]
    if k in bounds:
        lo, hi = bounds[k]
        bounds[k] = (max(lo, f), hi) if q > 1.0 else (lo, min(hi, f))
    elif len(trail) >= 3:
        out = [abs(r - 1.0) >= TOLERANCE for _, r in trail[-3:]]
        side = [r > 1.0 for _, r in trail[-3:]]
        if all(out) and side[0] != side[1] != side[2]:
            (f1, q1), (f2, _) = trail[-2], trail[-1]
            bounds[k] = (f1, f2) if q1 > 1.0 else (f2, f1)
    return bounds


def _bounded_update(new: float, bounds: tuple[float, float] | None) -> float:
    """The next variance factor of a group: ``f_k v_k'P_k v_k / r_k``, or, for a group whose
    root is bounded (:func:`_bound_root`) and that update falls outside the bounds, their
    geometric mean. Bisected so, the bounds close in on the root; once they are within ``2
    TOLERANCE`` of each other their geometric mean is within :data:`TOLERANCE` of it, as
    close as the tolerance on the ratio puts a factor whose ratio falls at most in
    proportion to it."""
    if bounds is None:
        return new
    lo, hi = bounds
    return new if lo < new < hi else float(np.sqrt(lo * hi))


def iterate_variance_components(problem, run, opts, progress=None):
    """Alternate adjustment and variance-factor updates; returns the last run and a dict
    with the factors (sigma multipliers), redundancy contributions and rounds."""
    history = []
    held: dict[str, str] = {}  # groups whose variance cannot be estimated, and why
    rounds = 0
    iters = run.iterations
    converged = False
    budget = MAX_ROUNDS  # rounds from the start, or from the last group held
    previous: dict[str, tuple[float, float]] = {}  # per group (ratio, f_k) of the last round
    trail: dict[str, list[tuple[float, float]]] = {}  # per group (f_k, ratio) of each update
    bounds: dict[str, tuple[float, float]] = {}  # per cycling group, factors around its root
    bracketed: dict[str, list[float]] = {}
    while rounds < budget:
        rounds += 1
        contrib = _contributions(problem, run)
        names = list(contrib)
        vtpv = np.array([contrib[k][0] for k in names])
        red = np.array([contrib[k][1] for k in names])
        if rounds == 1:
            first_red = {k: float(r) for k, r in zip(names, red)}
        factors = {k: float(problem.group_factor[k]) for k in names}
        gone = _inestimable(names, vtpv, red, first_red, held, factors, previous)
        previous = {
            k: (float(q / r), factors[k]) for k, q, r in zip(names, vtpv, red) if r > NO_REDUNDANCY
        }
        for k in gone:  # back to its a-priori sigmas, no longer estimated
            problem.group_factor[k] = 1.0
            held[k] = gone[k]
        est = np.array([k not in held for k in names])
        if gone:
            previous = {}  # the other groups' contributions change with the held one
            bounds, trail = {}, {}
            budget = rounds + MAX_ROUNDS
            history.append({})
            run = levenberg_marquardt(problem, run.state, opts, progress)
            iters += run.iterations
            continue
        if not np.any(est):
            break
        keys = [k for k, e in zip(names, est) if e]
        old = np.array([problem.group_factor[k] for k in keys])
        new, ratio = update_variance_factors(old, vtpv[est], red[est])
        history.append({k: float(r) for k, r in zip(keys, ratio)})
        within = np.abs(ratio - 1.0) < TOLERANCE
        for k, f, q in zip(keys, old, ratio):
            trail.setdefault(k, []).append((float(f), float(q)))
            bounds = _bound_root(k, trail[k], bounds)
        narrow = np.array(
            [k in bounds and bounds[k][1] < (1.0 + 2.0 * TOLERANCE) * bounds[k][0] for k in keys]
        )
        if np.all(within | narrow):
            converged = True
            between = narrow & ~within
            if not np.any(between):
                break
            # the ratio jumps across 1 between two factors less than 2 TOLERANCE apart
            # (_bounded_update): adjust once more at their geometric mean, within
            # TOLERANCE of the root
            for k in np.array(keys)[between]:
                lo, hi = bounds[k]
                bracketed[k] = [float(np.sqrt(lo)), float(np.sqrt(hi))]
                problem.group_factor[k] = float(np.sqrt(lo * hi))
            run = levenberg_marquardt(problem, run.state, opts, progress)
            iters += run.iterations
            rounds += 1
            contrib = _contributions(problem, run)
            history.append({k: contrib[k][0] / contrib[k][1] for k in keys})
            break
        for k, v in zip(keys, new):
            problem.group_factor[k] = _bounded_update(float(v), bounds.get(k))
        run = levenberg_marquardt(problem, run.state, opts, progress)
        iters += run.iterations
    run.iterations = iters
    info = {
        "factors": {k: float(np.sqrt(problem.group_factor[k])) for k in contrib},
        "redundancy": {k: float(contrib[k][1]) for k in contrib},
        "rounds": rounds,
        "converged": converged,
        "ratio_history": history,
        "not_estimated": dict(held),
        "bracketed": bracketed,
        "meaning": "estimated sigma of each group = factor x its a-priori sigma; groups in "
        "not_estimated keep their a-priori sigmas (factor 1)",
    }
    return run, info
