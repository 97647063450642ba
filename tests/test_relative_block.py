"""The block start without GNSS on a simulated UAV block (photogeom.simulate): relative
orientations, strips and GCPs give start values from which the library's bundle adjustment
reaches the minimum it reaches from the true values."""

import numpy as np
import pytest

import photogeom as pg

start_from_relative_orientation = pg.bundle.start_from_relative_orientation


def _strips(sim):
    ids = sim.block.image_ids.tolist()
    out, k = [], 0
    for c in sim.options["images_per_strip"]:
        out.append(ids[k : k + c])
        k += c
    return out


@pytest.mark.slow
def test_uav_block_start_lies_in_the_convergence_basin():
    sim = pg.simulate.uav_block("FC300S", seed=1)
    block, start = start_from_relative_orientation(sim.block, _strips(sim))
    truth = sim.truth
    # the start ignores GNSS/IMU and the start calibration is not exact: errors of metres
    # at 56 m flying height, a few degrees
    dpos = np.linalg.norm(block.exterior[:, :3] - truth.exterior[:, :3], axis=1)
    assert dpos.max() < 10.0
    assert np.degrees(np.abs(block.exterior[:, 3:] - truth.exterior[:, 3:])).max() < 10.0
    assert len(start.strips) == 3 and all(len(u) >= 3 for u in start.control_used)
    ours = pg.bundle_adjust(block)
    tie = (sim.block.role == "tie")[:, None]
    ref = pg.bundle_adjust(
        sim.block.replace(exterior=truth.exterior.copy(), xyz=np.where(tie, truth.xyz, block.xyz))
    )
    assert ours.converged and ref.converged
    assert ours.sigma0 == pytest.approx(ref.sigma0, rel=1e-9)
    assert np.abs(ours.block.exterior - ref.block.exterior).max() < 1e-6
    assert np.abs(ours.block.xyz - ref.block.xyz).max() < 1e-6


def test_unknown_image_in_strips_is_named():
    sim = pg.simulate.uav_block("FC300S", seed=1)
    with pytest.raises(pg.InputError, match="unknown image"):
        start_from_relative_orientation(sim.block, [[0, 1, 999]])
    with pytest.raises(pg.InputError, match="twice"):
        start_from_relative_orientation(sim.block, [[0, 1], [1, 2]])
