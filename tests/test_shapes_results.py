"""Result objects cannot be changed through their arrays.

Before: a Fit's arrays were writable, so ``fit.parameters[k] = ...`` made ``fit.params``
disagree with ``fit.model`` (scale 3.0 against the model's 1.5000085), and a copy made by
``with_crs`` / ``with_checks`` shared them: writing zeros into the copy's residuals turned
the original's ``rmse`` from 0.01648 into 0.0. A BundleFit's residuals could be changed
away from its block's.
"""

from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust import Fit


def _data():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(8, 3)) * 100
    R = pg.opk_matrix(0.1, 0.2, 0.3)
    tgt = 1.5 * src @ R.T + [10.0, 20.0, 30.0] + rng.normal(size=(8, 3)) * 0.01
    return src, tgt


def _arrays(obj) -> dict:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}


FITS = {
    "svd": lambda s, t: pg.absolute_orientation(s, t, method="svd"),
    "gauss-markov": lambda s, t: pg.absolute_orientation(s, t, method="gauss-markov"),
    "no statistics": lambda s, t: pg.absolute_orientation(s, t, statistics=False),
    "affine": lambda s, t: pg.estimate_transform("affine3d", s, t),
    "with checks": lambda s, t: pg.estimate_transform(
        "affine3d", s, t, check=np.arange(len(s)) >= 6
    ),
}


@pytest.mark.parametrize("name", sorted(FITS))
def test_fit_arrays_are_read_only(name):
    fit = FITS[name](*_data())
    arrays = _arrays(fit)
    assert {"parameters", "covariance", "cofactor", "residuals"} <= set(arrays)
    for key, a in arrays.items():
        with pytest.raises(ValueError, match="read-only"):
            a[...] = 0
        assert not a.flags.writeable, key


def test_a_copy_cannot_change_the_original():
    fit = FITS["gauss-markov"](*_data())
    rmse = fit.rmse
    copy_ = fit.with_crs("EPSG:25832")
    with pytest.raises(ValueError, match="read-only"):
        copy_.residuals[:] = 0
    assert fit.rmse == rmse
    checked = fit.with_checks(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="read-only"):
        checked.check_residuals[:] = 1


def test_parameters_stay_those_of_the_model():
    fit = FITS["svd"](*_data())
    k = fit.parameter_names.index("scale")
    with pytest.raises(ValueError, match="read-only"):
        fit.parameters[k] = 3.0
    assert fit.params["scale"] == pytest.approx(fit.model.scale, rel=1e-12)


def test_callers_arrays_stay_writable():
    values = np.array([1.0, 2.0])
    cov = np.eye(2)
    res = np.zeros((3, 2))
    fit = Fit(None, "m", ("a", "b"), values, cov, cov, 1.0, 1.0, 1, 4, res)
    assert values.flags.writeable and cov.flags.writeable and res.flags.writeable
    assert not fit.parameters.flags.writeable
    values[0] = 5.0  # the Fit holds a view: the caller's array is the caller's
    assert fit.parameters[0] == 5.0


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda f: pickle.loads(pickle.dumps(f))])
def test_copies_stay_read_only(clone):
    fit = clone(FITS["gauss-markov"](*_data()))
    for key, a in _arrays(fit).items():
        assert not a.flags.writeable, key


def test_bundle_fit_arrays_are_read_only():
    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)
    res = pg.bundle_adjust(sim.block)
    arrays = _arrays(res)
    assert {"residuals", "in_adjustment", "exterior_std"} <= set(arrays)
    for key, a in arrays.items():
        assert not a.flags.writeable, key
    np.testing.assert_allclose(
        res.residuals[res.in_adjustment],
        pg.bundle.reprojection_residuals(res.block)[res.in_adjustment],
        atol=1e-9,
    )


def _ransac_fit():
    rng = np.random.default_rng(1)
    s = rng.normal(size=(20, 3)) * 100
    t = s * 1.5 + 1 + rng.normal(size=(20, 3)) * 0.01
    t[3] += 50
    return pg.absolute_orientation(s, t, robust="ransac", threshold=0.1)


def test_extras_of_a_copy_cannot_change_the_original():
    """Before: writing False into a with_crs copy's inlier mask left the original with 0
    inliers instead of 19; adding a key to the copy's extras added it to the original's."""
    fit = _ransac_fit()
    copy_ = fit.with_crs("EPSG:25832")
    with pytest.raises(ValueError, match="read-only"):
        copy_.extras["inliers"][:] = False
    assert int(fit.extras["inliers"].sum()) == 19
    copy_.extras["note"] = 1
    assert "note" not in fit.extras


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda f: pickle.loads(pickle.dumps(f))])
def test_extras_of_copies_stay_read_only(clone):
    fit = clone(_ransac_fit())
    assert not fit.extras["inliers"].flags.writeable


def test_simulated_truth_is_read_only():
    """Before: zeros written into ``sim.field.coef`` turned ``sim.local_field`` at (100, 200)
    from (0.046, 0.226) px into (0, 0) while the block's observations kept the old field."""
    sim = pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)
    for obj in (sim, sim.field):
        for key, a in _arrays(obj).items():
            assert not a.flags.writeable, key
    clone = pickle.loads(pickle.dumps(sim))
    assert not clone.field.coef.flags.writeable and not clone.local.flags.writeable


def test_adjustment_arrays_are_read_only():
    """Before: ``adj.cofactor[0, 0] *= 4`` after ``Fit.from_adjustment(adj, ...)`` changed the
    Fit's cofactor but not its covariance (computed from it): their ratio went from sigma0^2
    = 4.79e-5 to 1.20e-5."""
    t = np.linspace(0.0, 1.0, 10)
    y = 2.0 * t + 1.0 + 0.01 * np.sin(7.0 * t)
    adj = pg.gauss_markov(
        lambda x: x[0] * t + x[1], [1.0, 0.0], y, jacobian=lambda x: np.column_stack([t, t**0])
    )
    fit = Fit.from_adjustment(adj, None, "line", point_dim=1)
    for key, a in _arrays(adj).items():
        assert not a.flags.writeable, key
    with pytest.raises(ValueError, match="read-only"):
        adj.cofactor[0, 0] *= 4
    assert fit.covariance[0, 0] / fit.cofactor[0, 0] == pytest.approx(fit.sigma0**2)
    bare = pg.gauss_markov(lambda x: x[0] * t + x[1], [1.0, 0.0], y, statistics=False)
    assert not bare.x.flags.writeable


def _snooped_fit():
    ids, x, X = pg.datasets.point_pairs("lidar_wang2014")
    X = X.copy()
    X[3, 0] += 1.0  # a 1 m blunder: removed by the snooping
    return pg.snooping_absolute_orientation(x, X, "gauss-markov", ids=ids)


@pytest.mark.parametrize("make_copy", [
    lambda f: f.with_crs("EPSG:25832"),
    lambda f: f.with_checks(np.zeros((1, 3))),
    lambda f: dataclasses.replace(f, notes=()),
])
def test_nested_extras_of_a_copy_cannot_change_the_original(make_copy):
    """Before: the copies of with_crs / with_checks / replace shared the lists and dicts
    inside ``extras``: appending 9 to a copy's ``extras["removed"]`` turned the original's
    [3] into [3, 9], and a value written into a copy's ``extras["textbook"]`` changed the
    original's."""
    fit = _snooped_fit()
    assert fit.extras["removed"] == [3]  # still a list, compared as one
    copy_ = make_copy(fit)
    copy_.extras["removed"].append(9)
    assert fit.extras["removed"] == [3]
    rng = np.random.default_rng(4)
    x = rng.uniform(-100, 100, (10, 2))
    T = pg.Similarity2D.from_textbook(1.2, 0.3, 5.0, -3.0)
    tfit = pg.estimate_transform("similarity2d", x, T.apply(x) + rng.normal(0, 0.01, (10, 2)))
    expected = tfit.model.textbook()  # the model's own, an independent copy of the numbers
    tcopy = make_copy(tfit)
    for key in list(tcopy.extras["textbook"]):
        tcopy.extras["textbook"][key] = (0.0, 0.0)
    assert {k: v[0] for k, v in tfit.extras["textbook"].items()} == pytest.approx(
        {k: expected[k] for k in tfit.extras["textbook"]}
    )


def test_nested_extras_arrays_stay_read_only_through_copies():
    fit = Fit._construct(**{
        **{f.name: getattr(_ransac_fit(), f.name) for f in dataclasses.fields(Fit)},
        "extras": {"per_image": {"a": [np.arange(3.0)]}},
    })
    for f in (fit, copy.deepcopy(fit), pickle.loads(pickle.dumps(fit)), fit.with_crs("EPSG:25832")):
        assert not f.extras["per_image"]["a"][0].flags.writeable
