"""The grid block commands called the images per strip of the simulated block
--images, `bundle simulate` --images-per-strip. Now --images-per-strip everywhere; --images
stays as a hidden alias."""

from __future__ import annotations

import json

import pytest


@pytest.mark.parametrize("command", ["evaluate", "sweep", "report"])
def test_help_names_images_per_strip(cli, command):
    code, out, _ = cli("grid", command, "--help")
    assert code == 0 and "--images-per-strip" in out and "--images " not in out


def test_images_per_strip_and_its_old_name_give_the_same_sweep(cli):
    runs = []
    for flag in ("--images-per-strip", "--images"):
        code, out, err = cli("grid", "sweep", "--preset", "FC300S", "--strips", "1", flag, "5",
                             "--spacings", "500,1000", "--json")
        assert code == 0, err
        d = json.loads(out)
        d.pop("time")
        d.pop("time_readjust")
        runs.append(d)
    assert runs[0] == runs[1]


def test_too_few_images_names_the_option(cli):
    code, _, err = cli("grid", "evaluate", "--preset", "FC300S", "--images-per-strip", "2")
    assert code == 2 and "--images-per-strip >= 3" in err
