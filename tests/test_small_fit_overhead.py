"""Per-call overhead of small fits: checks without array round trips or Python-level calls.

A 10-point 2D affine fit takes a fraction of a millisecond, so the conversions around the
arithmetic matter: the model's six parameters (already floats) went through a numpy array
and back, ``Affine2D.singular`` built the 2x2 matrix for a maximum of four numbers, and the
finite-magnitude check of each input went through numpy's Python-level reduction wrappers.
The checks themselves must stay (their errors are tested here as well).
"""

from __future__ import annotations

import math
import sys
import types

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import InputError
from photogeom.transforms import Affine2D, Similarity2D, _common, affine2d, similarity2d
from photogeom.validation import MAX_MAGNITUDE, check_finite_magnitude


def _no_arrays(monkeypatch, *modules):
    """Make ``np.array`` / ``np.asarray`` raise inside ``modules``."""

    def refuse(*args, **kwargs):
        raise AssertionError("array built")

    for mod in modules:
        proxy = types.SimpleNamespace(**{k: getattr(np, k) for k in dir(np) if not k[:1] == "_"})
        proxy.array = proxy.asarray = refuse
        monkeypatch.setattr(mod, "np", proxy)


def test_affine2d_from_floats_builds_no_array(monkeypatch):
    p = np.array([0.95, -0.07, 125.0, 0.09, 1.03, 130.0])
    _no_arrays(monkeypatch, _common, affine2d, similarity2d)
    tf = Affine2D(*p)  # numpy floats, as an estimate gives them
    assert all(type(getattr(tf, n)) is float for n in ("a1", "a2", "a3", "b1", "b2", "b3"))
    assert tf.singular is False
    s = Similarity2D(*p[:4])
    assert all(type(getattr(s, n)) is float for n in "abcd")


def test_parameter_checks_stay():
    with pytest.raises(InputError, match="Affine2D: parameters must be finite"):
        Affine2D(1.0, 0.0, 0.0, 0.0, float("nan"), 0.0)
    with pytest.raises(InputError, match="Affine2D: parameters must be finite"):
        Affine2D(1.0, 0.0, 0.0, 0.0, np.float64(np.inf), 0.0)
    with pytest.raises(InputError, match="Similarity2D: parameters must be finite"):
        Similarity2D(1.0, math.inf, 0.0, 0.0)
    # other scalar types still convert as before (ints, 0-d arrays, strings of numbers)
    tf = Affine2D(1, np.array(0.5), "2", 0, 1, np.int64(3))
    assert (tf.a1, tf.a2, tf.a3, tf.b3) == (1.0, 0.5, 2.0, 3.0)
    assert all(type(getattr(tf, n)) is float for n in ("a1", "a2", "a3", "b1", "b2", "b3"))


@pytest.mark.parametrize("scale", [1.0, 1e-160, 1e140])
def test_singular_as_defined(scale):
    """``singular`` is ``|det A| <= 1e-14 max|A|^2``, whatever the magnitude."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        A = rng.normal(size=(2, 2)) * scale
        if rng.uniform() < 0.5:  # rank one to rounding
            A[1] = A[0] * rng.normal() * (1 + rng.choice([0.0, 1e-16, 1e-13, 1e-6]))
        tf = Affine2D(A[0, 0], A[0, 1], 0.0, A[1, 0], A[1, 1], 0.0)
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        assert tf.singular == bool(abs(det) <= 1e-14 * max(np.abs(A).max() ** 2, 1e-300))


def _python_calls(fn) -> int:
    """Python-level function calls made by ``fn()`` (C functions not counted)."""
    calls = []

    def prof(frame, event, arg):
        if event == "call":
            calls.append(frame.f_code.co_name)

    sys.setprofile(prof)
    try:
        fn()
    finally:
        sys.setprofile(None)
    return len(calls) - 1  # fn itself


def test_finite_magnitude_check_calls_no_python_wrappers():
    pts = np.random.default_rng(0).uniform(0, 4000, (10, 2))
    assert _python_calls(lambda: check_finite_magnitude(pts, "source", "affine2d")) == 1


def test_finite_magnitude_errors_stay():
    pts = np.ones((10, 2))
    pts[3, 1] = np.nan
    with pytest.raises(InputError, match=r"1 row\(s\) contain NaN or infinite values \(row"):
        check_finite_magnitude(pts, "source", "affine2d")
    pts[3, 1] = -np.inf
    with pytest.raises(InputError, match="source: 1 row"):
        check_finite_magnitude(pts, "source", "affine2d")
    pts[3, 1] = -MAX_MAGNITUDE / 2  # sqrt(20) * 5e149 > 1e150
    with pytest.raises(InputError, match="overflow float64"):
        check_finite_magnitude(pts, "target", "affine2d")
    pts[3, 1] = -MAX_MAGNITUDE / 5  # 4.47 * 2e149 < 1e150
    check_finite_magnitude(pts, "target", "affine2d")
    with pytest.raises(InputError, match="overflow float64"):
        pg.estimate_transform("affine2d", pts * 10, pts)


def _import_calls(fn) -> int:
    """Calls into the import machinery made by ``fn()`` (after a first call)."""
    fn()
    calls = []

    def prof(frame, event, arg):
        if event == "call" and "importlib" in frame.f_code.co_filename:
            calls.append(frame.f_code.co_name)

    sys.setprofile(prof)
    try:
        fn()
    finally:
        sys.setprofile(None)
    return len(calls)


@pytest.mark.parametrize("model", ["similarity3d", "rigid3d"])
@pytest.mark.parametrize("statistics", [False, True])
def test_3d_fit_imports_nothing_per_call(model, statistics):
    """The orientation functions behind the 3D similarity are imported once, not on every
    call (an import statement in a function body cost some 5-7 us, 5 % of a 10-point fit)."""
    rng = np.random.default_rng(5)
    x = rng.uniform(-1, 1, (10, 3))
    X = 250.0 * x + [512_000.0, 4_215_000.0, 350.0] + rng.normal(0, 0.01, (10, 3))
    fit = pg.estimate_transform(model, x, X, statistics=statistics)
    assert fit.model.rotation == pytest.approx(np.eye(3), abs=1e-4)
    assert _import_calls(lambda: pg.estimate_transform(model, x, X, statistics=statistics)) == 0


def _unique_rows_first(cells: np.ndarray) -> np.ndarray:
    return np.unique(cells, axis=0, return_index=True)[1]


def test_distinct_points_as_numpy_unique():
    """The coincident-point grouping of the resection: the indices ``np.unique(...,
    axis=0, return_index=True)`` gives, in its order, on point sets with repeats."""
    from photogeom.orientation.resection import _distinct_points

    rng = np.random.default_rng(11)
    for _ in range(500):
        n = int(rng.integers(1, 40))
        g = rng.integers(0, 4, (n, 3)) * rng.choice([1.0, 1e-12, 1e5]) + rng.choice([0.0, 1e6])
        if rng.uniform() < 0.3:
            g = g + rng.normal(0, 1e-11, g.shape)
        lo = g.min(axis=0)
        extent = float(np.max(g.max(axis=0) - lo))
        expected = (
            np.zeros(1, dtype=np.intp)
            if extent == 0.0
            else _unique_rows_first(np.round((g - lo) / (1e-9 * extent)))
        )
        np.testing.assert_array_equal(_distinct_points(g), expected)


def test_resection_groups_points_without_structured_unique(monkeypatch):
    """``np.unique(rows, axis=0)`` goes through a structured-array view, moved axes and a
    Python-level sort wrapper: a tenth of a 20-point resection with start values. The
    resection groups coincident points with one lexicographic sort instead."""
    import photogeom.orientation.resection as resection

    ground = np.array([[0, 0, 0], [100, 0, 5], [0, 100, 10], [100, 100, 0], [50, 50, 20],
                       [20, 80, 3], [80, 20, 8], [50, 50, 20]], dtype=float)
    eo = pg.ExteriorOrientation.from_degrees(50.0, 50.0, 400.0, 2.0, -3.0, 30.0)
    io = pg.InteriorOrientation(100.0)
    image = pg.project(ground, io, eo)
    proxy = types.SimpleNamespace(**{k: getattr(np, k) for k in dir(np) if k[:1] != "_"})

    def unique(*args, **kwargs):
        if kwargs.get("axis") is not None:
            raise AssertionError("np.unique over rows")
        return np.unique(*args, **kwargs)

    proxy.unique = unique
    monkeypatch.setattr(resection, "np", proxy)
    fit = pg.space_resection(ground, image, io, initial=eo)
    np.testing.assert_allclose(fit.position, [50.0, 50.0, 400.0], atol=1e-6)
