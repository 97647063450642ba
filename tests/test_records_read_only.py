"""Every public result record holds read-only arrays, as a Fit does.

Before: the arrays of ``IntersectionResult``, ``BatchOrientation``, ``BatchResection``,
``LocalizationResult``, ``UndistortResult``, ``RPCIntersection``, ``Triangulation``,
``ModelPoints``, ``ParallaxReport``, ``RansacResult``, ``SnoopingResult``, the point tables
and the cloud records were writable: ``res.sigma0[:] = 0`` changed ``res.covariance`` of an
intersection, ``batch.degenerate[0] = True`` made a valid problem invalid, and pickled or
deep-copied records came back writable whatever the original.
"""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust.conditioning import normalize_points
from photogeom.adjust.ransac import ransac
from photogeom.adjust.snooping import data_snooping
from photogeom.bundle.triangulate import triangulate
from photogeom.io.points import PointBlocks, join_points, parse_points
from photogeom.orientation.stereo_model import model_points, parallax_report

IO = pg.InteriorOrientation(152.0, 0.01, -0.02)
EOS = [
    pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
    pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8),
    pg.ExteriorOrientation.from_degrees(1300, 1300, 1580, 3, -2, 95),
]


def _ground(n=6):
    rng = np.random.default_rng(0)
    return np.column_stack(
        [rng.uniform(1050, 1550, n), rng.uniform(750, 1100, n), rng.uniform(100, 300, n)]
    )


def _intersection():
    g = _ground()
    obs = np.stack([pg.project(g, IO, e) for e in EOS]) + 1e-3
    return pg.space_intersection(obs, [(IO, e) for e in EOS])


def _batch_orientation():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(2, 6, 3)) * 100
    return pg.absolute_orientation_batch(src, 2.0 * src + 1.0, residual_rms=True)


def _batch_resection():
    g = _ground(8)
    img = np.stack([pg.project(g, IO, e) for e in EOS[:2]])
    start = np.array([[e.X0 + 5, e.Y0, e.Z0, e.omega, e.phi, e.kappa] for e in EOS[:2]])
    return pg.space_resection_batch(np.stack([g, g]), img, IO, start)


def _rpc():
    return pg.RPC.from_file(pg.datasets.path("ikonos"))


def _localization():
    rpc = _rpc()
    c0, c1, r0, r1 = rpc.image_bounds
    return rpc.localize(
        np.array([c0 + 10.0, c1 - 10.0]), np.array([r0 + 10.0, r1 - 10.0]), 100.0,
        full_output=True,
    )


def _rpc_intersection():
    pair = [_rpc(), pg.RPC.from_file(pg.datasets.path("pleiades"))]
    g = np.array([[-56.17, -34.9, 50.0], [-56.15, -34.89, 20.0]])
    obs = np.stack([np.column_stack(r.project(*g.T)) for r in pair], axis=1)
    return pg.intersect_rpc(pair, obs)


def _undistort():
    return pg.BrownDistortion(k1=-0.03, p1=1e-4).undistort(np.array([[0.1, 0.2], [0.3, -0.1]]))


def _sim():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=3)


def _triangulation():
    block = _sim().block
    return triangulate(block, block.point_ids[:5], covariance=True)


def _relative():
    rng = np.random.default_rng(3)
    io = pg.InteriorOrientation(100.0, 0.0, 0.0)
    e1 = pg.ExteriorOrientation(0.0, 0.0, 1000.0, 0.0, 0.0, 0.0)
    e2 = pg.ExteriorOrientation(300.0, 5.0, 1002.0, 0.01, -0.02, 0.03)
    g = np.column_stack(
        [rng.uniform(-200, 500, 15), rng.uniform(-300, 300, 15), rng.uniform(0, 80, 15)]
    )
    xy1 = pg.project(g, io, e1) + rng.normal(0, 0.003, (15, 2))
    xy2 = pg.project(g, io, e2) + rng.normal(0, 0.003, (15, 2))
    return pg.relative_orientation(xy1, xy2, io)


def _ransac():
    rng = np.random.default_rng(4)
    y = rng.normal(size=30)
    y[3] = 50.0

    def solve(samples):
        return y[samples].mean(axis=1), np.ones(len(samples), dtype=bool)

    return ransac(30, 2, solve, lambda m: np.abs(y[None, :] - m[:, None]), 3.0, rng=1)


def _snooping():
    t = np.linspace(0.0, 1.0, 10)
    y = 2.0 * t + 1.0 + 0.01 * np.sin(7.0 * t)
    adj = pg.gauss_markov(
        lambda x: x[0] * t + x[1], [1.0, 0.0], y, weights=np.full(10, 1e4),
        jacobian=lambda x: np.column_stack([t, t**0]),
    )
    return data_snooping(adj)


TEXT = "id,x,y,z,X,Y,Z\n1,0,0,0,10,0,0\n2,1,0,0,11,0,0\n3,0,1,0,10,1,0\n4,0,0,1,10,0,1\n"


def _point_table():
    return parse_points(TEXT, "x,y,z", id_column="id")


def _point_pairs():
    return join_points(
        parse_points(TEXT, "x,y,z", id_column="id"), parse_points(TEXT, "X,Y,Z", id_column="id")
    )


def _point_block(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text(TEXT)
    return next(iter(PointBlocks(p, "x,y,z", id_column="id")))


def _cloud(tmp_path, name="c.las"):
    from photogeom.io.cloud import write_cloud

    rng = np.random.default_rng(5)
    xyz = rng.uniform(0, 100, (50, 3)) + np.array([500000.0, 5400000.0, 300.0])
    return write_cloud(tmp_path / name, xyz, crs="EPSG:25832"), xyz


def _cloud_info(tmp_path):
    from photogeom.io.cloud import cloud_info

    return cloud_info(_cloud(tmp_path)[0])


def _cloud_transform(tmp_path):
    from photogeom.io.cloud import transform_cloud

    path, _ = _cloud(tmp_path)
    T = pg.transforms.Similarity3D(1.0, np.eye(3), [1.0, 2.0, 3.0])
    return transform_cloud(path, tmp_path / "out.las", T)


def _cloud_registration(tmp_path):
    from photogeom.io.cloud import write_cloud

    path, xyz = _cloud(tmp_path)
    rng = np.random.default_rng(6)
    target = write_cloud(tmp_path / "t.las", xyz + 1.0 + rng.normal(0, 0.01, xyz.shape),
                         crs="EPSG:25832")
    return pg.distributed.register_clouds(path, target, check_every=5, scheduler="sync")


def _approximate_inverse():
    from photogeom.rpc import approximate_inverse

    return approximate_inverse(_rpc())


RECORDS = {
    "ApproximateInverse": lambda tmp: _approximate_inverse(),
    "IntersectionResult": lambda tmp: _intersection(),
    "BatchOrientation": lambda tmp: _batch_orientation(),
    "BatchResection": lambda tmp: _batch_resection(),
    "LocalizationResult": lambda tmp: _localization(),
    "RPCIntersection": lambda tmp: _rpc_intersection(),
    "UndistortResult": lambda tmp: _undistort(),
    "Triangulation": lambda tmp: _triangulation(),
    "ModelPoints": lambda tmp: model_points(_relative()),
    "ParallaxReport": lambda tmp: parallax_report(_relative()),
    "RansacResult": lambda tmp: _ransac(),
    "SnoopingResult": lambda tmp: _snooping(),
    "PointTable": lambda tmp: _point_table(),
    "PointPairs": lambda tmp: _point_pairs(),
    "PointBlock": _point_block,
    "CloudInfo": _cloud_info,
    "CloudTransformResult": _cloud_transform,
    "CloudRegistration": _cloud_registration,
    "AffineDecomposition": lambda tmp: pg.transforms.Affine3D(
        np.diag([2.0, 3.0, 4.0]) + 0.1, [0.0, 0.0, 0.0]
    ).decompose(),
    "PointNormalization": lambda tmp: normalize_points(np.arange(12.0).reshape(4, 3) ** 1.5),
    "WaveTerrain": lambda tmp: _sim().terrain,
    "Image": lambda tmp: (lambda b: b.images[b.image_ids[0]])(_sim().block),
    "Point": lambda tmp: (lambda b: b.points[b.point_ids[0]])(_sim().block),
}


def _arrays(obj) -> dict:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize("name", sorted(RECORDS))
def test_result_record_arrays_are_read_only(name, tmp_path):
    rec = RECORDS[name](tmp_path)
    assert type(rec).__name__ == name
    arrays = _arrays(rec)
    assert arrays, f"{name} holds no arrays"
    for key, a in arrays.items():
        assert not a.flags.writeable, f"{name}.{key} is writable"
        with pytest.raises(ValueError, match="read-only"):
            a[...] = a
    for clone in (copy.deepcopy(rec), pickle.loads(pickle.dumps(rec))):
        assert type(clone) is type(rec)
        for key, a in _arrays(clone).items():
            assert not a.flags.writeable, f"a copy's {name}.{key} is writable"
            np.testing.assert_array_equal(a, arrays[key])


@pytest.mark.parametrize(
    "name", ["ApproximateInverse", "ModelPoints", "ParallaxReport", "PointNormalization",
             "RansacResult"]
)
def test_records_compare_by_identity(name, tmp_path):
    """Before: ``==`` of two of these raised "the truth value of an array with more than one
    element is ambiguous" and ``hash`` "unhashable type: 'numpy.ndarray'"."""
    a, b = RECORDS[name](tmp_path), RECORDS[name](tmp_path)
    assert a == a and a != b
    assert len({a, b, a}) == 2


def test_a_write_cannot_change_an_intersections_statistics():
    """Before: ``res.sigma0[:] = 0`` zeroed ``res.covariance`` and ``res.std``."""
    res = _intersection()
    std = res.std.copy()
    with pytest.raises(ValueError, match="read-only"):
        res.sigma0[:] = 0.0
    np.testing.assert_array_equal(res.std, std)


def test_the_cached_inverse_of_an_rpc_cannot_be_changed():
    """Before: zeros written into ``approximate_inverse(rpc).coefficients`` changed the
    inverse cached on ``rpc``: its localisations then took 2 Newton iterations instead of 1."""
    from photogeom.rpc import approximate_inverse

    rpc = _rpc()
    c0, c1, r0, r1 = rpc.image_bounds
    col, row = np.linspace(c0, c1, 5), np.linspace(r0, r1, 5)
    before = rpc.localize(col, row, 50.0, full_output=True).iterations
    with pytest.raises(ValueError, match="read-only"):
        approximate_inverse(rpc).coefficients[:] = 0.0
    np.testing.assert_array_equal(rpc.localize(col, row, 50.0, full_output=True).iterations,
                                  before)


def test_callers_arrays_stay_their_own():
    """The records hold read-only views: the arrays given to a constructor stay writable."""
    from photogeom.orientation.intersection import IntersectionResult

    pts = np.zeros((2, 3))
    res = IntersectionResult(pts, np.zeros((2, 3, 3)), np.ones(2), 1.0, np.ones(2, int),
                             np.full(2, 2), np.zeros((2, 2, 2)), np.ones(2, bool), 3)
    assert pts.flags.writeable and not res.points.flags.writeable
    pts[0, 0] = 5.0
    assert res.points[0, 0] == 5.0
