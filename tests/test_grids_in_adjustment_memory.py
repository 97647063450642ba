"""Grids inside the bundle adjustment couple all nodes of a grid through its datum
conditions. With an amplitude (the default) they are a low-rank term that the solver adds
by the Woodbury identity, so the normal equations stay sparse; without one they are a
dense block of (2 nodes)^2 entries per grid, and a spacing whose blocks cannot fit in memory
is refused at once, naming the way out, instead of numpy's "Unable to allocate 27.5 GiB"
(20 px on 4000 x 3000 px images) or minutes of swapping (40 px)."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle.options import BundleOptions
from photogeom.calibration import adjust_with_grids
from photogeom.calibration import in_adjustment as ia
from photogeom.errors import InputError


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block


def test_a_grid_too_fine_for_the_memory_is_refused(block, monkeypatch):
    monkeypatch.setattr(ia, "physical_memory", lambda: 2**30)  # a 1 GiB machine
    layout = pg.calibration.GridLayout(4000, 3000, 50)
    need = ia.BYTES_PER_DATUM_ENTRY * block.n_images * (2.0 * layout.n_nodes) ** 2
    assert need > 2**30  # 6 grids of 81 x 61 nodes: about 65 GiB
    with pytest.raises(InputError) as exc:
        adjust_with_grids(block, 50, sigma_amplitude=None)
    msg = str(exc.value)
    assert f"{layout.n_nodes} nodes per grid over {block.n_images} grid(s)" in msg
    assert f"{need / 2**30:.1f} GiB" in msg and "1.0 GiB" in msg
    assert "larger spacing" in msg and "fit_residual_grids" in msg
    assert "sigma_amplitude" in msg


def _problem(block, spacing, sa, **kw):
    opts = BundleOptions(initial_damping=ia.INITIAL_DAMPING).validate()
    args = dict(per="image", datum="similarity", sc=1.0, st=0.3, border="mean")
    args.update(kw)
    return ia._GridProblem(
        block, opts, spacing, args["per"], args["datum"], args["sc"], args["st"], sa,
        args["border"],
    )


def test_with_an_amplitude_the_datum_adds_no_dense_block(block, monkeypatch):
    # 6 grids of 21 x 16 nodes at 200 px: dense datum blocks would be 6 x 672^2 = 2.7 M
    # entries of the normal matrix; the sparse rest has about 0.2 M
    gp = _problem(block, 200.0, 0.5)
    N, _ = gp.normal_equations(gp.bp.initial_state(), np.zeros(gp.n_grid))
    nodes = np.array([L.n_nodes for L in gp.layouts])
    dense = float(np.sum((2.0 * nodes) ** 2))
    assert N.nnz < 0.2 * dense
    # and the memory of dense blocks is not what limits such grids: 50 px on a "1 GiB
    # machine" (dense blocks: 65 GiB) is set up without a refusal
    monkeypatch.setattr(ia, "physical_memory", lambda: 2**30)
    gp = _problem(block, 50.0, 0.5)
    assert gp.U.shape == (gp.n_grid, 4 * block.n_images)


@pytest.mark.parametrize(
    "kw", [{}, {"per": "camera", "datum": "affine", "st": None}, {"border": "linear"}]
)
def test_the_low_rank_solve_equals_a_dense_solve_of_the_full_system(block, kw):
    """(S + U U')^-1 by Woodbury against LAPACK on the whole normal matrix with the datum
    conditions added (points not eliminated), away from the solution (a raw block)."""
    gp = _problem(block, 1000.0, 0.5, **kw)
    rng = np.random.default_rng(5)
    z = rng.normal(0.0, 0.3, gp.n_grid)
    N, g = gp.normal_equations(gp.bp.initial_state(), z)
    Ufull = np.zeros((N.shape[0], gp.U.shape[1]))
    Ufull[: gp.U_free.shape[0]] = gp.U_free.toarray()
    full = N.toarray() + Ufull @ Ufull.T
    ref = np.linalg.solve(full, -g)
    # conjugate gradients on the whole system with the datum (as before the low-rank term),
    # preconditioned by each grid's block with its image's orientation or camera's
    # calibration (by the diagonal alone: not in 840 iterations on the affine camera grid)
    for backend in ("auto", "dense", "superlu", "cg"):
        dx = ia._solve_by_points(N, g, 3 * gp.bp.p, backend, gp.U_free, gp.cg_blocks)
        tol = 1e-6 if backend == "cg" else 1e-9  # conjugate gradients: iterative accuracy
        assert np.max(np.abs(dx - ref)) < tol * np.max(np.abs(ref))
    # the gradient includes the datum term: the cost's derivative by finite differences
    dz = np.zeros(gp.n_grid)
    j = int(np.argmax(np.abs(gp.U[:, 0].toarray().ravel())))
    dz[j] = 1e-6
    s = gp.bp.initial_state()
    fd = (gp.cost(s, z + dz)[0] - gp.cost(s, z - dz)[0]) / (2e-6)
    gj = g[np.searchsorted(gp.free_idx, gp.off_g + j)]
    assert abs(fd - 2 * gj) < 1e-5 * abs(fd)


def test_the_estimate_is_of_every_grid_and_coarse_grids_pass(monkeypatch):
    monkeypatch.setattr(ia, "physical_memory", lambda: 10**9)
    ia._check_memory(np.array([63] * 16), 500.0)  # 16 images at 500 px: 16 MB
    with pytest.raises(InputError, match="16 grid"):
        ia._check_memory(np.array([1271] * 16), 100.0)  # 16 x 2542^2 x 120 B: 12.4 GB
    monkeypatch.setattr(ia, "physical_memory", lambda: None)  # unknown memory: no guard
    ia._check_memory(np.array([10**6]), 1.0)
