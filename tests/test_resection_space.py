"""Space resection: P3P, collinearity adjustment, self-calibration, Monte-Carlo statistics."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, InputError, TooFewPointsError

KINDS = ("nadir", "oblique", "close-range")


def make_case(kind: str, n: int, rng: np.random.Generator):
    """A random camera and n control points visible in its image (noise-free)."""
    if kind == "nadir":
        io = pg.InteriorOrientation(153.0, 0.01, -0.02)
        ang = [*np.radians(rng.uniform(-5, 5, 2)), rng.uniform(-np.pi, np.pi)]
        eo = pg.ExteriorOrientation(*rng.uniform(0, 2000, 2), rng.uniform(1200, 1800), *ang)
        depth = (eo.Z0 - 300.0, eo.Z0)
    elif kind == "oblique":
        io = pg.InteriorOrientation(100.0, -0.05, 0.03, distortion=pg.BrownDistortion(k1=-0.02))
        ang = [*np.radians(rng.uniform(-45, 45, 2)), rng.uniform(-np.pi, np.pi)]
        eo = pg.ExteriorOrientation(*rng.uniform(-500, 500, 2), rng.uniform(300, 800), *ang)
        depth = (300.0, 1500.0)
    else:  # close range: metres, any heading and roll, steep pitch
        io = pg.InteriorOrientation.digital(4000.0, 3000.0, 2000.0, fy=3990.0)
        ang = [
            rng.uniform(-np.pi, np.pi),
            np.radians(rng.uniform(-80, 80)),
            rng.uniform(-np.pi, np.pi),
        ]
        eo = pg.ExteriorOrientation(*rng.uniform(-10, 10, 3), *ang)
        depth = (2.0, 12.0)
    lim = 0.45 if io.unit == "mm" else 0.7
    xn = rng.uniform(-lim, lim, (n, 2))
    d = rng.uniform(*depth, n)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * d[:, None]
    ground = eo.position + pc @ eo.matrix
    return io, eo, ground, pg.project(ground, io, eo)


def assert_same_orientation(a: pg.ExteriorOrientation, b: pg.ExteriorOrientation, scale: float):
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-7 * scale)
    np.testing.assert_allclose(a.matrix, b.matrix, rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("n", [4, 6, 20])
def test_recovers_random_orientations_without_start_values(kind, n):
    rng = np.random.default_rng(100 * KINDS.index(kind) + n)
    for _ in range(4):
        io, eo, g, xy = make_case(kind, n, rng)
        fit = pg.space_resection(g, xy, io)
        assert fit.converged
        assert_same_orientation(fit.exterior, eo, np.linalg.norm(g[0] - eo.position))
        assert fit.rmse < 1e-8 * max(io.f, 1.0)
        assert fit.redundancy == 2 * n - 6


@pytest.mark.parametrize("kind", KINDS)
def test_three_points_with_start_values(kind):
    rng = np.random.default_rng(len(kind))
    for _ in range(4):
        io, eo, g, xy = make_case(kind, 3, rng)
        scale = np.linalg.norm(g - eo.position, axis=1).mean()
        start = pg.ExteriorOrientation(
            *(eo.position + rng.normal(0, 0.02 * scale, 3)),
            *(eo.angles + np.radians(rng.normal(0, 1, 3))),
        )
        fit = pg.space_resection(g, xy, io, initial=start)
        assert fit.redundancy == 0 and np.isnan(fit.sigma0)
        assert_same_orientation(fit.exterior, eo, scale)
        # the closed-form P3P has the true orientation among its (up to four) solutions
        sols = pg.p3p(g, xy, io)
        assert 1 <= len(sols) <= 4
        assert min(np.abs(s.matrix - eo.matrix).max() for s in sols) < 1e-6


def test_three_points_without_start_values_are_ambiguous_or_unique():
    rng = np.random.default_rng(5)
    io, _, g, xy = make_case("oblique", 3, rng)
    n_sol = len(pg.p3p(g, xy, io))
    if n_sol > 1:
        with pytest.raises(InputError, match=r"admit \d exterior orientations"):
            pg.space_resection(g, xy, io)
    else:  # pragma: no cover - depends on the random geometry
        pg.space_resection(g, xy, io)


def test_self_calibration_recovers_interior_orientation():
    rng = np.random.default_rng(8)
    io_true = pg.InteriorOrientation(
        4000.0, 12.0, -7.0, unit="px", distortion=pg.BrownDistortion(k1=-0.08, k2=0.02)
    )
    eo = pg.ExteriorOrientation.from_degrees(0.5, -8.0, 6.0, 20.0, 15.0, 30.0)
    xn = rng.uniform(-0.7, 0.7, (60, 2))
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(60)]) * rng.uniform(3, 12, (60, 1))
    g = eo.position + pc @ eo.matrix
    xy = pg.project(g, io_true, eo)
    io_start = pg.InteriorOrientation(3900.0, unit="px")
    fit = pg.space_resection(g, xy, io_start, calibrate=("f", "x0", "y0", "k1", "k2"))
    assert fit.interior.f == pytest.approx(4000.0, rel=1e-9)
    assert fit.interior.x0 == pytest.approx(12.0, abs=1e-6)
    assert fit.interior.distortion.k1 == pytest.approx(-0.08, rel=1e-7)
    assert fit.parameter_units["k1"] == "1" and fit.parameter_units["f"] == "px"
    assert_same_orientation(fit.exterior, eo, 10.0)


def test_self_calibration_on_flat_nadir_control_is_refused():
    io = pg.InteriorOrientation(100.0)
    eo = pg.ExteriorOrientation(0.0, 0.0, 1000.0)
    rng = np.random.default_rng(9)
    g = np.column_stack([rng.uniform(-400, 400, (20, 2)), np.zeros(20)])
    xy = pg.project(g, io, eo)
    with pytest.raises(DegenerateGeometryError, match="undetermined"):
        pg.space_resection(g, xy, io, initial=eo, calibrate=("f",))


def test_bad_input():
    rng = np.random.default_rng(10)
    io, _, g, xy = make_case("nadir", 6, rng)
    with pytest.raises(TooFewPointsError, match="at least 3"):
        pg.space_resection(g[:2], xy[:2], io)
    with pytest.raises(TooFewPointsError, match="at least 6"):
        pg.space_resection(g[:5], xy[:5], io, calibrate=("f", "x0", "y0", "k1", "k2", "p1"))
    with pytest.raises(InputError, match="calibrate"):
        pg.space_resection(g, xy, io, calibrate=("focal",))
    with pytest.raises(InputError, match="correspond"):
        pg.space_resection(g, xy[:5], io)
    with pytest.raises(InputError, match="NaN"):
        pg.space_resection(g, np.where(np.arange(12).reshape(6, 2) == 3, np.nan, xy), io)


def test_pixel_input_and_check_points():
    rng = np.random.default_rng(12)
    io, eo, g, xy = make_case("close-range", 12, rng)
    pix = io.image_to_pixel(xy)
    fit = pg.space_resection(
        g[:8],
        pix[:8],
        io,
        system="pixel",
        ids=list("abcdefgh"),
        check_ground=g[8:],
        check_image=pix[8:],
        check_ids=["w", "x", "y", "z"],
    )
    assert fit.ids == tuple("abcdefgh") and fit.check_residuals.shape == (4, 2)
    assert fit.check_rmse < 1e-7
    assert_same_orientation(fit.exterior, eo, 10.0)
    assert fit.camera.project(g[0]).shape == (2,)


@pytest.mark.parametrize("kind", ["nadir", "close-range"])
def test_standard_deviations_match_monte_carlo(kind):
    rng = np.random.default_rng(2024 if kind == "nadir" else 7)
    io, eo, g, xy = make_case(kind, 10, rng)
    io = io.with_distortion(None)
    xy = pg.project(g, io, eo)
    sigma = 0.004 if io.unit == "mm" else 0.5
    ref = pg.space_resection(g, xy, io, initial=eo, sigma=sigma)
    sd = np.array([ref.std_errors_prior[n] for n in ref.parameter_names])
    trials = 1000
    obs = xy + rng.normal(0.0, sigma, (trials, *xy.shape))
    batch = pg.space_resection_batch(g, obs, io, eo, sigma=sigma)
    assert batch.converged.all()
    spread = batch.parameters.std(axis=0, ddof=1)
    spread[3:] = np.angle(np.exp(1j * (batch.parameters[:, 3:] - eo.angles))).std(axis=0, ddof=1)
    np.testing.assert_allclose(spread / sd, 1.0, atol=0.10)
    # sigma0 is an unbiased estimate of the a-priori 1 on average
    assert np.mean(batch.sigma0**2) == pytest.approx(1.0, abs=0.05)
    # the batched solver and the Gauss-Markov engine agree on individual trials
    for i in (0, 1):
        one = pg.space_resection(g, obs[i], io, initial=eo, sigma=sigma)
        np.testing.assert_allclose(
            one.parameters, batch.parameters[i], rtol=0, atol=1e-6 * np.abs(sd).max()
        )
        np.testing.assert_allclose(one.cofactor, batch.cofactor[i], rtol=1e-6)
        assert one.sigma0 == pytest.approx(batch.sigma0[i], rel=1e-6)


def test_batch_input_checks():
    rng = np.random.default_rng(1)
    io, eo, g, xy = make_case("nadir", 6, rng)
    with pytest.raises(InputError, match="shape"):
        pg.space_resection_batch(g, xy, io, eo)
    res = pg.space_resection_batch(np.stack([g, g]), np.stack([xy, xy]), io, eo.parameters)
    np.testing.assert_allclose(res.parameters[1], eo.parameters, atol=1e-8)
    assert res.exterior(0).X0 == pytest.approx(eo.X0)
