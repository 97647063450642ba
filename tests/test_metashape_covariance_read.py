"""The ``<covariance>`` of a Metashape calibration XML as read back: a malformed one
(an unknown term in ``<params>``, an asymmetric matrix, a negative variance) is refused by
name instead of being read as it stands or with the unknown term dropped; a well-formed one
comes back from ``read_calibration_file`` as written, with its standard deviations (before:
none for an XML)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.camera.calibration_files import (
    METASHAPE_ORDER,
    PARAMETERS,
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


# --- round trip: write_calibration (.xml) -> read_calibration_file -------------------------

#: Typical standard deviations of each parameter (px for f, cx, cy, b1, b2; unitless else).
_SCALE = {"f": 2.0, "cx": 0.8, "cy": 0.9, "b1": 0.3, "b2": 0.1, "k1": 1e-3, "k2": 1e-3,
          "k3": 1e-4, "k4": 1e-5, "p1": 1e-5, "p2": 2e-5}  # fmt: skip
_NO_OPENCV = ("b1", "b2", "k4")  # OpenCV's std_deviations_intrinsics cannot hold them alone


@settings(max_examples=40, deadline=None)
@given(
    names=st.lists(st.sampled_from(PARAMETERS), min_size=1, max_size=11, unique=True),
    seed=st.integers(0, 2**32 - 1),
)
def test_round_trip_keeps_covariance_and_gives_std(tmp_path_factory, names, seed):
    rng = np.random.default_rng(seed)
    n = len(names)
    A = rng.normal(size=(n, n))
    s = np.array([_SCALE[v] for v in names])
    C = (A @ A.T + 0.1 * np.eye(n)) * np.outer(s, s)  # symmetric positive definite
    d = tmp_path_factory.mktemp("rt")
    pg.write_calibration(CAL, d / "c.xml", covariance=(names, C))
    cal, std, (got, G) = read_calibration_file(d / "c.xml")
    assert cal == CAL
    assert list(got) == [v for v in METASHAPE_ORDER if v in names]  # Metashape's order
    idx = [names.index(v) for v in got]
    np.testing.assert_array_equal(G, C[np.ix_(idx, idx)])  # 17 digits: exact
    assert set(std) == set(names)
    for k, v in enumerate(names):
        assert std[v] == pytest.approx(np.sqrt(C[k, k]), rel=1e-15)
    # Metashape's p1, p2 are photogeom's (no swap); OpenCV's are swapped. The OpenCV YAML of
    # the same covariance, read by cv2.FileStorage, gives the same standard deviations
    if not set(names) & set(_NO_OPENCV):
        pg.write_calibration(CAL, d / "c.yaml", covariance=(names, C))
        _, std_cv, _ = read_calibration_file(d / "c.yaml")
        assert set(std_cv) == set(std)
        for v in std:
            assert std_cv[v] == pytest.approx(std[v], rel=1e-12)


def test_xml_without_covariance_has_no_std(tmp_path):
    pg.write_calibration(CAL, tmp_path / "c.xml")
    assert read_calibration_file(tmp_path / "c.xml")[1:] == ({}, None)
