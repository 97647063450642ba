"""Pickled and deep-copied models keep their arrays read-only."""

from __future__ import annotations

import copy
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.imagecoords import PixelSystem
from photogeom.rpc.model import RPC

sys.path.insert(0, str(Path(__file__).parent))
from rpc_samples import unit_rpc_tables


def _rpc():
    line_num, den, samp_num = unit_rpc_tables()
    return RPC(1000, 1000, 45, 7, 100, 1000, 1000, 0.1, 0.1, 500,
               line_num, den, samp_num, den, correction=np.zeros((2, 3)))


def _arrays(obj):
    return [v for v in vars(obj).values() if isinstance(v, np.ndarray)]


def _twins(obj):
    return [pickle.loads(pickle.dumps(obj)), copy.deepcopy(obj)]


def test_rpc_copy_cannot_be_changed_behind_its_cached_coefficients():
    # before: the copy's arrays were writable; line_num[2] = 2 changed rpc.line_num while
    # the projection kept using the cached stacked coefficients
    rpc = _rpc()
    for twin in _twins(rpc):
        assert not any(a.flags.writeable for a in _arrays(twin))
        assert not twin.coefficients.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            twin.line_num[2] = 2.0
        assert twin.project(7.01, 45.01, 100.0) == rpc.project(7.01, 45.01, 100.0)


MODELS = {
    "Similarity3D": lambda: pg.transforms.Similarity3D(1.1, np.eye(3), [1.0, 2.0, 3.0]),
    "Affine3D": lambda: pg.transforms.Affine3D(np.eye(3) * 2.0, [1.0, 2.0, 3.0]),
    "Projective2D": lambda: pg.transforms.Projective2D(np.eye(3)),
    "Polynomial2D": lambda: pg.transforms.Polynomial2D(1, [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    "DLT": lambda: pg.DLT(np.arange(1.0, 12.0)),
    "AffineCamera": lambda: pg.AffineCamera([1.0, 0, 0, 0], [0, 1.0, 0, 0]),
    "PixelSystem": lambda: PixelSystem(0.004, (100.0, 200.0)),
}


@pytest.mark.parametrize("name", MODELS)
def test_copied_models_keep_read_only_arrays(name):
    # before: a Similarity3D copied by pickle had a writable translation, and changing it
    # changed its hash
    model = MODELS[name]()
    for twin in _twins(model):
        assert _arrays(twin) and not any(a.flags.writeable for a in _arrays(twin))
        if name not in ("DLT", "AffineCamera"):
            assert twin == model and hash(twin) == hash(model)


def test_copied_block_keeps_read_only_arrays():
    block = pg.simulate.uav_block(
        "FC300S", seed=1, strips=2, images_per_strip=3, tie_points_per_image=30
    ).block
    for twin in _twins(block):
        assert not any(a.flags.writeable for a in _arrays(twin))
        assert not any(a.flags.writeable for a in _arrays(twin.observations))
        np.testing.assert_array_equal(twin.xyz, block.xyz)
