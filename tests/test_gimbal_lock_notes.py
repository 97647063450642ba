"""Space resection and absolute orientation near phi = +-90 degrees: omega and kappa have
standard deviations inflated by 1 / cos(phi) and correlated to nearly -1 there; the fit
says so in a note (it said nothing while omega's std grew to 57 deg at phi 89.993 deg)."""

import math
import re

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project

IO = InteriorOrientation(f=35.0, unit="mm")
UTM = np.array([500000.0, 5000000.0, 300.0])


def _resection(phi_deg: float):
    rng = np.random.default_rng(0)
    eo = ExteriorOrientation(-300.0, 0.0, 20.0, 0.3, math.radians(phi_deg), -0.2)
    g = eo.position - eo.matrix[2] * 300.0 + rng.uniform(-80, 80, (15, 3))
    im = project(g, IO, eo) + rng.normal(0.0, 0.002, (15, 2))
    return pg.space_resection(g + UTM, im, IO)


def _absolute(phi_deg: float, method: str):
    rng = np.random.default_rng(1)
    x = rng.uniform(-100, 100, (15, 3))
    X = x @ pg.opk_matrix(0.3, math.radians(phi_deg), -0.2) + UTM + rng.normal(0, 0.01, x.shape)
    return pg.absolute_orientation(x, X, method=method)


def _check(fit, note: str):
    phi = fit.params["phi"]
    std = fit.std_errors
    assert f"1/cos(phi) = {1.0 / math.cos(phi):.3g}" in note
    assert f"({math.degrees(std['omega']):.3g} and {math.degrees(std['kappa']):.3g} deg)" in note
    rho = float(re.search(r"correlated ([+-][\d.]+)", note).group(1))
    assert abs(rho) > 0.999


@pytest.mark.parametrize("phi_deg", [89.0, 89.9, -89.99])
def test_resection_near_gimbal_lock_notes_the_inflated_angle_std(phi_deg):
    fit = _resection(phi_deg)
    notes = [n for n in fit.notes if "gimbal lock" in n]
    assert len(notes) == 1
    _check(fit, notes[0])
    assert not any("gimbal lock" in n for n in _resection(80.0).notes)


@pytest.mark.parametrize("method", ["svd", "quaternion", "gauss-markov", "gauss-helmert"])
def test_absolute_orientation_near_gimbal_lock_notes_the_inflated_angle_std(method):
    fit = _absolute(89.9, method)
    notes = [n for n in fit.notes if "gimbal lock" in n]
    assert len(notes) == 1
    _check(fit, notes[0])
    assert not any("gimbal lock" in n for n in _absolute(80.0, method).notes)


@pytest.mark.parametrize("phi_deg", [89.9, -89.99])
def test_dlt_orientation_near_gimbal_lock_notes_the_inflated_angle_std(phi_deg):
    # before: orientation_std() gave omega and kappa +-21..26 deg here, nothing said
    rng = np.random.default_rng(0)
    eo = ExteriorOrientation(-300.0, 0.0, 20.0, 0.3, math.radians(phi_deg), -0.2)
    g = eo.position - eo.matrix[2] * 300.0 + rng.uniform(-80, 80, (15, 3))
    fit = pg.estimate_dlt(g + UTM, project(g, IO, eo) + rng.normal(0.0, 0.002, (15, 2)))
    notes = [n for n in fit.notes if "gimbal lock" in n]
    assert len(notes) == 1
    std = fit.orientation_std()
    assert f"({std['omega']:.3g} and {std['kappa']:.3g} deg)" in notes[0]
    assert f"1/cos(phi) = {1.0 / math.cos(fit.exterior.phi):.3g}" in notes[0]
