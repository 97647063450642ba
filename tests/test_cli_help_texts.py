"""Help texts say the units and who reads an output file: orient absolute's
--sigma-source / --sigma-target gave no unit, --id-col claimed 'default: id' (the ids are
found as in transform estimate: id, point, point_id or name), --weights-col did not say
unitless; camera dlt estimate --output-params did not say which commands read it."""

from __future__ import annotations

import pytest


def _help(cli, *command) -> str:
    code, out, _ = cli(*command, "--help")
    assert code == 0
    return " ".join(out.split())


@pytest.mark.parametrize("text", [
    "Std. dev. of the source coordinates, in source units",
    "Std. dev. of the target coordinates, in target units (--unit)",
    "Id column (default: id, point, point_id or name)",
    "Column of per-point weights (unitless",
])
def test_orient_absolute_help(cli, text):
    assert text in _help(cli, "orient", "absolute")


def test_dlt_output_params_names_its_readers(cli):
    h = _help(cli, "camera", "dlt", "estimate")
    assert "'camera dlt convert --params'" in h and "orient intersection" in h
