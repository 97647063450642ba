"""Agreement of two computations of the same arrays, shared by the tests that compare two
paths of the adjustment."""

from __future__ import annotations

import numpy as np


def assert_close_to_scale(a, b, rtol: float = 1e-8) -> None:
    """``a`` and ``b`` have one shape, non-finite entries in the same places, and differ by
    at most ``rtol`` times the largest finite magnitude of ``a``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    ok = np.isfinite(a)
    np.testing.assert_array_equal(ok, np.isfinite(b))
    scale = max(np.max(np.abs(a[ok]), initial=0.0), 1e-300)
    assert np.max(np.abs(a[ok] - b[ok]), initial=0.0) <= rtol * scale
