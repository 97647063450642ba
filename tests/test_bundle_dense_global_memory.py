"""Memory of a block with many camera groups (any BAL file has a camera group per image).

The Schur reduction couples each point with the calibration parameters (11 per camera
group) of the images that observe it. Held densely (points x 3 x all parameters, rows x 3 x
all parameters) that grew with images x observations: the study's 250-image ILCE-7RM2
block with 1000 tie points per image, converted to BAL and adjusted with ``--datum free``,
grew to 22.6 GB and was killed by the kernel. The coupling is now held per pair (point,
camera group observing it), linear in the observations, and the reduced camera system's
calibration rows follow the co-visibility of the images: that block takes 1.5 GB.

A camera group observed by one image only is held in that image's unknowns (11 more per
image, eliminated with its orientation), so that a block with a camera per image has no
global parameter at all: memory and time linear in the images and their co-visible
neighbours. What still grows with the square of the camera groups shared by several images
(the dense local-global and global-global blocks, the inverse of the reduced system) is
estimated (``dense_global_bytes``) and an adjustment above ``memory_limit()`` is refused
with the number and the remedy, in seconds.
"""

from __future__ import annotations

import math
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import photogeom as pg
from photogeom.adjust import folding, schur
from photogeom.bundle import adjustment
from photogeom.bundle.io_bal import read_bal, write_bal
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from closeness import assert_close_to_scale as _close


def _per_image(tmp_path_factory, name, **kwargs):
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, **kwargs)
    path = tmp_path_factory.mktemp("bal") / f"{name}.bal"
    write_bal(sim.block, path, drop_extras=True)
    block = read_bal(path)
    assert len(block.calibrations) == block.n_images
    return block


@pytest.fixture(scope="module")
def per_image_cameras(tmp_path_factory):
    """A 2 x 4 image block with a camera group per image (through BAL)."""
    return _per_image(tmp_path_factory, "small", strips=2, images_per_strip=4)


def _paired(block):
    """The block with a camera group per pair of images (images 2k and 2k + 1)."""
    m = block.n_images
    ids = block.camera_ids[: (m + 1) // 2]
    return block.replace(
        camera_ids=ids,
        calibrations=block.calibrations[: ids.size],
        image_camera=np.arange(m) // 2,
        free={g: block.free[g] for g in ids.tolist()},
        image_variant={g: block.image_variant[g] for g in ids.tolist()},
    )


def _global_groups(monkeypatch):
    """Every camera group held as global parameters (the form before own groups were held
    in their images)."""
    monkeypatch.setattr(folding, "OWN_GROUPS_LOCAL", 10**9)
    monkeypatch.setattr(folding, "OWN_GROUPS_FRACTION", 10.0)
    monkeypatch.setattr(folding, "OWN_GROUPS_DENSE_ENTRIES", 2**62)


def test_memory_is_linear_in_the_observations(tmp_path_factory, per_image_cameras):
    """40 images with a camera group each: the dense coupling of the points and rows with
    the 440 calibration parameters alone needed 290 MB (the whole adjustment peaked at
    731 MB); the adjustment now peaks at about 135 MB."""
    block = _per_image(
        tmp_path_factory, "forty", strips=4, images_per_strip=10, tie_points_per_image=400
    )
    n_rows = block.observations.uv.shape[0]
    n_points = len(block.point_ids)
    g = len(block.calibrations) * adjustment.NCAL
    dense_coupling = 8.0 * g * (3 * n_rows + 9 * n_points)  # (rows + points) x 3 x g
    assert dense_coupling > 250e6
    pg.bundle_adjust(per_image_cameras, datum="free")  # imports and caches first
    tracemalloc.start()
    try:
        fit = pg.bundle_adjust(block, datum="free")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert fit.converged and fit.snooping is not None
    assert peak < 0.6 * dense_coupling


def test_the_sparse_coupling_gives_the_dense_results(per_image_cameras, monkeypatch):
    """Estimates, sigma0, standard deviations, point covariances, redundancy numbers and
    w-tests of the per-(point, group) coupling equal those of the dense coupling (which
    the blocks with fewer than 32 camera groups keep while it is small)."""
    block = per_image_cameras
    opts = {"datum": "free", "point_covariance": True, "free": ("f", "k1", "k2")}
    _global_groups(monkeypatch)
    dense = pg.bundle_adjust(block, **opts)  # 8 groups: dense
    monkeypatch.setattr(schur, "SPARSE_GLOBAL_GROUPS", 1)
    sparse = pg.bundle_adjust(block, **opts)
    assert sparse.converged and dense.converged
    assert sparse.sigma0 == pytest.approx(dense.sigma0, rel=1e-10)
    _close(sparse.block.exterior, dense.block.exterior, 1e-10)
    _close(sparse.block.xyz, dense.block.xyz, 1e-10)
    _close(sparse.exterior_std, dense.exterior_std)
    _close(sparse.point_std, dense.point_std)
    for gid, std in dense.calibration_std.items():
        _close(list(sparse.calibration_std[gid].values()), list(std.values()))
        _close(list(sparse.calibration[gid].values()), list(dense.calibration[gid].values()))
    _close(sparse.snooping["redundancy_numbers"], dense.snooping["redundancy_numbers"])
    # w = v / (sigma sqrt(r)): where r is tiny (2e-9 for a point seen in two images, along
    # the base) rounding dominates it in either form (the dense form differs by 5e-4 on
    # the 12-image block between two orders of the same observations)
    r = np.asarray(dense.snooping["redundancy_numbers"])
    well = r > 0.01
    assert well.mean() > 0.5
    w_sparse, w_dense = np.asarray(sparse.snooping["w"]), np.asarray(dense.snooping["w"])
    _close(w_sparse[well], w_dense[well])


def test_a_few_camera_groups_keep_the_dense_coupling(monkeypatch):
    L = 40
    local = np.repeat(np.arange(L), 2)
    point = np.tile(np.arange(2), L)
    free = np.ones((L, 6), dtype=bool)

    def system(groups):
        lg = (np.arange(L) % groups)[:, None] * 11 + np.arange(11)[None, :]
        gf = np.ones(groups * 11, dtype=bool)
        return schur.SchurSystem(
            L, 6, groups * 11, 2, local, point, lg, free, gf, own_groups="global"
        )

    assert not system(schur.SPARSE_GLOBAL_GROUPS - 1).sparse_global
    assert system(schur.SPARSE_GLOBAL_GROUPS).sparse_global
    # the dense arrays over the limit: sparse with one group too
    need = schur.dense_coupling_bytes(11, 2 * L, 2, 6)
    monkeypatch.setattr(schur, "DENSE_GLOBAL_BYTES", 0.9 * need)
    assert system(1).sparse_global
    monkeypatch.setattr(schur, "DENSE_GLOBAL_BYTES", 1.1 * need)
    assert not system(1).sparse_global


def test_the_estimate_grows_with_the_square_of_the_groups():
    one = adjustment.dense_global_bytes(1, 250, 6)
    study = adjustment.dense_global_bytes(250, 250, 6)  # the study block as BAL
    assert one < 0.02e9 < 0.4e9 < study < 0.6e9
    many = adjustment.dense_global_bytes(2000, 2000, 6)
    assert 30e9 < many < 40e9
    # not the points nor the observations: only images and groups enter
    assert adjustment.dense_global_bytes(8, 8, 6) < 1e6


def test_an_adjustment_over_the_limit_is_refused_before_it_starts(per_image_cameras, monkeypatch):
    block = _paired(per_image_cameras)  # 4 camera groups of 2 images each
    need = adjustment.dense_global_bytes(len(block.calibrations), block.n_images, 6)
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 0.5 * need)
    calls = []
    with pytest.raises(InputError) as err:
        pg.bundle_adjust(block, datum="free", progress=lambda *a: calls.append(a))
    assert calls == []  # no iteration ran
    text = str(err.value)
    assert "4 camera groups observed by more than one image hold 44 calibration" in text
    assert f"about {need / 1e9:.1f} GB of memory" in text
    assert "one camera group" in text
    # within the limit the same block is adjusted
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 2.0 * need)
    assert pg.bundle_adjust(block, datum="free").converged
    monkeypatch.setattr(adjustment, "memory_limit", lambda: math.inf)
    assert pg.bundle_adjust(block, datum="free").converged


def test_a_camera_per_image_is_not_refused(per_image_cameras, monkeypatch):
    """A camera group per image (a BAL file): the groups are held in their images, nothing
    grows with their square and a limit the global form exceeded (88 parameters coupled
    densely) is not reached; the results are those of the global form."""
    block = per_image_cameras
    old = adjustment.dense_global_bytes(len(block.calibrations), block.n_images, 6)
    now = adjustment.dense_global_bytes(0, block.n_images, 6 + adjustment.NCAL)
    assert now < 0.5 * old
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 0.5 * old)
    opts = {"datum": "free", "point_covariance": True, "free": ("f", "k1", "k2")}
    fit = pg.bundle_adjust(block, **opts)
    assert fit.converged
    monkeypatch.setattr(adjustment, "memory_limit", lambda: math.inf)
    _global_groups(monkeypatch)
    ref = pg.bundle_adjust(block, **opts)
    assert fit.iterations == ref.iterations
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-10)
    _close(fit.block.exterior, ref.block.exterior, 1e-10)
    _close(fit.block.xyz, ref.block.xyz, 1e-10)
    _close(fit.exterior_std, ref.exterior_std)
    _close(fit.point_std, ref.point_std)
    for gid in ref.calibration:
        _close(list(fit.calibration[gid].values()), list(ref.calibration[gid].values()), 1e-10)
        _close(list(fit.calibration_std[gid].values()), list(ref.calibration_std[gid].values()))
        _close(fit.calibration_covariance(gid)[1], ref.calibration_covariance(gid)[1])
    _close(fit.snooping["redundancy_numbers"], ref.snooping["redundancy_numbers"])


def test_a_group_per_image_takes_memory_linear_in_the_images():
    """400 local blocks with a group of 11 global parameters each (4400): held globally the
    global-global block alone took 155 MB (and its accumulation, masks and covariance four
    times that); held in the local blocks the normal equations and the step take a few
    MB."""
    L, b, gl = 400, 6, 11
    rng = np.random.default_rng(0)
    # points seen by 3 consecutive local blocks of a strip
    p = L * 4
    pt = np.repeat(np.arange(p), 3)
    loc = (np.arange(p)[:, None] // 4 + np.arange(3)[None, :]).ravel() % L
    n = pt.size
    lg = np.arange(L * gl).reshape(L, gl)
    sysm = schur.SchurSystem(
        L, b, L * gl, p, loc, pt, lg, np.ones((L, b), bool), np.ones(L * gl, bool)
    )
    lin = schur.Linearization(
        rng.standard_normal((n, 2)),
        rng.standard_normal((n, 2, b)),
        rng.standard_normal((n, 2, gl)),
        rng.standard_normal((n, 2, 3)),
        np.tile(np.eye(b), (L, 1, 1)),
        np.zeros((L, b)),
        np.zeros((p, 3, 3)),
        np.zeros((p, 3)),
        sp.identity(L * gl, format="csr"),
        np.zeros(L * gl),
        0.0,
    )
    tracemalloc.start()
    try:
        dc, dp, _ = sysm.normal_equations(lin, damping=1e-3).solve()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    dense_gg = 8.0 * (L * gl) ** 2
    assert dense_gg > 150e6
    assert peak < 0.25 * dense_gg
    assert dc.shape == (L * b + L * gl,) and np.all(np.isfinite(dc))
    assert dp.shape == (p, 3) and np.all(np.isfinite(dp))


def test_the_cli_refuses_in_its_words(cli, per_image_cameras, tmp_path, monkeypatch):
    from photogeom.bundle import write_csv_block

    path = tmp_path / "b"
    write_csv_block(_paired(per_image_cameras), path)
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 1e3)
    code, _, err = cli("bundle", "adjust", path, "--datum", "free")
    assert code == 2
    assert err.startswith("error: the block's 4 camera groups observed by more than one")
    assert "GB of memory" in err
    # a BAL file (a camera group per image) is not refused
    bal = tmp_path / "b.bal"
    write_bal(per_image_cameras, bal)
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 1e7)
    code, _, err = cli("bundle", "adjust", bal, "--datum", "free")
    assert code == 0, err
