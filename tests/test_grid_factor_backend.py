"""The grid's normal matrix is factorised sparse at every size.

Before: the library's "auto" choice, a dense Cholesky up to 2500 unknowns, factorised the
2035 nodes of a 7952 x 5304 px image at 150 px densely (263 ms per image, measured) and
the 4455 nodes at 100 px sparsely (56 ms): the grid-size sweep measured the 150 px grids
as more expensive than the 100 px ones, and its cost axis (min-max normalised computing
time, the closest-to-origin rule) was distorted. Times are not asserted here (they depend
on the machine); the backend and the solution are.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from photogeom.adjust.sparse import DENSE_MAX
from photogeom.calibration.grid import FiniteElementSystem, GridLayout


@pytest.mark.parametrize("spacing", [150.0, 200.0, 500.0])
def test_grids_under_the_dense_limit_are_factorised_sparse(spacing):
    rng = np.random.default_rng(3)
    layout = GridLayout(7952, 5304, spacing)  # the study's unstable camera
    assert layout.n_nodes <= DENSE_MAX  # where "auto" chose the dense Cholesky
    uv = rng.uniform([0, 0], [7951, 5303], (400, 2))
    fe = FiniteElementSystem(layout, uv, np.full(400, 1 / 0.3**2), 100.0)
    assert fe.factor.backend in ("cholmod", "superlu")
    l = rng.normal(0.0, 0.5, (400, 2))
    got = fe.solve(l)
    want = scipy.linalg.solve(fe.N.toarray(), fe._AtP @ l, assume_a="pos")  # dense, LAPACK
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-10)
