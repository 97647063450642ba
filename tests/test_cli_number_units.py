"""Every numeric option of the CLI refuses a number typed with a unit or a decimal comma in
its own words: the option's name, the unit its --help states, and what to type instead."""

from __future__ import annotations

import re

import pytest
import typer
import typer.main
from typer.testing import CliRunner

from photogeom.cli._common import FRACTION, PROBABILITY, number_message, option_unit
from photogeom.cli.main import app

#: Words of the layers below the CLI that must never reach the user.
_FOREIGN = ("Input should be", "valid number", "valid integer", "unable to parse", "pydantic")


def _numeric_options() -> list[tuple[list[str], object]]:
    """``(command path, option)`` of every int and float option, hidden ones too."""
    out = []

    def walk(cmd, path):
        if hasattr(cmd, "list_commands"):
            ctx = cmd.context_class(cmd)  # the click of the command itself (typer vendors one)
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), [*path, name])
            return
        for param in cmd.params:
            if getattr(param.type_descriptor, "annotation", None) in (int, float):
                out.append((path, param))

    walk(_ROOT, [])
    return out


_ROOT = typer.main.get_command(app)


def _refusal(path: list[str], option: str, value: str) -> str:
    """The message of ``photogeom PATH OPTION VALUE`` (the option is read first: click
    processes the options given before the missing arguments)."""
    with pytest.raises(typer.BadParameter) as info:
        _ROOT.main([*path, option, value], prog_name="photogeom", standalone_mode=False)
    return info.value.format_message()


def test_the_walk_finds_the_numeric_options():
    names = {(" ".join(path), max(p.opts, key=len)) for path, p in _numeric_options()}
    assert len(names) > 80
    for expected in [
        ("bundle simulate", "--sigma"),
        ("orient resection", "--f"),
        ("rpc localize", "--height"),
        ("cloud transform", "--chunk-size"),
        ("grid fit", "--spacing"),
    ]:
        assert expected in names


def test_every_numeric_option_refuses_a_unit_in_its_own_words():
    # before: "Invalid value for '--sigma': Input should be a valid number, unable to parse
    # string as a number" for every option but the grid commands' --spacing, --sigma-obs,
    # --overlap and --sigma-temporal
    problems = []
    for path, param in _numeric_options():
        option = max(param.opts, key=len)
        message = _refusal(path, option, "1mm")
        where = f"photogeom {' '.join(path)} {option} 1mm: {message}"
        if option not in message or "'1mm'" not in message:
            problems.append(f"{where} (no option name or value)")
        if any(word in message for word in _FOREIGN):
            problems.append(f"{where} (pydantic's words)")
        unit = option_unit(param.help)
        if unit not in (None, FRACTION, PROBABILITY) and unit not in message:
            problems.append(f"{where} (not the unit of its help, {unit})")
        if unit is None and "without a unit" not in message:
            problems.append(f"{where} (does not say it takes no unit)")
    assert not problems, "\n".join(problems)


def test_every_float_option_refuses_a_decimal_comma_with_the_number_to_type():
    problems = []
    for path, param in _numeric_options():
        option = max(param.opts, key=len)
        message = _refusal(path, option, "0,5")
        integer = param.type_descriptor.annotation is int
        fix = f"({option} 0)" if integer else f"give {option} 0.5"
        if fix not in message or any(word in message for word in _FOREIGN):
            problems.append(f"photogeom {' '.join(path)} {option} 0,5: {message}")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (
            ["bundle", "simulate", "--sigma", "0.5px"],
            "'0.5px' is not a number; --sigma is in px: give the number alone (--sigma 0.5)",
        ),
        (
            ["bundle", "simulate", "--gsd", "5cm"],
            "'5cm' is not a number; --gsd is in m/px, not cm: give it in m/px, without a unit",
        ),
        (
            ["orient", "absolute", "a.csv", "b.csv", "--alpha", "5%"],
            "'5%' is not a number; --alpha is a probability: give 0.05 for 5 %",
        ),
        (
            ["orient", "resection", "a.csv", "--f", "50mm"],
            "'50mm' is not a number; --f is in the unit of --unit: give the number alone "
            "(--f 50)",
        ),
        (
            ["rpc", "localize", "a.json", "b.csv", "--height", "10m"],
            "'10m' is not a number; --height is in m: give the number alone (--height 10)",
        ),
        (
            ["bundle", "simulate", "--strips", "3strips"],
            "'3strips' is not an integer; --strips is a count without a unit: give --strips 3",
        ),
        (
            ["bundle", "simulate", "--seed", "1.5"],
            "'1.5' is not an integer; --seed takes a whole number, such as --seed 1",
        ),
        (
            ["grid", "evaluate", "--overlap", "0,6"],
            "'0,6' is not a number; --overlap takes a decimal point: give --overlap 0.6",
        ),
    ],
)
def test_the_command_line_says_what_to_type(args, words):
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    text = " ".join(result.output.split())
    assert f"Invalid value for '{args[-2]}': {words}" in text


def test_a_number_without_a_unit_is_still_read():
    # the wrapper only rewords refusals: a plain number and an exponent go through
    with pytest.raises(typer.BadParameter) as info:
        _ROOT.main(
            ["bundle", "simulate", "--sigma", "1e-1", "--strips", "x"],
            prog_name="photogeom",
            standalone_mode=False,
        )
    assert "--strips" in info.value.format_message()


@pytest.mark.parametrize(
    ("help_text", "unit"),
    [
        ("Node spacing in pixels.", "px"),
        ("Std. dev. of image observations without one [px] (default: 1).", "px"),
        ("Ground sample distance [m/px] (default: the preset's).", "m/px"),
        ("Height (m) of every point, instead of an h column.", "m"),
        ("Pixel size in mm (digital camera, mm <-> pixels).", "mm"),
        ("Forward overlap of a stereo model (fraction).", FRACTION),
        ("Significance level of each w-test, in (0, 0.5) [default: 0.001].", PROBABILITY),
        ("Images per strip.", None),
    ],
)
def test_option_unit_reads_the_help(help_text, unit):
    assert option_unit(help_text) == unit


def test_number_message_names_the_typed_unit():
    message = number_message("30°", "--kappa", "the unit of --angle-unit")
    assert re.search(r"--kappa is in the unit of --angle-unit: give the number alone", message)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (
            ["orient", "resection", "a.csv", "--f", "50", "--principal-point", "1mm,2mm"],
            "--principal-point: expected comma-separated numbers, got '1mm,2mm'; give the "
            "numbers without a unit (--principal-point 1,2)",
        ),
        (
            ["camera", "project", "a.csv", "--f", "50", "--eo", "0m,0m,100m,0,0,0"],
            "--eo X0,Y0,Z0,omega,phi,kappa: expected comma-separated numbers, got "
            "'0m,0m,100m,0,0,0'; give the numbers without a unit (--eo 0,0,100,0,0,0)",
        ),
    ],
)
def test_lists_of_numbers_with_units_name_the_numbers_to_give(cli, args, words):
    # before: "expected comma-separated numbers, got '1mm,2mm'" only
    code, _, err = cli(*args)
    assert code == 2 and words in " ".join(err.split()), err


def test_a_list_with_a_word_that_is_no_number_gets_no_unit_advice(cli):
    code, _, err = cli("orient", "resection", "a.csv", "--f", "50", "--principal-point", "a,b")
    assert code == 2 and "got 'a,b'" in err and "without a unit" not in err
