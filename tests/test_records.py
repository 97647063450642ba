"""Fast construction of frozen result dataclasses (photogeom.records.build) and the shared
read-only stand-ins for statistics that were not computed."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from photogeom.adjust import Fit
from photogeom.adjust.result import Adjustment, not_computed
from photogeom.records import build


def _fit_values() -> dict:
    return dict(
        model=None, method="m", parameter_names=("a", "b"), parameters=np.zeros(2),
        covariance=np.eye(2), cofactor=np.eye(2), sigma0=1.0, sigma0_prior=1.0,
        redundancy=3, n_observations=5, residuals=np.zeros((0, 2)),
    )


def _same(a, b) -> bool:
    fa, fb = dataclasses.asdict(a), dataclasses.asdict(b)
    return fa.keys() == fb.keys() and all(
        np.array_equal(fa[k], fb[k]) if isinstance(fa[k], np.ndarray) else fa[k] == fb[k]
        for k in fa
    )


def test_build_equals_the_constructor_defaults_and_factories_included():
    values = _fit_values()
    built, constructed = build(Fit, values), Fit(**values)
    assert type(built) is Fit and _same(built, constructed)
    # default factories give fresh objects, as the constructor does
    assert built.extras == {} and built.extras is not build(Fit, values).extras
    with pytest.raises(dataclasses.FrozenInstanceError):
        built.sigma0 = 2.0


def test_build_refuses_missing_and_unknown_fields_as_the_constructor():
    values = _fit_values()
    del values["sigma0"]
    with pytest.raises(TypeError, match=r"missing field.*sigma0"):
        build(Fit, values)
    with pytest.raises(TypeError, match=r"unexpected field.*colour"):
        build(Fit, {**_fit_values(), "colour": 1})


def test_classes_with_post_init_or_slots_use_their_constructor():
    calls = []

    @dataclasses.dataclass(frozen=True)
    class Checked:
        x: int

        def __post_init__(self):
            calls.append(self.x)

    @dataclasses.dataclass(frozen=True, slots=True)
    class Slotted:
        x: int
        y: int = 2

    assert build(Checked, {"x": 3}).x == 3 and calls == [3]
    s = build(Slotted, {"x": 1})
    assert (s.x, s.y) == (1, 2)


def test_adjustment_built_equals_constructed():
    values = dict(x=np.ones(2), names=("a", "b"), residuals=np.zeros(4), cofactor=np.eye(2),
                  redundancy=2, n_observations=4, vtpv=0.5)
    assert _same(build(Adjustment, values), Adjustment(**values))


def test_not_computed_is_shared_read_only_nan():
    a = not_computed((3, 3))
    assert a.shape == (3, 3) and np.isnan(a).all() and a is not_computed((3, 3))
    assert not a.flags.writeable
    with pytest.raises(ValueError):
        a[0, 0] = 1.0
    e = not_computed((0, 2))
    assert e.shape == (0, 2) and not e.flags.writeable
    assert math.isnan(float(not_computed((1,))[0]))
