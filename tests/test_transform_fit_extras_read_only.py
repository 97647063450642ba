"""The extras of ``estimate_transform`` fits hold read-only arrays, as every Fit's do.

``Fit.__post_init__`` gives a Fit a dict of extras of its own with read-only arrays; the
estimator completed its fits field by field afterwards and left the extras it set last
writable: ``fit.extras["textbook_cofactor"][:] = 0`` went through (and into any copy made
with ``dataclasses.replace``, which shares it).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import photogeom as pg


def _pairs(d, n=10, seed=0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 100, (n, d))
    perm = [1, 0] if d == 2 else [1, 2, 0]  # a rotation in 3D
    return src, 1.1 * src[:, perm] + 3.0 + rng.normal(0, 0.01, (n, d))


def _arrays(extras):
    return {k: v for k, v in extras.items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize(
    ("model", "d", "kwargs"),
    [
        ("affine2d", 2, {}),
        ("similarity2d", 2, {}),
        ("affine3d", 3, {}),
        ("projective2d", 2, {}),
        ("projective2d", 2, {"errors_in": "both"}),
        ("polynomial2d", 2, {"order": 2}),
        ("affine2d", 2, {"check": [False] * 8 + [True] * 2}),
        ("affine2d", 2, {"source_system": "pixel", "target_system": "image"}),
        ("similarity3d", 3, {}),
    ],
)
def test_extras_arrays_read_only(model, d, kwargs):
    src, dst = _pairs(d, n=14)
    if "check" in kwargs:
        src, dst = src[:10], dst[:10]
    fit = pg.estimate_transform(model, src, dst, **kwargs)
    arrays = _arrays(fit.extras)
    if model in ("affine2d", "similarity2d", "affine3d", "projective2d"):
        assert "textbook_cofactor" in arrays
    for name, a in arrays.items():
        assert not a.flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            a[...] = 0.0
    # a copy made by replace cannot change them either, and the top-level arrays stay so
    copy = dataclasses.replace(fit, notes=())
    for name, a in _arrays(copy.extras).items():
        assert not a.flags.writeable, name
    for name in ("residuals", "covariance", "parameters", "check_residuals"):
        a = getattr(fit, name, None)
        if isinstance(a, np.ndarray):
            assert not a.flags.writeable, name


def test_textbook_std_unchanged_by_a_write_attempt():
    src, dst = _pairs(2)
    fit = pg.estimate_transform("affine2d", src, dst)
    Q = fit.extras["textbook_cofactor"]
    before = Q.copy()
    with pytest.raises(ValueError):
        Q[0, 0] = 1e9
    np.testing.assert_array_equal(fit.extras["textbook_cofactor"], before)
