"""`photogeom bundle`: simulate, adjust, convert and report image blocks.

* ``simulate OUT``: a simulated UAV block in the CSV block format, with the truth in
  ``OUT/truth/`` and the simulation's settings and blunders in ``OUT/simulation.json``;
* ``adjust INPUT``: the bundle adjustment of a CSV block folder, a BAL or Bundler file or a
  COLMAP text or binary folder (format detected, or ``--format``), with the adjusted block
  (``--output``), the summary as JSON (``--json``), an HTML report (``--report``), the result
  record (``--result``) that ``report`` renders again and the adjusted calibration as
  Metashape XML, camera JSON or OpenCV YAML (``--output-calibration``);
* ``convert INPUT OUTPUT``: between BAL, Bundler, COLMAP text or binary and CSV blocks;
* ``report RESULT.json``: the HTML report of a saved result record.
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError, OutputError
from ._common import (
    CRS_FORMS,
    SIZE_WORDS,
    AngleUnit,
    alpha_help,
    check_alpha,
    console,
    image_sizes_option,
    in_cli_words,
    iteration_progress,
    json_text,
    options_in_errors,
    refuse_stdout_dash,
    say,
    split_names,
    stage_spinner,
    typed_option,
)

app = typer.Typer(
    help="Bundle adjustment of image blocks: simulate, adjust, convert, report.",
    no_args_is_help=True,
)


class BlockFormat(str, Enum):
    """Block formats at the command line."""

    csv = "csv"
    bal = "bal"
    colmap = "colmap"
    colmap_bin = "colmap-bin"
    bundler = "bundler"


class Loss(str, Enum):
    """Losses of the image observations."""

    squared = "squared"
    huber = "huber"
    cauchy = "cauchy"


class Datum(str, Enum):
    """Datum of the adjustment."""

    auto = "auto"
    weighted = "weighted"
    free = "free"


class Start(str, Enum):
    """Start values of the adjustment."""

    given = "given"
    relative = "relative"
    metashape = "metashape"


_BAL_SUFFIXES = (".txt", ".bal", ".bz2")

#: Library words in error messages and the command-line options that say the same.
_CLI_WORDS = (
    ("pass drop_extras=True", "use --drop-extras"),
    (
        "(angles in radians, M = M3(kappa) M2(phi) M1(omega))",
        "(the attitudes in the unit their columns name, e.g. omega_deg of images.csv, with "
        "M = M3(kappa) M2(phi) M1(omega); or in the convention of the BAL or COLMAP file)",
    ),
    ("drop_extras=True", "--drop-extras"),
    ("(image_size=(width, height), or a mapping image id -> size;", "(--image-size "
     "WIDTHxHEIGHT;"),
    ("(image_size=(width, height))", "(--image-size WIDTHxHEIGHT)"),
    ("(image_list=)", "(--image-list)"),
    ("read it as Bundler (kind='bundler')", "give --format bundler (bundle convert: --from "
     "bundler)"),
    (
        "is read with read_csv_block(..., start_values=False) and given them by "
        "photogeom.bundle.start_from_relative_orientation (relative orientations, strips, "
        "control points)",
        "takes them from relative orientations of consecutive images, strips and the control "
        "points: use --start relative (with --strips, or the images in the order of "
        "images.csv)",
    ),
    (
        "(photogeom.bundle.start_from_relative_orientation; on the command line bundle adjust "
        "--start relative)",
        "(--start relative)",
    ),
    ("photogeom.bundle.start_from_relative_orientation", "--start relative"),
    (
        "(control points as check points, GNSS and IMU set to NaN: "
        "Block.without_datum_observations())",
        "(in the block's files: the control points' role set to check, the gnss_ and imu_ "
        "cells of images.csv emptied)",
    ),
    ("use datum='weighted' (or 'auto')", "use --datum weighted (or auto)"),
    ("pass datum='free'", "use --datum free"),
    ("datum='free'", "--datum free"),
    ("run bundle_adjust(..., point_covariance=True)", "use --point-covariance"),
    ("point_covariance=True", "--point-covariance"),
    ("max_iterations", "--max-iterations"),
    ("loss_scale", "--loss-scale"),
    ("read with image_key='id'", "read with --image-key id"),
    # bundle simulate: the layouts and terrains a command line can give
    (
        ", a count (random positions) or an (n, 2) array of X, Y",
        " or a count of points at random positions (0 or more)",
    ),
    (
        "terrain must be 'flat', 'hilly' or a callable Z(X, Y)",
        "--terrain must be 'flat' or 'hilly'",
    ),
)

#: The summary's pointers to the result's keys (``BundleFit.summary``) in the options' words;
#: the printed summary takes these and :data:`_CLI_WORDS`.
_SUMMARY_WORDS = (
    (
        "(all of them in snooping['flagged'] of the result)",
        "(all of them in the JSON of --json and --result: snooping.flagged)",
    ),
    (
        "they are listed in snooping['poorly_controlled']:",
        "they are listed in --report and in the JSON of --json and --result "
        "(snooping.poorly_controlled):",
    ),
    (
        "adjust with the calibration held first (no free parameters) and then free it from "
        "that result",
        "adjust with the calibration held first (--free none -o FIRST) and then adjust FIRST "
        "with it free",
    ),
    ("(leave it out of the free parameters)", "(leave it out of --free)"),
    *_CLI_WORDS,
)

#: ``free=('f', 'cx', ...)`` in a message: the same as ``--free f,cx,...``.
_FREE_TUPLE = re.compile(r"free=\(((?:'\w+',?\s*)+)\)")


class _CliWords:
    """Re-raise photogeom errors with the library's keyword names replaced by the options."""

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        from ..errors import PhotogeomError

        if isinstance(exc, PhotogeomError) and exc.args:
            text = in_cli_words(str(exc.args[0]), _CLI_WORDS)
            text = _FREE_TUPLE.sub(
                lambda m: "--free " + ",".join(re.findall(r"'(\w+)'", m.group(1))), text
            )
            if text != exc.args[0]:
                exc.args = (text, *exc.args[1:])
        return False


def _cli_words(fn):
    """Decorator: run a command with :class:`_CliWords`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _CliWords():
            return fn(*args, **kwargs)

    return wrapper


def detect_format(path: Path, given: BlockFormat | None, option: str = "--format") -> str:
    """The format of an existing block: ``given``, else by content (a file is BAL; a folder
    with ``cameras.csv`` is a CSV block, one with ``cameras.txt`` a COLMAP text model
    "colmap", one with ``cameras.bin`` COLMAP's binary model "colmap-bin", one with both
    "colmap-both": :func:`read_block` reads it both ways and refuses it, naming ``option``,
    when they differ). A COLMAP format the folder does not hold is refused naming
    ``option``."""
    if not path.exists():
        raise InputError(f"no file or folder {path}")
    colmap = ("colmap", "colmap-bin")
    if path.is_dir() and (given is None or given.value in colmap):
        from ..bundle.io_colmap import BINARY_FILES, TEXT_FILES

        txt = [f for f in TEXT_FILES if (path / f).is_file()]
        bins = [f for f in BINARY_FILES if (path / f).is_file()]
        if txt and bins and given is None and not (path / "cameras.csv").is_file():
            return "colmap-both"  # read_block reads both, takes them when they are the same
        have = "colmap" if txt else "colmap-bin"
        if given is not None and bool(txt) != bool(bins) and given.value != have:
            raise InputError(
                f"{path} holds a COLMAP {'text' if txt else 'binary'} model "
                f"({', '.join(txt or bins)}), not the {given.value} format: give {option} "
                f"{have} (or leave {option} out)"
            )
    if given is not None:
        return given.value
    if not path.is_dir():  # a file or a pipe (read once); the BAL reader refuses a device
        if path.suffix.lower() == ".json":
            raise InputError(
                f"{path} is JSON, not a block: a result record is rendered with "
                "'photogeom bundle report'"
            )
        if path.suffix.lower() == ".xml":  # no block format is XML
            raise InputError(
                f"{path} is XML, not a block: a Metashape camera export (cameras.xml) holds "
                "poses and calibrations but no tie points; adjust the Bundler file or COLMAP "
                "model Metashape exported of the same project, starting from this file: "
                f"photogeom bundle adjust MODEL --start metashape --start-file {path}"
            )
        from ..bundle.io_bundler import is_bundler_file

        return "bundler" if is_bundler_file(path) else "bal"
    if (path / "cameras.csv").is_file():
        return "csv"
    if (path / "cameras.txt").is_file() or (path / "images.txt").is_file():
        return "colmap"
    if any((path / f).is_file() for f in ("cameras.bin", "images.bin", "points3D.bin")):
        return "colmap-bin"
    raise InputError(
        f"{path}: not a block folder (no cameras.csv of a CSV block, no cameras.txt or "
        f"cameras.bin of a COLMAP model); give the format with {option} "
        "csv|colmap|colmap-bin|bal|bundler"
    )


def format_by_name(path: Path) -> str | None:
    """The block format a file name says: ``"bal"`` for ``.txt``, ``.bal`` and ``.bz2``,
    ``"bundler"`` for ``.out``, else None (a folder's name says nothing)."""
    suffix = path.suffix.lower()
    if suffix in _BAL_SUFFIXES:
        return "bal"
    if suffix == ".out":
        return "bundler"
    return None


def output_format(path: Path, given: BlockFormat | None, default: str | None, option: str) -> str:
    """The format to write ``path`` in: ``given``, else the one its name says
    (:func:`format_by_name`: ``.txt``, ``.bal``, ``.bz2`` BAL, ``.out`` Bundler), else
    ``default`` (a folder: ``bundle adjust`` writes the input's format). A name whose suffix
    says another format than ``given`` is refused naming ``option``."""
    named = format_by_name(path)
    if given is not None:
        if named is not None and named != given.value:
            says = "a BAL file" if named == "bal" else "a Bundler file"
            what = (
                "a folder of files" if given.value in ("csv", "colmap", "colmap-bin")
                else "a BAL file (.bal, .txt or .bz2)" if given.value == "bal"
                else "a Bundler file (.out)"
            )  # fmt: skip
            raise InputError(
                f"{option} {given.value} contradicts the name {path}, whose suffix "
                f"{path.suffix} says {says}: {given.value} is written as {what}; give a name "
                f"without {path.suffix}, or {option} {named} (or leave {option} out)"
            )
        return given.value
    if named is not None:
        return named
    if default is not None:
        return default
    raise InputError(
        f"cannot tell the format of {path} from its name: give {option} "
        "csv|colmap|colmap-bin|bal|bundler (CSV blocks and COLMAP models are folders; a BAL "
        "file ends in .txt, .bal or .bz2, a Bundler file in .out)"
    )


def read_block(
    path: Path,
    fmt: str,
    *,
    sigma: float | None,
    image_key: str,
    option: str = "--format",
    start_values: bool = True,
    image_size: str | None = None,
    image_list: Path | None = None,
    group_cameras: bool = False,
):
    """Read a block in format ``fmt`` of :func:`detect_format` (``sigma``: the ``--sigma`` of
    the command, px; ``option``: the command's format option, named in errors;
    ``start_values=False``: a CSV block's orientations and tie points may be empty;
    ``image_size``, ``image_list``, ``group_cameras``: ``--image-size``, ``--image-list``,
    ``--group-cameras`` of a BAL or Bundler file)."""
    import math

    from .. import bundle

    if sigma is not None and not (math.isfinite(sigma) and sigma > 0):
        # checked here: the readers would blame the first row of the file that lacks a sigma
        raise InputError(
            f"--sigma {sigma:g}: the standard deviation of the image observations must be a "
            "positive number of pixels"
        )
    kw = {} if sigma is None else {"sigma": sigma}
    shown = "colmap-bin" if fmt == "colmap-both" else fmt  # named in errors
    bundler = {"--image-list": image_list is not None, "--group-cameras": group_cameras}
    given = [o for o, v in bundler.items() if v]
    if given and fmt != "bundler":
        raise InputError(f"{' and '.join(given)} apply to a Bundler file; {path} is {shown}")
    if image_size is not None:
        if fmt not in ("bal", "bundler"):
            raise InputError(
                f"--image-size applies to a BAL or Bundler file; {path} is {shown}, whose "
                "cameras give the image sizes: leave --image-size out"
            )
        kw["image_size"] = image_sizes_option(image_size)
    try:
        if fmt == "bundler":
            return bundle.read_bundler(
                path, image_list=image_list, group_cameras=group_cameras, **kw
            )
        if fmt == "bal":
            return bundle.read_bal(path, **kw)
    except InputError as exc:  # the sizes given: in --image-size's words
        exc.args = (in_cli_words(str(exc), SIZE_WORDS), *exc.args[1:])
        raise
    if fmt == "colmap-both":  # a folder holding both models (detect_format)
        from ..bundle.io_colmap import ColmapModelsDiffer

        try:
            return bundle.read_colmap(path, image_key=ImageKey(image_key).value, **kw)
        except ColmapModelsDiffer as exc:
            raise InputError(
                f"{exc.head}; give {option} colmap-bin for the .bin files or {option} colmap "
                "for the .txt files, or remove one of the two"
            ) from None
    if fmt in ("colmap", "colmap-bin"):
        return bundle.read_colmap(
            path, image_key=ImageKey(image_key).value, binary=fmt == "colmap-bin", **kw
        )
    return bundle.read_csv_block(path, start_values=start_values, **kw)


def block_files(block, path: Path, fmt: str, *, drop_extras: bool, angle_unit: str):
    """The files of ``block`` written in format ``fmt`` at ``path`` (nothing is written: they
    go to :func:`write_all` with the command's other outputs)."""
    from ..bundle.io_formats import block_files as files

    options = {"angle_unit": angle_unit} if fmt == "csv" else {"drop_extras": drop_extras}
    out = files(block, path, fmt, **options)
    _note_sigma_not_written(block, path, fmt)
    return out


def _note_sigma_not_written(block, path: Path, fmt: str) -> None:
    """A note on stderr when a BAL, Bundler or COLMAP file is written for observations whose
    one standard deviation is not the 1 px its readers assume (the formats hold none; a
    block whose sigmas differ is refused or written with --drop-extras, named there)."""
    import numpy as np

    s = block.observations.sigma
    if fmt == "csv" or s.size == 0 or np.any(s != s[0]) or s[0] == 1.0:
        return
    typer.echo(
        f"note: {path}: the {fmt} format holds no standard deviations; the observations' "
        f"{s[0]:g} px is not written and its readers take 1 px: read it back with --sigma "
        f"{s[0]:g} for the same weights (sigma0 and the tests scale with it)",
        err=True,
    )


def check_targets(blocks=(), files=(), made=()) -> None:
    """Refuse, before anything is computed, outputs that cannot be written.

    ``blocks``: ``(option, path, format)`` of blocks to write; ``files``: ``(option, path)``
    of single files; ``made``: folders the command creates (files may go into them). A CSV
    or COLMAP block onto an existing file, a file onto a folder or into a folder that does
    not exist raise :class:`~photogeom.errors.OutputError` naming the option; ``-`` (the
    standard output of the options that print) raises
    :class:`~photogeom.errors.InputError`; two options
    naming one file (``--report r --result r``; a file and a BAL block) raise
    :class:`~photogeom.errors.InputError` naming both (one output would silently replace
    the other).
    """
    for opt, path, fmt in blocks:
        refuse_stdout_dash(opt, path, folder=fmt not in ("bal", "bundler"))
    for opt, path in files:
        refuse_stdout_dash(opt, path)
    named: dict[str, str] = {}
    singles = [(o, p) for o, p, f in blocks if f in ("bal", "bundler")] + list(files)
    for opt, path in singles:
        if path is None:
            continue
        key = os.path.normcase(os.path.realpath(path))
        if key in named and named[key] != opt:
            raise InputError(
                f"{named[key]} and {opt} both name {path}: one output would replace the other; "
                "give different files"
            )
        named.setdefault(key, opt)
    for opt, path, fmt in blocks:
        if path is not None:
            # the block readers and writers (and the adjustment the package imports with
            # them) load only for a command that writes a block
            from ..bundle.io_formats import check_block_target

            check_block_target(path, fmt, opt)
    for opt, path in files:
        if path is None:
            continue
        if path.is_dir():
            raise OutputError(f"{opt}: cannot write {path}: it is a folder; give a file name")
        if path.parent.exists() and not path.parent.is_dir():
            raise OutputError(
                f"{opt}: cannot write {path}: {path.parent} is a file, not a folder"
            )
        if str(path.parent) and not path.parent.is_dir() and path.parent not in made:
            raise OutputError(
                f"{opt}: cannot write {path}: folder {path.parent} does not exist; create it first"
            )


def write_all(files: dict, texts=(), folders=(), csv_blocks=()) -> None:
    """Write block files (path -> bytes) and texts ((path, str), UTF-8) in one batch: all
    are written or none is; ``folders`` are created first and removed again on failure.
    ``csv_blocks``: the CSV block folders among them, from which the record of a joint
    adjustment with grids that their block does not have is removed after the batch
    (:func:`~photogeom.bundle.io_csv.remove_stale_record`)."""
    from ..bundle.io_csv import remove_stale_record
    from ..bundle.io_formats import write_files

    batch = dict(files)
    for path, text in texts:
        if path in batch:  # a report or result named like a file of the output block
            raise InputError(
                f"{path} would be written twice, as a file of the output block and as another "
                "output: give that output a file outside the block, or another name"
            )
        batch[path] = text.encode("utf-8")
    write_files(batch, folders)
    for d in csv_blocks:
        remove_stale_record(Path(d), batch)


def free_names(text: str | None) -> tuple[str, ...] | None:
    """The calibration parameters of ``--free`` (comma-separated names, or ``none``; the same
    in ``simulate`` and ``adjust``): None when not given."""
    from ..bundle import CALIBRATION_NAMES

    names = split_names(text)
    if names is None:
        return None
    names = [n.lower() for n in names]
    if names == ["none"]:
        return ()
    unknown = [n for n in names if n not in CALIBRATION_NAMES]
    if unknown:
        raise InputError(
            f"--free: unknown calibration parameter(s) {', '.join(unknown)}; the names are "
            f"{', '.join(CALIBRATION_NAMES)} (or 'none')"
        )
    return tuple(names)


SigmaOpt = Annotated[
    float | None,
    typer.Option(
        "--sigma",
        help="Std. dev. of image observations without one [px] (default: 1 for BAL and "
        "COLMAP, 0.5 for CSV blocks without a sigma column).",
    ),
]
class ImageKey(str, Enum):
    """How the images of a COLMAP model are named in the block."""

    by_name = "name"
    by_id = "id"


ImageSizeOpt = Annotated[
    str | None,
    typer.Option(
        "--image-size",
        help="BAL/Bundler input: the images' size WIDTHxHEIGHT [px], or SIZES.csv of "
        "image_id,width,height rows for images of several sizes (Bundler default: read "
        "from the image files its list names; BAL: the smallest even size holding the "
        "observations).",
        show_default=False,
    ),
]
ImageListOpt = Annotated[
    Path | None,
    typer.Option(
        "--image-list",
        help="Bundler input: its image list (default: NAME.out.list.txt or list.txt next to "
        "it; without one the images are named by camera index).",
        show_default=False,
    ),
]
GroupCamerasOpt = Annotated[
    bool,
    typer.Option(
        "--group-cameras",
        help="Bundler input: one camera group for the images with equal f, k1, k2 and size "
        "(default: a camera per image, as Bundler).",
    ),
]
ImageKeyOpt = Annotated[
    ImageKey, typer.Option("--image-key", help="COLMAP: image ids from 'name' or 'id'.")
]
DropExtrasOpt = Annotated[
    bool,
    typer.Option(
        "--drop-extras",
        help="BAL/COLMAP/Bundler output: leave out what the format cannot hold (control and check "
        "points, GNSS/IMU, unequal sigmas) instead of refusing.",
    ),
]


# --- simulate ------------------------------------------------------------------------------------


class Preset(str, Enum):
    """Camera presets of the simulator."""

    ILCE_7RM2 = "ILCE-7RM2"
    FC6310 = "FC6310"
    FC300S = "FC300S"


@app.command("simulate")
@options_in_errors(
    size="--size", strips="--strips", images_per_strip="--images-per-strip", gsd="--gsd",
    tie_points_per_image="--tie-points-per-image", gcps="--gcps", checks="--checks",
    sigma="--sigma", gcp_sigma="--gcp-sigma", blunders="--blunders",
    blunder_size="--blunder-size", local_field="--local-field",
)
@_cli_words
def simulate(
    output: Annotated[
        Path, typer.Argument(help="Folder for the simulated CSV block (created if missing).")
    ],
    preset: Annotated[
        Preset, typer.Option("--preset", "-p", help="Camera preset.")
    ] = Preset.FC300S,
    seed: Annotated[
        int, typer.Option(min=0, help="Random seed (same seed, same block), an integer >= 0.")
    ] = 1,
    size: Annotated[
        str,
        typer.Option(help="'small': --strips x --images-per-strip; 'study': the study's block."),
    ] = "small",
    strips: Annotated[int, typer.Option(help="Number of strips.")] = 3,
    images_per_strip: Annotated[int, typer.Option(help="Images per strip.")] = 7,
    gsd: Annotated[
        float | None, typer.Option(help="Ground sample distance [m/px] (default: the preset's).")
    ] = None,
    tie_points_per_image: Annotated[
        float, typer.Option(help="Mean number of tie points in an image's footprint.")
    ] = 120.0,
    terrain: Annotated[str, typer.Option(help="'hilly' or 'flat'.")] = "hilly",
    gcps: Annotated[
        str,
        typer.Option(
            help="Control point layout: corners, corners+centre, edges, centre, gridK, "
            "none, or a count."
        ),
    ] = "corners+centre",
    checks: Annotated[str, typer.Option(help="Check point layout (as --gcps) or a count.")] = "4",
    sigma: Annotated[float, typer.Option(help="Tie-point image noise [px].")] = 0.3,
    gcp_sigma: Annotated[float, typer.Option(help="Control/check image noise [px].")] = 0.5,
    gnss: Annotated[
        bool,
        typer.Option("--gnss/--no-gnss", help="GNSS positions of the images (sigma 3/3/5 cm)."),
    ] = True,
    imu: Annotated[
        bool, typer.Option("--imu/--no-imu", help="IMU attitudes of the images (sigma 1 deg).")
    ] = True,
    blunders: Annotated[int, typer.Option(help="Tie observations with a blunder.")] = 0,
    blunder_size: Annotated[float, typer.Option(help="Blunder length [px].")] = 50.0,
    local_field: Annotated[
        float | None,
        typer.Option(help="RMS of the image-variant local distortion [px] (default: preset's)."),
    ] = None,
    free: Annotated[
        str | None,
        typer.Option(
            help="Calibration parameters the block marks free, comma-separated "
            "(default f,cx,cy,k1,k2,k3,p1,p2; 'none' for none)."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Simulate a UAV block with known truth, written as a CSV block.

    OUTPUT gets cameras.csv, images.csv, points.csv and observations.csv (the block to adjust:
    noisy observations, initial values), OUTPUT/truth/ the same ids with the true values, and
    OUTPUT/simulation.json the settings and the blunders (image id, point id, offset in px).
    """
    from .. import bundle
    from .. import simulate as sim_mod

    def layout(text: str):
        t = text.strip()
        return int(t) if t.isdigit() else t

    if gsd is not None and not (math.isfinite(gsd) and gsd > 0):
        raise InputError(f"--gsd must be a positive number of metres per pixel, got {gsd}")
    kwargs = dict(
        seed=seed,
        size=size,
        strips=strips,
        images_per_strip=images_per_strip,
        gsd=gsd,
        tie_points_per_image=tie_points_per_image,
        terrain=terrain,
        gcps=layout(gcps),
        checks=layout(checks),
        sigma=sigma,
        gcp_sigma=gcp_sigma,
        blunders=blunders,
        blunder_size=blunder_size,
        local_field=local_field,
        free=free_names(free),
    )
    if not gnss:
        kwargs["gnss_sigma"] = None
    if not imu:
        kwargs["imu_sigma_deg"] = None
    check_targets(
        blocks=[("OUTPUT", output, "csv"), ("OUTPUT", output / "truth", "csv")],
        files=[("OUTPUT", output / "simulation.json")],
        made=[output],
    )
    with stage_spinner(f"simulating the {preset.value} block"):
        sim = sim_mod.uav_block(preset.value, **kwargs)
    o = sim.block.observations
    from ..adjust.fit import _jsonable

    record = _jsonable(
        {
            "preset": preset.value,
            "seed": seed,
            "options": sim.options,
            "summary": sim.summary(),
            "blunders": [
                {
                    "image": o.image_ids[r].item(),
                    "point": o.point_ids[r].item(),
                    "offset_px": [float(a) for a in d],
                }
                for r, d in zip(sim.blunder_rows.tolist(), sim.blunder_offsets)
            ],
            "block": str(output),
            "truth": str(output / "truth"),
            "true_camera": {n: float(getattr(sim.camera, n)) for n in bundle.CALIBRATION_NAMES},
        }
    )
    files = {
        **block_files(sim.block, output, "csv", drop_extras=False, angle_unit="deg"),
        **block_files(sim.truth, output / "truth", "csv", drop_extras=False, angle_unit="deg"),
    }
    write_all(
        files,
        [(output / "simulation.json", json_text(record))],
        folders=[output, output / "truth"],
        csv_blocks=[output, output / "truth"],
    )
    if as_json:
        typer.echo(json_text(record), nl=False)
        return
    out = console()
    say(sim.summary(), out)
    say(
        f"wrote the block to {output}, the truth to {output / 'truth'}, the settings and "
        f"blunders to {output / 'simulation.json'}",
        out,
    )


# --- adjust --------------------------------------------------------------------------------------


@app.command("adjust")
@_cli_words
def adjust(
    source: Annotated[
        Path,
        typer.Argument(
            help="A CSV block folder, a BAL or Bundler file or a COLMAP text or binary folder."
        ),
    ],
    fmt: Annotated[
        BlockFormat | None,
        typer.Option(
            "--format",
            help="Format of SOURCE (default: detected; colmap: the text model cameras.txt, "
            "..., colmap-bin: COLMAP's binary model cameras.bin, ...).",
        ),
    ] = None,
    free: Annotated[
        str | None,
        typer.Option(
            help="Calibration parameters to estimate for every camera, comma-separated "
            "(e.g. f,cx,cy,k1,k2,k3,p1,p2; 'none' for none; default: the block's)."
        ),
    ] = None,
    loss: Annotated[Loss, typer.Option(help="Loss of the image observations.")] = Loss.squared,
    loss_scale: Annotated[
        float | None,
        typer.Option(help="Robust loss scale in sigmas (default 1.345 Huber, 2.385 Cauchy)."),
    ] = None,
    datum: Annotated[
        Datum,
        typer.Option(
            help="weighted: control/GNSS; free: inner constraints; auto: weighted "
            "when there is control or GNSS."
        ),
    ] = Datum.auto,
    point_covariance: Annotated[
        bool, typer.Option("--point-covariance", help="Marginal 3x3 covariance of every point.")
    ] = False,
    variance_components: Annotated[
        bool,
        typer.Option(
            "--variance-components", help="Estimate one variance factor per observation group."
        ),
    ] = False,
    snooping: Annotated[
        bool, typer.Option("--snooping/--no-snooping", help="Baarda's w-test per observation.")
    ] = True,
    alpha: Annotated[
        float | None,
        typer.Option(
            help=alpha_help(
                "observation's w-test",
                upper=0.5,
                uses="the summary, --json, --report and --result flag at it; refused with "
                "--no-snooping",
            ),
            show_default=False,
        ),
    ] = None,
    max_iterations: Annotated[int, typer.Option(help="Iterations at most.")] = 100,
    start: Annotated[
        Start,
        typer.Option(
            "--start",
            help="Start values: given (the block's exterior orientations and tie points: "
            "GNSS/IMU, an earlier adjustment) or relative (new ones from relative "
            "orientations of consecutive images, strips and the control points, for a block "
            "without GNSS/IMU: the X0, Y0, Z0, omega, phi, kappa cells of images.csv and the "
            "tie points' X, Y, Z may then be empty or missing) or metashape (the poses and "
            "calibrations of a Metashape camera export, --start-file, for a Bundler file or "
            "COLMAP model of the same project: images matched by label, a camera group per "
            "sensor, tie points triangulated).",
        ),
    ] = Start.given,
    start_file: Annotated[
        Path | None,
        typer.Option(
            "--start-file",
            help="With --start metashape: the Metashape camera export (File > Export > "
            "Export Cameras, Agisoft XML).",
            show_default=False,
        ),
    ] = None,
    strips: Annotated[
        str | None,
        typer.Option(
            "--strips",
            help="With --start relative: the image ids of each strip in flight order, "
            "comma-separated, strips separated by ';' (e.g. '1,2,3;6,5,4'), every image "
            "once [default: the images in the order of the block's file, a new strip where "
            "two consecutive images share fewer than 5 points or three fewer than 3].",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            help="Write the adjusted block here (a folder for CSV and COLMAP, a file for BAL "
            "and Bundler).",
        ),
    ] = None,
    output_fmt: Annotated[
        BlockFormat | None,
        typer.Option(
            "--output-format",
            help="Format of --output (default: BAL for .txt/.bal/.bz2 names, Bundler for "
            ".out, as bundle convert --to; any other name: that of SOURCE; colmap-bin: "
            "COLMAP's binary model; a suffix that says another format is refused).",
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    report: Annotated[
        Path | None, typer.Option("--report", help="Write an HTML report to this file.")
    ] = None,
    result: Annotated[
        Path | None,
        typer.Option(
            "--result",
            help="Write the result record (JSON) that 'photogeom bundle report' renders.",
        ),
    ] = None,
    unit: Annotated[
        str | None,
        typer.Option(
            help="Length unit of the object coordinates, a label of the numbers shown "
            "[default: the unit of the block's CRS (--crs or the '# crs:' line of points.csv), "
            "else m]; one that contradicts the CRS is refused.",
            show_default=False,
        ),
    ] = None,
    angle_unit: Annotated[
        AngleUnit,
        typer.Option(
            "--angle-unit",
            help="Unit of the angles shown and of a CSV block written with -o (arcsec: "
            "shown, the block in deg).",
        ),
    ] = AngleUnit.deg,
    sigma: SigmaOpt = None,
    image_key: ImageKeyOpt = ImageKey.by_name,
    image_size: ImageSizeOpt = None,
    image_list: ImageListOpt = None,
    group_cameras: GroupCamerasOpt = False,
    drop_extras: DropExtrasOpt = False,
    crs: Annotated[
        str | None,
        typer.Option(
            "--crs",
            help=f"CRS of the block's object coordinates ({CRS_FORMS}; default: the "
            "'# crs:' line of points.csv); recorded in the results and the adjusted block; "
            "geographic CRSs (degrees) are refused.",
            show_default=False,
        ),
    ] = None,
    gnss_crs: Annotated[
        str | None,
        typer.Option(
            "--gnss-crs",
            help="CRS of the GNSS positions (e.g. EPSG:4979: gnss_X,gnss_Y,gnss_Z are lon, "
            "lat, h): converted into the block's CRS (without one: a local ENU frame at the "
            "centre of the GNSS positions) for the adjustment; the adjusted projection "
            "centres are given back in it.",
            show_default=False,
        ),
    ] = None,
    allow_ballpark: Annotated[
        bool, typer.Option(help="Accept an approximate PROJ datum shift (--gnss-crs).")
    ] = False,
    output_calibration: Annotated[
        Path | None,
        typer.Option(
            "--output-calibration",
            help="Write the adjusted calibration with its standard deviations, format by "
            "suffix: .xml Metashape, .json photogeom camera (--camera), .yaml/.yml OpenCV, "
            ".txt COLMAP cameras.txt (no standard deviations); several camera groups: "
            "NAME-GROUP.SUFFIX each.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Bundle adjustment with self-calibration of a block read from a file.

    Prints the summary (or JSON with --json); on a terminal the iterations are shown as they
    run. Everything is computed before any file is written.
    """
    from ..bundle import bundle_adjust
    from ..report.bundle_record import bundle_result_data

    # a level is refused where no test runs, not silently ignored (as grid fit, orient absolute)
    alpha = check_alpha(
        alpha, upper=0.5, off=None if snooping else "--no-snooping turns off: leave out "
        "--no-snooping or --alpha",
    )  # fmt: skip
    read_fmt = detect_format(source, fmt)
    src_fmt = "colmap-bin" if read_fmt == "colmap-both" else read_fmt  # COLMAP reads .bin
    out_fmt = (
        None if output is None else output_format(output, output_fmt, src_fmt, "--output-format")
    )
    check_targets(
        blocks=[("--output", output, out_fmt)],
        files=[("--report", report), ("--result", result)],
    )
    if output_calibration is not None:
        from ..camera.calibration_files import calibration_format

        cal_fmt = calibration_format(output_calibration, "--output-calibration")
    if strips is not None and start is not Start.relative:
        raise InputError(
            "--strips is for --start relative: add --start relative, or leave out --strips"
        )
    if (start_file is not None) != (start is Start.metashape):
        raise InputError(
            "--start-file is for --start metashape: add --start metashape, or leave out "
            "--start-file" if start_file is not None else "--start metashape takes the poses "
            "from a Metashape camera export: give it with --start-file cameras.xml"
        )
    relative = start is Start.relative
    poses = None
    if start_file is not None:
        from ..bundle.io_metashape import read_metashape_cameras

        with stage_spinner(f"reading {start_file}"):
            poses = read_metashape_cameras(start_file)
    with stage_spinner(f"reading {source}"):
        block = read_block(
            source, read_fmt, sigma=sigma, image_key=image_key, start_values=not relative,
            image_size=image_size, image_list=image_list, group_cameras=group_cameras,
        )  # fmt: skip
    start_note = start_info = None
    if poses is not None:
        from ..bundle.io_metashape import start_from_metashape

        block, done = start_from_metashape(block, poses)
        start_note = done.summary()
        start_info = {"file": str(start_file), **done.to_dict()}
        if crs is not None and block.crs is not None:
            from ._common import same_crs

            if not same_crs(block.crs, crs):
                raise InputError(
                    f"--start metashape puts the block in the geocentric coordinates of "
                    f"{start_file} ({block.crs}), but --crs says {crs}: leave out --crs"
                )
    block, georef = _block_crs(block, crs, gnss_crs, allow_ballpark)
    if relative:
        with stage_spinner("start values from relative orientations"):
            block, start_note, start_info = relative_start(block, strips)
    if output is not None:
        _refuse_output_terms(block, free_names(free), output, out_fmt)
        _refuse_output_names(block, output, out_fmt)
    cal_files: list[tuple[object, Path]] = []
    if output_calibration is not None:
        cal_files = calibration_targets(output_calibration, block.camera_ids.tolist())
        if cal_fmt in ("opencv", "colmap"):
            _refuse_opencv_terms(block, free_names(free), output_calibration, cal_fmt)
        check_targets(
            files=[("--report", report), ("--result", result)]
            + [("--output-calibration", p) for _, p in cal_files]
        )
    if unit is None:  # the CRS's unit, as orient absolute and transform estimate label it
        unit = _crs_length_unit(block.crs) or "m"
    elif block.crs is not None:  # a label that contradicts the CRS: refused, as they do
        from ..crs import cartesian_crs

        where = "--crs" if crs is not None else "the block's CRS (points.csv '# crs:' line)"
        try:
            cartesian_crs(block.crs, what=where, unit=unit)
        except InputError as exc:
            text = str(exc).replace(f"the unit given is {unit!r}", f"--unit is {unit}")
            raise InputError(text.replace("leave the unit out", "leave --unit out")) from None
    options = dict(
        loss=loss.value,
        loss_scale=loss_scale,
        datum=datum.value,
        point_covariance=point_covariance,
        variance_components=variance_components,
        snooping=snooping,
        alpha=alpha,
        max_iterations=max_iterations,
    )
    names = free_names(free)
    if names is not None:
        options["free"] = names
    prog, progress = iteration_progress(max_iterations)
    if prog is not None:
        with prog:
            fit = bundle_adjust(block, progress=progress, **options)
    else:
        fit = bundle_adjust(block, **options)
    angle = angle_unit.value
    if block.crs is not None:
        fit = _with_curvature_note(fit)
    if georef is not None:
        georef = _georef_back(fit, georef, allow_ballpark)
    texts: list[tuple[Path, str]] = []
    if report is not None or result is not None:
        from ..report.invocation import cli_command

        data = bundle_result_data(fit, unit=unit, angle_unit=angle)
        _add_georef(data, georef)
        # the adjustment's inputs and options, shown by 'bundle report' of the saved record
        data["command"] = cli_command()
        if result is not None:
            texts.append((result, json.dumps(data, indent=1, allow_nan=False) + "\n"))
        if report is not None:
            from ..report.bundle import bundle_report  # matplotlib: only for --report

            texts.append(
                (report, bundle_report(data, f"Bundle adjustment: {source.name}").to_html())
            )
    if cal_files:
        from ..camera.calibration_files import calibration_text

        cams = fit.block.cameras
        for group, path in cal_files:
            per_image = sorted(fit.block.image_variant.get(group, ()))
            if per_image:  # a file holds one calibration: the group's, offsets left out
                typer.echo(
                    f"note: camera group {group!r} estimates {', '.join(per_image)} per image: "
                    f"{path} holds the group's value, without the images' offsets (they are "
                    "in --result and --json: images[].f_offset, ...)",
                    err=True,
                )
            texts.append(
                (
                    path,
                    calibration_text(
                        cams[group],
                        cal_fmt,
                        std=fit.calibration_std[group],
                        covariance=fit.calibration_covariance(group),
                    ),
                )
            )
    files = {}
    if output is not None:  # a CSV block holds deg, gon or rad: arcsec is shown, deg written
        block_angle = block_angle_unit(angle)
        files = block_files(
            fit.block, output, out_fmt, drop_extras=drop_extras, angle_unit=block_angle
        )
    from ..bundle.io_formats import FOLDER_FORMATS

    write_all(
        files,
        texts,
        folders=[output] if out_fmt in FOLDER_FORMATS else [],
        csv_blocks=[output] if output is not None and out_fmt == "csv" else [],
    )
    if as_json:
        d = fit.to_dict(angle)
        d["unit"] = unit
        d["input"] = {"path": str(source), "format": src_fmt, "start": start.value}
        if start_info is not None:  # the strips found or given, as the summary's line
            d["input"]["start_" + start.value] = start_info
        _add_georef(d, georef)
        typer.echo(json_text(d), nl=False)
        _refuse_unconverged(fit, max_iterations, relative)
        return
    out = console()
    say(f"{source} ({src_fmt})", out)
    if start_note is not None:
        say(start_note, out)
    say(in_cli_words(fit.summary(angle, unit), _SUMMARY_WORDS), out)
    if georef is not None:
        say(
            f"GNSS positions of {georef['n_gnss']} image(s) converted from "
            f"{georef['gnss_crs_name']} into the block's system; the adjusted projection "
            f"centres in {georef['gnss_crs_name']} are in the JSON (--json, --result: "
            "images[].position_gnss_crs)",
            out,
        )
    if output is not None:
        say(
            f"adjusted block written to {output} ({out_fmt})" + _angles_written(out_fmt, angle),
            out,
        )
    for path, _ in texts:
        say(f"wrote {path}", out)
    _refuse_unconverged(fit, max_iterations, relative)


def _refuse_unconverged(fit, max_iterations: int, relative: bool) -> None:
    """Exit 1 after a run that did not converge (its summary, JSON and files are those of
    the last iterate, written for inspection), with one line on stderr: a script must not
    take the result for an adjusted block. The route to better start values is
    ``--start relative`` unless the run started there or the block has fewer than three
    control points observed (which that route needs)."""
    if fit.converged:
        return
    from ..bundle.result import observed_control

    n_ctrl = observed_control(fit.block)
    if relative:
        route = (
            "the start values came from relative orientations (--start relative) already: "
            "check the strips (--strips, each in flight order) and the control points"
        )
    elif n_ctrl < 3:
        route = (
            "give better start values (an earlier adjustment's; --start relative needs 3 "
            f"control points observed in the images and the block has {n_ctrl}: BAL and "
            "Bundler files and COLMAP models hold none, a CSV block can)"
        )
    else:
        route = "give better start values (--start relative for a block without GNSS/IMU)"
    typer.echo(
        f"error: the adjustment did not converge ({fit.iterations} of at most "
        f"{max_iterations} iterations): the summary and the files written hold its last "
        f"iterate, not an adjusted block; raise --max-iterations if the cost still falls, "
        f"else {route}",
        err=True,
    )
    raise typer.Exit(1)


#: Points two consecutive images of a found strip share (a relative orientation needs 5)
#: and points three consecutive images share (the scale transfer; ``min_common``).
_STRIP_PAIR, _STRIP_TRIPLE = 5, 3


def parse_strips(text: str, block) -> list[list]:
    """The strips of ``--strips`` ('1,2,3;6,5,4') as lists of the block's image ids; every
    image once."""
    by_text = {str(i): i for i in block.image_ids.tolist()}
    out: list[list] = []
    for part in text.split(";"):
        cells = [c.strip() for c in part.split(",")]
        if not any(cells):
            continue
        if not all(cells):
            raise InputError(f"--strips: an empty image id in {part.strip()!r}")
        unknown = [c for c in cells if c not in by_text]
        if unknown:
            raise InputError(
                f"--strips: {', '.join(map(repr, unknown[:5]))} is not an image id of the "
                f"block (its ids: {', '.join(list(by_text)[:8])}"
                f"{' ...' if len(by_text) > 8 else ''})"
            )
        if len(cells) < 2:
            raise InputError(f"--strips: strip {cells[0]!r} has one image; a strip needs two")
        out.append([by_text[c] for c in cells])
    listed = [i for s in out for i in s]
    twice = sorted({str(i) for i in listed if listed.count(i) > 1})
    if twice:
        raise InputError(f"--strips: image(s) {', '.join(twice[:5])} listed twice")
    left = [i for i in by_text if by_text[i] not in set(listed)]
    if left:
        raise InputError(
            f"--strips: {len(left)} image(s) in no strip ({', '.join(left[:8])}): every image "
            "needs its start values; add them to a strip, or delete them from the block"
        )
    return out


def found_strips(block) -> list[list]:
    """Strips from the order of the block's images: a new strip where two consecutive images
    share fewer than ``_STRIP_PAIR`` points or three fewer than ``_STRIP_TRIPLE``."""
    import numpy as np
    from scipy import sparse

    m = block.n_images
    A = sparse.csr_matrix(
        (np.ones(block.n_observations), (block.obs_image, block.obs_point)),
        shape=(m, block.n_points),
    )
    A.data[:] = 1.0
    pair = np.asarray(A[:-1].multiply(A[1:]).sum(axis=1)).ravel()  # images k, k + 1
    triple = np.asarray(A[:-2].multiply(A[1:-1]).multiply(A[2:]).sum(axis=1)).ravel()
    ids = block.image_ids.tolist()
    out, cur = [], [ids[0]]
    for k in range(1, m):
        ok = pair[k - 1] >= _STRIP_PAIR and (len(cur) < 2 or triple[k - 2] >= _STRIP_TRIPLE)
        if ok:
            cur.append(ids[k])
        else:
            out.append(cur)
            cur = [ids[k]]
    out.append(cur)
    lone = [s[0] for s in out if len(s) < 2]
    if lone:
        raise InputError(
            f"--start relative: image(s) {', '.join(map(str, lone[:8]))} share fewer than "
            f"{_STRIP_PAIR} points with the images next to them in the block's file: give "
            "the strips in flight order with --strips"
        )
    return out


def relative_start(block, strips: str | None):
    """The block with start values from relative orientations (``--start relative``), a
    line that says how they were found and the same for ``--json`` (``strips``: the image
    ids of each strip in flight order; ``strips_from``: ``"--strips"`` or ``"file order"``;
    ``control_points``: the control points the strips were oriented to; ``bridged``: per pair
    whose relative orientation failed from the essential matrix and started from its
    neighbour's, ``[image, image, neighbour's image, neighbour's image]``)."""
    import numpy as np

    from ..bundle import start_from_relative_orientation
    from ..bundle.result import observed_control
    from ..errors import DegenerateGeometryError

    if block.n_images < 2:
        raise InputError("--start relative needs at least two images")
    n_ctrl = observed_control(block)
    if n_ctrl < 3:  # before the relative orientations (seconds to minutes) are computed
        raise InputError(
            f"--start relative orients the strips to control points, and the block has "
            f"{n_ctrl} observed in its images (at least 3 needed, not on a line; BAL and "
            "Bundler files and COLMAP models hold none): adjust the block from the start "
            "values its file holds (leave out --start relative), or give control points in "
            "a CSV block (bundle convert SOURCE FOLDER --to csv, then rows of role 'control' "
            "in points.csv and their observations in observations.csv)"
        )
    given = strips is not None
    lists = parse_strips(strips, block) if given else found_strips(block)
    new, st = start_from_relative_orientation(block, lists)
    # every image is in a strip: a tie point left where it was got no start value (a CSV
    # block without start values holds a placeholder 0 there)
    kept = np.flatnonzero((block.role == "tie") & np.all(new.xyz == block.xyz, axis=1))
    if kept.size:
        bad = block.point_ids[kept].tolist()
        raise DegenerateGeometryError(
            f"--start relative: {kept.size} tie point(s) get no start value (no relative "
            "orientation reached them and the new cameras cannot intersect them: rays nearly "
            f"parallel or crossing behind the cameras): {', '.join(map(str, bad[:8]))}"
            f"{' ...' if kept.size > 8 else ''}; delete them from the block's files"
        )
    sizes = ", ".join(str(len(s)) for s in lists)
    control = set(block.point_ids[block.role == "control"].tolist())
    n_ctrl = len({p for u in st.control_used for p in u} & control)
    how = "--strips" if given else "the order of the images in the block's file"
    bridged = [
        [_plain(m.images[k]), _plain(m.images[k + 1]), _plain(m.images[j]), _plain(m.images[j + 1])]
        for m in st.strips
        for k, j in m.bridged
    ]
    info = {
        "strips": [[_plain(i) for i in s] for s in lists],
        "strips_from": "--strips" if given else "file order",
        "control_points": n_ctrl,
        "bridged": bridged,
    }
    line = (
        f"start values from relative orientations: {len(lists)} strip(s) of {sizes} images "
        f"({how}), oriented to {n_ctrl} control point(s)"
    )
    if bridged:
        pairs = ", ".join(f"{a}-{b} (from {c}-{d})" for a, b, c, d in bridged[:8])
        more = f" and {len(bridged) - 8} more" if len(bridged) > 8 else ""
        line += (
            f"; {len(bridged)} pair(s) failed from the essential matrix and were oriented "
            f"from the neighbouring pair's relative orientation: images {pairs}{more}"
        )
    return new, line, info


def _plain(value):
    """An image id as JSON holds it (a numpy integer or string as int or str)."""
    return value.item() if hasattr(value, "item") else value


def calibration_targets(path: Path, groups: list) -> list[tuple[object, Path]]:
    """The file of each camera group for ``--output-calibration PATH``: PATH itself for one
    group, ``STEM-GROUP.SUFFIX`` beside it for several (characters other than letters,
    digits, ``.``, ``_`` and ``-`` of a group id become ``_``); two groups given one name
    are refused."""
    if len(groups) == 1:
        return [(groups[0], path)]
    out: list[tuple[object, Path]] = []
    seen: dict[Path, object] = {}
    for g in groups:
        tag = re.sub(r"[^A-Za-z0-9._-]", "_", str(g))
        p = path.with_name(f"{path.stem}-{tag}{path.suffix}")
        if p in seen:
            raise InputError(
                f"--output-calibration: camera groups {seen[p]!r} and {g!r} would both be "
                f"written to {p}; rename one of the groups in the block"
            )
        seen[p] = g
        out.append((g, p))
    return out


def _refuse_opencv_terms(
    block, free: tuple[str, ...] | None, path: Path, fmt: str = "opencv"
) -> None:
    """Refuse, before the adjustment, an OpenCV or COLMAP (``fmt``) ``--output-calibration``
    of a block whose calibration has (or will estimate) K4 or B2, which their models have
    not."""
    tool = "OpenCV" if fmt == "opencv" else "COLMAP"
    _refuse_terms(
        block, free, ("k4", "b2"), f"--output-calibration {path}: {tool}'s camera models have",
        "hold them at zero (--free without k4 and b2) or write the calibration as .xml or "
        ".json",
    )


def _refuse_output_terms(block, free: tuple[str, ...] | None, path: Path, fmt: str) -> None:
    """Refuse, before the adjustment, an ``--output`` block file whose format's camera
    cannot hold terms the block's calibration has (or will estimate): the writer would
    refuse it after the adjustment."""
    from ..bundle import CALIBRATION_NAMES, io_bal, io_colmap

    if fmt == "csv":
        return
    # the writers' own lists: BAL and Bundler share the camera of io_bal.centred_cameras
    missing = io_colmap.TERMS_NOT_HELD if fmt.startswith("colmap") else io_bal.TERMS_NOT_HELD
    keep = [n for n in CALIBRATION_NAMES if n not in missing]
    name = {"bal": "a BAL file", "bundler": "a Bundler file"}.get(fmt, "a COLMAP model")
    _refuse_terms(
        block, free, missing, f"--output {path}: {name}'s camera has",
        f"estimate only what it holds (--free {','.join(keep)}, or fewer) with those terms "
        "zero in the block, or write the adjusted block as a CSV folder (-o FOLDER "
        "--output-format csv" + (")" if fmt.startswith("colmap") else "; or colmap)"),
    )


def _refuse_output_names(block, path: Path, fmt: str) -> None:
    """Refuse, before the adjustment, image ids that the ``--output`` format cannot write
    back (the writer would refuse them after the adjustment)."""
    from ..bundle._textio import unwritable_name
    from ..bundle.io_bundler import refuse_unlisted_names

    try:
        if fmt == "bundler":
            refuse_unlisted_names(block.image_ids)
        elif fmt.startswith("colmap"):
            bad = unwritable_name(block.image_ids)
            if bad is not None:
                raise InputError(
                    f"image id {bad[0]!r}: a COLMAP model cannot hold an image name that "
                    f"{bad[1]}; rename the image"
                )
    except InputError as exc:
        raise InputError(f"--output {path}: {exc}") from None


def _refuse_terms(
    block, free: tuple[str, ...] | None, terms: tuple[str, ...], what: str, fix: str
) -> None:
    """Refuse a block whose calibration has non-zero ``terms`` or estimates them (``free``
    the ``--free`` names, None for the block's own); ``what`` begins the message ("...
    has"), ``fix`` ends it."""
    for g, cal in block.cameras.items():
        names = set(block.free[g] if free is None else free)
        bad = [n.upper() for n in terms if n in names or getattr(cal, n) != 0.0]
        if bad:
            raise InputError(
                f"{what} no {' and no '.join(bad)}, which camera group {g!r} estimates or "
                f"holds non-zero: {fix}"
            )


def _crs_length_unit(crs: str | None) -> str | None:
    """The length unit of the block's CRS (``ftUS`` for EPSG:2263), or None without a CRS
    or when PROJ cannot tell."""
    if not crs:
        return None
    from ..crs import cartesian_crs
    from ..errors import PhotogeomError

    try:
        return cartesian_crs(crs, what="--crs").unit or None
    except PhotogeomError:
        return None


def _block_crs(block, crs: str | None, gnss_crs: str | None, allow_ballpark: bool):
    """The block with its CRS checked or recorded (``--crs``) and its GNSS positions brought
    from ``--gnss-crs`` into its system; and the record of that conversion (or None)."""
    from ..crs import cartesian_crs

    fix = (
        "convert the block's coordinates first (photogeom crs convert --to enu --origin "
        "LAT,LON,H for a local east-north-up frame, or to a projected CRS) and give the CRS of "
        "the GNSS positions with --gnss-crs"
    )
    if crs is not None:
        info = cartesian_crs(crs, what="--crs", fix=fix)
        if block.crs is not None:
            from ._common import same_crs

            if not same_crs(block.crs, info.text):
                raise InputError(
                    f"the block records the CRS {block.crs} (points.csv '# crs:' line) but "
                    f"--crs says {crs}: --crs names the CRS of the coordinates, it does not "
                    "convert them; convert them with photogeom crs convert"
                )
        else:
            block = block.replace(crs=info.text)
    elif block.crs is not None:
        from ._common import recorded_crs

        recorded_crs(block.crs, "the block's CRS (points.csv '# crs:' line)", fix=fix)
    if gnss_crs is None:
        return block, None
    import numpy as np

    from .. import crs as _crs
    from ..bundle.georef import gnss_into_block_crs
    from ..crs import crs_label, parse_crs

    g = gnss_crs.strip()
    if not g.lower().startswith("enu:"):
        parse_crs(g, what="--gnss-crs")
    try:
        block = gnss_into_block_crs(block, g, allow_ballpark=allow_ballpark)
    except InputError as exc:
        text = str(exc).replace("crs=, --crs;", "--crs;").replace("(gnss_crs / --gnss-crs)", "")
        raise InputError(f"--gnss-crs {g}: {text}") from None
    n = int(np.all(np.isfinite(block.gnss), axis=1).sum())
    angular = _crs.frame_from_text(g) is None and parse_crs(g).is_geographic
    return block, {"gnss_crs": g, "gnss_crs_name": crs_label(g), "n_gnss": n, "angular": angular}


def _with_curvature_note(fit):
    """``fit`` with a note when its object coordinates are map coordinates with heights over
    an extent where the Earth's curvature shows (:func:`photogeom.crs.curvature_note`)."""
    from dataclasses import replace

    from ..crs import curvature_note
    from ._common import recorded_crs

    note = curvature_note(
        recorded_crs(fit.block.crs, "block crs"),
        fit.block.xyz,
        what="object coordinates of the block",
    )
    return fit if note is None else replace(fit, notes=(*fit.notes, note))


def _georef_back(fit, georef: dict, allow_ballpark: bool) -> dict:
    """The conversion record with the adjusted projection centres in the GNSS CRS."""
    pos = fit.positions_in(georef["gnss_crs"], allow_ballpark=allow_ballpark)
    return {**georef, "crs": fit.crs, "positions": pos}


def _add_georef(d: dict, georef: dict | None) -> None:
    """Put the GNSS CRS and the projection centres in it into a JSON record."""
    if georef is None:
        return
    d["georeferencing"] = {
        "gnss_crs": georef["gnss_crs"],
        "gnss_crs_name": georef["gnss_crs_name"],
        "block_crs": georef["crs"],
        "n_gnss": georef["n_gnss"],
        "angular": georef["angular"],
        "axes": ["lon", "lat", "h"] if georef["angular"] else ["x", "y", "z"],
        "note": "GNSS positions converted from gnss_crs into block_crs for the adjustment; "
        "images[].position_gnss_crs: adjusted projection centres in gnss_crs (x/longitude "
        "first)",
    }
    for row, p in zip(d["images"], georef["positions"].tolist()):
        row["position_gnss_crs"] = p


# --- convert -------------------------------------------------------------------------------------


def block_angle_unit(angle_unit: str) -> str:
    """The angle unit a CSV block is written in for ``--angle-unit``: the unit itself, deg
    for arcsec (a CSV block holds deg, gon or rad, named in its column headers)."""
    return "deg" if angle_unit == "arcsec" else angle_unit


def _angles_written(fmt: str | None, angle_unit: str) -> str:
    """The words of the output line when ``--angle-unit arcsec`` wrote a CSV block in deg."""
    if fmt == "csv" and angle_unit == "arcsec":
        return "; angles written in deg (a CSV block holds deg, gon or rad)"
    return ""


@app.command("convert")
@_cli_words
def convert(
    source: Annotated[
        Path,
        typer.Argument(
            help="Block to read (BAL or Bundler file, COLMAP text or binary, CSV folder)."
        ),
    ],
    target: Annotated[Path, typer.Argument(help="Where to write (a folder for CSV and COLMAP).")],
    from_fmt: Annotated[
        BlockFormat | None,
        typer.Option(
            "--from",
            help="Format of SOURCE (default: detected; colmap-bin: COLMAP's binary model).",
        ),
    ] = None,
    to_fmt: Annotated[
        BlockFormat | None,
        typer.Option(
            "--to",
            help="Format of TARGET (default: BAL for .txt/.bal/.bz2 names, Bundler for .out; "
            "colmap-bin: COLMAP's binary model; a suffix that says another format is "
            "refused).",
        ),
    ] = None,
    angle_unit: Annotated[
        AngleUnit,
        typer.Option(
            "--angle-unit",
            help="Angle unit of a CSV block written (arcsec: written in deg, as bundle "
            "adjust -o does; a CSV block holds deg, gon or rad).",
        ),
    ] = AngleUnit.deg,
    sigma: SigmaOpt = None,
    image_key: ImageKeyOpt = ImageKey.by_name,
    image_size: ImageSizeOpt = None,
    image_list: ImageListOpt = None,
    group_cameras: GroupCamerasOpt = False,
    drop_extras: DropExtrasOpt = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Convert a block between BAL, Bundler, COLMAP text or binary and CSV (conventions
    converted exactly)."""
    read_fmt = detect_format(source, from_fmt, "--from")
    src = "colmap-bin" if read_fmt == "colmap-both" else read_fmt  # COLMAP reads .bin
    dst = output_format(target, to_fmt, None, "--to")
    # a CSV block holds deg, gon or rad (named in its column headers): arcsec, accepted by
    # every bundle command, is written in deg, as bundle adjust -o does
    block_angle = block_angle_unit(angle_unit.value)
    check_targets(blocks=[("TARGET", target, dst)])
    with stage_spinner(f"converting {source} to {dst}"):
        block = read_block(
            source, read_fmt, sigma=sigma, image_key=image_key, option="--from",
            image_size=image_size, image_list=image_list, group_cameras=group_cameras,
        )  # fmt: skip
        files = block_files(
            block, target, dst, drop_extras=drop_extras, angle_unit=block_angle
        )
    from ..bundle.io_formats import FOLDER_FORMATS

    # a CSV block's record of a joint adjustment with grids is a folder inside TARGET
    write_all(
        files,
        folders=sorted({f.parent for f in files}) if dst in FOLDER_FORMATS else [],
        csv_blocks=[target] if dst == "csv" else [],
    )
    info = {
        "source": str(source),
        "source_format": src,
        "target": str(target),
        "target_format": dst,
        "camera_groups": len(block.calibrations),
        "images": block.n_images,
        "points": block.n_points,
        "observations": block.n_observations,
    }
    if dst == "csv":
        info["angle_unit"] = block_angle
    if as_json:
        typer.echo(json_text(info), nl=False)
        return
    say(
        f"{source} ({src}) -> {target} ({dst}): {info['camera_groups']} camera group(s), "
        f"{info['images']} images, {info['points']} points, {info['observations']} image "
        "observations" + _angles_written(dst, angle_unit.value)
    )


# --- report --------------------------------------------------------------------------------------


@app.command("report")
@_cli_words
def report_cmd(
    result: Annotated[
        Path, typer.Argument(help="Result record written by 'photogeom bundle adjust --result'.")
    ],
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            "--report",
            help="HTML report to write (--report: the same option, the name of bundle adjust).",
        ),
    ] = Path(
        "bundle-report.html"
    ),
    title: Annotated[str | None, typer.Option(help="Title of the report.")] = None,
    max_rows: Annotated[
        int,
        typer.Option(
            help="Rows of the image, flagged and poorly controlled observation tables at most."
        ),
    ] = 50,
) -> None:
    """Render the HTML report of a saved bundle adjustment result (JSON record)."""
    from ..report.bundle import bundle_report, read_bundle_result

    if max_rows < 1:
        raise InputError(f"--max-rows must be at least 1, not {max_rows}")
    refuse_stdout_dash(typed_option("--output", "--report"), output)
    if str(output.parent) and not output.parent.is_dir():
        name = typed_option("--output", "--report")
        raise InputError(f"{name}: cannot write {output}: folder {output.parent} does not exist")
    from ..io.jsonfile import build_from_json

    data = read_bundle_result(result)
    # a record edited or damaged below its top-level entries: named, never a traceback
    rep = build_from_json(
        lambda d: bundle_report(d, title or f"Bundle adjustment: {result.stem}", max_rows=max_rows),
        data,
        result,
        "a bundle adjustment result",
    )
    path = rep.write(output)
    say(f"wrote {path}")
