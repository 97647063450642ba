"""The grid-size sweep says where it is.

On a study-size block (250 images, 1000 tie points each) one pass of ``grid sweep`` fits
250 grids and re-adjusts the block at each of the 7 default spacings, minutes in all, and
the timing passes follow; the command showed only ``sweep: grids and re-adjustment at 7
spacings`` and the elapsed time, the same line from the first second to the last.
``sweep_spacings(..., stage=...)`` now names the spacing, the step and the images fitted,
and the CLI shows it.
"""

from __future__ import annotations

import pytest

import photogeom as pg
from photogeom.calibration import sweep_spacings

SPACINGS = [1000.0, 2000.0]


@pytest.fixture(scope="module")
def adjusted():
    sim = pg.simulate.uav_block("ILCE-7RM2", seed=1, strips=2, images_per_strip=4)
    return pg.bundle_adjust(sim.block, snooping=False)


def test_the_sweep_names_each_spacing_and_step_in_order(adjusted):
    texts: list[str] = []
    sw = sweep_spacings(adjusted, SPACINGS, folds=0, repeats=2, stage=texts.append)
    n = len(adjusted.block.image_ids)
    order = []
    for c, sp in enumerate(SPACINGS):
        at = f"spacing {c + 1} of 2 ({sp:g} px)"
        order += [
            texts.index(f"{at}: fitting grids"),
            texts.index(f"{at}: fitting grids, {n} of {n} images"),
            texts.index(f"{at}: re-adjusting"),
        ]
    assert order == sorted(order)  # spacing after spacing, each fitted then re-adjusted
    counts = [t for t in texts if t.startswith("spacing 1 of 2 (1000 px): fitting grids, ")]
    assert counts == [f"spacing 1 of 2 (1000 px): fitting grids, {k} of {n} images" for k in
                      range(n + 1)]  # fmt: skip
    again = [t for t in texts if t.startswith("timing again")]
    assert again == [
        f"timing again, pass {p} of at most 2: spacing {c + 1} of 2 ({sp:g} px)"
        for p in range(2, sw["timings"] + 1)
        for c, sp in enumerate(SPACINGS)
    ]


def test_the_stage_leaves_the_sweep_unchanged(adjusted):
    plain = sweep_spacings(adjusted, SPACINGS, folds=0, repeats=1)
    shown = sweep_spacings(adjusted, SPACINGS, folds=0, repeats=1, stage=lambda text: None)
    assert shown["step"].tolist() == plain["step"].tolist()


def test_grid_sweep_shows_the_spacing_it_is_at(cli, monkeypatch):
    import photogeom.cli._common as cc

    shown: list[str] = []
    real = cc.LogProgress.update

    def update(self, text):
        shown.append(text)
        real(self, text)

    monkeypatch.setattr(cc.LogProgress, "update", update)
    code, _, err = cli(
        "grid", "sweep", "--preset", "FC300S", "--strips", "1", "--images-per-strip", "5",
        "--spacings", "500,1000", "--repeats", "1",
    )  # fmt: skip
    assert code == 0, err
    assert "sweep: spacing 1 of 2 (500 px): fitting grids, 5 of 5 images" in shown
    assert "sweep: spacing 2 of 2 (1000 px): re-adjusting" in shown
