"""The option tables of the documentation name what the commands take.

docs/cli.md and docs/bundle-adjustment.md give tables of options; a test beside this one
checks that every option they list exists. These check the other direction: what a command
accepts is in its table.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"

pytestmark = pytest.mark.skipif(not DOCS.is_dir(), reason="docs/ is not beside the tests")


def _table_row(page: str, option: str) -> str:
    """The one table row of ``docs/page`` whose first cell starts with ``option``."""
    rows = [
        line
        for line in (DOCS / page).read_text(encoding="utf-8").splitlines()
        if line.startswith(f"| `{option} ") or line.startswith(f"| `{option}`")
    ]
    assert len(rows) == 1, f"{page}: {len(rows)} table rows for {option}"
    return rows[0]


def test_output_calibration_row_names_every_suffix():
    # the table and synopsis of bundle adjust listed .xml, .json and .yaml, while
    # --output-calibration cal.txt writes a COLMAP cameras.txt (as its --help says)
    from photogeom.camera.calibration_files import CALIBRATION_SUFFIXES

    row = _table_row("bundle-adjustment.md", "--output-calibration")
    first, meaning = re.split(r"(?<!\\)\|", row)[1:3]
    text = (DOCS / "bundle-adjustment.md").read_text(encoding="utf-8")
    synopsis = re.search(r"\[--output-calibration ([^\]]+)\]", text).group(1)
    for suffix in CALIBRATION_SUFFIXES:
        assert f"`{suffix}`" in meaning, f"{suffix} is not described"
        if suffix != ".yml":  # the short form of .yaml, described beside it
            assert suffix in first.replace("\\", ""), f"{suffix} not in {first}"
            assert suffix in synopsis, f"{suffix} not in the synopsis {synopsis}"


def _cli_params() -> dict:
    """``{"group command": [click parameter, ...]}`` of the whole command line."""
    import typer

    from photogeom.cli.main import app

    out: dict = {}

    def walk(cmd, path):
        if hasattr(cmd, "list_commands"):
            ctx = cmd.context_class(cmd)  # the click of the command itself (typer vendors one)
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])
        else:
            out[" ".join(path)] = list(cmd.params)

    walk(typer.main.get_command(app), [])
    return out


def _cli_md_sections() -> dict:
    """``{"group command": section text}`` of the command sections of docs/cli.md."""
    sections: dict = {}
    name = None
    for line in (DOCS / "cli.md").read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            m = re.match(r"#+ `photogeom ([a-z-]+) ([a-z-]+)", line)
            name = f"{m.group(1)} {m.group(2)}" if m else None
            if name:
                sections[name] = []
        elif name:
            sections[name].append(line)
    return {k: "\n".join(v) for k, v in sections.items()}


def test_cli_md_option_tables_are_complete():
    # the table of transform estimate had no --source-crs, that of orient relative no
    # --id-col: a section that gives a command's option table names every option of it
    params = _cli_params()
    problems = []
    for command, text in _cli_md_sections().items():
        if command not in params or "| option | meaning |" not in text:
            continue
        for p in params[command]:
            names = [o for o in (*p.opts, *p.secondary_opts) if o.startswith("-")]
            if not names or names == ["--help"] or p.param_type_name == "argument":
                continue
            if not any(re.search(re.escape(n) + r"(?![\w-])", text) for n in names):
                problems.append(f"{command}: {'/'.join(names)} is not in its table")
    assert not problems, problems


def test_every_option_is_named_in_the_documentation():
    # nine options were named on no page (camera dlt estimate --linear, cloud transform
    # --quiet, grid correct-images --interpolation, grid evaluate|sweep|report --overlap,
    # grid fit --min-support, rpc fit|refine --style, rpc localize --max-iter): every option
    # of every command is named in README.md or docs/*.md, by one of its names
    root = DOCS.parent
    text = "\n".join(
        p.read_text(encoding="utf-8") for p in [root / "README.md", *sorted(DOCS.glob("*.md"))]
    )
    problems = []
    for command, plist in sorted(_cli_params().items()):
        for p in plist:
            names = [o for o in (*p.opts, *p.secondary_opts) if o.startswith("--")]
            if not names or names == ["--help"] or p.param_type_name == "argument":
                continue
            if not any(re.search(re.escape(n) + r"(?![\w-])", text) for n in names):
                problems.append(f"{command} {'/'.join(names)}")
    assert not problems, problems


def test_opencv_json_calibration_is_named_where_calibrations_are_listed(cli, tmp_path):
    # an OpenCV FileStorage JSON (camera_matrix, ...) is read by camera convert, --camera and
    # --calibration, but their help and docs/cli.md listed "OpenCV YAML/XML" only
    import cv2
    import numpy as np

    path = tmp_path / "opencv.json"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 4000)
    fs.write("image_height", 3000)
    fs.write("camera_matrix", np.array([[2000.0, 0, 1999.5], [0, 2000.0, 1499.5], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[0.1, 0.01, 0.0, 0.0, 0.001]]))
    fs.release()
    code, out, err = cli("camera", "convert", path, tmp_path / "cal.xml")
    assert code == 0, err  # read, as the help should say
    helps = {
        ("camera", "convert"): "source <path>",
        ("camera", "project"): "--calibration <path>",
        ("orient", "resection"): "--calibration <path>",
        ("orient", "relative"): "--calibration <path>",
    }
    for command, what in helps.items():
        code, out, _ = cli(*command, "--help")
        assert code == 0
        block = " ".join(out[out.index(what) :].split())[:400]
        assert "YAML/XML/JSON" in block, (command, block)
    text = (DOCS / "cli.md").read_text(encoding="utf-8")
    listed = re.findall(
        r"OpenCV (?:`cv2\.FileStorage` )?YAML(?:/XML(?:/JSON)?|, XML or JSON| or XML)", text
    )
    assert listed and all("JSON" in s for s in listed), listed


def test_output_format_row_names_every_block_format():
    # the row of bundle adjust -o listed csv|bal|colmap|colmap-bin: --output-format bundler
    # (and its file, not folder) was missing
    from photogeom.bundle.io_formats import FORMATS

    row = _table_row("bundle-adjustment.md", "-o PATH")
    first = re.split(r"(?<!\\)\|", row)[1]
    named = re.search(r"--output-format ([a-z\\|-]+)", first).group(1).split("\\|")
    assert sorted(named) == sorted(FORMATS)
    assert "a file for BAL and Bundler" in row
