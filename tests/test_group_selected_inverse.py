"""The diagonal of the inverse of a sparse SPD matrix by a supernodal selected inversion
over groups of unknowns (:class:`photogeom.adjust.selected_inverse.GroupSelectedInverse`),
against LAPACK's inverse of the whole matrix, for any grouping and elimination order."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from photogeom.adjust.selected_inverse import GroupSelectedInverse
from photogeom.errors import DegenerateGeometryError


def _spd(n: int, density: float, seed: int, arrow: int = 0) -> sp.csr_matrix:
    """A sparse SPD matrix; ``arrow`` unknowns (the last) coupled to every other one."""
    A = sp.random(n, n, density=density, random_state=seed, format="csr")
    if arrow:
        rng = np.random.default_rng(seed)
        B = sp.lil_matrix((n, n))
        B[n - arrow :, :] = rng.normal(size=(arrow, n)) * 0.3
        A = A + B.tocsr()
    return (A @ A.T + 0.1 * sp.identity(n)).tocsr()


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("groups", [1, 7, 60])
def test_diagonal_equals_the_dense_inverse_for_any_grouping_and_order(seed, groups):
    rng = np.random.default_rng(seed)
    n = 240
    N = _spd(n, 0.01, seed, arrow=5 if seed % 2 else 0)
    labels = np.unique(rng.integers(0, groups, n), return_inverse=True)[1].ravel()
    K = int(labels.max()) + 1
    rank = rng.permutation(K)
    got = GroupSelectedInverse(N, labels, rank).diagonal()
    ref = np.diag(np.linalg.inv(N.toarray()))
    np.testing.assert_allclose(got, ref, rtol=1e-10)


def test_a_banded_chain_merges_into_supernodes_and_stays_exact():
    """A tridiagonal matrix in its natural order: every group is its parent's only child
    with the parent's pattern below, so the chain is one supernode."""
    n = 50
    N = sp.diags([-np.ones(n - 1), 2.5 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tocsr()
    got = GroupSelectedInverse(N, np.arange(n), np.arange(n)).diagonal()
    np.testing.assert_allclose(got, np.diag(np.linalg.inv(N.toarray())), rtol=1e-12)


def test_an_indefinite_matrix_is_refused():
    N = sp.csr_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(DegenerateGeometryError, match="not positive definite"):
        GroupSelectedInverse(N, np.array([0, 1, 2]), np.array([0, 1, 2]), what="the test")


def test_the_order_may_be_a_list():
    N = _spd(30, 0.1, 4)
    got = GroupSelectedInverse(N, list(range(30)), list(range(29, -1, -1))).diagonal()
    np.testing.assert_allclose(got, np.diag(np.linalg.inv(N.toarray())), rtol=1e-10)
