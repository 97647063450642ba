"""The ``<covariance>`` of a Metashape calibration XML as read back: a malformed one
(an unknown term in ``<params>``, an asymmetric matrix, a negative variance) is refused by
name instead of being read as it stands or with the unknown term dropped."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.camera.calibration_files import (
    metashape_covariance_from_xml,
    read_calibration_file,
)

CAL = pg.MetashapeCalibration(4000, 3000, 3500.0, cx=3.0, cy=-2.0, k1=-0.1, p1=1e-4, p2=-2e-4)


def _xml(params: str, coeffs: str) -> str:
    return CAL.to_xml_string().replace(
        "</calibration>",
        f"<covariance><params>{params}</params><coeffs>{coeffs}</coeffs></covariance>"
        "</calibration>",
    )


@pytest.mark.parametrize(
    ("params", "coeffs", "match"),
    [
        ("f foo", "1 0 0 2", r"names foo, not parameters"),  # before: foo dropped silently
        ("f fx", "1 0 0 2", r"names fx, not parameters"),
        ("f cx", "1 0.5 0.4 2", r"not symmetric: entry \(f, cx\) is 0.5 but \(cx, f\) is 0.4"),
        ("f cx", "-1 0 0 2", r"variance of f is negative \(-1.0\)"),
        ("f cx", "1 0 0 -2", r"variance of cx is negative \(-2.0\)"),
        ("f f", "1 0 0 1", r"distinct"),
        ("f cx", "1 0 0", r"3 finite <coeffs> for 2 <params>; expected 4"),
    ],
)
def test_malformed_covariance_is_refused_by_name(tmp_path, params, coeffs, match):
    with pytest.raises(pg.FileFormatError, match=match):
        metashape_covariance_from_xml(_xml(params, coeffs))
    path = tmp_path / "cal.xml"
    path.write_text(_xml(params, coeffs))
    with pytest.raises(pg.FileFormatError, match=match):
        read_calibration_file(path)


def test_rounding_asymmetry_and_zero_variance_are_accepted():
    # 17 significant digits of a symmetric matrix read back exactly; a tiny asymmetry (far
    # below 1e-9 of sqrt(var_i var_j)) and a zero variance (a parameter held) are kept
    names, C = metashape_covariance_from_xml(_xml("f cx p3", "4 0.5 0 0.5000000000001 1 0 0 0 0"))
    assert names == ("f", "cx")
    np.testing.assert_array_equal(C, [[4.0, 0.5], [0.5000000000001, 1.0]])


def test_cli_convert_names_the_bad_covariance(cli, tmp_path):
    src = tmp_path / "cal.xml"
    src.write_text(_xml("f cx", "1 0.5 0.4 2"))
    code, _, err = cli("camera", "convert", src, tmp_path / "cal.json")
    assert code != 0 and "not symmetric" in err and "(f, cx)" in err
    assert not (tmp_path / "cal.json").exists()


@pytest.mark.parametrize("suffix", [".xml", ".json", ".yaml"])
def test_writer_refuses_what_the_reader_refuses(tmp_path, suffix):
    with pytest.raises(pg.InputError, match="not symmetric"):
        pg.write_calibration(
            CAL, tmp_path / f"c{suffix}", covariance=(("f", "cx"), [[1.0, 0.5], [0.4, 2.0]])
        )
    with pytest.raises(pg.InputError, match="variance of cx is negative"):
        pg.write_calibration(
            CAL, tmp_path / f"c{suffix}", covariance=(("f", "cx"), [[1.0, 0.0], [0.0, -2.0]])
        )
    assert not any(tmp_path.iterdir())
