"""Camera groups observed by one image held in that image's unknowns.

A block with a camera group per image (BAL, Bundler, COLMAP models with a camera per image)
held every group's 11 calibration parameters as global parameters of the reduced camera
system: dense blocks of images x parameters and parameters squared, 36 GB at 2000 images.
Held in their images' unknowns (eliminated and inverted blockwise like the orientations)
they take memory linear in the images and their co-visible neighbours. The results must be
those of the global form: estimates, sigma0, standard deviations and covariances of the
orientations, points (check points too) and calibrations, redundancy numbers and w-tests,
with control, GNSS and IMU, a free network, mixed (own and shared) groups, image-variant
parameters, held parameters, a robust loss and variance components.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust import folding
from photogeom.bundle import adjustment

sys.path.insert(0, str(Path(__file__).parent))
from closeness import assert_close_to_scale as _close


def _own_groups(block, which):
    """``block`` with images ``which`` in camera groups of their own (copies of theirs)."""
    cams = list(block.camera_ids.tolist())
    cals = list(block.calibrations)
    ic = block.image_camera.copy()
    free, iv = dict(block.free), dict(block.image_variant)
    for i in which:
        g = int(ic[i])
        gid = f"own{i}"
        cams.append(gid)
        cals.append(cals[g])
        free[gid], iv[gid] = free[cams[g]], iv[cams[g]]
        ic[i] = len(cams) - 1
    used = np.unique(ic)  # groups without images left out
    remap = np.full(len(cams), -1)
    remap[used] = np.arange(used.size)
    ids = [cams[k] for k in used.tolist()]
    return block.replace(
        camera_ids=np.array(ids, dtype=object),
        calibrations=tuple(cals[k] for k in used.tolist()),
        image_camera=remap[ic],
        free={g: free[g] for g in ids},
        image_variant={g: iv[g] for g in ids},
    )


@pytest.fixture(scope="module")
def bal(tmp_path_factory):
    from photogeom.bundle.io_bal import read_bal, write_bal

    s = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    path = tmp_path_factory.mktemp("bal") / "small.bal"
    write_bal(s.block, path, drop_extras=True)
    return read_bal(path)


@pytest.fixture(scope="module")
def sim():
    return pg.simulate.uav_block(
        "FC6310", seed=2, strips=2, images_per_strip=6, tie_points_per_image=120
    )


def _image_variant(block):
    return block.replace(image_variant={g: ("f",) for g in block.camera_ids.tolist()})


def _global(monkeypatch):
    monkeypatch.setattr(folding, "OWN_GROUPS_LOCAL", 10**9)
    monkeypatch.setattr(folding, "OWN_GROUPS_FRACTION", 10.0)
    monkeypatch.setattr(folding, "OWN_GROUPS_DENSE_ENTRIES", 2**62)


CASES = {
    # every image its own group; control, GNSS, IMU; check points
    "all": (lambda b: _own_groups(b, range(b.n_images)), {"free": ("f", "cx", "cy", "k1")}),
    # a robust loss on a BAL file (a camera group per image, a free network)
    "robust": (None, {"datum": "free", "free": ("f", "k1", "k2"), "loss": "cauchy"}),
    # half of the images in groups of their own, the others sharing one
    "mixed": (lambda b: _own_groups(b, range(0, b.n_images, 2)), {"free": ("f", "k1", "k2")}),
    # image-variant f (held in the groups, estimated per image) and held parameters
    "image_variant": (
        lambda b: _image_variant(_own_groups(b, range(b.n_images))),
        {"free": ("f", "cx", "k1")},
    ),
    # variance components
    "vce": (lambda b: _own_groups(b, range(b.n_images)), {"variance_components": True}),
    # a free network
    "free": (
        lambda b: _own_groups(b.without_datum_observations(), range(b.n_images)),
        {"datum": "free", "free": ("f", "k1")},
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_own_groups_give_the_results_of_global_ones(sim, bal, case, monkeypatch):
    make, opts = CASES[case]
    block = bal if make is None else make(sim.block)
    problem = adjustment.Problem(block, pg.bundle.BundleOptions(**opts))
    assert problem.sys.inner is not None  # the own groups are held in their images
    fit = pg.bundle_adjust(block, point_covariance=True, **opts)
    _global(monkeypatch)
    assert adjustment.Problem(block, pg.bundle.BundleOptions(**opts)).sys.inner is None
    ref = pg.bundle_adjust(block, point_covariance=True, **opts)
    assert fit.converged and ref.converged
    assert fit.iterations == ref.iterations
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-10)
    _close(fit.block.exterior, ref.block.exterior, 1e-10)
    # the image-variant block's points differ by 6.5e-10 relative, as much as those of the
    # two global forms (dense, per point and group: 6.8e-10)
    _close(fit.block.xyz, ref.block.xyz, 1e-9)
    _close(fit.exterior_std, ref.exterior_std)
    _close(fit.point_std, ref.point_std)  # check points included
    if ref.image_calibration_std is not None:
        _close(fit.image_calibration_std, ref.image_calibration_std)
    assert fit.calibration.keys() == ref.calibration.keys()
    for gid in ref.calibration:
        _close(list(fit.calibration[gid].values()), list(ref.calibration[gid].values()), 1e-10)
        _close(list(fit.calibration_std[gid].values()), list(ref.calibration_std[gid].values()))
        names, C = fit.calibration_covariance(gid)
        names_ref, C_ref = ref.calibration_covariance(gid)
        assert names == names_ref
        _close(C, C_ref)
    r, r_ref = fit.snooping["redundancy_numbers"], ref.snooping["redundancy_numbers"]
    _close(r, r_ref)
    # w = v / (sigma sqrt(r)): rounding grows where r is small; the two global forms
    # (dense and per point and group) differ by as much (1.9e-5 absolute, 5e-6 relative,
    # on "image_variant", 6e-8 on "all")
    well = np.asarray(r_ref) > 0.01
    _close(np.asarray(fit.snooping["w"])[well], np.asarray(ref.snooping["w"])[well], 2e-5)
    if ref.check["ids"]:
        _close(fit.check["errors"], ref.check["errors"], 1e-9)
    if ref.variance_components is not None:
        for k, v in ref.variance_components["factors"].items():
            assert fit.variance_components["factors"][k] == pytest.approx(v, rel=1e-8)


def test_camera_groups_without_images_beside_own_ones_take_no_dense_coupling(bal):
    """Camera groups without images (a COLMAP model's cameras of images it did not
    register) are held. Beside a camera group per image they stood as the folded
    system's only global parameters, coupled densely with every point (points x 3 x 11
    per such group: 2.3 GB more for 10 of them beside a 500-image BAL block); they are
    left out of it, and the adjustment is that of the block without them."""
    ids = bal.camera_ids.tolist()
    extra = [f"unused{k}" for k in range(3)]
    block = bal.replace(
        camera_ids=np.array(ids + extra, dtype=object),
        calibrations=tuple(bal.calibrations) + (bal.calibrations[0],) * 3,
        free={**bal.free, **{g: bal.free[ids[0]] for g in extra}},
        image_variant={**bal.image_variant, **{g: bal.image_variant[ids[0]] for g in extra}},
    )
    opts = {"datum": "free", "free": ("f", "k1", "k2")}
    problem = adjustment.Problem(block, pg.bundle.BundleOptions(**opts))
    assert problem.sys.inner is not None
    assert problem.sys.inner.n_global == 0  # nothing couples the points with them
    fit = pg.bundle_adjust(block, point_covariance=True, **opts)
    ref = pg.bundle_adjust(bal, point_covariance=True, **opts)
    assert fit.iterations == ref.iterations
    assert fit.sigma0 == pytest.approx(ref.sigma0, rel=1e-12)
    _close(fit.block.exterior, ref.block.exterior, 1e-12)
    _close(fit.exterior_std, ref.exterior_std, 1e-12)
    _close(fit.point_std, ref.point_std, 1e-12)
    for gid in ids:
        _close(list(fit.calibration_std[gid].values()), list(ref.calibration_std[gid].values()))
    for k, gid in enumerate(extra):  # held at their values, no standard deviation
        assert fit.block.calibrations[len(ids) + k] == block.calibrations[len(ids) + k]
        assert all(np.isnan(v) for v in fit.calibration_std[gid].values())


def test_the_reported_reduced_system_is_the_one_solved(bal, sim):
    """A camera group per image (f, k1, k2 free) is solved as one block of 6 + 3 unknowns
    per image: 8 x 9 = 72 unknowns, as the solver record says (it said 136, the images'
    6 and the groups' 11 calibration parameters, held ones included, beside the non-zeros
    of the 72-unknown system). With shared groups: 6 per image and 11 per group."""
    fit = pg.bundle_adjust(bal, datum="free", free=("f", "k1", "k2"), snooping=False)
    assert fit.block.n_images == 8
    assert fit.solver["reduced_system_size"] == 8 * 9
    assert fit.solver["reduced_system_nonzeros"] <= 72 * 72
    shared = pg.bundle_adjust(sim.block, snooping=False)
    n_groups = len(sim.block.camera_ids)
    assert shared.solver["reduced_system_size"] == 6 * sim.block.n_images + 11 * n_groups


@pytest.mark.parametrize("own, folded", [(32, False), (175, False), (250, True), (500, True)])
def test_a_few_own_groups_among_many_images_stay_global(own, folded):
    """500 images, ``own`` of them in camera groups of their own, the others sharing one:
    the own groups are held in their images from half of the images on (every image then
    carries their free parameters, held where it has no group of its own). Below, the
    global form is the faster (3 iterations with statistics, CPU: folded / global 21.6 /
    8.0 s with 32 own groups, 24.1 / 19.6 s with 175, 21.6 / 26.4 s with 250); 32 own
    groups were folded."""
    m = 500
    group = np.where(np.arange(m) < own, np.arange(m), own)  # the others share group `own`
    local_global = group[:, None] * adjustment.NCAL + np.arange(adjustment.NCAL)
    n_global = (own + (own < m)) * adjustment.NCAL
    got = folding.folded_locals(local_global, n_global)
    assert got.sum() == (own if folded else 0)


def test_many_own_groups_among_very_many_images_are_folded():
    """However small their fraction, own groups whose dense blocks with the images would
    be large are folded: 150 own groups among 20 000 images sharing one camera (the global
    form's images x calibration block alone: 20 000 x 6 x 1661 x 8 bytes = 1.6 GB)."""
    m, own = 20000, 150
    group = np.where(np.arange(m) < own, np.arange(m), own)
    local_global = group[:, None] * adjustment.NCAL + np.arange(adjustment.NCAL)
    got = folding.folded_locals(local_global, (own + 1) * adjustment.NCAL)
    assert got.sum() == own
