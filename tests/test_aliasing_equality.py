"""Equality and hashing of the transformation models (value semantics, never an error)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import photogeom as pg

T = pg.transforms


def _models():
    rng = np.random.default_rng(0)
    x2 = rng.uniform(-5, 5, (30, 2))
    x3 = rng.uniform(-5, 5, (30, 3))
    R = pg.rotation_from_angles(0.1, 0.2, 0.3)
    poly2 = pg.estimate_transform("polynomial2d", x2, 1.1 * x2 + 0.01 * x2**2, order=2).model
    return {
        "Similarity2D": T.Similarity2D(1.1, 0.2, 3.0, 4.0),
        "Affine2D": T.Affine2D(1.1, 0.2, 3.0, 0.1, 0.9, 4.0),
        "Projective2D": T.Projective2D.from_parameters([1.1, 0.2, 3, 0.1, 0.9, 4, 1e-4, 2e-4]),
        "Rigid3D": T.Rigid3D(R, [1.0, 2.0, 3.0]),
        "Similarity3D": T.Similarity3D(1.1, R, [1.0, 2.0, 3.0]),
        "Affine3D": T.Affine3D(np.eye(3) * 1.1 + 0.01, [1.0, 2.0, 3.0]),
        "Projective3D": pg.estimate_transform("projective3d", x3, 1.1 * x3 + 1.0).model,
        "Polynomial2D": poly2,
        "Polynomial3D": pg.estimate_transform("polynomial3d", x3, 1.1 * x3 + 1, order=2).model,
        "Polynomial2DInverse": poly2.inverse(),
    }


MODELS = _models()


@pytest.mark.parametrize("name", MODELS)
def test_equal_models_compare_equal_and_hash_alike(name):
    # before: every model holding arrays raised ValueError ("truth value of an array ... is
    # ambiguous") on ==, and TypeError ("unhashable type: 'numpy.ndarray'") on hash
    m = MODELS[name]
    twins = [copy.deepcopy(m), pickle.loads(pickle.dumps(m))]
    if hasattr(m, "to_dict"):
        twins.append(T.from_dict(m.to_dict()))
    for twin in twins:
        assert twin is not m
        assert twin == m and not (twin != m)
        assert hash(twin) == hash(m)
    assert m in [object(), twins[0]] and len({m, *twins}) == 1


@pytest.mark.parametrize("name", [n for n in MODELS if hasattr(MODELS[n], "with_parameters")])
def test_models_with_other_values_differ(name):
    m = MODELS[name]
    p = np.array(m.parameters, dtype=float)
    p[-1] += 1e-9
    other = m.with_parameters(p)
    assert other != m and not (other == m)


def test_models_of_other_classes_or_other_objects_differ():
    rig = MODELS["Rigid3D"]
    sim = T.Similarity3D(1.0, rig.rotation, rig.translation)
    assert rig != sim and sim != rig and rig != "Rigid3D" and rig != 1


def test_negative_zero_equals_zero_and_hashes_alike():
    a = T.Rigid3D(np.eye(3), [0.0, 0.0, 0.0])
    b = T.Rigid3D(np.eye(3), [-0.0, 0.0, -0.0])
    assert a == b and hash(a) == hash(b)


def test_pixel_system_keeps_its_own_read_only_pairs_and_compares_by_value():
    from photogeom.imagecoords import PixelSystem

    # before: the caller's principal-point array was kept, so changing it moved the
    # principal point of the pixel system (to_image of (100, 200) gave (0.4, 0) mm)
    pp = np.array([100.0, 200.0])
    size = np.array([0.004, 0.004])
    ps = PixelSystem(size, pp, focal_length=35.0)
    pp[0] = 0.0
    size[1] = 1.0
    np.testing.assert_array_equal(ps.principal_point, [100.0, 200.0])
    np.testing.assert_array_equal(ps.pixel_size, [0.004, 0.004])
    assert not ps.principal_point.flags.writeable
    twin = PixelSystem(0.004, (100, 200), focal_length=35.0)
    assert ps == twin and hash(ps) == hash(twin) and ps == copy.deepcopy(ps)
    assert ps != PixelSystem(0.004, (100, 201), focal_length=35.0)


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=4, tie_points_per_image=40
    ).block


def test_block_image_and_point_records_compare_by_value(block):
    # before: == raised ValueError (array fields) for two views of the same image or point
    i, j = block.image_ids[:2].tolist()
    p, q = block.point_ids[:2].tolist()
    assert block.images[i] == block.images[i] and block.images[i] != block.images[j]
    assert block.points[p] == block.points[p] and block.points[p] != block.points[q]
    moved = block.replace(xyz=block.xyz + 1.0)
    assert moved.points[p] != block.points[p]


def test_result_records_compare_by_identity_without_error():
    io = pg.InteriorOrientation(100.0)
    e1 = pg.ExteriorOrientation.from_degrees(0, 0, 800, 1, -2, 3)
    e2 = pg.ExteriorOrientation.from_degrees(300, 10, 805, -2, 1, 5)
    g = np.array([[0.0, 0.0, 10.0], [100.0, 50.0, 20.0], [200.0, -30.0, 0.0]])
    xy = np.stack([pg.project(g, io, e1), pg.project(g, io, e2)])
    r = pg.space_intersection(xy, [(io, e1), (io, e2)])
    x, X = np.random.default_rng(0).uniform(-5, 5, (2, 2, 10, 3))
    b = pg.absolute_orientation_batch(x, X * 1.1 + 1.0)
    for res in (r, b):
        twin = copy.deepcopy(res)
        assert res == res and res != twin and len({res, twin}) == 2
