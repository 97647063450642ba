"""`absolute_orientation` refuses options of another mode (docs run).

docs/absolute-orientation.md ("Bad input"): options for the wrong method raise an
``InputError`` saying what is expected. ``threshold`` without ``robust="ransac"`` and
``iterate`` with a method other than the Gauss-Helmert adjustment were accepted and ignored:
``absolute_orientation(source, target, threshold=0.1)`` returned the plain SVD fit, as if no
threshold had been given.
"""

from __future__ import annotations

import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def pairs():
    _, source, target = pg.datasets.point_pairs("lidar_wang2014")
    return source, target


def test_threshold_without_ransac_is_refused(pairs):
    with pytest.raises(pg.InputError, match=r"threshold .* only with robust='ransac'"):
        pg.absolute_orientation(*pairs, threshold=0.1)
    fit = pg.absolute_orientation(*pairs, robust="ransac", threshold=0.1)
    assert fit.inliers.sum() >= 3


@pytest.mark.parametrize("method", ["svd", "quaternion", "closed-form", "gauss-markov"])
def test_iterate_with_another_method_is_refused(pairs, method):
    with pytest.raises(pg.InputError, match="iterate applies to method='gauss-helmert'"):
        pg.absolute_orientation(*pairs, method, iterate=True)


def test_iterate_with_ransac_is_refused(pairs):
    with pytest.raises(pg.InputError, match="without robust="):
        pg.absolute_orientation(
            *pairs, "gauss-helmert", robust="ransac", threshold=0.1, iterate=True
        )


def test_iterate_with_gauss_helmert_is_used(pairs):
    direct = pg.absolute_orientation(*pairs, "gauss-helmert")
    iterative = pg.absolute_orientation(*pairs, "gauss-helmert", iterate=True)
    assert iterative.iterations >= 1
    assert iterative.scale == pytest.approx(direct.scale, rel=1e-9)


@pytest.mark.parametrize("robust", [False, True])
def test_overflowing_coordinates_are_refused_by_name(pairs, robust):
    # docs/absolute-orientation.md (Bad input): coordinates whose sums of squares overflow
    # give an InputError naming the overflow. RANSAC said instead that every sample was
    # degenerate (coincident or collinear points), and the direct methods emitted numpy's
    # RuntimeWarning first: with warnings as errors that, not the InputError, was raised
    import warnings

    source, target = pairs
    kw = {"robust": "ransac", "threshold": 0.1} if robust else {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(pg.InputError, match="overflow float64"):
            pg.absolute_orientation(source * 1e200, target, **kw)
