"""The smooth second component of the simulated local field (``local_field_smooth``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration.grid import fit_grid
from photogeom.errors import InputError
from photogeom.simulate.fields import LocalDistortionField

#: ILCE-7RM2 image size, px
W, H = 7952, 5304

#: Blocks of the presets (seed 3, 2 x 3 images, 40 tie points per image) as the simulator
#: drew them before the smooth component existed: observations (count, sum, sum of squares,
#: last row) and the sum of squares of the local field, px.
PINNED = {
    "ILCE-7RM2": (
        274,
        1991536.8088128448,
        9524421835.358498,
        (6230.9726573689195, 5215.725430860414),
        263.5036348751057,
    ),
    "FC6310": (
        337,
        1521355.6477652374,
        4399182995.664951,
        (2964.750659188767, 2918.299398439804),
        5.825100856054525,
    ),
    "FC300S": (
        355,
        1325070.4021746549,
        3152090080.9151134,
        (2443.3067857285746, 2359.936110457414),
        6.183468397934444,
    ),
}


@pytest.mark.parametrize("camera", sorted(PINNED))
def test_without_a_smooth_component_the_presets_draw_the_same_blocks(camera):
    """The default (0) draws nothing more: every preset's observations are those of before."""
    n, total, squares, last, local2 = PINNED[camera]
    for kw in ({}, {"local_field_smooth": 0.0}):
        s = pg.simulate.uav_block(
            camera, seed=3, strips=2, images_per_strip=3, tie_points_per_image=40, **kw
        )
        o = s.observed
        assert o.shape[0] == n
        assert float(o.sum()) == pytest.approx(total, rel=1e-13)
        assert float(np.sum(o * o)) == pytest.approx(squares, rel=1e-13)
        np.testing.assert_allclose(o[-1], last, rtol=1e-14)
        assert float(np.sum(s.local**2)) == pytest.approx(local2, rel=1e-12)
        assert s.field.smooth == 0.0 and s.options["local_field_smooth"] == 0.0


def _mean_square(F: LocalDistortionField) -> float:
    """Mean over images and a 40 x 30 pixel grid of the squared displacement length, px^2."""
    gu, gv = np.meshgrid(np.linspace(0.0, W - 1, 40), np.linspace(0.0, H - 1, 30))
    uv = np.column_stack([gu.ravel(), gv.ravel()])
    m = F.image_ids.size
    d = F.rows(np.repeat(np.arange(m), uv.shape[0]), np.tile(uv, (m, 1)))
    return float(np.mean(np.sum(d**2, axis=1)))


def _coef_mean_square(coef: np.ndarray) -> float:
    """Mean over images of the squared displacement length over the whole image, px^2: half
    the sum of the squared coefficients (the waves are orthogonal over the image)."""
    return float(np.sum(coef**2) / (2 * coef.shape[0]))


def test_the_smooth_components_rms_is_the_mean_over_the_image():
    """Drawn alone over 120 images from each of five seeds, the mean square length over a
    pixel grid is smooth**2 (within 5 %) and agrees with the coefficients' (within 2 %)."""
    ms, mc = [], []
    for seed in range(5):
        F = LocalDistortionField.random(
            np.random.default_rng(seed), np.arange(120), W, H, rms=0.0, smooth=0.8
        )
        ms.append(_mean_square(F))
        mc.append(_coef_mean_square(F.coef))
    assert np.mean(ms) == pytest.approx(0.64, rel=0.05)
    assert np.mean(ms) == pytest.approx(np.mean(mc), rel=0.02)


@pytest.mark.parametrize(("rms", "smooth"), [(0.0, 0.8), (0.6, 0.8), (0.3, 0.95)])
def test_the_components_have_the_requested_rms(rms, smooth):
    """Over 5 x 4000 independent images the mean square length is rms**2 + smooth**2 and that
    of the smooth part alone (the field minus the first component drawn from the same seed)
    smooth**2, within 2 %."""
    total, part = [], []
    for seed in range(5):
        kw = dict(rms=rms, modes=6, correlation=0.0)
        ids = np.arange(4000)
        F = LocalDistortionField.random(np.random.default_rng(seed), ids, W, H, smooth=smooth, **kw)
        F0 = LocalDistortionField.random(np.random.default_rng(seed), ids, W, H, **kw)
        assert F.total_rms == pytest.approx(np.hypot(rms, smooth))
        total.append(_coef_mean_square(F.coef))
        first = F0.coef if rms > 0 else 0.0
        part.append(_coef_mean_square(F.coef - first))
    assert np.mean(total) == pytest.approx(rms**2 + smooth**2, rel=0.02)
    assert np.mean(part) == pytest.approx(smooth**2, rel=0.02)


def test_the_smooth_component_lies_in_the_four_longest_waves_and_coefficient_std_says_so():
    """Drawn alone it has only the waves with max(|kx|, |ky|) <= 1; beside a first
    component, the coefficients' spread over 4000 images is ``coefficient_std`` (the root sum
    of squares of both), which ``field_bound`` takes as the prior."""
    F = LocalDistortionField.random(
        np.random.default_rng(1), np.arange(5), W, H, rms=0.0, smooth=1.0
    )
    assert sorted(map(tuple, F.waves.tolist())) == [(0, 1), (1, -1), (1, 0), (1, 1)]
    F = LocalDistortionField.random(
        np.random.default_rng(2),
        np.arange(4000),
        W,
        H,
        rms=0.5,
        modes=3,
        correlation=0.0,
        smooth=0.8,
    )
    spread = np.concatenate(
        [F.coef[:, :, 0, :].std(axis=(0, 2)), F.coef[:, :, 1, :].std(axis=(0, 2))]
    )
    np.testing.assert_allclose(spread, F.coefficient_std(), rtol=0.05)
    long = np.max(np.abs(F.waves), axis=1) <= 1
    first = LocalDistortionField.random(
        np.random.default_rng(2), np.arange(4000), W, H, rms=0.5, modes=3, correlation=0.0
    ).coefficient_std()
    std = F.coefficient_std()
    assert np.all(std[np.tile(long, 2)] > first[np.tile(long, 2)])
    np.testing.assert_array_equal(std[~np.tile(long, 2)], first[~np.tile(long, 2)])


@pytest.mark.parametrize(("correlation", "static"), [(0.9, 0.0), (0.6, 0.3)])
def test_the_smooth_component_is_image_variant_with_the_fields_correlation(correlation, static):
    """Its coefficients (first component 0) are correlated between images 0 and ``lag`` as
    ``(1 - static) correlation**lag + static`` (``image_covariance``), over 300 blocks of 4
    images; consecutive images differ."""
    rng = np.random.default_rng(4)
    c = np.stack(
        [
            LocalDistortionField.random(
                rng,
                np.arange(4),
                W,
                H,
                rms=0.0,
                smooth=1.0,
                correlation=correlation,
                static=static,
            ).coef.reshape(4, -1)
            for _ in range(300)
        ]
    )  # (draws, images, coefficients)
    for lag in (1, 3):
        a, b = c[:, 0], c[:, lag]
        r = float(np.mean(a * b) / np.sqrt(np.mean(a * a) * np.mean(b * b)))
        expect = (1.0 - static) * correlation**lag + static
        assert r == pytest.approx(expect, abs=0.04)
    assert not np.allclose(c[:, 0], c[:, 1])


def test_the_smooth_component_is_what_a_coarse_grid_recovers():
    """A 2000 px grid fitted to the noise-free residuals (2000 points) of the smooth component
    recovers it to under 35 % of its RMS in every image; the preset's field (1 / |k|, wave
    numbers up to 6) leaves more than 60 %."""

    def ratio(**kw) -> np.ndarray:
        rng = np.random.default_rng(6)
        F = LocalDistortionField.random(rng, np.arange(3), W, H, **kw)
        uv = np.column_stack([rng.uniform(0, W - 1, 2000), rng.uniform(0, H - 1, 2000)])
        out = []
        for i in range(3):
            d = F.rows(np.full(2000, i), uv)
            g = fit_grid(uv, -d, (W, H), 2000, sigma_obs=0.3, sigma_constraint=40.0, folds=0)
            e = g.evaluate(uv) + d
            out.append(np.sqrt(np.mean(np.sum(e**2, 1)) / np.mean(np.sum(d**2, 1))))
        return np.array(out)

    assert np.all(ratio(rms=0.0, smooth=1.0) < 0.35)
    assert np.all(ratio(rms=1.0) > 0.6)


def test_the_simulated_block_carries_the_smooth_component():
    """``uav_block(local_field_smooth=...)``: the field, ``local`` and the observations
    include it; options and summary state it; the observations minus the ideal pixels and
    the noise are the field at the ideal pixels."""
    kw = dict(strips=2, images_per_strip=3, tie_points_per_image=60)
    s = pg.simulate.uav_block("ILCE-7RM2", seed=5, local_field=0.4, local_field_smooth=0.9, **kw)
    assert s.field.smooth == 0.9 and s.field.rms == 0.4
    assert s.options["local_field_smooth"] == 0.9
    assert "smooth 0.9 px" in s.summary()
    np.testing.assert_allclose(s.local_field(s.block.obs_image, s.ideal), s.local, atol=1e-12)
    np.testing.assert_allclose(s.observed - s.ideal - s.noise, s.local, atol=1e-9)
    s0 = pg.simulate.uav_block("ILCE-7RM2", seed=5, local_field=0.4, **kw)
    # the first component is the same draw: the smooth one is what the two blocks differ by
    assert s0.field.coef.shape == s.field.coef.shape
    long = np.max(np.abs(s.field.waves), axis=1) <= 1
    np.testing.assert_array_equal(s.field.coef[:, ~long], s0.field.coef[:, ~long])
    assert not np.allclose(s.field.coef[:, long], s0.field.coef[:, long])
    only = pg.simulate.uav_block("ILCE-7RM2", seed=5, local_field=0.0, local_field_smooth=0.9, **kw)
    assert only.field.waves.shape == (4, 2) and np.any(only.local != 0)


def test_field_bound_takes_the_smooth_component_into_its_prior():
    """Fields with both components drawn again 20 times, geometry kept: the best
    estimator's error spread matches the expected error computed from the prior with both
    components, and the expected field RMS is sqrt(rms**2 + smooth**2)."""
    sim = pg.simulate.uav_block(
        "FC300S",
        seed=11,
        strips=2,
        images_per_strip=3,
        tie_points_per_image=80,
        local_field=0.3,
        local_field_modes=2,
        local_field_smooth=0.6,
    )
    F0, b = sim.field, sim.block
    expected = pg.calibration.field_bound(sim)
    assert expected["field_rms"] == pytest.approx(np.hypot(0.3, 0.6), rel=0.02)
    rng = np.random.default_rng(5)
    sigma = b.observations.sigma
    err2 = []
    for _ in range(20):
        F = LocalDistortionField.random(
            rng, F0.image_ids, F0.width, F0.height, rms=0.3, modes=2, correlation=0.9, smooth=0.6
        )
        local = F.rows(b.obs_image, sim.ideal)
        noise = rng.normal(0.0, 1.0, sim.ideal.shape) * sigma[:, None]
        r = pg.calibration.field_bound(dataclasses.replace(sim, field=F, local=local, noise=noise))
        err2.append(r["error_rms"] ** 2)
    e_exp = expected["expected_ratio"] * expected["field_rms"]
    assert np.sqrt(np.mean(err2)) == pytest.approx(e_exp, rel=0.08)
    only = pg.simulate.uav_block(
        "FC300S",
        seed=11,
        strips=2,
        images_per_strip=3,
        tie_points_per_image=150,
        local_field=0.0,
        local_field_smooth=0.6,
    )
    assert 0.0 < pg.calibration.field_bound(only)["expected_ratio"] < 1.0


@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf")])
def test_a_negative_or_non_finite_smooth_rms_is_refused_by_name(value):
    with pytest.raises(InputError, match=r"^local_field_smooth must be >= 0"):
        pg.simulate.uav_block("FC300S", seed=1, local_field_smooth=value)
    with pytest.raises(InputError, match=r"^smooth must be >= 0"):
        LocalDistortionField.random(np.random.default_rng(0), [0, 1], W, H, rms=1.0, smooth=value)
