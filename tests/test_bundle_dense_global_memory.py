"""An adjustment whose camera groups would not fit in memory is refused before it starts.

The Schur reduction holds the coupling of the calibration parameters (11 per camera group,
held ones included) with every point and observation densely. A BAL file gives every image
its own camera group, so the memory grows with images x observations: the study's
250-image ILCE-7RM2 block with 1000 tie points per image, converted to BAL and adjusted
with ``--datum free``, grew to 22.6 GB of resident memory over four minutes and was killed
by the kernel (the same block in one camera group takes 0.8 GB). The need is now estimated
(``dense_global_bytes``) and an adjustment above ``memory_limit()`` is refused with the
number and the remedy, in seconds.
"""

from __future__ import annotations

import tracemalloc

import pytest

import photogeom as pg
from photogeom.bundle import adjustment
from photogeom.bundle.io_bal import read_bal, write_bal
from photogeom.errors import InputError


@pytest.fixture(scope="module")
def per_image_cameras(tmp_path_factory):
    """A 2 x 4 image block with a camera group per image (through BAL)."""
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    path = tmp_path_factory.mktemp("bal") / "block.bal"
    write_bal(sim.block, path, drop_extras=True)
    block = read_bal(path)
    assert len(block.calibrations) == block.n_images == 8
    return block


def test_the_estimate_matches_the_measured_peak(per_image_cameras):
    block = per_image_cameras
    n_rows = block.observations.uv.shape[0]
    need = adjustment.dense_global_bytes(
        len(block.calibrations), len(block.point_ids), n_rows, 6, True
    )
    assert pg.bundle_adjust(block, datum="free").converged  # imports and caches first
    tracemalloc.start()
    try:
        pg.bundle_adjust(block, datum="free")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # the dense arrays dominate the peak of a block with a camera group per image
    assert 0.5 * peak < need < 1.5 * peak


def test_the_estimate_grows_with_groups_times_observations():
    one = adjustment.dense_global_bytes(1, 50_599, 258_623, 6, True)
    per_image = adjustment.dense_global_bytes(250, 50_599, 258_623, 6, True)
    assert per_image == pytest.approx(250 * one)
    assert one < 0.3e9 < 60e9 < per_image  # the study block: 0.26 GB and 64.6 GB


def test_an_adjustment_over_the_limit_is_refused_before_it_starts(per_image_cameras, monkeypatch):
    block = per_image_cameras
    need = adjustment.dense_global_bytes(
        len(block.calibrations), len(block.point_ids), block.observations.uv.shape[0], 6, True
    )
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 0.5 * need)
    calls = []
    with pytest.raises(InputError) as err:
        pg.bundle_adjust(block, datum="free", progress=lambda *a: calls.append(a))
    assert calls == []  # no iteration ran
    text = str(err.value)
    assert "8 camera groups hold 88 calibration parameters" in text
    assert f"about {need / 1e9:.1f} GB of memory" in text
    assert "one camera group" in text
    # within the limit the same block is adjusted
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 2.0 * need)
    assert pg.bundle_adjust(block, datum="free").converged


def test_the_cli_refuses_in_its_words(cli, per_image_cameras, tmp_path, monkeypatch):
    path = tmp_path / "b.bal"
    write_bal(per_image_cameras, path)
    monkeypatch.setattr(adjustment, "memory_limit", lambda: 1e3)
    code, _, err = cli("bundle", "adjust", path, "--datum", "free")
    assert code == 2
    assert err.startswith("error: the block's 8 camera groups") and "GB of memory" in err
