"""The residual-grid study re-created on simulated blocks, and its block-level evaluation.

* :func:`field_recovery` - the fitted grids against the simulator's true local field, at the
  supported nodes inside each image;
* :func:`evaluate_readjustment` - residuals (RMS, mean length per image and block), steps
  per model and, for a simulated block, check-point errors against the truth, before and
  after the correction;
* :func:`sweep_spacings` - the grid-size sweep: step per model and computing time per
  spacing, the closest-to-origin spacing per model and the most frequent one
  (:func:`~photogeom.calibration.choose_spacing`,
  :func:`~photogeom.calibration.most_frequent_spacing`);
* :func:`run_study` - the pipeline of the study on one simulated preset: adjust, fit,
  correct, re-adjust, evaluate, a coarse grid against the fine one, the sweep; each also on
  re-matched observations (:meth:`~photogeom.simulate.SimulatedBlock.rematch`: fresh
  noise, as the study's matching of its corrected images), where a grid is not credited
  with the noise it fitted;
* :func:`visible_field` - the part of the true local field that an adjustment leaves in
  the residuals (the rest is taken up by orientations, calibration and points);
* :func:`compare_in_adjustment` - post-processing against grids estimated inside the
  adjustment on one simulated block: field recovery, check points, steps, time.
"""

from __future__ import annotations

import numbers
import time
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from ..bundle.block import Block, _lookup
from ..errors import InputError
from .blocks import (
    _adjust_corrected,
    _uncorrected_ids,
    block_residuals,
    correct_block_observations,
    fit_residual_grids,
    readjust,
)
from .evaluate import choose_spacing, compare_residuals, most_frequent_spacing
from .grid import _rms_len, check_spacing
from .steps import model_steps

__all__ = [
    "compare_in_adjustment",
    "evaluate_readjustment",
    "field_recovery",
    "run_study",
    "sweep_spacings",
    "visible_field",
    "visible_recovery",
]

#: Standard deviation (m) of the tie points held at their truth by ``visible_field``.
HELD_POINT_SIGMA = 1e-6

#: Timings of each spacing's grid fit and correction in the grid-size sweep, at most; the
#: cost is their minimum (:func:`sweep_spacings`, ``repeats``).
TIMING_REPEATS = 3

#: The clock of the grid-size sweep's computing time (s): the CPU time of this process,
#: every thread (BLAS, OpenCV) counted, and not the wall clock, which also counts the other
#: processes of a shared machine (:func:`sweep_spacings`).
_clock = time.process_time


def field_recovery(sim, grids) -> dict:
    """Compare fitted grids with the true local field of a simulated block.

    At every supported node inside the image (``grid.support``) the grid's value is
    compared with ``-sim.local_field(image, node)`` (the modelled residual is computed
    minus observed, the field is added to the observations).

    Parameters
    ----------
    sim : SimulatedBlock
        The simulated block (its true local field).
    grids : mapping
        ``image id -> ResidualGrid`` fitted to it.

    Returns
    -------
    dict
        ``images``: per image ``{"field_rms", "difference_rms", "ratio", "nodes"}`` (px);
        ``block``: the same over all images' supported nodes.
    """
    out, all_t, all_d = {}, [], []
    for iid, g in grids.items():  # images, not points
        u, v = g.layout.node_coordinates()
        uv = np.column_stack([u.ravel(), v.ravel()])
        keep = g.support.ravel() & (uv[:, 0] <= g.layout.width - 0.5)
        keep &= uv[:, 1] <= g.layout.height - 0.5
        uv = uv[keep]
        if uv.shape[0] == 0:
            continue
        truth = -np.asarray(sim.local_field(iid, uv))
        d = g.evaluate(uv) - truth
        out[iid] = {
            "field_rms": _rms_len(truth),
            "difference_rms": _rms_len(d),
            "ratio": _rms_len(d) / _rms_len(truth) if _rms_len(truth) > 0 else float("nan"),
            "nodes": int(uv.shape[0]),
        }
        all_t.append(truth)
        all_d.append(d)
    if not all_t:
        raise InputError("field_recovery: no grid has a supported node (use a larger spacing)")
    t, d = np.concatenate(all_t), np.concatenate(all_d)
    return {
        "images": out,
        "block": {
            "field_rms": _rms_len(t),
            "difference_rms": _rms_len(d),
            "ratio": _rms_len(d) / _rms_len(t),
            "nodes": int(t.shape[0]),
        },
    }


def visible_field(sim, *, hold_points: bool = False, **options) -> np.ndarray:
    """The part of the simulated local field that the adjustment leaves in the residuals.

    The block's truth is adjusted (same settings as :func:`photogeom.bundle_adjust`, Brown
    self-calibration) with noise-free observations ``ideal + local field``: its residuals
    (computed minus observed, px, per observation in block order) are what any fit to the
    residuals of an adjustment can see. The difference to ``-sim.local`` was taken up by the
    exterior orientations, the calibration and the points: a smooth deformation of the
    object displaces each image differently, so per-image fields of long wavelength are
    partly indistinguishable from the object and orientation (a null space of the
    residuals, not a weakness of the grid).

    Parameters
    ----------
    sim : SimulatedBlock
    hold_points : bool
        Hold every tie point at its true coordinates (control with a standard deviation of
        1e-6 m), to see how much of the field the points take up.
    **options
        Settings of :func:`photogeom.bundle_adjust`, e.g. ``fix_exterior=True`` (what the
        orientations take up) or ``free=()`` (no self-calibration).

    Returns
    -------
    numpy.ndarray, shape (n, 2)
        NaN for check-point rows (not adjusted).
    """
    from ..bundle.adjustment import bundle_adjust
    from ..bundle.residuals import reprojection_residuals

    block = sim.truth.with_observations(uv=sim.ideal + sim.local)
    if hold_points:
        tie = block.role == "tie"
        sigma = block.point_sigma.copy()
        sigma[tie] = HELD_POINT_SIGMA
        block = block.replace(role=np.where(tie, "control", block.role), point_sigma=sigma)
    fit = bundle_adjust(block, **{"snooping": False, **options})
    v = reprojection_residuals(fit.block)
    v[~fit.in_adjustment] = np.nan
    return v


def visible_recovery(sim, grids, visible: np.ndarray | None = None) -> dict:
    """Fitted grids against :func:`visible_field` at the tie observations.

    Parameters
    ----------
    sim : SimulatedBlock
        The simulated block.
    grids : mapping
        ``image id -> ResidualGrid`` fitted to it.
    visible : numpy.ndarray, shape (n_observations, 2), optional
        The visible field (px) if already computed; default :func:`visible_field` of
        ``sim``.

    Returns
    -------
    dict
        ``field_rms`` (the true field at the tie observations), ``visible_rms``,
        ``visible_share`` (their ratio), ``difference_rms`` (grid minus visible field) and
        ``ratio`` (difference over visible RMS), px.
    """
    v = visible_field(sim) if visible is None else np.asarray(visible)
    b = sim.block
    tie = (b.role[b.obs_point] == "tie") & np.all(np.isfinite(v), axis=1)
    rows = np.flatnonzero(tie)
    ids = b.image_ids[b.obs_image[rows]]
    est = np.full((rows.size, 2), np.nan)
    for iid in np.unique(ids).tolist():  # images, not points
        if iid not in grids:
            continue
        sel = ids == iid
        est[sel] = grids[iid].evaluate(b.observations.uv[rows[sel]])
    ok = np.all(np.isfinite(est), axis=1)
    vis, est, loc = v[rows[ok]], est[ok], sim.local[rows[ok]]
    d = est - vis
    return {
        "field_rms": _rms_len(loc),
        "visible_rms": _rms_len(vis),
        "visible_share": _rms_len(vis) / _rms_len(loc) if _rms_len(loc) > 0 else float("nan"),
        "difference_rms": _rms_len(d),
        "ratio": _rms_len(d) / _rms_len(vis) if _rms_len(vis) > 0 else float("nan"),
    }


def _truth_errors(block: Block, sim, ids) -> np.ndarray:
    """Coordinates of points ``ids`` in ``block`` minus their truth, (k, 3) (NaN where the
    block has not triangulated a point)."""
    ids = np.asarray(ids)
    bpos = _lookup(block.point_ids, ids, "evaluate_readjustment", "point_ids")
    tpos = _lookup(sim.truth.point_ids, ids, "evaluate_readjustment (the truth)", "point_ids")
    return block.xyz[bpos] - sim.truth.xyz[tpos]


def _check_errors(block: Block, sim) -> dict:
    ids = np.asarray(sim.check_ids)
    if ids.size == 0:
        return {}
    e = _truth_errors(block, sim, ids)
    rmse = np.sqrt(np.nanmean(e * e, axis=0))
    return {"errors": e, "rmse": rmse, "rmse_gsd": rmse / sim.gsd}


def _tie_errors(block: Block, sim) -> dict:
    """RMSE (X, Y, Z) of every triangulated tie point against the truth: the object's
    accuracy measured at thousands of points rather than a few check points."""
    e = _truth_errors(block, sim, sim.tie_ids)
    e = e[np.all(np.isfinite(e), axis=1)]
    rmse = np.sqrt(np.mean(e * e, axis=0)) if e.size else np.full(3, np.nan)
    return {"points": int(e.shape[0]), "rmse": rmse, "rmse_gsd": rmse / sim.gsd}


def _surveyed_errors(block: Block, surveyed: dict, gsd: float) -> dict:
    """Check points of ``block`` (their triangulated coordinates) minus ``surveyed``
    (``{str(id): (3,)}``)."""
    ids = block.point_ids[block.role == "check"]
    keep = [k for k in ids.tolist() if str(k) in surveyed]
    if not keep:
        raise InputError(
            "surveyed: none of the block's check points "
            f"({', '.join(map(str, ids[:5].tolist())) or 'none'}) has a surveyed coordinate; "
            "give the check points' ids as the block names them"
        )
    row = {k: i for i, k in enumerate(block.point_ids.tolist())}
    e = np.array([block.xyz[row[k]] - np.asarray(surveyed[str(k)], float) for k in keep])
    rmse = np.sqrt(np.nanmean(e * e, axis=0))
    return {"ids": keep, "errors": e, "rmse": rmse, "rmse_gsd": rmse / gsd}


def evaluate_readjustment(before, after, *, sim=None, surveyed=None, overlap: float = 0.6) -> dict:
    """Residuals, steps and check-point errors before and after the correction.

    Parameters
    ----------
    before, after : BundleFit
        The first adjustment and the re-adjustment (:func:`readjust`).
    sim : SimulatedBlock, optional
        Adds the check-point errors against the true coordinates (object units and GSD).
    surveyed : mapping, optional
        ``{point id: (X, Y, Z)}`` surveyed coordinates of check points. Adds the
        check-point errors, triangulated minus surveyed, before and after (object units,
        and GSD of the first adjustment's block). Ids are matched as text. Default without
        ``sim``: the survey the adjusted block keeps (``before.block.surveyed``), if it has
        check points; a block read from a folder written before the survey was kept has
        none, and these errors are then left out.
    overlap : float
        Target forward overlap (fraction) of the stereo models whose steps are measured
        (:func:`model_steps`; the study: 0.6).

    Returns
    -------
    dict
        ``residuals`` (:func:`compare_residuals` of the tie-point residuals per image and
        block), ``steps_before``, ``steps_after`` (``{(a, b): GSD}``), ``mean_step_before``,
        ``mean_step_after``, ``step_reduction`` (of the mean) and, with ``sim`` or
        ``surveyed``, ``check_before``, ``check_after`` (``errors`` (k, 3), ``rmse``,
        ``rmse_gsd``); with ``sim`` also ``tie_before``, ``tie_after``: the RMSE of every
        triangulated tie point against its true coordinates (``points``, ``rmse``,
        ``rmse_gsd``), the object's accuracy at thousands of points where a simulated block
        has a few check points. ``adjustment``: ``{"before": ..., "after": ...}``, sigma0
        and its redundancy of each fit
        (:func:`~photogeom.calibration.evaluate.adjustment_statistics`; the re-adjustment's
        over the chain's effective redundancy when it has one; None for a stand-in without
        its fit's statistics, as a block read as adjusted).
    """
    from .evaluate import adjustment_statistics

    rb = {k: v[1] for k, v in block_residuals(before.block).items() if v[1].size}
    ra = {k: v[1] for k, v in block_residuals(after.block).items() if k in rb}
    sb = model_steps(before.block, overlap=overlap)
    sa = model_steps(after.block, overlap=overlap)
    common = [k for k in sb if k in sa]
    mb = float(np.mean([sb[k] for k in common])) if common else float("nan")
    ma = float(np.mean([sa[k] for k in common])) if common else float("nan")
    out = {
        "residuals": compare_residuals(rb, ra),
        "steps_before": sb,
        "steps_after": sa,
        "mean_step_before": mb,
        "mean_step_after": ma,
        "step_reduction": 1.0 - ma / mb if mb > 0 else float("nan"),
        # a block read as adjusted (a stand-in of the first fit) has no statistics
        "adjustment": {
            k: adjustment_statistics(f) if hasattr(f, "sigma0") else None
            for k, f in (("before", before), ("after", after))
        },
    }
    if sim is not None and surveyed is not None:
        raise InputError("give sim (the truth) or surveyed check coordinates, not both")
    if sim is not None:
        out["check_before"] = _check_errors(before.block, sim)
        out["check_after"] = _check_errors(after.block, sim)
        out["tie_before"] = _tie_errors(before.block, sim)
        out["tie_after"] = _tie_errors(after.block, sim)
    else:
        b = before.block
        check = b.role == "check"
        if surveyed is None and b.surveyed is not None and np.any(check):
            surveyed = dict(zip(b.point_ids[check].tolist(), b.surveyed_xyz[check]))
        if surveyed is None:
            return out
        table = {str(k): v for k, v in dict(surveyed).items()}
        gsd = before.block.gsd()
        out["check_before"] = _surveyed_errors(before.block, table, gsd)
        out["check_after"] = _surveyed_errors(after.block, table, gsd)
    return out


def _spacings(values, name: str) -> list[float]:
    """``values`` as a list of spacings (px), each checked (:func:`check_spacing`); text
    and booleans are refused by ``name``."""
    if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
        raise InputError(f"{name} must be a list of numbers of pixels, not {values!r}")
    return [check_spacing(s, f"{name}[{i}]") for i, s in enumerate(values)]


def sweep_spacings(
    fit,
    spacings: Sequence[float],
    *,
    overlap: float = 0.6,
    rematched: Block | None = None,
    exclude: Sequence = (),
    repeats: int = TIMING_REPEATS,
    stage: Callable[[str], None] | None = None,
    **options,
) -> dict:
    """The grid-size sweep on an adjusted block.

    For every spacing: fit the grids, correct the observations, re-adjust, the step per
    model and the computing time; then per model the closest-to-origin spacing of the
    min-max normalised step and time, and the block's most frequent spacing.

    The computing time of a spacing is the CPU time of this process (``time.process_time``,
    every thread counted) spent fitting the grids and correcting the observations with
    them: the part of the work that depends on the spacing. The wall clock would count the
    other processes of a shared machine, so the chosen spacing would follow the machine's
    load. The re-adjustment is timed apart (``time_readjust``) and left out of the cost: it
    solves the same block at every spacing, and min-max normalisation cancels a constant
    added to every time, so the re-adjustment would add only its fluctuation. Before the
    first spacing one image's grid is fitted and applied untimed (a warm-up), so that the
    first call's costs are not counted.

    CPU time still varies with the load of a shared machine (caches and memory shared with
    other processes: one spacing's fit can take twice as long), and a spacing's time is
    common to every model, so one slow timing moved many models' choices at once. The fit
    and the correction are therefore timed up to ``repeats`` times per spacing and the
    cost is the minimum (the work itself does not vary; the load only adds to it). The
    repeats interleave the spacings (every spacing once, then every spacing again), so a
    burst of load falls on one timing of several spacings, not on every timing of one.
    Only the timing is repeated: the grids of the first pass give the re-adjustment and
    the steps. A further pass is made only while the repeated passes so far and this one
    (estimated as the sum of the current minima) stay within the CPU time of the first
    pass (fits, corrections, re-adjustments and steps), so the repeats add about the first
    pass's CPU time at most (a pass can take longer than its estimate; measured on a 2 x 6
    image block: the sweep took 1.4-2.4 times, on average 1.84 times, the CPU time of one
    timing); ``timings`` in the result says how many were made.

    Parameters
    ----------
    fit : BundleFit
        The first adjustment.
    spacings : sequence of float
        At least two spacings (px).
    overlap : float
        Target forward overlap (fraction) of the stereo models whose steps are measured
        (:func:`model_steps`; the study: 0.6).
    rematched : Block, optional
        ``fit.block`` with its observations measured again (same rows), e.g.
        ``sim.rematch(fit.block)`` (:meth:`~photogeom.simulate.SimulatedBlock.rematch`): the
        grids fitted to ``fit``'s residuals also correct these observations, which are
        re-adjusted the same way; their steps and choice are returned beside the others.
    exclude : sequence of image ids
        Images that get no grid (e.g. too few residuals for one): their observations are
        re-adjusted as they are (``readjust(..., uncorrected=exclude)``).
    repeats : int, default ``TIMING_REPEATS`` (3)
        Timings of each spacing's fit and correction at most (an integer >= 1); the cost
        is their minimum. 1: one timing, no repeated pass.
    stage : callable, optional
        Called as ``stage(text)`` whenever the sweep moves on, with the spacing it is at
        and the step, e.g. ``"spacing 3 of 7 (300 px): fitting grids, 120 of 250
        images"``, ``"spacing 3 of 7 (300 px): re-adjusting"``, ``"timing again, pass 2 of
        at most 3: spacing 3 of 7 (300 px)"``: a study-size block takes minutes per pass,
        and a display of the elapsed time alone does not say how far it is. Without a
        ``progress`` option the per-image count of the fit is included in the text.
    **options
        Passed to :func:`fit_residual_grids`.

    Returns
    -------
    dict
        ``spacings``, ``models`` (keys), ``step`` (models, s) GSD, ``time`` (s,) CPU
        seconds of the grid fit and the correction, the minimum over the timings (the
        cost), ``timings`` (int) the number of timings per spacing, ``time_readjust`` (s,)
        CPU seconds of the re-adjustment (not in the cost), ``step_before`` (models,),
        ``choice`` (the dict of :func:`choose_spacing`),
        ``spacing`` (the most frequent choice); with ``rematched`` also
        ``step_rematched``, ``choice_rematched`` and ``spacing_rematched`` (the same
        models and the same times: the grids are fitted once per spacing).
    """
    # every spacing checked before the first is fitted (a sweep takes minutes)
    g = _spacings(spacings, "sweep_spacings: spacings")
    if len(g) < 2:
        raise InputError("sweep_spacings: give at least two spacings")
    if isinstance(repeats, bool) or not isinstance(repeats, numbers.Integral) or repeats < 1:
        raise InputError(
            f"sweep_spacings: repeats must be an integer >= 1 (timings per spacing), "
            f"not {repeats!r}"
        )
    if rematched is not None:
        _check_rematched(fit.block, rematched)
    before = model_steps(fit.block, overlap=overlap)
    keys = list(before)
    if not keys:
        raise InputError("sweep_spacings: the block has no pair of consecutive stereo models")
    left_out = _uncorrected_ids(fit.block, exclude)
    if left_out:
        if "images" in options:
            raise InputError("sweep_spacings: give exclude= or images=, not both")
        options["images"] = [k for k in fit.block.image_ids.tolist() if k not in left_out]
    runs = 1 if rematched is None else 2
    step = np.full((runs, len(keys), len(g)), np.nan)
    times = np.zeros(len(g))
    times_re = np.zeros(len(g))
    _warm_up(fit.block, g[0], left_out, options)
    say = stage if stage is not None else _silent
    start = _clock()
    for c, sp in enumerate(g):  # spacings, not points
        at = f"spacing {c + 1} of {len(g)} ({sp:g} px)"
        say(f"{at}: fitting grids")
        fit_options = options
        if stage is not None and "progress" not in options:
            fit_options = {**options, "progress": _image_counter(stage, f"{at}: fitting grids")}
        t0 = _clock()
        grids = fit_residual_grids(fit.block, sp, **fit_options)
        corrected = correct_block_observations(fit.block, grids, uncorrected=exclude)
        t1 = _clock()
        say(f"{at}: re-adjusting")
        re = _adjust_corrected(corrected, snooping=False)
        times[c], times_re[c] = t1 - t0, _clock() - t1
        s = model_steps(re.block, overlap=overlap)
        step[0, :, c] = [s.get(k, np.nan) for k in keys]
        if rematched is not None:
            say(f"{at}: re-adjusting the re-matched observations")
            again = readjust(rematched, grids, uncorrected=exclude, snooping=False)
            s = model_steps(again.block, overlap=overlap)
            step[1, :, c] = [s.get(k, np.nan) for k in keys]
    timings = _repeat_timings(
        fit.block, g, times, repeats, _clock() - start, exclude, options, say
    )
    ok = np.all(np.isfinite(step), axis=(0, 2))
    t = np.broadcast_to(times, step[0, ok].shape)
    choice = choose_spacing(g, step[0, ok], t)
    out = {
        "spacings": g,
        "models": [k for k, o in zip(keys, ok) if o],
        "step": step[0, ok],
        "time": times,
        "timings": timings,
        "time_readjust": times_re,
        "step_before": np.array([before[k] for k, o in zip(keys, ok) if o]),
        "choice": choice,
        "spacing": most_frequent_spacing(choice),
    }
    if rematched is not None:
        out["step_rematched"] = step[1, ok]
        out["choice_rematched"] = choose_spacing(g, step[1, ok], t)
        out["spacing_rematched"] = most_frequent_spacing(out["choice_rematched"])
    return out


def _repeat_timings(
    block: Block,
    spacings: list[float],
    times: np.ndarray,
    repeats: int,
    budget: float,
    exclude: Sequence,
    options: dict,
    say: Callable[[str], None] | None = None,
) -> int:
    """Time every spacing's fit and correction again, in passes over all spacings, and
    keep each spacing's minimum in ``times`` (in place).

    Parameters
    ----------
    block : Block
        The adjusted block of the sweep.
    spacings : list of float
        The sweep's spacings, px, in its order (every pass takes them in this order).
    times : numpy.ndarray, shape (s,)
        The first pass's CPU seconds per spacing; lowered to the minimum over the passes.
    repeats : int
        Timings per spacing at most (the first pass's included).
    budget : float
        CPU seconds the repeated passes may take together: a pass is started only if the
        passes so far plus this one (estimated as ``times.sum()``) stay within it.
    exclude : sequence
        Images that get no grid (their observations are not corrected).
    options : dict
        The sweep's options of :func:`fit_residual_grids`.
    say : callable, optional
        ``say(text)`` names the pass and the spacing being timed (``stage`` of
        :func:`sweep_spacings`).

    Returns
    -------
    int
        The timings made per spacing (1 to ``repeats``).
    """
    say = say if say is not None else _silent
    spent, made = 0.0, 1
    while made < repeats and spent + float(times.sum()) <= budget:
        begin = _clock()
        for c, sp in enumerate(spacings):  # spacings, not points
            say(
                f"timing again, pass {made + 1} of at most {repeats}: "
                f"spacing {c + 1} of {len(spacings)} ({sp:g} px)"
            )
            t0 = _clock()
            grids = fit_residual_grids(block, sp, **options)
            correct_block_observations(block, grids, uncorrected=exclude)
            times[c] = min(times[c], _clock() - t0)
        spent += _clock() - begin
        made += 1
    return made


def _silent(text: str) -> None:
    """A ``stage`` that shows nothing."""


def _image_counter(stage: Callable[[str], None], text: str) -> Callable[[int, int], None]:
    """A ``progress(done, total)`` of :func:`fit_residual_grids` that passes
    ``"<text>, <done> of <total> images"`` to ``stage``."""

    def count(done: int, total: int) -> None:
        stage(f"{text}, {done} of {total} images")

    return count


def _warm_up(block: Block, spacing: float, left_out: set, options: dict) -> None:
    """Fit and apply one image's grid, untimed, before the sweep's first spacing.

    The first call of the fit and the correction in a process pays for imports and caches
    that later calls do not; without this the first spacing's time would carry them.

    Parameters
    ----------
    block : Block
        The adjusted block of the sweep.
    spacing : float
        The first spacing of the sweep, px.
    left_out : set
        Images that get no grid.
    options : dict
        The sweep's options of :func:`fit_residual_grids` (its progress display is not
        shown for the warm-up).
    """
    ids = options.get("images")
    if ids is None:
        ids = [k for k in block.image_ids.tolist() if k not in left_out]
    ids = list(ids)
    if not ids:
        return
    first = ids[0]
    grids = fit_residual_grids(block, spacing, **{**options, "images": [first], "progress": False})
    others = [k for k in block.image_ids.tolist() if k != first]
    correct_block_observations(block, grids, uncorrected=others)


def _check_rematched(block: Block, rematched) -> None:
    """Refuse a re-matched block that is not ``block``'s observations row for row."""
    if not isinstance(rematched, Block):
        raise InputError(f"rematched must be a Block, not {type(rematched).__name__}")
    if not block.same_observation_rows(rematched):
        raise InputError(
            "rematched: its observations are not the adjusted block's in the same rows "
            "(same image and point per row); make it with sim.rematch(fit.block) from an "
            "adjustment with snooping=False"
        )


def run_study(
    preset: str = "ILCE-7RM2",
    *,
    seed: int = 1,
    size: str = "small",
    spacing: float = 100.0,
    coarse_spacing: float = 2000.0,
    sweep: Sequence[float] | None = (100, 150, 200, 300, 500, 1000, 2000),
    fit_options: dict | None = None,
    rematch: bool = True,
    **simulate,
) -> dict:
    """The study's pipeline on one simulated preset.

    Simulate (:func:`photogeom.simulate.uav_block`), adjust with Brown self-calibration,
    fit grids of ``spacing``, correct and re-adjust with the orientation fixed, and
    evaluate; the same with ``coarse_spacing`` (the study's 2000 px against 100 px); the
    grid-size sweep over ``sweep`` (None: skipped); the fitted field against the truth.

    The grids are fitted with the defaults of :func:`fit_residual_grids` (the block's
    observation sigmas, the constraint sigma scaled with the spacing, 0.1 px at 100 px)
    and no cross-validation unless ``fit_options`` says otherwise.

    With ``rematch`` the evaluation is also made as the study made it: the study matched
    the corrected images anew, so the grids met measurements whose noise they had not
    fitted. :meth:`~photogeom.simulate.SimulatedBlock.rematch` draws that second
    measurement (noise from ``numpy.random.default_rng((seed, 1))``); the same grids
    correct it and it is re-adjusted the same way. Correcting the first observations
    themselves (``evaluation``) credits the grids with the noise they fitted.

    Parameters
    ----------
    preset : str, default "ILCE-7RM2"
        Camera preset (:func:`photogeom.simulate.preset`).
    seed : int, default 1
        Seed of the simulation.
    size : {"small", "study"}, default "small"
        Block size, as in :func:`~photogeom.simulate.uav_block`.
    spacing : float, default 100.0
        Node spacing of the fine grids, px.
    coarse_spacing : float, default 2000.0
        Node spacing of the coarse grids, px.
    sweep : sequence of float or None, default (100, 150, 200, 300, 500, 1000, 2000)
        Spacings (px) of the grid-size sweep; None skips it.
    fit_options : dict, optional
        Keywords of :func:`fit_residual_grids` (default: ``folds=0``).
    rematch : bool, default True
        Also evaluate on re-matched observations (see above).
    **simulate
        Further keywords of :func:`~photogeom.simulate.uav_block`.

    Returns
    -------
    dict
        ``preset``, ``images``, ``gsd``, ``evaluation`` (:func:`evaluate_readjustment`),
        ``coarse`` (the same for the coarse grid), ``coarse_share`` (the coarse grid's
        step reduction over the fine one's), ``residual_reduction`` (block RMS),
        ``field`` (:func:`field_recovery`), ``sweep`` (:func:`sweep_spacings`), ``times``;
        with ``rematch`` also ``rematched`` and ``coarse_rematched`` (evaluations of the
        re-matched observations), ``coarse_share_rematched``, and the sweep's
        ``step_rematched`` / ``spacing_rematched``.
    """
    from ..bundle.adjustment import bundle_adjust
    from ..simulate import uav_block

    # the spacings checked before the simulation and the adjustment (minutes)
    spacing = check_spacing(spacing, "run_study: spacing")
    coarse_spacing = check_spacing(coarse_spacing, "run_study: coarse_spacing")
    if sweep is not None:
        sweep = _spacings(sweep, "run_study: sweep")
    opts = {"folds": 0, **(fit_options or {})}
    times = {}
    t0 = time.perf_counter()
    sim = uav_block(preset, seed=seed, size=size, **simulate)
    times["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = bundle_adjust(sim.block, snooping=False)
    times["adjust"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    grids = fit_residual_grids(fit.block, spacing, **opts)
    times["fit_grids"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    re = readjust(fit.block, grids, snooping=False)
    times["readjust"] = time.perf_counter() - t0
    ev = evaluate_readjustment(fit, re, sim=sim)
    coarse_grids = fit_residual_grids(fit.block, coarse_spacing, **opts)
    coarse = evaluate_readjustment(fit, readjust(fit.block, coarse_grids, snooping=False), sim=sim)
    gain = ev["mean_step_before"] - ev["mean_step_after"]
    cgain = coarse["mean_step_before"] - coarse["mean_step_after"]
    rem = sim.rematch(fit.block, seed=None if seed is None else (seed, 1)) if rematch else None
    out = {
        "preset": str(preset),
        "images": int(sim.block.n_images),
        "gsd": float(sim.gsd),
        "spacing": float(spacing),
        "coarse_spacing": float(coarse_spacing),
        "evaluation": ev,
        "coarse": coarse,
        "coarse_share": cgain / gain if gain > 0 else float("nan"),
        "residual_reduction": ev["residuals"]["block"]["reduction_rms"],
        "field": field_recovery(sim, grids),
        "sweep": None,
        "times": times,
        "grids": grids,
        "fit": fit,
        "refit": re,
    }
    if rem is not None:
        ev_r = evaluate_readjustment(fit, readjust(rem, grids, snooping=False), sim=sim)
        co_r = evaluate_readjustment(fit, readjust(rem, coarse_grids, snooping=False), sim=sim)
        g_r = ev_r["mean_step_before"] - ev_r["mean_step_after"]
        out["rematched"] = ev_r
        out["coarse_rematched"] = co_r
        out["coarse_share_rematched"] = (
            (co_r["mean_step_before"] - co_r["mean_step_after"]) / g_r if g_r > 0 else float("nan")
        )
    if sweep is not None:
        t0 = time.perf_counter()
        out["sweep"] = sweep_spacings(fit, sweep, rematched=rem, **opts)
        times["sweep"] = time.perf_counter() - t0
    return out


def compare_in_adjustment(
    sim,
    spacing: float = 500.0,
    *,
    sigma_constraint: float = 1.0,
    sigma_temporal: float | None = 0.3,
    sigma_amplitude: float | str | None = "residuals",
    per: str = "image",
    overlap: float = 0.6,
    combined_spacing: float | None = 300.0,
    rematch_seed: int | None = 1,
) -> dict:
    """Post-processing against grids estimated inside the adjustment, on one simulated block.

    Both start from the same Brown self-calibrating adjustment of ``sim.block``; both use
    the grid ``spacing`` and smoothness ``sigma_constraint``. Post-processing: grids fitted to
    the residuals, observations corrected, re-adjusted with orientation and calibration
    fixed (the study). In-adjustment: :func:`~photogeom.calibration.adjust_with_grids`
    (``per``, ``sigma_temporal``, ``sigma_amplitude``). Combined: the in-adjustment result
    post-processed with grids of ``combined_spacing`` (default smoothness; None: not run) -
    the orientation of the adjustment with grids, the residual steps removed afterwards.

    With ``rematch_seed`` every run is also evaluated on re-matched observations
    (:meth:`~photogeom.simulate.SimulatedBlock.rematch`, the same fresh noise for all
    runs): its grids correct them and they are re-adjusted with its orientation and
    calibration, so that no run is credited with the noise it fitted.

    Parameters
    ----------
    sim : SimulatedBlock
        The simulated block.
    spacing : float, default 500.0
        Grid node spacing, px.
    sigma_constraint : float, default 1.0
        Smoothness standard deviation, px.
    sigma_temporal : float or None, default 0.3
        As in :func:`~photogeom.calibration.adjust_with_grids` (``per="image"`` only).
    sigma_amplitude : float, "residuals" or None, default "residuals"
        As in :func:`~photogeom.calibration.adjust_with_grids`.
    per : {"image", "camera"}, default "image"
        As in :func:`~photogeom.calibration.adjust_with_grids`.
    overlap : float, default 0.6
        Forward overlap of the stereo models of the step measure.
    combined_spacing : float or None, default 300.0
        Spacing (px) of the post-processing after the in-adjustment run; None: not run.
    rematch_seed : int or None, default 1
        Seed of the re-matched observations; None: not evaluated on them.

    Returns
    -------
    dict
        ``post_hoc``, ``in_adjustment`` and ``combined``, each with ``field``
        (:func:`field_recovery`, block ratio against the true field; NaN for ``combined``),
        ``visible`` (:func:`visible_recovery`),
        ``check_rmse_gsd`` (X, Y, Z), ``tie_rmse_gsd`` (X, Y, Z: every tie point against
        the truth), ``mean_step`` (GSD), ``residual_rms`` (px, tie
        points), ``seconds`` (the first adjustment included); with ``rematch_seed`` also
        ``mean_step_rematched`` and ``tie_rmse_gsd_rematched``; ``before`` the first
        adjustment's ``check_rmse_gsd`` and ``mean_step``; ``images``, ``spacing``.
    """
    from ..bundle.adjustment import bundle_adjust
    from .in_adjustment import adjust_with_grids

    # the spacings checked before the adjustments (minutes)
    spacing = check_spacing(spacing, "compare_in_adjustment: spacing")
    if combined_spacing is not None:
        combined_spacing = check_spacing(
            combined_spacing, "compare_in_adjustment: combined_spacing"
        )
    t0 = time.perf_counter()
    fit = bundle_adjust(sim.block, snooping=False)
    t_first = time.perf_counter() - t0
    vis = visible_field(sim)
    out = {"images": int(sim.block.n_images), "spacing": float(spacing)}
    t0 = time.perf_counter()
    grids = fit_residual_grids(fit.block, spacing, folds=0, sigma_constraint=sigma_constraint)
    re = readjust(fit.block, grids, snooping=False)
    t_post = time.perf_counter() - t0
    t0 = time.perf_counter()
    ga = adjust_with_grids(
        fit.block,
        spacing,
        per=per,
        sigma_constraint=sigma_constraint,
        sigma_temporal=sigma_temporal if per == "image" else None,
        sigma_amplitude=sigma_amplitude,
        std=False,
    )
    t_in = time.perf_counter() - t0
    ev_post = evaluate_readjustment(fit, re, sim=sim, overlap=overlap)
    ev_in = evaluate_readjustment(fit, ga.fit, sim=sim, overlap=overlap)
    runs = [("post_hoc", grids, ev_post, t_post), ("in_adjustment", ga.grids, ev_in, t_in)]
    again = {}
    if rematch_seed is not None:
        in_rem = sim.rematch(ga.block, seed=rematch_seed)
        again["post_hoc"] = readjust(
            sim.rematch(fit.block, seed=rematch_seed), grids, snooping=False
        )
        again["in_adjustment"] = readjust(in_rem, ga.grids, snooping=False)
    if combined_spacing is not None:
        t0 = time.perf_counter()
        g2 = fit_residual_grids(ga.fit.block, combined_spacing, folds=0)
        re2 = readjust(ga.fit.block, g2, snooping=False)
        t_both = t_in + time.perf_counter() - t0
        ev_both = evaluate_readjustment(fit, re2, sim=sim, overlap=overlap)
        runs.append(("combined", None, ev_both, t_both))
        if rematch_seed is not None:
            again["combined"] = readjust(
                correct_block_observations(in_rem, ga.grids), g2, snooping=False
            )
    out["before"] = {
        "check_rmse_gsd": ev_post["check_before"].get("rmse_gsd"),
        "tie_rmse_gsd": ev_post["tie_before"]["rmse_gsd"],
        "mean_step": ev_post["mean_step_before"],
    }
    for name, g, ev, t in runs:
        ra = ev["residuals"]["block"]
        vr = visible_recovery(sim, g, vis) if g else {"ratio": float("nan")}
        if name == "post_hoc":
            out["visible_share"] = vr["visible_share"]
        out[name] = {
            "field": field_recovery(sim, g)["block"]["ratio"] if g else float("nan"),
            "visible": vr["ratio"],
            "check_rmse_gsd": ev["check_after"].get("rmse_gsd"),
            "tie_rmse_gsd": ev["tie_after"]["rmse_gsd"],
            "mean_step": ev["mean_step_after"],
            "residual_rms": ra["after"]["rms"],
            "seconds": t_first + t,
        }
        if name in again:
            ev_r = evaluate_readjustment(fit, again[name], sim=sim, overlap=overlap)
            out[name]["mean_step_rematched"] = ev_r["mean_step_after"]
            out[name]["tie_rmse_gsd_rematched"] = ev_r["tie_after"]["rmse_gsd"]
    out["in_adjustment_result"] = ga
    return out
