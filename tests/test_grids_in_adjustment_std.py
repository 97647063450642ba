"""Standard deviations of the nodes of grids inside the bundle adjustment: the diagonal of
the inverse normal matrix, from triangular solves against the factor of the system
reduced by the points (with the datum by the Woodbury identity), never a dense inverse.

Before, ``std=True`` inverted the reduced system densely: four arrays of (camera-side
unknowns)^2 doubles, 2.5 GB for 21 images of 42 Mpx at 500 px (8700 unknowns), and
"Unable to allocate 2.05 GiB" under a 6 GB limit for 40 images (16 600 unknowns); now
0.66 and 0.73 GB."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust.sparse import HAVE_CHOLMOD
from photogeom.bundle.options import BundleOptions
from photogeom.calibration import in_adjustment as ia


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3).block


def _problem(block, spacing, sa, per="image"):
    opts = BundleOptions(initial_damping=ia.INITIAL_DAMPING).validate()
    datum = "similarity" if per == "image" else "affine"
    st = 0.3 if per == "image" else None
    return ia._GridProblem(block, opts, spacing, per, datum, 1.0, st, sa, "mean")


def _normal_equations(gp):
    z = np.random.default_rng(5).normal(0.0, 0.3, gp.n_grid)
    return gp.normal_equations(gp.bp.initial_state(), z)[0]


BACKENDS = ["auto", "dense", "superlu", "cg"] + (["cholmod"] if HAVE_CHOLMOD else [])


@pytest.mark.parametrize("per, sa", [("image", 0.5), ("camera", 0.5), ("image", None)])
def test_node_cofactors_equal_the_dense_inverse_of_the_whole_system(block, per, sa):
    """Against LAPACK's inverse of the whole normal matrix (points not eliminated, the
    datum conditions added densely): the independent way."""
    gp = _problem(block, 1000.0, sa, per)
    N = _normal_equations(gp)
    full = N.toarray()
    if gp.U_free is not None:
        U = gp.U_free.toarray()
        full[: U.shape[0], : U.shape[0]] += U @ U.T
    Q = np.linalg.inv(full)
    rows = np.searchsorted(gp.free_idx, np.arange(gp.off_g, gp.off_p))
    ref = np.diag(Q)[rows]
    for backend in BACKENDS:
        got = ia._grid_cofactors(gp, N, backend)
        np.testing.assert_allclose(got, ref, rtol=1e-9, err_msg=backend)


def test_node_cofactors_need_no_dense_inverse(block, monkeypatch):
    """2696 camera-side unknowns (250 px grids): the dense inverse took four arrays of
    2696^2 doubles (230 MB) in numpy; now the numpy memory stays below one such array
    (batches of 4 MB here)."""
    monkeypatch.setattr(ia, "STD_BATCH_BYTES", 4 * 2**20, raising=False)
    gp = _problem(block, 250.0, 0.5)
    N = _normal_equations(gp)
    nc = gp.free_idx.size - 3 * gp.bp.p
    assert nc > 2500  # above the size that "auto" factorises densely
    tracemalloc.start()
    try:
        cof = ia._grid_cofactors(gp, N)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert np.all(cof > 0) and cof.size == gp.n_grid
    assert peak < 8.0 * nc * nc


SPARSE = ["superlu"] + (["cholmod"] if HAVE_CHOLMOD else [])


@pytest.mark.parametrize("per", ["image", "camera"])
def test_node_cofactors_by_selected_inversion_not_a_solve_per_node(block, per, monkeypatch):
    """With a sparse factor the diagonal comes from a supernodal selected inversion in the
    factor's order, not from one triangular solve over the whole factor per node (170 s
    on the 250-image study block at 1000 px, now 14 s); against LAPACK's inverse of the
    reduced system with the datum added densely (2696 unknowns: 250 px grids)."""
    from photogeom.adjust.sparse import SparseFactor

    def refuse(*args, **kwargs):
        raise AssertionError("a triangular solve per node")

    gp = _problem(block, 250.0, 0.5, per)
    N = _normal_equations(gp)
    S = ia._reduce_points(N, 3 * gp.bp.p)[0].toarray()
    U = gp.U_free.toarray()
    nc = S.shape[0]
    rows = np.searchsorted(gp.free_idx[:nc], np.arange(gp.off_g, gp.off_p))
    ref = np.diag(np.linalg.inv(S + U @ U.T))[rows]
    monkeypatch.setattr(SparseFactor, "inverse_diagonal", refuse)
    for backend in SPARSE:
        got = ia._grid_cofactors(gp, N, backend)
        np.testing.assert_allclose(got, ref, rtol=1e-9, err_msg=backend)
