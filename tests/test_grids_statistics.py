"""Residual grids, statistics: redundancy and variance components against exact
expectations computed densely and independently of the grid code's trace formulas."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import GridLayout, adjust_with_grids, fit_grid
from photogeom.calibration.in_adjustment import _datum_rows

sys.path.insert(0, str(Path(__file__).parent))
from residual_grids import node_field, observe


def _scattered(rng, n, w, h):
    return np.column_stack([rng.uniform(-0.5, w - 0.5, n), rng.uniform(-0.5, h - 0.5, n)])


def _expected_forms(layout, uv, s_obs, s_c, border):
    """Exact E[v'Pv] and E[w'P_c w] (one component) under the model of the fit: the field
    drawn from the smoothness prior (density ~ exp(-|C z|^2 / 2 s_c^2), flat in the
    constant / bilinear fields, which leave v and C z unchanged), the observations with
    independent noise of s_obs. Dense, with pseudo-inverses; none of the grid's code but
    the design and constraint matrices."""
    A = layout.design_matrix(uv).toarray()
    C = layout.constraint_matrix(border).toarray()
    p = 1.0 / np.asarray(s_obs, float) ** 2 * np.ones(uv.shape[0])
    P = np.diag(p)
    N = A.T @ P @ A + C.T @ C / s_c**2
    Ni = np.linalg.inv(N)
    cov_z = s_c**2 * np.linalg.pinv(C.T @ C)  # the prior on the fields C does not null
    cov_l = A @ cov_z @ A.T + np.diag(1.0 / p)
    K = A @ Ni @ A.T @ P - np.eye(A.shape[0])  # v = K l
    G = C @ Ni @ A.T @ P  # C z_hat = G l
    e_o = float(np.trace(K.T @ P @ K @ cov_l))
    e_c = float(np.trace(G.T @ G @ cov_l)) / s_c**2
    return e_o, e_c


@pytest.mark.parametrize("border", ["mean", "linear"])
def test_redundancy_is_the_expected_weighted_square_sum(border):
    """sigma0^2 = (v'Pv + w'P_c w) / r is unbiased only if r is the expectation of the sum
    under the model. With border="mean" the n_nodes constraint rows have one dependency
    (their degree-weighted sum is zero for every field): the redundancy was 2 (n + n_nodes
    - n_nodes) = 2 n, 2 more than the expectation 2 (n - 1)."""
    rng = np.random.default_rng(3)
    w, h, g, n = 500, 400, 100, 90
    uv = _scattered(rng, n, w, h)
    s_obs = rng.uniform(0.2, 0.6, n)
    grid = fit_grid(
        uv,
        rng.normal(0, 0.3, (n, 2)),
        (w, h),
        g,
        sigma_obs=s_obs,
        sigma_constraint=0.15,
        border=border,
        folds=0,
    )
    e_o, e_c = _expected_forms(grid.layout, uv, s_obs, 0.15, border)
    assert grid.redundancy == pytest.approx(2 * (e_o + e_c), abs=1e-6)
    assert grid.redundancy == 2 * (n - (1 if border == "mean" else 4))


def test_variance_components_meet_their_expectations():
    """Förstner's estimate is the point where each group's weighted square sum equals its
    expectation under the estimated variances. The constraint group's expectation counted
    the dependent row of border="mean" (one per component), so the estimated constraint
    variance was low by 2 / r_c (here 2 / 25: 8 %; on 300 fields drawn from the prior the
    mean estimate was 0.948 +- 0.015 of the truth, now 1.017 +- 0.015)."""
    rng = np.random.default_rng(12)
    w, h, g, n = 600, 500, 100, 400
    uv = _scattered(rng, n, w, h)
    x, y = uv[:, 0] / w, uv[:, 1] / h
    field = np.column_stack([np.sin(4.0 * x + 1.0) * np.cos(3.0 * y), np.cos(5.0 * x * y)])
    l = -0.6 * field + rng.normal(0.0, 0.3, (n, 2))
    grid = fit_grid(uv, l, (w, h), g, sigma_obs=1.0, sigma_constraint="vce", folds=0)
    s_o, s_c = float(grid.sigma_obs[0]), grid.sigma_constraint
    A = grid.layout.design_matrix(uv)
    C = grid.layout.constraint_matrix("mean")
    z = grid.nodes.reshape(-1, 2)
    q_o = float(np.sum((A @ z - l) ** 2)) / s_o**2
    q_c = float(np.sum((C @ z) ** 2)) / s_c**2
    e_o, e_c = _expected_forms(grid.layout, uv, s_o, s_c, "mean")
    assert 10 < 2 * e_c < 60  # a small constraint redundancy, where the count matters
    # the root is found to vce_tol = 1e-3 on the ratio of the factors
    assert q_c / (2 * e_c) == pytest.approx(1.0, abs=2e-3)
    assert q_o / (2 * e_o) == pytest.approx(1.0, abs=2e-3)
    assert grid.sigma0 == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("border, extra", [("mean", 0), ("linear", -2)])
def test_in_adjustment_redundancy_counts_the_rank_of_the_grid_prior(border, extra):
    """One camera grid (no amplitude, affine datum) adds 2 u node unknowns and, through its
    pseudo-observations, the 2 u - k node directions they determine: k = 0 with
    border="mean" (the constant fields C leaves free are held by the datum), k = 2 with
    "linear" (of the bilinear fields the datum holds 6 of 8). The rows were counted:
    2 (u - 1) smoothness rows and 6 datum rows, 4 more than the nodes for "mean"."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=3, local_field=0.0, sigma=0.3
    )
    kw = dict(free=(), max_iterations=20)
    block = sim.truth.with_observations(uv=sim.observed, sigma=0.3)
    ba = pg.bundle_adjust(block, snooping=False, **kw)
    ga = adjust_with_grids(
        block,
        2000.0,
        per="camera",
        sigma_constraint=100.0,
        sigma_amplitude=None,
        border=border,
        std=False,
        **kw,
    )
    assert ga.redundancy - ba.redundancy == extra
    L = GridLayout(4000, 3000, 2000.0)
    assert L.constraint_rank(border) == np.linalg.matrix_rank(L.constraint_matrix(border).toarray())


def test_in_adjustment_sigma0_and_node_std_on_fields_drawn_from_the_prior():
    """Blocks simulated from the model the adjustment states: per-image grids drawn from
    the prior their pseudo-observations define (smoothness 0.3 px, amplitude 0.5 px,
    consecutive images equal to 0.3 px, the similarity datum held), image noise 0.3 px,
    GNSS, IMU and control coordinates drawn with their sigmas. sigma0 must be 1 and the
    a-posteriori node standard deviations the spread of the node errors. The
    pseudo-observation rows were counted in the redundancy (1436 for 984): sigma0 came out
    0.83 and the node standard deviations as much too small. 20 trials: the mean sigma0
    varies by 0.006 between seeds (tolerance 0.03), the ratio of the pooled RMS node error
    to the standard deviations by 0.03 (the grids of consecutive images are correlated;
    tolerance 0.12)."""
    sim = pg.simulate.uav_block(
        "FC300S", seed=5, strips=2, images_per_strip=3, local_field=0.0, sigma=0.3
    )
    truth, sigma, sc, sa, st = sim.truth, 0.3, 0.3, 0.5, 0.3
    w, h = (int(x) for x in truth.image_sizes()[0])
    L = GridLayout(w, h, 1000.0)
    m, k = truth.n_images, 2 * L.n_nodes
    C = L.constraint_matrix("mean").toarray()
    one = np.kron(C.T @ C, np.eye(2)) / sc**2 + np.eye(k) / sa**2
    prec = np.kron(np.eye(m), one)
    for i in range(m - 1):  # consecutive images (one camera): z_i - z_(i+1) ~ N(0, st^2)
        d = np.zeros((k, m * k))
        d[:, i * k : (i + 1) * k], d[:, (i + 1) * k : (i + 2) * k] = np.eye(k), -np.eye(k)
        prec += d.T @ d / st**2
    cov = np.linalg.inv(prec)
    D = np.kron(np.eye(m), _datum_rows(L, "similarity"))
    cov -= cov @ D.T @ np.linalg.solve(D @ cov @ D.T, D @ cov)  # conditioned on D z = 0
    wv, V = np.linalg.eigh(cov)
    root = V * np.sqrt(np.clip(wv, 0.0, None))
    rng = np.random.default_rng(21)
    ctrl = truth.role == "control"
    errors, s0, std = [], [], None
    for trial in range(20):
        nodes = (root @ rng.standard_normal(root.shape[1])).reshape(m, *L.shape, 2)
        ideal = sim.ideal + rng.normal(0.0, sigma, sim.ideal.shape)
        uv = observe(truth, ideal, [node_field(L, nodes[i]) for i in range(m)])
        survey = truth.surveyed_xyz + rng.standard_normal(truth.xyz.shape) * truth.point_sigma
        block = truth.with_observations(uv=uv, sigma=sigma).replace(
            gnss=truth.gnss + rng.standard_normal(truth.gnss.shape) * truth.gnss_sigma,
            imu=truth.imu + rng.standard_normal(truth.imu.shape) * truth.imu_sigma,
            surveyed=np.where(ctrl[:, None], survey, np.nan),
        )
        ga = adjust_with_grids(
            block,
            1000.0,
            sigma_constraint=sc,
            sigma_temporal=st,
            sigma_amplitude=sa,
            std=trial == 0,
            max_iterations=30,
        )
        ids = truth.image_ids.tolist()
        errors.append(np.array([ga.grids[i].nodes for i in ids]) - nodes)
        s0.append(ga.sigma0)
        if trial == 0:
            std = np.array([ga.node_std[i] for i in ids])
    assert float(np.mean(s0)) == pytest.approx(1.0, abs=0.03)
    ratio = np.sqrt(np.mean(np.square(errors)) / np.mean(std**2))
    assert ratio == pytest.approx(1.0, abs=0.12)
