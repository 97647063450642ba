"""``stereo_models`` computes the images' GSD once.

Each candidate model offset of each strip asked ``image_overlap`` for its pairs, and each
call computed every image's GSD again from every observation of the block: 131 passes over
the 259 000 observations of the study's 250-image block (1000 tie points per image), 2.7 s
of the 5.5 s of one ``model_steps``, which a grid-size sweep calls once per spacing and
the block once more. The calls grew with images x observations; now one pass.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom.calibration import image_overlap, steps


@pytest.fixture(scope="module")
def block():
    return pg.simulate.uav_block("FC300S", seed=1, strips=2, images_per_strip=12).block


def test_one_pass_over_the_observations(block, monkeypatch):
    calls = []
    real = steps._image_gsd

    def counted(b):
        calls.append(1)
        return real(b)

    monkeypatch.setattr(steps, "_image_gsd", counted)
    sm = steps.stereo_models(block)
    assert len(sm.models) > 0 and max(sm.offsets) >= 2  # several candidate offsets tried
    assert len(calls) == 1


def test_the_models_overlaps_are_image_overlap(block):
    sm = steps.stereo_models(block)
    row = {iid: i for i, iid in enumerate(block.image_ids.tolist())}
    a = np.array([row[x] for x, _ in sm.models])
    b = np.array([row[y] for _, y in sm.models])
    assert np.allclose(sm.model_overlap, image_overlap(block, a, b), rtol=0, atol=1e-12)
    assert all(0.4 < o < 0.8 for o in sm.model_overlap)  # about the 60 % asked for
