"""JSON round trip ``from_dict(json(to_dict()))`` of every transformation model, including
the forms that are easy to lose: a non-orthogonal Similarity3D (``check=False``), rotations
at gimbal lock, singular linear parts, polynomial inverses."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom import transforms as tr
from photogeom.errors import InputError
from photogeom.rotation import matrix_from_quaternion, rotation_from_angles

_num = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
_small = st.floats(-1e-3, 1e-3, allow_nan=False, allow_infinity=False)
_pos = st.floats(1e-3, 1e3, allow_nan=False, allow_infinity=False)
_vec3 = st.lists(_num, min_size=3, max_size=3)


@st.composite
def _rotation(draw):
    """A proper rotation: random (quaternion) or at gimbal lock (phi = +-90 deg)."""
    if draw(st.booleans()):
        q = draw(st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
            lambda v: float(np.dot(v, v)) > 1e-3))
        return matrix_from_quaternion(q)
    w, k = draw(st.floats(-3, 3)), draw(st.floats(-3, 3))
    R = rotation_from_angles(w, draw(st.sampled_from([np.pi / 2, -np.pi / 2])), k)
    return R if draw(st.booleans()) else R.T


@st.composite
def _model(draw):
    kind = draw(st.sampled_from([
        "similarity2d", "affine2d", "affine2d_singular", "projective2d", "polynomial2d",
        "polynomial2d_inverse", "rigid3d", "similarity3d", "similarity3d_raw",
        "similarity3d_helmert", "affine3d", "affine3d_singular", "projective3d",
        "polynomial3d", "polynomial3d_inverse",
    ]))
    if kind == "similarity2d":
        return tr.Similarity2D(*draw(st.lists(_num, min_size=4, max_size=4)))
    if kind == "affine2d":
        return tr.Affine2D(*draw(st.lists(_num, min_size=6, max_size=6)))
    if kind == "affine2d_singular":  # second row a multiple of the first
        a1, a2, a3, f, b3 = draw(st.lists(_num, min_size=5, max_size=5))
        return tr.Affine2D(a1, a2, a3, f * a1, f * a2, b3)
    if kind.startswith("polynomial"):
        dim = 2 if "2d" in kind else 3
        order = draw(st.integers(1, 3))
        n = tr.polynomial_term_count(order, dim)
        coef = np.array(draw(st.lists(_small, min_size=dim * n, max_size=dim * n)))
        coef = coef.reshape(dim, n)
        coef[:, 1:dim + 1] += np.eye(dim)  # the linear terms near the identity
        cls = tr.Polynomial2D if dim == 2 else tr.Polynomial3D
        fwd = cls(order, coef, draw(st.lists(_num, min_size=dim, max_size=dim)), draw(_pos))
        return fwd.inverse() if kind.endswith("inverse") else fwd
    if kind.startswith("projective"):
        dim = 2 if kind.endswith("2d") else 3
        M = np.eye(dim + 1) + np.array(
            draw(st.lists(st.floats(-0.5, 0.5), min_size=(dim + 1) ** 2,
                          max_size=(dim + 1) ** 2))).reshape(dim + 1, dim + 1)
        M[dim, dim] = 1.0
        return (tr.Projective2D if dim == 2 else tr.Projective3D)(M)
    if kind == "rigid3d":
        return tr.Rigid3D(draw(_rotation()), draw(_vec3))
    if kind == "similarity3d":
        return tr.Similarity3D(draw(_pos), draw(_rotation()), draw(_vec3))
    if kind == "similarity3d_raw":  # a non-orthogonal matrix kept as given
        A = np.eye(3) + np.array(draw(st.lists(st.floats(-0.2, 0.2), min_size=9,
                                               max_size=9))).reshape(3, 3)
        return tr.Similarity3D(draw(_pos), A, draw(_vec3), check=False)
    if kind == "similarity3d_helmert":
        t = draw(_vec3)
        r = draw(st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
        return tr.Similarity3D.from_helmert(
            *t, *r, draw(st.floats(-50, 50)),
            convention=draw(st.sampled_from(["position_vector", "coordinate_frame"])),
            rotation=draw(st.sampled_from(["exact", "small-angle"])))
    A = np.array(draw(st.lists(_num, min_size=9, max_size=9))).reshape(3, 3)
    if kind == "affine3d_singular":  # coplanar image: the third row in the span of the others
        A[2] = 0.5 * A[0] - 2.0 * A[1]
    return tr.Affine3D(A, draw(_vec3))


@settings(max_examples=300, deadline=None)
@given(_model(), st.integers(0, 2**32 - 1))
def test_every_model_survives_its_json_round_trip(model, seed):
    data = model.to_dict()
    again = tr.from_dict(json.loads(json.dumps(data, allow_nan=False)))
    assert type(again) is type(model)
    assert again.to_dict() == data
    repr(again)  # never raises (gimbal lock, non-orthogonal matrices)
    pts = np.random.default_rng(seed).uniform(-10, 10, (5, model.dim))
    if isinstance(model, tr.Polynomial2DInverse | tr.Polynomial3DInverse):
        pts = model.forward.apply(pts)  # points the inverse can reach
        np.testing.assert_array_equal(again.apply_with_status(pts).points,
                                      model.apply_with_status(pts).points)
    else:
        np.testing.assert_array_equal(again.apply(pts), model.apply(pts))
    if isinstance(model, tr.Similarity3D):
        assert again.check is model.check


def test_small_angle_helmert_round_trip_reported_case():
    sim = pg.Similarity3D.from_helmert(
        -446.448, 125.157, -542.06, -150.2, -247, -842.1, 20.4894,
        convention="position_vector", rotation="small-angle")
    data = sim.to_dict()
    assert data["check"] is False
    again = tr.from_dict(json.loads(json.dumps(data)))
    np.testing.assert_array_equal(again.rotation, sim.rotation)
    x = np.array([[3_000_000.0, 500_000.0, 5_000_000.0]])
    np.testing.assert_array_equal(again.apply(x), sim.apply(x))


def test_similarity3d_check_entry_must_be_a_boolean():
    data = tr.Similarity3D(1.0, np.eye(3), [0, 0, 0]).to_dict()
    with pytest.raises(InputError, match="'check' must be true or false"):
        tr.from_dict({**data, "check": "no"})
    # an old file without the entry is still read (check defaults to true)
    del data["check"]
    assert tr.from_dict(data).check is True


def test_closed_form_orientation_json_feeds_transform_apply(cli, tmp_path):
    from photogeom import datasets

    kraus = datasets.path("kraus_absolute_orientation")
    code, out, err = cli("orient", "absolute", kraus, "--method", "closed-form", "--json")
    assert code == 0, err
    cf = tmp_path / "cf.json"
    cf.write_text(out)
    assert json.loads(out)["model_parameters"]["check"] is False
    code, out, err = cli("transform", "apply", cf, kraus, "--cols", "x,y,z", "--out-cols",
                         "E,N,H")
    assert code == 0, err
    rows = [line.split(",") for line in out.splitlines() if line[:1].isdigit()]
    got = np.array([[float(v) for v in r[1:4]] for r in rows])
    # peer: the closed-form estimate of the library, applied directly
    pts = pg.io.read_points(kraus, "x,y,z").coords
    fit = pg.absolute_orientation(pts, pg.io.read_points(kraus, "X,Y,Z").coords,
                                  method="closed-form")
    np.testing.assert_allclose(got, fit.model.apply(pts), rtol=0, atol=1e-9)
