"""Every number that ``photogeom grid evaluate --json`` and ``grid sweep --json`` write has
its unit in ``"units"``, by its own name or by the name of the field that holds it (counts
and ids excepted).

Before, the records of ``"steps"`` of evaluate (``{"image_a", "image_b", "before",
"after"}``, the steps of ``"steps_before"`` and ``"steps_after"`` by model pair with typed
ids) had no unit: ``"units"`` named ``steps_before`` and ``steps_after`` (GSD) but not
``steps``; and sweep --rematch wrote ``"chosen_rematched"`` and ``"spacing_rematched"`` (px)
without one.
"""

from __future__ import annotations

import json

#: Fields that hold counts or ids, not measured numbers.
COUNTS = {"n", "observations", "unknowns", "image_id", "image_a", "image_b", "timings"}


def _unlabelled(doc: dict) -> set[str]:
    units = doc["units"]
    missing = set()

    def walk(x, path):
        if isinstance(x, dict):
            for k, v in x.items():
                walk(v, (*path, k))
        elif isinstance(x, list):
            for v in x:
                walk(v, (*path, "*"))
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            if path[-1] not in COUNTS and not any(p in units for p in path):
                missing.add(".".join(path))

    walk({k: v for k, v in doc.items() if k != "units"}, ())
    return missing


def test_every_number_of_the_json_has_a_unit(cli):
    code, text, err = cli("grid", "evaluate", "--preset", "FC300S", "--strips", "1", "--images",
                          "3", "--spacing", "500", "--rematch", "--json")  # fmt: skip
    assert code == 0, err
    d = json.loads(text)
    assert d["steps"] and d["rematched"]["steps"]  # the records are there to be labelled
    assert _unlabelled(d) == set()
    assert d["units"]["steps"] == d["units"]["steps_before"] == "GSD"
    # the records hold the numbers of steps_before and steps_after, by model pair
    for doc in (d, d["rematched"]):
        for r in doc["steps"]:
            key = f"{r['image_a']}-{r['image_b']}"
            assert r["before"] == doc["steps_before"][key]
            assert r["after"] == doc["steps_after"][key]


def test_every_number_of_the_sweep_json_has_a_unit(cli):
    code, text, err = cli("grid", "sweep", "--preset", "FC300S", "--strips", "1", "--images",
                          "3", "--spacings", "500,1000", "--repeats", "1", "--rematch",
                          "--json")  # fmt: skip
    assert code == 0, err
    d = json.loads(text)
    assert "spacing_rematched" in d and "chosen_rematched" in d
    assert _unlabelled(d) == set()
    # the re-matched choice is one of the spacings, in their unit
    assert d["units"]["spacing_rematched"] == d["units"]["spacings"] == "px"
    assert d["spacing_rematched"] in d["spacings"]
    assert set(d["chosen_rematched"]) <= set(d["spacings"])
