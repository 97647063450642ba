"""absolute_orientation(..., reflection="rotation"): the best proper rotation where a mirror
image fits better (point sets of one handedness by construction, deformed), checked against
the constrained least-squares solution of Umeyama (1991) computed here independently."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError, ReflectionError
from photogeom.rotation import opk_matrix


def _nearly_flat_pair():
    """A right-handed similarity of a nearly flat point set whose heights are then mirrored
    about their mean plane (and a little noise): the mirror image fits better."""
    rng = np.random.default_rng(4)
    x = np.column_stack([rng.uniform(0, 100, 9), rng.uniform(0, 60, 9), rng.normal(0, 3, 9)])
    R = opk_matrix(0.1, -0.05, 0.7)
    X = 2.0 * x @ R.T + [500.0, 200.0, 40.0]
    zm = X[:, 2].mean()
    X[:, 2] = zm - (X[:, 2] - zm) + rng.normal(0, 0.1, 9)
    return x, X


def _umeyama_proper(x, X):
    xc, Xc = x - x.mean(axis=0), X - X.mean(axis=0)
    U, S, Vt = np.linalg.svd(Xc.T @ xc)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / np.sum(xc**2)
    return s, R, X.mean(axis=0) - s * R @ x.mean(axis=0)


def test_default_refuses_the_reflection():
    x, X = _nearly_flat_pair()
    with pytest.raises(ReflectionError):
        pg.absolute_orientation(x, X, method="svd")


def test_rotation_keeps_the_best_proper_rotation():
    x, X = _nearly_flat_pair()
    fit = pg.absolute_orientation(x, X, method="svd", reflection="rotation")
    s, R, t = _umeyama_proper(x, X)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(fit.rotation, R, atol=1e-12)
    assert fit.scale == pytest.approx(s, rel=1e-12)
    np.testing.assert_allclose(fit.translation, t, atol=1e-9)
    np.testing.assert_allclose(fit.residuals, s * x @ R.T + t - X, atol=1e-9)
    assert any("reflection='rotation'" in n for n in fit.notes)


def test_rotation_leaves_a_fit_without_reflection_unchanged():
    x, X = _nearly_flat_pair()
    X[:, 2] = 2 * X[:, 2].mean() - X[:, 2]  # the heights back: a similarity plus noise
    a = pg.absolute_orientation(x, X, method="svd")
    b = pg.absolute_orientation(x, X, method="svd", reflection="rotation")
    np.testing.assert_array_equal(a.parameters, b.parameters)
    assert a.notes == b.notes


@pytest.mark.parametrize(
    "kw", [dict(method="gauss-markov"), dict(reflection="mirror"),
           dict(robust="ransac", threshold=1.0)],
)  # fmt: skip
def test_rotation_is_an_option_of_svd_only(kw):
    x, X = _nearly_flat_pair()
    kw = {"method": "svd", "reflection": "rotation", **kw}
    with pytest.raises(InputError, match="reflection"):
        pg.absolute_orientation(x, X, **kw)
