"""Grids inside the bundle adjustment with ``backend="cg"``: conjugate gradients reach the
solution of the direct factorisation, per image and per camera.

Preconditioned by the diagonal alone, conjugate gradients did not converge in ``10 n``
iterations on these systems (each grid's datum term is a stiff rank-4 or rank-6 coupling
of all its nodes, and a grid competes with its image's orientation or its camera group's
calibration), so the Marquardt damping grew and the adjustment stopped after
``max_iterations`` far from the minimum (sigma0 8.7 instead of 1.02). The preconditioner's
blocks are now each grid's nodes with the orientation (per image) or calibration (per
camera) they compete with; a solve that still does not converge is a ConvergenceError
naming the direct backends, not a damped step."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import photogeom as pg
from photogeom.adjust import sparse as sps
from photogeom.calibration import adjust_with_grids
from photogeom.calibration import in_adjustment as ia
from photogeom.errors import ConvergenceError


def _same_solution(block, per):
    ref = adjust_with_grids(block, 1000, per=per, std=False, backend="auto")
    cg = adjust_with_grids(block, 1000, per=per, std=False, backend="cg", max_iterations=20)
    assert ref.converged and cg.converged
    assert cg.iterations == ref.iterations
    keys = list(ref.grids)
    a = np.stack([ref.grids[k].nodes for k in keys])
    b = np.stack([cg.grids[k].nodes for k in keys])
    # documented: node values within 1e-8 of the largest, sigma0 to 1e-10 (measured:
    # 1e-11 px on nodes of 1.5-9 px, sigma0 to 2e-14)
    assert np.max(np.abs(a - b)) < 1e-8 * np.max(np.abs(a))
    assert cg.sigma0 == pytest.approx(ref.sigma0, rel=1e-10)


def test_cg_with_a_camera_grid_reaches_the_direct_solution():
    block = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block
    _same_solution(block, "camera")


def test_cg_with_image_grids_reaches_the_direct_solution():
    # one strip: the weakest geometry of the simulator, 900-1400 iterations per solve
    block = pg.simulate.uav_block("FC300S", seed=1, strips=1, images_per_strip=4).block
    _same_solution(block, "image")


def test_a_cg_solve_that_does_not_converge_names_the_direct_backends(monkeypatch):
    """The diagonal preconditioner (before) does not converge here: that is an error
    naming the way out, not a damped step."""
    block = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block
    plain = ia.factorize
    monkeypatch.setattr(ia, "factorize", lambda S, **kw: plain(S, **{**kw, "blocks": None}))
    with pytest.raises(ConvergenceError, match="backend='cholmod' or 'auto'"):
        adjust_with_grids(block, 1000, per="camera", std=False, backend="cg")


def test_preconditioner_blocks_of_any_shape_solve_exactly():
    rng = np.random.default_rng(4)
    A = sp.random(200, 50, density=0.08, random_state=4) + sp.eye(200, 50)
    N = sp.csc_matrix(A.T @ A)
    b = rng.standard_normal(50)
    labels = rng.integers(0, 7, 50)  # non-contiguous blocks of different sizes
    x = sps.factorize(N, backend="cg", blocks=labels).solve(b)
    np.testing.assert_allclose(x, np.linalg.solve(N.toarray(), b), rtol=1e-8, atol=1e-12)
    # one block holding everything: the preconditioner is the inverse, one iteration
    x = sps.factorize(N, backend="cg", blocks=np.zeros(50, int)).solve(b)
    np.testing.assert_allclose(x, np.linalg.solve(N.toarray(), b), rtol=1e-10, atol=1e-14)
    with pytest.raises(ValueError, match="50 unknowns"):
        sps.factorize(N, backend="cg", blocks=np.zeros(49, int))


def test_cg_factorises_nothing_for_the_final_fits_chain(monkeypatch):
    # the final fit's sigma0 is over the chain's effective redundancy, which solves with the
    # joint normal equations: they were factorised with backend="auto" (CHOLMOD or dense)
    # whatever the adjustment's backend, what "cg" is chosen to avoid on blocks too large
    # to factorise; they are solved by conjugate gradients now, to the same redundancy
    block = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block
    ref = adjust_with_grids(block, 1000, per="camera", std=False, backend="auto")
    used = []
    plain = ia.factorize

    def spy(S, **kw):
        used.append(kw.get("backend", "auto"))
        return plain(S, **kw)

    monkeypatch.setattr(ia, "factorize", spy)
    cg = adjust_with_grids(block, 1000, per="camera", std=False, backend="cg", max_iterations=20)
    assert used and set(used) == {"cg"}
    assert cg.fit.effective_redundancy["value"] == pytest.approx(
        ref.fit.effective_redundancy["value"], rel=1e-8
    )
