"""`grid evaluate --preset foo` answered "unknown camera preset 'foo'; choose from ...
or pass a CameraPreset" (a Python object, and no option named); grid sweep --spacings 100
answered "sweep_spacings: --spacings: give at least two" (a library function's name)."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("command", ["evaluate", "sweep"])
def test_unknown_preset_names_the_option(cli, command):
    code, _, err = cli("grid", command, "--preset", "foo")
    assert code == 2
    assert err.startswith("error: --preset foo: choose one of ILCE-7RM2, FC6310, FC300S"), err
    assert "CameraPreset" not in err


def test_one_spacing_names_the_option_only(cli):
    code, _, err = cli("grid", "sweep", "--preset", "FC300S", "--strips", "1",
                       "--images-per-strip", "3", "--spacings", "100")
    assert code == 2 and err.startswith("error: --spacings: give at least two"), err
