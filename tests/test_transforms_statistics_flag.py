"""estimate_transform(..., statistics=False): the same estimate as with statistics, without them.

Every model, few and many points (the solver paths of large problems), weights, check points,
handedness flips, errors in both systems; and bad input is refused the same way.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.errors import DegenerateGeometryError, InputError, TooFewPointsError
from photogeom.estimation import transforms as est


def _pairs(model: str, n: int, seed: int = 0, noise: float = 0.01):
    """Noisy point pairs of a random transformation of the model's kind (large coordinates
    on the target side, as in practice)."""
    rng = np.random.default_rng(seed)
    if model.endswith("2d"):
        src = rng.uniform(0, 4000, (n, 2))
        if model == "projective2d":
            H = np.array([[0.97, -0.03, 6.4], [-0.016, 0.97, 4.5], [-1e-5, -3e-5, 1.0]])
            h = np.column_stack([src, np.ones(n)]) @ H.T
            dst = h[:, :2] / h[:, 2:]
        elif model == "polynomial2d":
            dst = src @ [[0.9, 0.1], [-0.2, 1.1]] + 1e-5 * src**2 + [5e5, 4e6]
        else:
            dst = src @ [[0.95, -0.07], [0.09, 1.03]] + [512_000.0, 4_215_000.0]
    else:
        src = rng.uniform(-1, 1, (n, 3))
        R = pg.opk_matrix(0.3, -0.2, 2.5).T
        if model == "projective3d":
            H = np.eye(4)
            H[:3, :3] = 2.0 * R
            H[3, :3] = [0.01, -0.02, 0.015]
            h = np.column_stack([src, np.ones(n)]) @ H.T
            dst = h[:, :3] / h[:, 3:]
        elif model == "affine3d":
            dst = src @ (R * [1.0, 1.2, 0.8]).T + [5e5, 4e6, 300.0]
        elif model == "polynomial3d":
            dst = src @ R.T + 0.01 * src**2 + 3.0
        else:
            scale = 1.0 if model == "rigid3d" else 250.0
            dst = scale * src @ R.T + [512_000.0, 4_215_000.0, 350.0]
    return src, dst + rng.normal(0, noise, dst.shape)


MODELS = [
    ("similarity2d", None),
    ("affine2d", None),
    ("projective2d", None),
    ("polynomial2d", 2),
    ("rigid3d", None),
    ("similarity3d", None),
    ("affine3d", None),
    ("projective3d", None),
    ("polynomial3d", 2),
]


def _both(model, src, dst, **kw):
    full = pg.estimate_transform(model, src, dst, **kw)
    bare = pg.estimate_transform(model, src, dst, statistics=False, **kw)
    return full, bare


def _assert_same_estimate(full, bare, rtol=1e-12):
    assert type(bare.model) is type(full.model)
    assert bare.parameter_names == full.parameter_names
    scale = np.maximum(np.abs(full.parameters), 1e-300)
    err = np.max(np.abs(bare.parameters - full.parameters) / scale)
    assert err <= rtol, f"parameters differ by {err:.1e} (relative)"


def _assert_bare(fit, d):
    u = len(fit.parameter_names)
    assert fit.residuals.shape == (0, d)
    assert fit.covariance.shape == (u, u) and np.all(np.isnan(fit.covariance))
    assert np.all(np.isnan(fit.cofactor)) and np.isnan(fit.sigma0)
    assert fit.normalized_residuals is None and fit.redundancy_numbers is None
    assert sum("statistics=False" in note for note in fit.notes) == 1
    assert not fit.covariance.flags.writeable and not fit.residuals.flags.writeable
    assert "textbook" not in fit.extras and "linearised" not in fit.extras


@pytest.mark.parametrize("model, order", MODELS)
@pytest.mark.parametrize("n", [12, 300])
def test_same_estimate_every_model(model, order, n):
    src, dst = _pairs(model, n, seed=n)
    full, bare = _both(model, src, dst, order=order)
    _assert_same_estimate(full, bare)
    d = 2 if model.endswith("2d") else 3
    _assert_bare(bare, d)
    assert bare.redundancy == full.redundancy and bare.n_observations == full.n_observations
    assert bare.converged and bare.iterations == full.iterations
    # the bare fit is a working transformation
    np.testing.assert_allclose(bare.model.apply(src), full.model.apply(src), rtol=1e-12,
                               atol=1e-9)


@pytest.mark.parametrize(
    "model, n",
    [("affine2d", 5000), ("affine3d", 3000), ("projective2d", 5000), ("similarity3d", 70001)],
)
def test_same_estimate_large_problems(model, n):
    """Many points take other solver paths (coordinates solved separately, normal equations,
    one-pass moments): still the same estimate with and without statistics."""
    src, dst = _pairs(model, n, seed=7)
    full, bare = _both(model, src, dst)
    _assert_same_estimate(full, bare, rtol=1e-11)
    _assert_bare(bare, src.shape[1])


def test_projective_keeps_the_nonlinear_adjustment():
    """Without statistics the projective fit is still the adjustment of the rational form,
    not the linearised solution."""
    src, dst = _pairs("projective2d", 40, seed=3, noise=0.5)
    full, bare = _both("projective2d", src, dst)
    lin = np.array([full.extras["linearised"]["parameters"][k] for k in full.parameter_names])
    assert np.max(np.abs(lin - bare.parameters) / np.abs(bare.parameters)) > 1e-6
    _assert_same_estimate(full, bare)
    assert bare.iterations >= 1 and bare.method == full.method


def test_errors_in_both_systems():
    src, dst = _pairs("projective2d", 30, seed=5, noise=0.05)
    src = src + np.random.default_rng(6).normal(0, 0.05, src.shape)
    full, bare = _both("projective2d", src, dst, errors_in="both")
    _assert_same_estimate(full, bare)
    _assert_bare(bare, 2)
    assert "source_residuals" not in bare.extras


@pytest.mark.parametrize("model", ["similarity2d", "affine2d", "projective2d", "affine3d",
                                   "similarity3d"])
def test_weights_check_points_and_ids(model):
    src, dst = _pairs(model, 40, seed=11)
    n = src.shape[0]
    w = np.random.default_rng(2).uniform(0.5, 2.0, n)
    check = np.zeros(n, bool)
    check[::5] = True
    ids = [f"P{i}" for i in range(n)]
    full, bare = _both(model, src, dst, weights=w, check=check, ids=ids, unit="m")
    _assert_same_estimate(full, bare)
    assert bare.ids == full.ids and bare.check_ids == full.check_ids
    np.testing.assert_allclose(bare.check_residuals, full.check_residuals, atol=1e-9)
    assert bare.residual_unit == full.residual_unit
    _assert_bare(bare, src.shape[1])
    assert bare.elapsed > 0 and bare.extras.keys() == full.extras.keys() - {
        "textbook", "textbook_units", "textbook_cofactor", "linearised", "helmert", "handedness"}


def test_handedness_flip():
    rng = np.random.default_rng(4)
    px = rng.uniform(0, 3000, (20, 2))
    mm = np.c_[px[:, 0], -px[:, 1]] * 0.01 + rng.normal(0, 1e-3, (20, 2))
    kw = dict(source_system="pixel", target_system="image")
    for model in ("similarity2d", "affine2d", "projective2d"):
        full, bare = _both(model, px, mm, **kw)
        _assert_same_estimate(full, bare)
        assert bare.extras["handedness"] == full.extras["handedness"]
        assert bare.extras["handedness"]["source_flip_y"]


def test_covariance_per_point():
    src, dst = _pairs("affine2d", 25, seed=8)
    rng = np.random.default_rng(9)
    m = rng.normal(size=(25, 2, 2)) * 0.01
    cov = m @ np.swapaxes(m, 1, 2) + 1e-4 * np.eye(2)
    full, bare = _both("affine2d", src, dst, covariance=cov)
    _assert_same_estimate(full, bare)


@pytest.mark.parametrize("statistics", [True, False])
def test_bad_input_is_refused_the_same_way(statistics):
    kw = {"statistics": statistics}
    src, dst = _pairs("affine2d", 12)
    bad = src.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match=r"source: 1 row\(s\) contain NaN.*row index 3"):
        pg.estimate_transform("affine2d", bad, dst, **kw)
    s3, d3 = _pairs("similarity3d", 12)
    bad3 = d3.copy()
    bad3[7, 2] = np.inf
    with pytest.raises(InputError, match=r"target: 1 row\(s\).*row index 7"):
        pg.estimate_transform("similarity3d", s3, bad3, **kw)
    with pytest.raises(TooFewPointsError, match="at least 4 needed"):
        pg.estimate_transform("projective2d", src[:3], dst[:3], **kw)
    with pytest.raises(TooFewPointsError, match="at least 3 needed"):
        pg.estimate_transform("similarity3d", s3[:2], d3[:2], **kw)
    t = np.linspace(0, 10, 8)
    line = np.c_[t, 2 * t + 1]
    for model in ("affine2d", "projective2d"):
        with pytest.raises(DegenerateGeometryError, match="collinear"):
            pg.estimate_transform(model, line, line * 2, **kw)
    line3 = np.c_[t, 2 * t, -t]
    with pytest.raises(DegenerateGeometryError, match="similarity3d: the 8 source points are "
                                                      "collinear"):
        pg.estimate_transform("similarity3d", line3, line3 + 1, **kw)
    with pytest.raises(InputError, match=r"shape \(n, 3\)"):
        pg.estimate_transform("similarity3d", src, dst, **kw)


def test_collinear_target_of_a_similarity_is_named():
    """A target set on one line (the source spread out) is refused naming the target side,
    although the cross-covariance alone would not show it at this tolerance."""
    rng = np.random.default_rng(12)
    src = rng.normal(size=(10, 3))
    t = rng.normal(size=10)
    dst = np.c_[t, 2 * t, 3 * t] * 1e3 + 1e-9 * rng.normal(size=(10, 3))
    for statistics in (True, False):
        with pytest.raises(DegenerateGeometryError, match="10 target points are collinear"):
            pg.estimate_transform("similarity3d", src, dst, statistics=statistics)


def test_linearised_start_from_normal_equations_equals_qr(monkeypatch):
    """The linearised projective solution of many points comes from moment-built normal
    equations (eigen-decomposition); it equals the QR solution of the design."""
    for model, n in (("projective2d", 800), ("projective3d", 500)):
        src, dst = _pairs(model, n, seed=21, noise=0.05)
        ref = pg.estimate_transform(model, src, dst)
        monkeypatch.setattr(est, "NORMAL_FROM", 0)
        fast = pg.estimate_transform(model, src, dst)
        monkeypatch.undo()
        a = np.array(list(ref.extras["linearised"]["parameters"].values()))
        b = np.array(list(fast.extras["linearised"]["parameters"].values()))
        np.testing.assert_allclose(b, a, rtol=1e-10, atol=1e-14)
        assert fast.extras["linearised"]["vtv"] == pytest.approx(
            ref.extras["linearised"]["vtv"], rel=1e-10)
        _assert_same_estimate(ref, fast, rtol=1e-9)


def test_exact_projective_data_falls_back_to_qr(monkeypatch):
    """Noise-free points make the linearised normal matrix singular: the QR path decides."""
    src, dst = _pairs("projective2d", 50, seed=2, noise=0.0)
    monkeypatch.setattr(est, "NORMAL_FROM", 0)
    fit = pg.estimate_transform("projective2d", src, dst)
    H = np.array([[0.97, -0.03, 6.4], [-0.016, 0.97, 4.5], [-1e-5, -3e-5, 1.0]])
    np.testing.assert_allclose(fit.model.matrix, H, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_cheap_geometry_certificate_never_overrules_the_rank_rule(d):
    """The scatter-based certificate may only skip the exact rank check when that check
    passes: point sets flattened to ratios around the rule's 1e-10 and beyond, far from the
    origin or not."""
    rng = np.random.default_rng(d)
    for ratio in (1e-3, 1e-6, 1e-8, 1e-10, 1e-11, 1e-13, 0.0):
        for offset in (0.0, 1e6):
            for n in (d + 1, 30, 4000):
                pts = rng.normal(size=(n, d))
                pts[:, -1] *= ratio
                pts = pts @ np.linalg.qr(rng.normal(size=(d, d)))[0] + offset
                for need in range(2, d + 1):
                    if est._spread_certified(pts, need):
                        assert est._rank(pts)[0] >= need, (ratio, offset, n, need)
    # a clearly spread set is certified (the cheap path is taken)
    assert est._spread_certified(rng.normal(size=(20, d)), d)


@pytest.mark.parametrize("d", [2, 3])
def test_joint_certificate_of_two_point_sets(d):
    """One scatter of both sets certifies each of them exactly when the separate certificates
    do (and so never overrules the rank rule either): flattened sets on either side, far from
    the origin or not."""
    rng = np.random.default_rng(10 + d)
    sets = []
    for ratio in (1.0, 1e-6, 1e-11, 1e-13, 0.0):
        for offset in (0.0, 1e6):
            pts = rng.normal(size=(25, d))
            pts[:, -1] *= ratio
            sets.append(pts @ np.linalg.qr(rng.normal(size=(d, d)))[0] + offset)
    for a in sets:
        for b in sets[::3]:
            for need in range(2, d + 1):
                separate = est._spread_certified(a, need) and est._spread_certified(b, need)
                assert est._CentredPair.of(a, b).certified(need) == separate
