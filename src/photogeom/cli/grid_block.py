"""`photogeom grid evaluate | sweep | report`: residual grids of a whole adjusted block.

The block is a folder (or file) readable by ``photogeom.bundle.read_block`` (CSV block
format, COLMAP text or binary model, BAL or Bundler file) holding an **adjusted** block, or
``--preset NAME`` for a simulated block of the study's cameras (simulated and adjusted
first). ``evaluate`` fits grids, corrects, re-adjusts with the orientation fixed and prints
the residuals and steps before and after; ``sweep`` tries several spacings and chooses one
by the closest-to-origin rule; ``report`` writes the HTML report with the study's figures.
"""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError, PhotogeomError
from ._common import (
    SIZE_WORDS,
    JsonOpt,
    console,
    fraction,
    image_sizes_option,
    in_cli_words,
    iteration_progress,
    json_id,
    json_text,
    nan_to_none,
    pair_records,
    pixels,
    print_id_table,
    read_detected_block,
    say,
    split_numbers,
    stage_spinner,
    typed_option,
    unit_hint,
)
from .bundle import ImageSizeOpt

BlockArg = Annotated[
    Path | None,
    typer.Argument(
        help="Adjusted block: a CSV block folder, COLMAP text or binary model, BAL file or "
        "Bundler file (.out, its image list and images beside it: they give the image sizes, "
        "else --image-size)."
    ),
]
PresetOpt = Annotated[
    str | None,
    typer.Option(help="Simulated block instead: ILCE-7RM2, FC6310 or FC300S (then adjusted)."),
]
#: --spacing of the commands that also take --grids (None: not given, 100 px)
FitSpacingOpt = Annotated[
    float | None,
    typer.Option(
        help="Node spacing of the grids in pixels (default 100; not with --grids).",
        parser=pixels("--spacing"),
    ),
]
DEFAULT_SPACING = 100.0
#: --repeats of the sweep: ``calibration.study.TIMING_REPEATS``, written out so that the
#: command line does not import the library when it starts
TIMING_REPEATS = 3
ExcludeOpt = Annotated[
    str | None,
    typer.Option(
        help="Image ids that get no grid, comma-separated (e.g. images with too few tie "
        "points for a grid): their observations are re-adjusted uncorrected. Quote an id "
        "with white space at its ends or a comma: '\" im0 \",IMG_7'."
    ),
]
_SIGMA_C_HELP = (
    "Standard deviation of the smoothness pseudo-observations: px, 'scaled' (0.1 px x "
    "(spacing / 100 px)^2) or 'vce' (variance components)"
)
SigmaCOpt = Annotated[str, typer.Option(help=_SIGMA_C_HELP + ".")]
#: of the commands with --in-adjustment, whose grids in the adjustment take no variance components
SigmaCInAdjOpt = Annotated[str, typer.Option(help=_SIGMA_C_HELP + "; not with --in-adjustment.")]


def _sigma_option(text: str, option: str, words: dict):
    """A sigma option's value: one of ``words`` (text -> value) or a positive number of px."""
    t = text.strip().lower()
    if t in words:
        return words[t]
    try:
        x = float(t)
    except ValueError:
        names = " or ".join(repr(w) for w in words)
        raise InputError(
            f"{option} must be a number of pixels, {names}, not {text!r}"
            + unit_hint(text, option)
        ) from None
    if not x > 0 or x == float("inf"):
        raise InputError(f"{option} must be a positive number of pixels, not {text!r}")
    return x


def _sigma_c(text: str):
    """The --sigma-constraint value: a number of px, 'scaled' or 'vce'."""
    return _sigma_option(text, "--sigma-constraint", {"scaled": "scaled", "vce": "vce"})


def _sigma_a(text: str):
    """The --sigma-amplitude value: a number of px, 'residuals' or 'none' (None)."""
    return _sigma_option(text, "--sigma-amplitude", {"residuals": "residuals", "none": None})


SeedOpt = Annotated[
    int, typer.Option(min=0, help="Seed of the simulated block (--preset), an integer >= 0.")
]
StripsOpt = Annotated[int, typer.Option(help="Strips of the simulated block (--preset).")]
ImagesOpt = Annotated[
    int,
    typer.Option(
        "--images-per-strip", help="Images per strip of the simulated block (--preset)."
    ),
]
#: The former name of --images-per-strip (as in 'bundle simulate'), still accepted.
ImagesOldOpt = Annotated[
    int | None, typer.Option("--images", hidden=True, help="Former name of --images-per-strip.")
]
OverlapOpt = Annotated[
    float,
    typer.Option(
        help="Forward overlap of a stereo model (fraction).", parser=fraction("--overlap")
    ),
]
InAdjOpt = Annotated[
    bool,
    typer.Option(
        "--in-adjustment",
        help="Estimate the grids inside the bundle adjustment instead of after it "
        "(coarse grids: every node is an unknown).",
    ),
]
PerOpt = Annotated[
    str, typer.Option(help="With --in-adjustment: one grid per 'image' or per 'camera'.")
]
SigmaTOpt = Annotated[
    float | None,
    typer.Option(
        help="With --in-adjustment --per image: standard deviation (px) of the equality of "
        "consecutive images' grids (temporal constraints); omit for none.",
        parser=pixels("--sigma-temporal"),
    ),
]
SigmaAOpt = Annotated[
    str,
    typer.Option(
        help="With --in-adjustment: standard deviation (px) of every node's value about zero, "
        "the expected size of the field; 'residuals': twice the RMS of the BLOCK's tie-point "
        "residuals; 'none': no amplitude."
    ),
]
PostOpt = Annotated[
    float | None,
    typer.Option(
        help="With --in-adjustment: post-process its result with grids of this spacing "
        "(px): the orientation of the adjustment with grids, finer grids for the steps."
    ),
]
CheckOpt = Annotated[
    Path | None,
    typer.Option(
        "--check-points",
        help="CSV of surveyed check-point coordinates (id, X, Y, Z; the ids of the BLOCK's "
        "check points): their errors before and after, triangulated minus surveyed.",
    ),
]
GridsOpt = Annotated[
    Path | None,
    typer.Option(
        "--grids",
        help="Grids file (from 'photogeom grid fit') to evaluate instead of fitting grids: "
        "the BLOCK's observations corrected with it and re-adjusted (orientation and "
        "calibration fixed); --spacing and --sigma-constraint do not apply.",
    ),
]
RematchOpt = Annotated[
    bool,
    typer.Option(
        "--rematch",
        help="With --preset: also evaluate on re-matched observations (the same points "
        "measured again with fresh noise, as the study matched its corrected images anew), "
        "so that the grids are not credited with the noise they fitted.",
    ),
]
SpacingsOpt = Annotated[
    str, typer.Option(help="Spacings to try, comma-separated pixels (at least two).")
]
RepeatsOpt = Annotated[
    int,
    typer.Option(
        min=1,
        help="Timings of each spacing's grid fit and correction, at most (an integer >= 1): "
        "the cost is the least CPU time of them, taken in passes over all spacings. Further "
        "passes stop when they would take more CPU time than the first pass.",
    ),
]


class _Fit:
    """A block standing for the first adjustment (the block read is already adjusted)."""

    def __init__(self, block, bal: bool = False) -> None:
        self.block = block
        self.bal = bal  # read from a BAL file: its image size is the reader's guess


def _source(
    block: Path | None,
    preset: str | None,
    seed: int,
    strips: int,
    images: int,
    image_size: str | None = None,
):
    """(first fit, simulated block or None); ``images``: --images-per-strip; ``image_size``:
    --image-size of a BAL or Bundler BLOCK. A spinner names the stage on a terminal."""
    import photogeom as pg

    if (block is None) == (preset is None):
        raise InputError("give either a BLOCK folder or --preset NAME (not both)")
    if preset is not None:
        if image_size is not None:
            raise InputError(
                "--image-size applies to a BAL or Bundler BLOCK; a --preset block's cameras "
                "give the image sizes: leave --image-size out"
            )
        names = ("ILCE-7RM2", "FC6310", "FC300S")  # bundle simulate's --preset choices
        if preset not in names:
            raise InputError(f"--preset {preset}: choose one of {', '.join(names)}")
        if strips < 1 or images < 3:
            raise InputError("--strips must be >= 1 and --images-per-strip >= 3")
        with stage_spinner(f"simulating the {preset} block") as step:
            sim = pg.simulate.uav_block(
                preset, seed=seed, strips=strips, images_per_strip=images
            )
            step(f"adjusting the {preset} block")
            return pg.bundle_adjust(sim.block, snooping=False), sim
    if not block.exists():
        raise InputError(f"BLOCK: {block} does not exist")
    read, bal = read_sized_block(block, image_size)
    warn_if_unadjusted(read, block)
    return _Fit(read, bal), None


def read_sized_block(
    path: Path, image_size: str | None, takes_size: str = "a BAL or Bundler file"
) -> tuple[object, bool]:
    """The block at ``path`` (format by content) for the grid commands, and whether it is a
    BAL file read at the size its reader guessed.

    Parameters
    ----------
    path : Path
        The BLOCK (folder, BAL or Bundler file or pipe).
    image_size : str or None
        ``--image-size WIDTHxHEIGHT`` (px): the size of every image of a BAL or Bundler
        file; refused for a format whose cameras give the sizes.
    takes_size : str
        What the command's ``--image-size`` applies to, named in that refusal.

    Returns
    -------
    (Block, bool)
        The block; True for a BAL file read without ``image_size``, whose size (the smallest
        even one holding the observations, and so the grids' extent and pixel origin) is a
        guess: a warning on stderr names --image-size.

    Raises
    ------
    InputError
        --image-size for a folder format, a Bundler file whose images are not found.
    """
    from ..bundle.io_formats import detect_format

    kind = detect_format(path)  # a pipe is read once here and kept for the reader
    if image_size is not None and kind not in ("bal", "bundler"):
        raise InputError(
            f"--image-size applies to {takes_size}; {path} is a block whose cameras give "
            "the image sizes: leave --image-size out"
        )
    options = {} if image_size is None else {"image_size": image_sizes_option(image_size)}
    try:
        with stage_spinner(f"reading {path}"):
            block = read_detected_block(path, **options)
    except InputError as exc:  # a Bundler file's image sizes: the option that gives them
        head, sep, _ = str(exc).partition("; give the images' size")
        if not sep:
            exc.args = (in_cli_words(str(exc), SIZE_WORDS), *exc.args[1:])
            raise
        raise InputError(
            f"{head}; put the images where its image list says, or give their size with "
            "--image-size WIDTHxHEIGHT"
        ) from None
    guessed = kind == "bal" and image_size is None
    if guessed:  # the pixel origin, and so the grids, follow that size
        w, h = (int(x) for x in block.image_sizes()[0])
        say(
            f"warning: {path}: a BAL file holds no image size; the grids are fitted for "
            f"{w} x {h} px, the smallest even size holding the observations, and fit only "
            "images of that size: give the images' size with --image-size WIDTHxHEIGHT",
            stderr=True,
        )
    return block, guessed


#: RMS of the tie-point residuals in units of their sigmas above which a block read as
#: adjusted is taken for one that was not (an adjustment that converged gives about
#: sigma0, a few at most with blunders; the start values of a block to adjust give tens to
#: hundreds).
UNADJUSTED_RMS = 10.0


def warn_if_unadjusted(block, path: Path) -> None:
    """Warn on stderr when the block's tie-point residuals are far above their sigmas.

    The grids commands model the residuals of an adjusted block; the residuals of a block
    not yet adjusted (its initial orientation, e.g. ``bundle simulate``'s block folder) are
    the errors of the start values, and grids fitted to them "remove" tens of pixels.

    Parameters
    ----------
    block : Block
        The block read from ``path``.
    path : Path
        The BLOCK argument, named in the warning.
    """
    import numpy as np

    from ..bundle import reprojection_residuals

    tie = block.role[block.obs_point] == "tie"
    if not np.any(tie):
        return
    v = reprojection_residuals(block, behind="nan")[tie]
    w = v / block.observations.sigma[tie, None]
    rms_w = float(np.sqrt(np.nanmean(w**2)))
    if np.isfinite(rms_w) and rms_w <= UNADJUSTED_RMS:  # NaN: every point behind, warns
        return
    rms_px = float(np.sqrt(np.nanmean(v**2)))
    say(
        f"warning: {path}: the tie-point residuals (RMS {rms_px:.3g} px, {rms_w:.3g} times "
        "their sigmas) are those of a block not adjusted: the grids model the residuals of "
        f"an adjusted block; adjust it first ({adjust_command(block, path)}",
        stderr=True,
    )


def adjust_command(block, path: Path) -> str:
    """The ``bundle adjust`` command that adjusts the block read from ``path`` and what to
    give then, in the block's own format: a BAL or Bundler block is one file (a folder
    name would be taken for the file's), a Bundler file written beside its images (its
    list names them relative to its folder), and a block without control points and GNSS
    positions (any BAL or Bundler file, COLMAP model) needs ``--datum free``."""
    import numpy as np

    from ..bundle.io_formats import FOLDER_FORMATS, detect_format

    try:
        fmt = detect_format(path)
    except PhotogeomError:  # a pipe already read: the folder formats are not pipes
        fmt = "bal"
    if fmt in FOLDER_FORMATS:
        target, what = "adjusted/", "the adjusted folder"
    else:
        target = str(Path(path).with_name("adjusted.out" if fmt == "bundler" else "adjusted.bal"))
        what = target
    held = np.any(block.role == "control") or np.any(np.all(np.isfinite(block.gnss), axis=1))
    free = "" if held else " --datum free"
    return f"'photogeom bundle adjust {path}{free} -o {target}') and give {what}"


def _cli(msg: str) -> str:
    return (
        msg.replace("sigma_constraint", "--sigma-constraint")
        .replace("grid spacing", "--spacing")
        .replace("a larger spacing", "a larger --spacing")
        .replace("choose a spacing", "choose a --spacing")
        .replace("leave the image out", "leave the image out with --exclude ID")
        .replace("with uncorrected=", "with --exclude ID")
        .replace("overlap must", "--overlap must")
        .replace("sigma_temporal needs per='image'", "--sigma-temporal needs --per image")
        .replace("sigma_temporal", "--sigma-temporal")
        .replace("sigma_amplitude='residuals'", "--sigma-amplitude residuals")
        .replace("sigma_amplitude", "--sigma-amplitude")
        .replace("per must be one of", "--per must be one of")
        .replace("surveyed: none of", "--check-points: none of")
        .replace(
            "fit grids for every image of the block (fit_residual_grids) to correct its "
            "observations",
            "give --grids a file with a grid for every image of the BLOCK "
            "('photogeom grid fit BLOCK')",
        )
        .replace(
            "fit the grids of this block (fit_residual_grids)",
            "give --grids the grids file of this BLOCK ('photogeom grid fit BLOCK')",
        )
    )


def _left_out(fit, exclude: str | None, block: Path | None, preset: str | None) -> list:
    """The block's image ids named by --exclude (text), unknown ids refused."""
    from .grid import _exclude_ids, _refuse_unknown

    named = list(dict.fromkeys(_exclude_ids(exclude)))
    if not named:
        return []
    ids = fit.block.image_ids.tolist()
    _refuse_unknown(named, [str(k) for k in ids], Path(preset) if block is None else block)
    return [k for k in ids if str(k) in set(named)]


def _evaluate(
    block,
    preset,
    spacing,
    sigma_constraint,
    seed,
    strips,
    images,
    overlap,
    *,
    in_adjustment=False,
    per="image",
    sigma_temporal=None,
    post_spacing=None,
    check_points=None,
    sigma_amplitude="residuals",
    grids_file=None,
    spacing_given=True,
    rematch=False,
    exclude=None,
    image_size=None,
):
    from ..calibration import (
        adjust_with_grids,
        evaluate_readjustment,
        fit_residual_grids,
        load_grids,
        readjust,
    )

    sigma_constraint = _sigma_c(sigma_constraint)
    if grids_file is not None:
        if in_adjustment:
            raise InputError(
                "--grids evaluates grids fitted after the adjustment; --in-adjustment "
                "estimates its own: give one of them"
            )
        if spacing_given or sigma_constraint != "scaled":
            raise InputError(
                "--spacing and --sigma-constraint set the grids that are fitted; with --grids "
                "the grids of the file are used: leave them out (or fit with "
                "'photogeom grid fit BLOCK --spacing ...')"
            )
        if not grids_file.exists():  # a file or a pipe (read once by load_grids)
            raise InputError(f"--grids: {grids_file} does not exist")
    if check_points is not None and preset is not None:
        raise InputError(
            "--check-points applies to a BLOCK folder (a --preset is checked against its truth)"
        )
    if rematch and preset is None:
        raise InputError(
            "--rematch needs --preset: re-matching draws new measurements of a simulated "
            "block's points (on a real block, match the corrected images again and give "
            "that block)"
        )
    if rematch and in_adjustment:
        raise InputError(
            "--rematch evaluates grids fitted after the adjustment; with --in-adjustment use "
            "photogeom.calibration.compare_in_adjustment"
        )
    if exclude is not None and in_adjustment:
        raise InputError(
            "--exclude leaves images out of the grids fitted after the adjustment; "
            "--in-adjustment estimates a grid for every image: give one of them"
        )
    fit, sim = _source(block, preset, seed, strips, images, image_size)
    left = _left_out(fit, exclude, block, preset)
    fitted = [k for k in fit.block.image_ids.tolist() if k not in left]
    surveyed = _surveyed(check_points) if check_points is not None else None
    if in_adjustment and sigma_constraint == "vce":
        raise InputError("--sigma-constraint vce does not apply with --in-adjustment")
    amplitude = _sigma_a(sigma_amplitude)
    if not in_adjustment and (
        per != "image"
        or sigma_temporal is not None
        or post_spacing is not None
        or amplitude != "residuals"
    ):
        raise InputError(
            "--per, --sigma-temporal, --sigma-amplitude and --post-spacing apply with "
            "--in-adjustment only"
        )
    try:
        if in_adjustment:
            from ..bundle.options import BundleOptions

            most = BundleOptions().max_iterations
            prog, progress = iteration_progress(most, "adjusting with grids")
            with prog if prog is not None else nullcontext():
                ga = adjust_with_grids(
                    fit.block,
                    spacing,
                    per=per,
                    sigma_constraint=sigma_constraint,
                    sigma_temporal=sigma_temporal,
                    sigma_amplitude=amplitude,
                    std=False,
                    progress=progress,
                )
            grids, re = ga.grids, ga.fit
            if post_spacing is not None:
                grids = fit_residual_grids(re.block, post_spacing, folds=0)
                re = readjust(re.block, grids, snooping=False)
        elif grids_file is not None:
            grids = load_grids(grids_file)
            with stage_spinner("re-adjusting with the corrected observations"):
                re = readjust(fit.block, grids, uncorrected=left, snooping=False)
        else:
            with stage_spinner(f"fitting grids of {spacing:g} px") as step:
                grids = fit_residual_grids(
                    fit.block, spacing, sigma_constraint=sigma_constraint, folds=0,
                    images=fitted,
                )  # fmt: skip
                step("re-adjusting with the corrected observations")
                re = readjust(fit.block, grids, uncorrected=left, snooping=False)
        ev = evaluate_readjustment(fit, re, sim=sim, surveyed=surveyed, overlap=overlap)
        if rematch:  # as run_study: the same grids on a second measurement of the points
            with stage_spinner("re-matched observations: correcting and re-adjusting"):
                rem = sim.rematch(fit.block, seed=(seed, 1))
                again = readjust(rem, grids, uncorrected=left, snooping=False)
                ev["rematched"] = evaluate_readjustment(fit, again, sim=sim, overlap=overlap)
                ev["rematched"]["notes"] = list(again.notes)
    except PhotogeomError as exc:  # every error (ConvergenceError of vce too) in CLI words
        head, sep, _ = str(exc).partition(": the grids are of another camera or block")
        if sep and getattr(fit, "bal", False):  # the size BAL does not hold, not the grids
            w, h = (int(x) for x in fit.block.image_sizes()[0])
            exc.args = (
                f"{head}: {block} is a BAL file, which holds no image size, read as {w} x {h} "
                "px (the smallest even size holding its observations); for grids fitted with "
                "grid fit --image-size, give the same --image-size WIDTHxHEIGHT here",
            )
            raise
        exc.args = (_cli(str(exc)),)
        raise
    ev["excluded"] = left
    # why sigma0 is over the chain's redundancy or the re-adjustment's own, and the
    # re-adjustment's own notes (the library's words: note_words gives the command's)
    ev["notes"] = list(re.notes)
    return fit, re, grids, ev, sim


#: Phrases of the re-adjustment's notes (``readjust``, ``adjust_with_grids``,
#: ``chain_redundancy``) that name Python, and what ``grid evaluate`` says instead.
NOTE_WORDS: tuple[tuple[str, str], ...] = (
    ("; see effective_redundancy)", "; the redundancy marked effective)"),
    (
        "judge the precision on observations measured again (the corrected images matched "
        "anew)",
        "judge the precision on observations measured again (the corrected images matched "
        "anew; --rematch for a --preset block)",
    ),
    (
        "(adjust the block first, then fit the grids to its residuals)",
        "(adjust BLOCK first, 'photogeom bundle adjust BLOCK -o ADJUSTED', and evaluate "
        "ADJUSTED)",
    ),
    (
        "the block is the joint estimate of adjust_with_grids (GridAdjustment.block)",
        "BLOCK is the joint estimate of an adjustment with grids (its folder "
        "joint_adjustment)",
    ),
    (
        "pass GridAdjustment.grids whole (uncorrected= leaves images out of the correction) "
        "for the joint adjustment's chain",
        "give that adjustment's own grids, all of them, with --grids (--exclude leaves "
        "images out of the correction) for the joint adjustment's chain",
    ),
    (
        "a joint adjustment with grids (adjust_with_grids), but",
        "a joint adjustment with grids, but",
    ),
    (
        "pass the final fit's block (GridAdjustment.fit.block, a copy of it or a CSV block "
        "folder written from it) to fit_residual_grids and readjust",
        "give the final fit's block (a CSV block folder written from it) as BLOCK",
    ),
)


def note_words(notes) -> list[str]:
    """The notes of a re-adjustment (``BundleFit.notes``) in the words of ``grid evaluate``:
    its options and BLOCK instead of Python names (:data:`NOTE_WORDS`, then the common
    :data:`~photogeom.cli._common.CLI_WORDS`)."""
    return [in_cli_words(in_cli_words(str(n), NOTE_WORDS)) for n in notes]


def _spacings(text: str) -> list[float]:
    """The --spacings of ``sweep`` and ``report``: at least two positive, distinct numbers
    of pixels (checked before the block is read or adjusted)."""
    g = split_numbers(text, None, "--spacings", unit="px")
    if len(g) < 2:
        raise InputError(f"--spacings: give at least two spacings (px), not {text!r}")
    bad = [x for x in g if not x > 0]
    if bad:
        raise InputError(
            f"--spacings: every spacing must be a positive number of pixels, not {bad[0]:g}"
        )
    twice = sorted({x for x in g if g.count(x) > 1})
    if twice:
        raise InputError(f"--spacings: {', '.join(f'{x:g}' for x in twice)} given twice")
    return g


def _sweep_words(msg: str) -> str:
    """A library error of ``sweep_spacings`` in the words of --spacings."""
    return (
        _cli(msg)
        .replace("choose a --spacing of at most", "choose --spacings of at most")
        .replace("--spacing ", "--spacings: ")
        .replace("sweep_spacings: give at least two spacings", "--spacings: give at least two")
        .replace(
            "sweep_spacings: the block has no pair of consecutive stereo models",
            "the block has no pair of consecutive stereo models (strips of images overlapping "
            "by about --overlap, each model sharing points with the next): the sweep ranks "
            "spacings by the height step between models; 'photogeom grid evaluate' compares "
            "the residuals of a block without models",
        )
    )


def _surveyed(path: Path) -> dict:
    """``{id: (X, Y, Z)}`` from a point CSV (--check-points)."""
    from ..io.points import read_points

    if not path.exists():
        raise InputError(f"--check-points: {path} does not exist")
    t = read_points(path, "X,Y,Z", role_column=None, auto_weights=False)
    return dict(zip(t.ids, t.coords))


def _ev_json(ev) -> dict:
    blk = ev["residuals"]["block"]
    out = {
        "residual_convention": "computed minus observed",
        "units": {
            **dict.fromkeys(("rms", "mean_length", "rms_x", "rms_y"), "px"),
            **dict.fromkeys(
                ("steps_before", "steps_after", "steps", "mean_step_before", "mean_step_after",
                 "check_rmse_gsd_before", "check_rmse_gsd_after", "tie_rmse_gsd_before",
                 "tie_rmse_gsd_after"),
                "GSD",
            ),
            **dict.fromkeys(
                ("reduction_rms", "reduction_mean_length", "step_reduction", "sigma0",
                 "redundancy"), "1"
            ),
        },
        # sigma0 of each fit and the redundancy it is over (the re-adjustment's: the chain's
        # effective redundancy when "effective")
        "adjustment": ev["adjustment"],
        "residuals": {
            "block": blk,
            # keyed by text (JSON keys are text); "image_id" keeps the id's type
            "images": {
                str(k): {"image_id": json_id(k), **v}
                for k, v in ev["residuals"]["images"].items()
            },
        },
        "steps_before": {f"{a}-{b}": v for (a, b), v in ev["steps_before"].items()},
        "steps_after": {f"{a}-{b}": v for (a, b), v in ev["steps_after"].items()},
        # the same steps by model pair with typed ids ("a-b" is ambiguous for ids with "-")
        "steps": pair_records(ev["steps_before"], before=ev["steps_before"],
                              after=ev["steps_after"]),
        "mean_step_before": ev["mean_step_before"],
        "mean_step_after": ev["mean_step_after"],
        "step_reduction": ev["step_reduction"],
        "excluded": [str(k) for k in ev.get("excluded", [])],
        "excluded_ids": [json_id(k) for k in ev.get("excluded", [])],
        # the re-adjustment's notes, as printed
        "notes": note_words(ev.get("notes", [])),
    }
    if ev.get("check_before"):
        out["check_rmse_gsd_before"] = ev["check_before"]["rmse_gsd"].tolist()
        out["check_rmse_gsd_after"] = ev["check_after"]["rmse_gsd"].tolist()
    if ev.get("tie_before"):
        out["tie_rmse_gsd_before"] = ev["tie_before"]["rmse_gsd"].tolist()
        out["tie_rmse_gsd_after"] = ev["tie_after"]["rmse_gsd"].tolist()
    if ev.get("rematched"):
        rm = ev["rematched"]
        out["rematched"] = {
            "steps_before": {f"{a}-{b}": v for (a, b), v in rm["steps_before"].items()},
            "steps_after": {f"{a}-{b}": v for (a, b), v in rm["steps_after"].items()},
            "steps": pair_records(rm["steps_before"], before=rm["steps_before"],
                                  after=rm["steps_after"]),
            "mean_step_before": rm["mean_step_before"],
            "mean_step_after": rm["mean_step_after"],
            "step_reduction": rm["step_reduction"],
            "adjustment": rm["adjustment"],
            "notes": note_words(rm.get("notes", [])),
        }
    return out


def evaluate(
    block: BlockArg = None,
    preset: PresetOpt = None,
    spacing: FitSpacingOpt = None,
    sigma_constraint: SigmaCInAdjOpt = "scaled",
    overlap: OverlapOpt = 0.6,
    seed: SeedOpt = 1,
    strips: StripsOpt = 2,
    images: ImagesOpt = 6,
    images_old: ImagesOldOpt = None,
    in_adjustment: InAdjOpt = False,
    per: PerOpt = "image",
    sigma_temporal: SigmaTOpt = None,
    sigma_amplitude: SigmaAOpt = "residuals",
    post_spacing: PostOpt = None,
    check_points: CheckOpt = None,
    grids_file: GridsOpt = None,
    rematch: RematchOpt = False,
    exclude: ExcludeOpt = None,
    image_size: ImageSizeOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Fit grids, correct, re-adjust (orientation fixed) and compare residuals and steps;
    with --in-adjustment the grids are unknowns of the adjustment itself."""
    images = images if images_old is None else images_old  # --images: the former name
    _, _, _, ev, _ = _evaluate(
        block,
        preset,
        DEFAULT_SPACING if spacing is None else spacing,
        sigma_constraint,
        seed,
        strips,
        images,
        overlap,
        in_adjustment=in_adjustment,
        per=per,
        sigma_temporal=sigma_temporal,
        sigma_amplitude=sigma_amplitude,
        post_spacing=post_spacing,
        check_points=check_points,
        grids_file=grids_file,
        spacing_given=spacing is not None,
        rematch=rematch,
        exclude=exclude,
        image_size=image_size,
    )
    if as_json:  # no stereo model pair: the steps are null
        typer.echo(json_text(nan_to_none(_ev_json(ev))))
        return
    from rich.table import Table

    out = console()
    if not ev["steps_before"]:
        say(
            f"no pair of consecutive stereo models in the block (--overlap {overlap:g}): "
            "no height steps, only the residuals are compared"
        )
    t = Table(title="tie-point residuals (px), steps (GSD), sigma0 and redundancy (unitless)")
    for c in ("quantity", "before", "after", "reduction"):
        t.add_column(c, justify="right")
    blk = ev["residuals"]["block"]
    t.add_row(
        "RMS",
        f"{blk['before']['rms']:.4f}",
        f"{blk['after']['rms']:.4f}",
        f"{100 * blk['reduction_rms']:.1f} %",
    )
    t.add_row(
        "mean length",
        f"{blk['before']['mean_length']:.4f}",
        f"{blk['after']['mean_length']:.4f}",
        f"{100 * blk['reduction_mean_length']:.1f} %",
    )
    adj = ev["adjustment"]
    t.add_row("sigma0 (unitless)", *(_sigma0_cell(adj[k]) for k in ("before", "after")), "")
    t.add_row("redundancy", *(_redundancy_cell(adj[k]) for k in ("before", "after")), "")
    if ev["steps_before"]:
        t.add_row(
            "mean step",
            f"{ev['mean_step_before']:.3f}",
            f"{ev['mean_step_after']:.3f}",
            f"{100 * ev['step_reduction']:.1f} %",
        )
    if ev.get("rematched"):
        rm = ev["rematched"]
        t.add_row(
            "mean step, re-matched",
            f"{rm['mean_step_before']:.3f}",
            f"{rm['mean_step_after']:.3f}",
            f"{100 * rm['step_reduction']:.1f} %",
        )
        t.add_row("sigma0, re-matched", "", _sigma0_cell(rm["adjustment"]["after"]), "")
    out.print(t)
    if ev["steps_before"]:
        m = Table(title="step per model pair (GSD)")
        for c in ("first model", "before", "after"):
            m.add_column(c, justify="right")
        for k, v in ev["steps_before"].items():
            a = ev["steps_after"].get(k, float("nan"))
            m.add_row(f"{k[0]}-{k[1]}", f"{v:.3f}", f"{a:.3f}")
        print_id_table(out, m)
    cb, ca = ev.get("check_before"), ev.get("check_after")
    if cb and ca:
        c = Table(title="check-point RMSE (GSD)")
        against = "the simulated truth" if preset is not None else "surveyed"
        for col in (f"against {against}", "X", "Y", "Z"):
            c.add_column(col, justify="right")
        c.add_row("before", *(f"{x:.3f}" for x in cb["rmse_gsd"]))
        c.add_row("after", *(f"{x:.3f}" for x in ca["rmse_gsd"]))
        out.print(c)
    tb, ta = ev.get("tie_before"), ev.get("tie_after")
    if tb and ta:
        t = Table(title=f"tie-point RMSE (GSD), all {ta['points']} points")
        for col in ("against the simulated truth", "X", "Y", "Z"):
            t.add_column(col, justify="right")
        t.add_row("before", *(f"{x:.3f}" for x in tb["rmse_gsd"]))
        t.add_row("after", *(f"{x:.3f}" for x in ta["rmse_gsd"]))
        out.print(t)
    if ev["excluded"]:
        say(_excluded_words(ev["excluded"]), out)
    for n in note_words(ev["notes"]):
        say(f"note: {n}", out)
    for n in note_words(ev.get("rematched", {}).get("notes", [])):
        say(f"note (re-matched observations): {n}", out)


#: A cell of the evaluation table for the first adjustment of a BLOCK read as adjusted.
NOT_ADJUSTED_HERE = "n/a (BLOCK read as adjusted)"


def _sigma0_cell(stats: dict | None) -> str:
    """A sigma0 of the evaluation table (unitless)."""
    from ..report.format import fmt_sigma0

    return NOT_ADJUSTED_HERE if stats is None else fmt_sigma0(stats)


def _redundancy_cell(stats: dict | None) -> str:
    """A redundancy of the evaluation table: a count, or the chain's effective redundancy
    (a real number, marked)."""
    from ..report.format import fmt_redundancy

    return NOT_ADJUSTED_HERE if stats is None else fmt_redundancy(stats)


def _excluded_words(left: list) -> str:
    return (
        f"left out (--exclude; no grid, observations uncorrected): {len(left)} image(s): "
        f"{', '.join(map(str, left[:20]))}{' ...' if len(left) > 20 else ''}"
    )


def sweep(
    block: BlockArg = None,
    preset: PresetOpt = None,
    spacings: SpacingsOpt = "100,150,200,300,500,1000,2000",
    sigma_constraint: SigmaCOpt = "scaled",
    overlap: OverlapOpt = 0.6,
    seed: SeedOpt = 1,
    strips: StripsOpt = 2,
    images: ImagesOpt = 6,
    images_old: ImagesOldOpt = None,
    rematch: RematchOpt = False,
    exclude: ExcludeOpt = None,
    repeats: RepeatsOpt = TIMING_REPEATS,
    image_size: ImageSizeOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Grid-size sweep: step per model and time per spacing, the closest-to-origin choice.

    The time is the CPU time (s) of fitting the grids and correcting the observations at
    each spacing, the least of up to --repeats timings (--json: time, and timings, the
    number made), the cost the choice weighs; the re-adjustment's CPU time is shown apart
    (--json: time_readjust) and not weighed.
    """
    import numpy as np
    from rich.table import Table

    from ..calibration import sweep_spacings

    images = images if images_old is None else images_old  # --images: the former name
    g = _spacings(spacings)
    sigma_constraint = _sigma_c(sigma_constraint)
    if rematch and preset is None:
        raise InputError(
            "--rematch needs --preset: re-matching draws new measurements of a simulated "
            "block's points"
        )
    fit, sim = _source(block, preset, seed, strips, images, image_size)
    left = _left_out(fit, exclude, block, preset)
    rem = sim.rematch(fit.block, seed=(seed, 1)) if rematch else None  # as grid evaluate
    try:
        with stage_spinner(f"sweep: grids and re-adjustment at {len(g)} spacings") as step:
            sw = sweep_spacings(
                fit, g, overlap=overlap, sigma_constraint=sigma_constraint, folds=0,
                rematched=rem, exclude=left, repeats=repeats, stage=_sweep_stage(step),
            )  # fmt: skip
    except PhotogeomError as exc:
        exc.args = (_sweep_words(str(exc)),)
        raise
    if as_json:
        typer.echo(
            json_text(
                {
                    "units": {
                        **dict.fromkeys(
                            (
                                "spacings",
                                "chosen",
                                "spacing",
                                "chosen_rematched",
                                "spacing_rematched",
                            ),
                            "px",
                        ),
                        **dict.fromkeys(("step", "step_before", "step_rematched"), "GSD"),
                        **dict.fromkeys(("time", "time_readjust"), "s (CPU)"),
                    },
                    "spacings": sw["spacings"],
                    "time": sw["time"].tolist(),
                    "timings": sw["timings"],
                    "time_readjust": sw["time_readjust"].tolist(),
                    "models": [f"{a}-{b}" for a, b in sw["models"]],
                    "model_pairs": pair_records(dict.fromkeys(map(tuple, sw["models"]))),
                    "step": sw["step"].tolist(),
                    "step_before": sw["step_before"].tolist(),
                    "chosen": np.asarray(sw["choice"]["spacing"]).tolist(),
                    "spacing": sw["spacing"],
                    "excluded": [str(k) for k in left],
                    "excluded_ids": [json_id(k) for k in left],
                    **(
                        {
                            "step_rematched": sw["step_rematched"].tolist(),
                            "chosen_rematched": np.asarray(
                                sw["choice_rematched"]["spacing"]
                            ).tolist(),
                            "spacing_rematched": sw["spacing_rematched"],
                        }
                        if rem is not None
                        else {}
                    ),
                }
            )
        )
        return
    out = console()
    t = Table(
        title="mean step (GSD) and CPU time per spacing (the cost: grid fit and correction, "
        f"the least of {sw['timings']} timing{'s' if sw['timings'] > 1 else ''})"
    )
    for c in ("spacing (px)", "mean step", "CPU s, cost", "CPU s, re-adjust", "chosen by models"):
        t.add_column(c, justify="right")
    ch = np.asarray(sw["choice"]["spacing"])
    for c, s in enumerate(sw["spacings"]):
        t.add_row(
            f"{s:g}",
            f"{np.mean(sw['step'][:, c]):.3f}",
            f"{sw['time'][c]:.2f}",
            f"{sw['time_readjust'][c]:.2f}",
            str(int(np.sum(ch == s))),
        )
    out.print(t)
    say(
        f"step before: {np.mean(sw['step_before']):.3f} GSD; chosen spacing "
        f"{sw['spacing']:g} px ({int(np.sum(ch == sw['spacing']))} of {ch.size} models)",
        out,
    )
    if rem is not None:
        steps = ", ".join(
            f"{s:g} px {np.mean(sw['step_rematched'][:, c]):.3f}"
            for c, s in enumerate(sw["spacings"])
        )
        say(
            f"re-matched observations: mean step {steps} GSD; chosen spacing "
            f"{sw['spacing_rematched']:g} px",
            out,
        )
    if left:
        say(_excluded_words(left), out)


def report(
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            "--report",
            help="HTML report to write (--report: the same option, the name of grid fit).",
        ),
    ],
    block: BlockArg = None,
    preset: PresetOpt = None,
    spacing: FitSpacingOpt = None,
    spacings: SpacingsOpt = "100,150,200,300,500,1000,2000",
    sigma_constraint: SigmaCInAdjOpt = "scaled",
    overlap: OverlapOpt = 0.6,
    seed: SeedOpt = 1,
    strips: StripsOpt = 2,
    images: ImagesOpt = 6,
    images_old: ImagesOldOpt = None,
    in_adjustment: InAdjOpt = False,
    per: PerOpt = "image",
    sigma_temporal: SigmaTOpt = None,
    sigma_amplitude: SigmaAOpt = "residuals",
    check_points: CheckOpt = None,
    grids_file: GridsOpt = None,
    rematch: RematchOpt = False,
    exclude: ExcludeOpt = None,
    repeats: RepeatsOpt = TIMING_REPEATS,
    image_size: ImageSizeOpt = None,
) -> None:
    """Evaluate and sweep, then write the HTML report with the study's figures (with
    --in-adjustment: the grids of the adjustment in the figures, the sweep post-processed)."""
    from ..calibration import sweep_spacings
    from ..report.grid_study import grid_study_report
    from .bundle import check_targets

    images = images if images_old is None else images_old  # --images: the former name
    g = _spacings(spacings)
    # before the evaluation and the sweep
    check_targets(files=[(typed_option("--output", "--report"), output)])
    fit, re, grids, ev, sim = _evaluate(
        block,
        preset,
        DEFAULT_SPACING if spacing is None else spacing,
        sigma_constraint,
        seed,
        strips,
        images,
        overlap,
        in_adjustment=in_adjustment,
        per=per,
        sigma_temporal=sigma_temporal,
        sigma_amplitude=sigma_amplitude,
        check_points=check_points,
        grids_file=grids_file,
        spacing_given=spacing is not None,
        rematch=rematch,
        exclude=exclude,
        image_size=image_size,
    )
    sc = _sigma_c(sigma_constraint)
    # the re-matched block of the evaluation (the same seed draws the same measurement)
    rem = sim.rematch(fit.block, seed=(seed, 1)) if rematch else None
    try:
        with stage_spinner(f"sweep: grids and re-adjustment at {len(g)} spacings") as step:
            sw = sweep_spacings(
                fit, g, overlap=overlap, sigma_constraint=sc, folds=0, rematched=rem,
                exclude=ev["excluded"], repeats=repeats, stage=_sweep_stage(step),
            )  # fmt: skip
    except PhotogeomError as exc:
        exc.args = (_sweep_words(str(exc)),)
        raise
    res = {
        "preset": (preset or str(block)) + (" (grids in the adjustment)" if in_adjustment else ""),
        "evaluation": ev,
        "fit": fit,
        "refit": re,
        "grids": grids,
        "sweep": sw,
        "simulated": preset is not None,
    }
    if ev.get("rematched"):
        res["rematched"] = ev["rematched"]
    res["notes"] = note_words(ev["notes"])  # as grid evaluate prints them
    path = grid_study_report(res, output)
    say(f"wrote {path}")


def _sweep_stage(step):
    """The ``stage`` of ``sweep_spacings`` for a :func:`stage_spinner`'s ``step``: the
    spacing and the step of the sweep, after ``sweep:``."""

    def stage(text: str) -> None:
        step(f"sweep: {text}")

    return stage


def register(app: typer.Typer) -> None:
    """Add ``evaluate``, ``sweep`` and ``report`` to the ``photogeom grid`` group."""
    app.command("evaluate")(evaluate)
    app.command("sweep")(sweep)
    app.command("report")(report)
