"""Fast construction of frozen result dataclasses.

A frozen dataclass's constructor sets each field with ``object.__setattr__``; for results
with a dozen or more fields that costs more than a small least-squares solve. :func:`build`
gives the same object (defaults and default factories applied, required and unknown fields
refused as the constructor would) by filling the instance dictionary once. Classes with a
``__post_init__`` or ``__slots__`` go through their constructor.
"""

from __future__ import annotations

from dataclasses import MISSING, fields
from typing import TypeVar

T = TypeVar("T")

_SPECS: dict = {}


def _spec(cls) -> tuple | None:
    """(plain defaults, default factories, required names, all names) of dataclass ``cls``,
    or None when it must be built by its constructor; cached per class."""
    if cls in _SPECS:
        return _SPECS[cls]
    spec = None
    if not (hasattr(cls, "__post_init__") or hasattr(cls, "__slots__")):
        plain, factories, required = {}, {}, set()
        for f in fields(cls):
            if f.default is not MISSING:
                plain[f.name] = f.default
            elif f.default_factory is not MISSING:
                factories[f.name] = f.default_factory
            else:
                required.add(f.name)
        spec = (plain, factories, frozenset(required), frozenset(f.name for f in fields(cls)))
    _SPECS[cls] = spec
    return spec


def build(cls: type[T], values: dict) -> T:
    """``cls(**values)`` for a frozen dataclass ``cls``, without the per-field setattr cost.

    Raises
    ------
    TypeError
        A required field is missing, or a name is not a field (as the constructor would).
    """
    spec = _SPECS.get(cls) or _spec(cls)
    if spec is None:
        return cls(**values)
    plain, factories, required, names = spec
    keys = values.keys()
    if not (keys >= required and names.issuperset(keys)):
        missing, unknown = sorted(required - keys), sorted(keys - names)
        raise TypeError(
            f"{cls.__name__}: "
            + "; ".join(
                f"{what} field(s) {', '.join(which)}"
                for what, which in (("missing", missing), ("unexpected", unknown))
                if which
            )
        )
    obj = object.__new__(cls)
    d = obj.__dict__
    d.update(plain)
    for name, factory in factories.items():
        if name not in values:
            d[name] = factory()
    d.update(values)
    return obj
