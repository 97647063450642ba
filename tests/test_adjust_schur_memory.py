"""Memory of the linearisation and the Schur reduction per Levenberg-Marquardt iteration.

Every iteration linearises and forms the normal equations anew; arrays as large as the
Jacobian blocks that are allocated afresh each time cost page faults (system time) besides
their copies: the 250-image ILCE-7RM2 block with 1000 tie points per image faulted in
about 800 MB of fresh memory per iteration. The reduction gathers each image's rows by
themselves instead of reordered copies of all rows, and the scatter index of the points'
coupling with the calibration is formed once; the derivatives are whitened in place.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import photogeom as pg
from photogeom.bundle.adjustment import Problem
from photogeom.bundle.options import BundleOptions


@pytest.fixture(scope="module")
def linearized():
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=1, strips=2, images_per_strip=8, tie_points_per_image=300
    )
    problem = Problem(sim.block, BundleOptions().validate())
    state = problem.initial_state()
    _, e2, _ = problem.cost(state)
    return problem, problem.linearize(state, problem.robust_weights(e2))


def _jacobian_bytes(lin) -> int:
    return lin.A.nbytes + lin.G.nbytes + lin.P.nbytes + lin.r.nbytes


def test_the_reduction_allocates_little_beyond_its_results(linearized):
    """The normal equations of 4806 observation rows: temporaries beyond the reduced
    system's blocks of 5.7 times the Jacobian blocks before (reordered copies of all rows,
    the coupling's scatter index), 2.7 times now."""
    problem, lin = linearized
    s = problem.sys
    assert not s.sparse_global and s.n_global == 11
    s.normal_equations(lin, damping=1e-3)  # the structure's own arrays: formed once
    tracemalloc.start()
    try:
        ne = s.normal_equations(lin, damping=1e-3)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert ne.S.shape == (s.nc, s.nc)
    assert peak - kept <= 4.0 * _jacobian_bytes(lin)


def test_the_coupling_scatter_formed_once_gives_the_sums_over_the_rows(linearized):
    """``H_j = sum over the rows k of point j of P_k' G_k`` in the columns of the rows'
    camera group, summed independently row by row (``np.add.at``), at two iterations."""
    problem, lin = linearized
    s = problem.sys
    for damping in (1e-3, 1e-6):
        ne = s.normal_equations(lin, damping=damping)
        ref = np.zeros((s.n_points, 3, s.n_global))
        cols = s.local_global[s.local]  # (n, gl)
        pg_ = np.einsum("kdi,kdc->kic", ne.lin.P, ne.lin.G)  # (n, 3, gl), fixed ones masked
        np.add.at(ref, (s.point[:, None, None], np.arange(3)[None, :, None], cols[:, None, :]), pg_)
        np.testing.assert_allclose(ne.H, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_the_normal_equations_keep_no_copy_of_blocks_without_fixed_columns(linearized):
    """All exterior orientations free (some calibration parameters fixed): the orientation
    block ``A`` is used as it is, the calibration block ``G`` masked; before, both were
    copied at every iteration."""
    problem, lin = linearized
    s = problem.sys
    assert s.local_free.all() and not s.global_free.all()
    ne = s.normal_equations(lin, damping=1e-3)
    assert ne.lin.A is lin.A
    fixed = ~s.global_free[s.local_global[s.local]]  # (n, gl)
    assert fixed.any()
    np.testing.assert_array_equal(ne.lin.G, np.where(fixed[:, None, :], 0.0, lin.G))


def test_the_linearisation_whitens_the_derivatives_in_place(linearized):
    """The whitened calibration and point blocks are the projection's own derivative
    arrays scaled in place: the linearisation's transient memory 1.67 times its Jacobian
    blocks before (scaled copies), 1.47 times now."""
    problem, lin = linearized
    state = problem.initial_state()
    weights = np.ones(lin.r.shape[0])
    tracemalloc.start()
    try:
        new = problem.linearize(state, weights)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak - kept <= 1.57 * _jacobian_bytes(new)
    for a, b in zip((new.r, new.A, new.G, new.P), (lin.r, lin.A, lin.G, lin.P)):
        np.testing.assert_array_equal(a, b)
