"""write_calibration with both ``std`` and ``covariance``: they must agree.

Before: the covariance silently replaced the standard deviations given (the docstring said
the covariance gives them only where ``std`` does not): ``std={"f": 0.1235}`` with a
covariance whose f variance is 0.9 was written, and read back, as std f = 0.9487.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import photogeom as pg
from photogeom.camera.calibration_files import read_calibration_file, write_calibration
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import InputError

CAL = MetashapeCalibration(width=4000, height=3000, f=3000.5, cx=1.5, cy=-2.0, k1=0.01)
COV = (("f", "cx"), np.array([[0.9, 0.1], [0.1, 0.4]]))


@pytest.mark.parametrize("suffix", ["json", "xml", "yaml"])
def test_disagreeing_std_is_refused(tmp_path, suffix):
    with pytest.raises(InputError, match=r"std of f is 0\.1235 but the covariance gives 0\.948"):
        write_calibration(CAL, tmp_path / f"c.{suffix}", std={"f": 0.1235}, covariance=COV)
    assert not (tmp_path / f"c.{suffix}").exists()


def test_std_and_covariance_of_one_adjustment_read_back(tmp_path):
    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)
    fit = pg.bundle_adjust(sim.block)
    g = fit.block.camera_ids.tolist()[0]
    names, C = fit.calibration_covariance(g)
    write_calibration(fit.block.cameras[g], tmp_path / "c.json",
                      std=fit.calibration_std[g], covariance=(names, C))  # fmt: skip
    _, std, cov = read_calibration_file(tmp_path / "c.json")
    assert cov[0] == names and np.array_equal(cov[1], C)
    given = {n: v for n, v in fit.calibration_std[g].items() if math.isfinite(v)}
    assert std == given and set(given) == set(names)


def test_std_alone_and_covariance_alone(tmp_path):
    write_calibration(CAL, tmp_path / "a.json", std={"f": 0.1235, "cx": math.nan, "k1": 1e-5})
    assert read_calibration_file(tmp_path / "a.json")[1] == {"f": 0.1235, "k1": 1e-5}
    write_calibration(CAL, tmp_path / "b.json", covariance=COV)
    assert read_calibration_file(tmp_path / "b.json")[1] == {
        "f": math.sqrt(0.9), "cx": math.sqrt(0.4)
    }
    # std for a parameter the covariance does not name: kept beside it
    write_calibration(CAL, tmp_path / "c.json", std={"k1": 1e-5}, covariance=COV)
    assert read_calibration_file(tmp_path / "c.json")[1] == {
        "f": math.sqrt(0.9), "cx": math.sqrt(0.4), "k1": 1e-5
    }
