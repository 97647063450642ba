"""NaN / inf in a comma-separated option reached the library, which named its own
argument ('origin lat0=nan', 'scales must be ...', 'origin_px must be ...', '--spacing' for
--spacings, 'exterior orientation kappa is NaN'). Now refused by the option's name."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def pts(tmp_path: Path) -> Path:
    p = tmp_path / "g.csv"
    p.write_text("id,X,Y,Z\nA,1300,650,169\n")
    return p


CASES = [
    (["camera", "project", "{pts}", "--f", "152", "--eo", "1,2,3,4,5,-inf"],
     "--eo X0,Y0,Z0,omega,phi,kappa"),
    (["camera", "project", "{pts}", "--f", "152", "--unit", "px", "--principal-point", "nan,3",
      "--eo", "1000,800,1600,2,3,10"], "--principal-point"),
    (["camera", "dlt", "convert", "--dlt", "1,2,3,4,5,6,7,8,9,10,nan"], "--dlt L1,...,L11"),
    (["crs", "convert", "{pts}", "--from", "EPSG:4979", "--to", "enu", "--origin", "nan,8,0"],
     "--origin"),
    (["grid", "sweep", "--preset", "FC300S", "--spacings", "nan,100"], "--spacings"),
    (["orient", "resection", "{pts}", "{pts}", "--f", "152", "--initial", "1,2,3,4,5,inf"],
     "--initial"),
]


@pytest.mark.parametrize(("args", "option"), CASES, ids=[c[1] for c in CASES])
def test_non_finite_numbers_name_the_option(cli, pts, args, option):
    code, _, err = cli(*[a.format(pts=pts) for a in args])
    assert code == 2
    assert err.startswith(f"error: {option}: ") and "is not a finite number" in err, err


def test_finite_numbers_still_pass(cli, pts):
    code, out, err = cli("camera", "project", pts, "--f", "152.14", "--x0", "0.008", "--y0",
                         "-0.12", "--eo", "1114,862,1600,2,3,10")
    assert code == 0, err
    assert "A,22.7354" in out
