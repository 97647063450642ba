"""estimate_transform: a 3D affinity fitted to coplanar targets (singular linear part) is
returned with and without statistics, its textbook form reported undefined; a projective
solution that sends the source origin to infinity gets advice that fits the cause."""

from __future__ import annotations

import json

import numpy as np
import pytest

import photogeom as pg
from photogeom import transforms as tr
from photogeom.errors import DegenerateGeometryError, InputError

# --- affine3d onto a plane ---------------------------------------------------------------


def _coplanar(noise: float = 0.0, seed: int = 1):
    """Source points in space, target points on the plane Z = 0.5 X - 2 Y - 1."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(-10, 10, (9, 3))
    xy = src @ np.array([[1.0, 0.2, 0.1], [0.3, 1.1, -0.2]]).T + [10.0, 20.0]
    xy += rng.normal(0.0, noise, xy.shape)
    dst = np.column_stack([xy, 0.5 * xy[:, 0] - 2.0 * xy[:, 1] - 1.0])
    return src, dst


def _by_hand(src, dst):
    """Independent least squares: [x 1] @ M = X, one column per target coordinate."""
    D = np.column_stack([src, np.ones(len(src))])
    M = np.linalg.lstsq(D, dst, rcond=None)[0]  # (4, 3)
    return M[:3].T, M[3]


@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_coplanar_target_estimate_with_and_without_statistics(noise):
    src, dst = _coplanar(noise)
    A, t = _by_hand(src, dst)
    assert abs(np.linalg.det(A)) < 1e-12  # the plane: the linear part is singular
    full = pg.estimate_transform("affine3d", src, dst)
    bare = pg.estimate_transform("affine3d", src, dst, statistics=False)
    for fit in (full, bare):
        np.testing.assert_allclose(fit.model.linear, A, atol=1e-9)
        np.testing.assert_allclose(fit.model.translation, t, atol=1e-9)
        assert fit.model.singular
        assert any("singular" in n and "coplanar" in n for n in fit.notes)
    np.testing.assert_allclose(bare.parameters, full.parameters, rtol=0, atol=1e-12)
    tb = full.extras["textbook"]
    for name in ("sx", "sy", "sz", "shear_xy", "shear_xz", "shear_yz", "omega", "phi",
                 "kappa"):
        assert np.isnan(tb[name][0]) and np.isnan(tb[name][1])
    # the shifts are defined: the parametric tx, ty, tz with their standard deviations
    sd = np.sqrt(np.diag(full.covariance))[-3:]
    for k, name in enumerate(("tx", "ty", "tz")):
        assert tb[name][0] == pytest.approx(t[k], abs=1e-9)
        assert tb[name][1] == pytest.approx(sd[k], rel=1e-9, abs=1e-15)
    json.dumps(full.to_dict(), allow_nan=False)  # NaN written as null
    with pytest.raises(InputError, match="singular"):
        full.model.textbook()  # asked explicitly: refused with the reason
    with pytest.raises(DegenerateGeometryError, match="no inverse"):
        full.model.inverse()


def test_coplanar_target_on_the_command_line(cli, tmp_path):
    src, dst = _coplanar()
    lines = ["id,x,y,z,X,Y,Z"] + [
        f"{i},{','.join(repr(float(v)) for v in (*p, *q))}"
        for i, (p, q) in enumerate(zip(src, dst, strict=True))
    ]
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("\n".join(lines) + "\n")
    code, out, err = cli("transform", "estimate", "affine3d", pairs, "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["extras"]["textbook"]["sx"] == [None, None]
    assert any("singular" in n for n in data["notes"])
    code, out, err = cli("transform", "estimate", "affine3d", pairs)
    assert code == 0, err and "singular" in out


def test_near_coplanar_but_regular_target_keeps_its_textbook():
    src, dst = _coplanar()
    dst[:, 2] += np.random.default_rng(3).normal(0, 1e-3, len(dst))  # off the plane
    fit = pg.estimate_transform("affine3d", src, dst)
    assert not fit.model.singular and not any("singular" in n for n in fit.notes)
    assert np.isfinite([v for v, _ in fit.extras["textbook"].values()]).all()
    assert tr.Affine3D.from_textbook(
        [fit.extras["textbook"][n][0] for n in ("sx", "sy", "sz")],
        [fit.extras["textbook"][n][0] for n in ("shear_xy", "shear_xz", "shear_yz")],
        *(fit.extras["textbook"][n][0] for n in ("omega", "phi", "kappa")),
        fit.model.translation,
    ).linear == pytest.approx(fit.model.linear, abs=1e-9)


# --- projective: the source origin sent to infinity --------------------------------------


def _proj(H, p):
    q = np.column_stack([p, np.ones(len(p))]) @ H.T
    return q[:, :-1] / q[:, -1:]


@pytest.mark.parametrize("errors_in", ["target", "both"])
def test_four_of_five_collinear_through_the_origin_is_called_degenerate(errors_in):
    src = np.array([[0, 0], [1, 0.5], [2, 1], [3, 1.5], [-1, 4]], dtype=float)
    dst = np.random.default_rng(0).normal(size=(5, 2))
    with pytest.raises(DegenerateGeometryError) as info:
        pg.estimate_transform("projective2d", src, dst, errors_in=errors_in)
    msg = str(info.value)
    assert "general position" in msg and "shift" not in msg
    # and indeed no shift helps: the configuration stays degenerate
    with pytest.raises(DegenerateGeometryError):
        pg.estimate_transform("projective2d", src + np.array([5.0, 7.0]), dst, errors_in=errors_in)


@pytest.mark.parametrize("n", [4, 6])
def test_a_true_transformation_of_the_origin_to_infinity_is_told_to_shift(n):
    H = np.array([[1.0, 0.2, 3.0], [0.1, 1.0, -2.0], [0.1, 0.05, 0.0]])  # h33 = 0
    src = np.array([[1, 1], [2, -1], [-1, 3], [3, 2], [-2, -1], [1, -4]], dtype=float)[:n]
    with pytest.raises(DegenerateGeometryError, match="shift the source coordinates"):
        pg.estimate_transform("projective2d", src, _proj(H, src))
    # the advice works: shifted source coordinates give the transformation, checked by hand
    fit = pg.estimate_transform("projective2d", src + 10.0, _proj(H, src))
    probe = np.array([[0.5, 2.0], [-1.5, 0.3]])
    np.testing.assert_allclose(fit.model.apply(probe + 10.0), _proj(H, probe), atol=1e-8)


def test_affine2d_fitted_to_collinear_targets_says_it_is_singular():
    """A 2D affinity onto collinear target points maps the plane onto a line: the fit says
    so (as the 3D affinity onto a plane does), and a regular fit does not."""
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 100, (10, 2))
    t = rng.uniform(0, 1, 10)
    fit = pg.estimate_transform("affine2d", x, np.c_[t * 50 + 3, t * 20 + 1])
    assert fit.model.singular and fit.model.textbook()["sx"] == pytest.approx(0, abs=1e-12)
    assert any("singular" in n and "collinear" in n for n in fit.notes)
    with pytest.raises(DegenerateGeometryError, match="singular"):
        fit.model.inverse()
    regular = pg.estimate_transform("affine2d", x, x @ [[1.1, 0.2], [-0.1, 0.9]] + 5)
    assert not regular.model.singular and not any("singular" in n for n in regular.notes)


def test_from_dict_names_a_missing_parameter():
    """A parameter set without one of its model's entries: an InputError naming the entry
    (a bare KeyError 'omega' before)."""
    with pytest.raises(InputError, match="similarity3d parameters without the entry 'omega'"):
        tr.from_dict({"model": "similarity3d", "scale": 1.0})
    with pytest.raises(InputError, match="affine2d parameters without the entry"):
        tr.from_dict({"model": "affine2d", "a1": 1.0})
