"""`orient absolute --method gauss-helmert --initial X` always failed ("initial
values apply to the iterative adjustment; pass iterate=True"): the command did not ask the
library for the iterative adjustment its --initial starts."""

from __future__ import annotations

import json

import pytest

from photogeom import datasets

LIDAR = str(datasets.path("lidar_wang2014"))


@pytest.mark.parametrize("initial", ["zeros", "svd"])
def test_gauss_helmert_with_initial_iterates_to_the_direct_solution(cli, initial):
    code, out, err = cli("orient", "absolute", LIDAR, "-m", "gauss-helmert", "--json")
    assert code == 0, err
    direct = json.loads(out)
    code, out, err = cli("orient", "absolute", LIDAR, "-m", "gauss-helmert", "--initial",
                         initial, "--json")
    assert code == 0, err
    it = json.loads(out)
    assert it["iterations"] > 0 and it["converged"]
    assert it["sigma0"] == pytest.approx(direct["sigma0"], rel=1e-9)
    for k in ("tx", "ty", "tz", "scale", "omega", "phi", "kappa"):
        assert it["parameters"][k]["value"] == pytest.approx(
            direct["parameters"][k]["value"], rel=1e-8, abs=1e-9)
