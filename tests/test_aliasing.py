"""Data hygiene of the Python API: results pickle and copy, inputs are not kept or changed."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import photogeom as pg


def _pairs(n=12, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-500, 500, (n, 3))
    R = pg.rotation_from_angles(0.1, 0.2, 0.3)
    X = 1.0001 * x @ R.T + [10.0, -20.0, 5.0] + rng.normal(scale=0.01, size=(n, 3))
    return x, X


ABSOLUTE = {
    "svd": lambda x, X: pg.absolute_orientation(x, X),
    "gauss-helmert": lambda x, X: pg.absolute_orientation(x, X, "gauss-helmert"),
    "closed-form": lambda x, X: pg.absolute_orientation(x, X, "closed-form"),
    "no statistics": lambda x, X: pg.absolute_orientation(x, X, statistics=False),
    "ransac": lambda x, X: pg.ransac_absolute_orientation(x, X, threshold=0.1),
    "snooping": lambda x, X: pg.snooping_absolute_orientation(x, X),
    "compare": lambda x, X: pg.compare_absolute_methods(x, X),
}


@pytest.mark.parametrize("name", ABSOLUTE)
def test_absolute_orientation_results_pickle_and_deepcopy(name):
    # parameter_units was a shared types.MappingProxyType: "cannot pickle 'mappingproxy'"
    x, X = _pairs()
    fit = ABSOLUTE[name](x, X)
    for twin in (pickle.loads(pickle.dumps(fit)), copy.deepcopy(fit)):
        assert type(twin) is type(fit)
        if name != "compare":
            np.testing.assert_array_equal(twin.parameters, fit.parameters)
            assert dict(twin.parameter_units) == dict(fit.parameter_units)
            np.testing.assert_array_equal(twin.transform.apply(x), fit.transform.apply(x))


def test_absolute_orientation_parameter_units_are_not_shared_between_fits():
    x, X = _pairs()
    a = pg.absolute_orientation(x, X, unit="m")
    b = pg.absolute_orientation(x, X, unit="m")
    assert a.parameter_units == {
        "tx": "m", "ty": "m", "tz": "m", "omega": "rad", "phi": "rad", "kappa": "rad",
        "scale": "1",
    }
    assert a.parameter_units is not b.parameter_units


@pytest.fixture(scope="module")
def small_block():
    return pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=4, tie_points_per_image=40
    ).block


def _tables(b):
    return dict(
        cameras=b.cameras,
        image_ids=np.array(b.image_ids),
        image_camera=b.camera_ids[b.image_camera],
        exterior=np.array(b.exterior),
        point_ids=np.array(b.point_ids),
        xyz=np.array(b.xyz),
        obs_image_ids=np.array(b.observations.image_ids),
        obs_point_ids=np.array(b.observations.point_ids),
        uv=np.array(b.observations.uv),
        sigma=np.array(b.observations.sigma),
        role=np.array(b.role),
        point_sigma=np.array(b.point_sigma),
    )


def test_block_from_arrays_keeps_no_reference_to_the_callers_ids_and_roles(small_block):
    # before: the id and role arrays were kept as given, so reusing them changed the block
    # (point 0 vanished from block.points while obs_point still pointed at its row)
    t = _tables(small_block)
    b = pg.bundle.Block.from_arrays(**t)
    first = b.point_ids[0].item()
    for key in ("image_ids", "point_ids", "obs_image_ids", "obs_point_ids"):
        t[key][...] = t[key][1]
    t["role"][...] = "check"
    assert b.point_ids[0] == first and first in b.points
    np.testing.assert_array_equal(b.image_ids, small_block.image_ids)
    np.testing.assert_array_equal(b.observations.point_ids, small_block.observations.point_ids)
    np.testing.assert_array_equal(b.role, small_block.role)


def test_block_arrays_are_read_only_so_derived_blocks_cannot_change_each_other(small_block):
    # before: replace / with_observations / bundle_adjust's block shared writable arrays with
    # the block they came from: res.block.observations.uv[0] = ... changed sim.block too
    b = small_block
    uv0 = b.observations.uv.copy()
    derived = [
        b.replace(xyz=b.xyz + 1.0),
        b.with_observations(sigma=0.7),
        b.select_observations(np.ones(b.n_observations, dtype=bool)),
        b.without_datum_observations(),
        pg.bundle_adjust(b, snooping=False).block,
    ]
    for d in (b, *derived):
        for name in ("image_ids", "point_ids", "exterior", "xyz", "role", "point_sigma", "gnss",
                     "obs_image", "obs_point", "calibration_offset"):
            assert not getattr(d, name).flags.writeable, name
        for name in ("image_ids", "point_ids", "uv", "sigma"):
            assert not getattr(d.observations, name).flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            d.observations.uv[0] = 0.0
    np.testing.assert_array_equal(b.observations.uv, uv0)


def test_block_replace_leaves_the_callers_array_writable(small_block):
    xyz = small_block.xyz + 1.0
    b = small_block.replace(xyz=xyz)
    assert xyz.flags.writeable and not b.xyz.flags.writeable
    np.testing.assert_array_equal(b.xyz, xyz)


def test_block_replace_keeps_no_reference_to_the_callers_array(small_block):
    # before: replace(xyz=arr) kept a view of arr, so arr[0] = ... moved point 0 of the block
    xyz = small_block.xyz + 1.0
    exterior = small_block.exterior.copy()
    b = small_block.replace(xyz=xyz, exterior=exterior)
    xyz[0] = 99.0
    exterior[0, :3] = 0.0
    np.testing.assert_array_equal(b.xyz[0], small_block.xyz[0] + 1.0)
    np.testing.assert_array_equal(b.exterior, small_block.exterior)


def test_fit_with_checks_keeps_a_copy_of_the_check_residuals():
    # before: the Fit kept the caller's array, so changing it afterwards changed
    # fit.check_residuals and fit.check_rmse
    x, X = _pairs()
    fit = pg.absolute_orientation(x, X)
    v = np.full((2, 3), 0.01)
    checked = fit.with_checks(v, ["a", "b"])
    rmse = checked.check_rmse
    v[:] = 100.0
    np.testing.assert_array_equal(checked.check_residuals, np.full((2, 3), 0.01))
    assert checked.check_rmse == rmse


def test_bundle_calibration_covariance_cannot_be_changed_for_later_calls(small_block):
    # before: the stored array was returned writable; C[...] = 0 changed what every later
    # call (and a report built from the fit) returned
    fit = pg.bundle_adjust(small_block, snooping=False)
    group = small_block.camera_ids[0].item()
    names, C = fit.calibration_covariance(group)
    before = C.copy()
    with pytest.raises(ValueError, match="read-only"):
        C[...] = 0.0
    np.testing.assert_array_equal(fit.calibration_covariance(group)[1], before)
    assert names and before.shape == (len(names), len(names))


def test_block_free_and_image_variant_are_read_only_mappings(small_block):
    # before: plain dicts shared by derived blocks: b2.free[g] = () changed the free
    # parameters of the block b2 was made from
    b2 = small_block.replace(xyz=small_block.xyz + 1.0)
    group = small_block.camera_ids[0].item()
    free = small_block.free[group]
    with pytest.raises(TypeError):
        b2.free[group] = ()
    with pytest.raises(TypeError):
        b2.image_variant[group] = ("f",)
    assert small_block.free[group] == free and b2.free == {group: free}
    for twin in (pickle.loads(pickle.dumps(b2)), copy.deepcopy(b2)):
        assert twin.free == b2.free and twin.image_variant == b2.image_variant
