"""Variance-component estimation (Förstner / Helmert, iterated) for the bundle adjustment.

Groups: image observations of tie points, image observations of control points, control
point coordinates, GNSS positions, IMU attitudes. For each group k with whitened residuals
``v_k`` and redundancy contribution ``r_k = n_k - tr(P_k J Q J')`` the variance factor is
updated as ``f_k <- f_k * v_k'P_k v_k / r_k`` and the adjustment repeated until every ratio
is 1 within the tolerance. With a robust loss ``v_k'P_k v_k`` holds the robust weights and
``r_k`` is the group's share of the Stein redundancy
(:func:`photogeom.bundle.robust.stein_redundancy`), from the adjustment weighted by the
score slopes: the expectation of ``v_k'P_k v_k`` over the group's variance factor under
normal errors. The estimated standard
deviation of a group is its a-priori one times ``sqrt(f_k)``. A group without redundancy,
or whose iterated estimate runs to zero (its redundancy contribution collapsing), keeps its
a-priori sigmas and is listed in ``not_estimated``.
"""

from __future__ import annotations

import numpy as np

from ..adjust.variance_components import update_variance_factors
from ..camera.frame_kernel import opk_from_increment_jacobian
from ._angles import opk_from_rotations
from .adjustment import levenberg_marquardt
from .robust import point_trace_shares, score_slopes

#: Stop when every group's ratio v'Pv / r is within this of 1.
TOLERANCE = 0.01
MAX_ROUNDS = 20
#: A group whose redundancy contribution falls below this share of its first-round value
#: is collapsing: the iterated estimate of its variance runs to zero.
COLLAPSE = 1e-3
#: A redundancy contribution at most this is none (nothing controls the group).
NO_REDUNDANCY = 1e-6

GROUP_TEXT = {
    "image_tie": "image observations of tie points",
    "image_control": "image observations of control points",
    "control": "control-point coordinates",
    "gnss": "GNSS positions",
    "imu": "IMU attitudes",
}


def _inestimable(names, vtpv, red, first_red, held) -> dict:
    """Groups (not yet held) whose variance cannot be estimated, with the reason: no
    redundancy from the start (nothing else controls them), or a redundancy contribution
    collapsed below :data:`COLLAPSE` of its first round's while its ratio ``v'Pv / r`` is
    still below 1 (the iterated estimate of the group's variance running to zero)."""
    out = {}
    for k, q, r in zip(names, vtpv, red):
        if k in held:
            continue
        if first_red[k] <= NO_REDUNDANCY:
            out[k] = "no redundancy: no other observations control this group"
        elif r <= NO_REDUNDANCY or (r < COLLAPSE * first_red[k] and q < (1 - TOLERANCE) * r):
            out[k] = (
                "its iterated estimate runs to zero (residuals much smaller than its "
                f"redundancy of {first_red[k]:.3g} expects: too few observations to estimate "
                "its variance)"
            )
    return out


def _contributions(problem, run):
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
    ctrl_extra = 0.0
    if opts.loss != "squared":
        per_obs, per_point = point_trace_shares(
            opts.loss, opts.scale, lin1.r, lin1.P, problem.obs_j, lin1.point_info
        )
        red_img = red_img + per_obs
        ctrl_extra = float(np.sum(per_point))
    out = {}
    ctrl = problem.obs_is_control
    if np.any(~ctrl):
        out["image_tie"] = (float(r_img[~ctrl].sum()), float(red_img[~ctrl].sum()))
    if np.any(ctrl):
        out["image_control"] = (float(r_img[ctrl].sum()), float(red_img[ctrl].sum()))
    _, _, _, _, _, parts = problem.prior_terms(run.state)
    gf = problem.group_factor
    if "gnss" in parts:
        k = problem.has_gnss
        w = 1.0 / (problem.block.gnss_sigma[k] ** 2 * gf["gnss"])
        q = np.einsum("kii->ki", Q.local[k][:, :3, :3])
        out["gnss"] = (float((parts["gnss"] ** 2).sum()), float((1.0 - w * q).sum()))
    if "imu" in parts:
        k = problem.has_imu
        s = problem.block.imu_sigma[k] * np.sqrt(gf["imu"])
        J = opk_from_increment_jacobian(opk_from_rotations(run.state.M[k])) / s[:, :, None]
        q = np.einsum("kai,kij,kaj->ka", J, Q.local[k][:, 3:6, 3:6], J)
        out["imu"] = (float((parts["imu"] ** 2).sum()), float((1.0 - q).sum()))
    if "control" in parts:
        c = problem.control
        w = 1.0 / (problem.control_sigma**2 * gf["control"])
        q = np.einsum("kii->ki", Qpp[c])
        out["control"] = (
            float((parts["control"] ** 2).sum()),
            float((1.0 - w * q).sum()) + ctrl_extra,
        )
    return out


def iterate_variance_components(problem, run, opts, progress=None):
    """Alternate adjustment and variance-factor updates; returns the last run and a dict
    with the factors (sigma multipliers), redundancy contributions and rounds."""
    history = []
    held: dict[str, str] = {}  # groups whose variance cannot be estimated, and why
    rounds = 0
    iters = run.iterations
    converged = False
    budget = MAX_ROUNDS  # rounds from the start, or from the last group held
    while rounds < budget:
        rounds += 1
        contrib = _contributions(problem, run)
        names = list(contrib)
        vtpv = np.array([contrib[k][0] for k in names])
        red = np.array([contrib[k][1] for k in names])
        if rounds == 1:
            first_red = {k: float(r) for k, r in zip(names, red)}
        gone = _inestimable(names, vtpv, red, first_red, held)
        for k in gone:  # back to its a-priori sigmas, no longer estimated
            problem.group_factor[k] = 1.0
            held[k] = gone[k]
        est = np.array([k not in held for k in names])
        if gone:
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
        if np.all(np.abs(ratio - 1.0) < TOLERANCE):
            converged = True
            break
        for k, v in zip(keys, new):
            problem.group_factor[k] = float(v)
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
        "meaning": "estimated sigma of each group = factor x its a-priori sigma; groups in "
        "not_estimated keep their a-priori sigmas (factor 1)",
    }
    return run, info
