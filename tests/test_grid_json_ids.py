"""The ``--json`` of ``grid fit``, ``evaluate`` and ``sweep`` keeps the image ids' types.

Before: ``grid fit --json`` keyed the images by text only (an int id 0 came back as "0",
while the grids file keeps 0), ``evaluate`` and ``sweep`` named the model pairs as one text
``"a-b"`` (``"im-0-im-1"``: which ``-`` splits the two ids?) and ``excluded`` held texts.
The old fields stay; beside them ``image_id`` in each image's entry, ``steps`` (evaluate)
and ``model_pairs`` (sweep) as records with ``image_a`` and ``image_b``, and
``excluded_ids``, each id of its own type.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

import photogeom as pg


@pytest.fixture(scope="module")
def blocks(tmp_path_factory):
    """The same adjusted 4-image strip twice: int ids 0..3, and text ids im-0..im-3."""
    root = tmp_path_factory.mktemp("ids")
    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=2, strips=1, images_per_strip=4, tie_points_per_image=150
    )
    b = pg.bundle_adjust(sim.block, snooping=False).block
    ints = root / "ints"
    pg.bundle.write_csv_block(b, ints)
    texts = root / "texts"
    pg.bundle.write_csv_block(b, texts)
    for name in ("images.csv", "observations.csv"):  # first column: the image id
        path = texts / name
        lines = path.read_text().splitlines()
        out = []
        for line in lines:
            if line.startswith("#") or line.startswith(("id,", "image_id,")):
                out.append(line)
                continue
            row = next(csv.reader([line]))
            row[0] = f"im-{row[0]}"
            out.append(",".join(row))
        path.write_text("\n".join(out) + "\n")
    return ints, texts


def test_grid_fit_json_keeps_int_image_ids(cli, blocks, tmp_path: Path):
    ints, _ = blocks
    code, text, err = cli("grid", "fit", ints, "--spacing", "2000", "--folds", "0",
                          "-o", tmp_path / "g.json", "--json")  # fmt: skip
    assert code == 0, err
    images = json.loads(text)["images"]
    assert list(images) == ["0", "1", "2", "3"]  # the keys as before
    assert [v["image_id"] for v in images.values()] == [0, 1, 2, 3]
    assert all(type(v["image_id"]) is int for v in images.values())
    assert list(pg.calibration.load_grids(tmp_path / "g.json")) == [0, 1, 2, 3]


def test_grid_evaluate_json_pairs_ids_holding_a_dash(cli, blocks):
    _, texts = blocks
    code, text, err = cli("grid", "evaluate", texts, "--spacing", "2000", "--json")
    assert code == 0, err
    ev = json.loads(text)
    pairs = [(s["image_a"], s["image_b"]) for s in ev["steps"]]
    assert pairs == [("im-0", "im-1"), ("im-1", "im-2")]
    assert list(ev["steps_before"]) == ["im-0-im-1", "im-1-im-2"]  # as before
    for s in ev["steps"]:
        key = f"{s['image_a']}-{s['image_b']}"
        assert s["before"] == ev["steps_before"][key] and s["after"] == ev["steps_after"][key]
    assert [v["image_id"] for v in ev["residuals"]["images"].values()] == [
        "im-0", "im-1", "im-2", "im-3"
    ]
    assert ev["excluded"] == [] and ev["excluded_ids"] == []


def test_grid_evaluate_and_sweep_json_keep_int_ids(cli, blocks):
    ints, _ = blocks
    code, text, err = cli("grid", "evaluate", ints, "--spacing", "2000", "--exclude", "3",
                          "--json")  # fmt: skip
    assert code == 0, err
    ev = json.loads(text)
    assert ev["excluded"] == ["3"] and ev["excluded_ids"] == [3]
    assert [(s["image_a"], s["image_b"]) for s in ev["steps"]] == [(0, 1), (1, 2)]
    assert [v["image_id"] for v in ev["residuals"]["images"].values()] == [0, 1, 2, 3]
    code, text, err = cli("grid", "sweep", ints, "--spacings", "1000,2000", "--exclude", "3",
                          "--json")  # fmt: skip
    assert code == 0, err
    sw = json.loads(text)
    assert sw["models"] == ["0-1", "1-2"]  # as before
    assert sw["model_pairs"] == [{"image_a": 0, "image_b": 1}, {"image_a": 1, "image_b": 2}]
    assert sw["excluded"] == ["3"] and sw["excluded_ids"] == [3]
