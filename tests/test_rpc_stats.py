"""Terrain-dependent RPCs of order 2 and 3 from noisy control points: a fit whose
denominator nearly vanishes inside the points' box is refused with the fix named;
the suggested larger regularization gives a usable RPC."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from photogeom.errors import DegenerateGeometryError
from photogeom.io import write_points
from photogeom.rpc import fit_rpc_to_points
from photogeom.rpc.fitting import NOISY_REGULARIZATION, UnstableFitError

sys.path.insert(0, str(Path(__file__).parent))
from rpc_samples import ikonos_points


@pytest.mark.parametrize(("order", "n", "seed"), [(2, 25, 0), (2, 40, 2), (3, 45, 0)])
def test_unstable_noisy_fit_is_refused(order, n, seed):
    """Before: returned with check RMSEs of 7-360 px (errors up to 7000 px) for 0.5 px
    noise, sigma0 0.4-0.8, and only a note about the denominator (20 fits per case)."""
    rng = np.random.default_rng(seed)
    G, im = ikonos_points(rng, n)
    noisy = im + rng.normal(0, 0.5, im.shape)
    with pytest.raises(UnstableFitError, match=r"unstable fit .* regularization .*0\.001") as e:
        fit_rpc_to_points(G, noisy, order=order, sigma=0.5)
    assert isinstance(e.value, DegenerateGeometryError)
    assert "lower order" in str(e.value)


def test_the_suggested_regularization_fits_noisy_points():
    rng = np.random.default_rng(3)
    G, im = ikonos_points(rng, 40)
    gc, ic = ikonos_points(rng, 300)
    noisy = im + rng.normal(0, 0.5, im.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a few check points just outside the box
        fit = fit_rpc_to_points(
            G, noisy, order=2, sigma=0.5, regularization=NOISY_REGULARIZATION,
            check_ground=gc, check_image=ic,
        )  # fmt: skip
    assert fit.extras["min_denominator"] > 0.5
    assert fit.check_rmse < 2.0  # 0.5 px noise on the control points


def test_noise_free_points_still_fit_order_3():
    rng = np.random.default_rng(5)
    G, im = ikonos_points(rng, 45)
    fit = fit_rpc_to_points(G, im, order=3)
    assert fit.rmse < 1e-3


def test_cli_names_its_options(cli, tmp_path):
    rng = np.random.default_rng(0)
    G, im = ikonos_points(rng, 25)
    im = im + rng.normal(0, 0.5, im.shape)
    p = tmp_path / "noisy.csv"
    write_points(p, [f"P{i}" for i in range(25)], np.column_stack([G, im]),
                 ["lon", "lat", "h", "col", "row"])  # fmt: skip
    code, _, err = cli("rpc", "fit", p, "--order", "2", "--sigma", "0.5")
    assert code != 0
    assert "unstable fit" in err and "--regularization" in err and "--order" in err


def test_sigma0_of_a_regularised_fit_uses_its_effective_redundancy():
    """Before: v'Pv / (2n - u) although the penalty holds part of the coefficients: mean
    sigma0 1.06 (order 2, 40 points) and 1.09 (order 3, 80 points) over 100 redraws of
    0.5 px noise with regularization 1e-3; now 0.99 for both (2n - tr(H))."""
    G, im = ikonos_points(np.random.default_rng(240), 80)
    rng = np.random.default_rng(7)
    s0 = []
    for _ in range(30):
        noisy = im + rng.normal(0, 0.5, im.shape)
        fit = fit_rpc_to_points(G, noisy, order=3, sigma=0.5, regularization=1e-3)
        s0.append(fit.sigma0)
    # 30 fits: the mean sigma0 scatters by about 0.015
    assert np.mean(s0) == pytest.approx(1.0, abs=0.045)
    r = fit.redundancy
    assert r == 2 * 80 - 78 and r < fit.extras["effective_redundancy"] < 2 * 80
    # a negligible penalty holds (almost) nothing
    one = fit_rpc_to_points(G, noisy, order=1, sigma=0.5)
    assert one.extras["effective_redundancy"] == pytest.approx(one.redundancy, abs=1e-6)
