"""Fast construction of frozen result dataclasses.

A frozen dataclass's constructor sets each field with ``object.__setattr__``; for results
with a dozen or more fields that costs more than a small least-squares solve. :func:`build`
gives the same object (defaults and default factories applied, required and unknown fields
refused as the constructor would) by filling the instance dictionary once. Classes with a
``__post_init__`` or ``__slots__`` go through their constructor, unless they set the class
attribute ``_build_post_init = True``: then :func:`build` fills the dictionary and calls
their ``__post_init__`` (one that only works on the filled fields, such as
:func:`read_only_fields`). :func:`compact_repr` is
their ``repr``, bounded whatever the size of the problem.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields
from itertools import islice
from typing import TypeVar

import numpy as np

T = TypeVar("T")

_SPECS: dict = {}


def _spec(cls) -> tuple | None:
    """(plain defaults, default factories, required names, all names) of dataclass ``cls``,
    or None when it must be built by its constructor; cached per class."""
    if cls in _SPECS:
        return _SPECS[cls]
    spec = None
    lean_post_init = getattr(cls, "_build_post_init", False)
    if lean_post_init or not (hasattr(cls, "__post_init__") or hasattr(cls, "__slots__")):
        plain, factories, required = {}, {}, set()
        for f in fields(cls):
            if f.default is not MISSING:
                plain[f.name] = f.default
            elif f.default_factory is not MISSING:
                factories[f.name] = f.default_factory
            else:
                required.add(f.name)
        names = frozenset(f.name for f in fields(cls))
        spec = (plain, factories, frozenset(required), names, lean_post_init)
    _SPECS[cls] = spec
    return spec


def build(kind: type[T], values: dict) -> T:
    """``kind(**values)`` for a frozen dataclass ``kind``, without the per-field setattr cost.

    Parameters
    ----------
    kind : type
        The frozen dataclass (any other class is called as ``kind(**values)``).
    values : dict
        The field values by name; fields with defaults may be left out.

    Returns
    -------
    object
        The instance of ``kind``, its ``__post_init__`` run as the constructor runs it.

    Raises
    ------
    TypeError
        A required field is missing, or a name is not a field (as the constructor would).
    """
    spec = _SPECS.get(kind) or _spec(kind)
    if spec is None:
        return kind(**values)
    plain, factories, required, names, post_init = spec
    keys = values.keys()
    if not (keys >= required and names.issuperset(keys)):
        missing, unknown = sorted(required - keys), sorted(keys - names)
        raise TypeError(
            f"{kind.__name__}: "
            + "; ".join(
                f"{what} field(s) {', '.join(which)}"
                for what, which in (("missing", missing), ("unexpected", unknown))
                if which
            )
        )
    obj = object.__new__(kind)
    d = obj.__dict__
    d.update(plain)
    for name, factory in factories.items():
        if name not in values:
            d[name] = factory()
    d.update(values)
    if post_init:
        obj.__post_init__()
    return obj


#: Longest sequence or mapping, and largest array, that :func:`compact_repr` shows in full.
REPR_ITEMS = 16


def _brief(value, depth: int = 0) -> str:
    """A bounded repr: arrays of more than :data:`REPR_ITEMS` elements by shape and dtype,
    long sequences and mappings by their first items and their length."""
    if isinstance(value, np.ndarray):
        if value.size <= REPR_ITEMS:
            return " ".join(repr(value).split())
        return f"<array {value.shape} {value.dtype}>"
    if isinstance(value, (tuple, list)):
        left, right = ("(", ")") if isinstance(value, tuple) else ("[", "]")
        if depth > 2:
            return f"{left}<{len(value)} items>{right}"
        shown = [_brief(v, depth + 1) for v in value[:REPR_ITEMS]]
        if len(value) > REPR_ITEMS:
            shown = [*shown[:3], f"... <{len(value)} items>"]
        tail = "," if isinstance(value, tuple) and len(value) == 1 else ""
        return left + ", ".join(shown) + tail + right
    if isinstance(value, Mapping):
        if depth > 2:
            return f"{{<{len(value)} entries>}}"
        items = list(islice(value.items(), REPR_ITEMS + 1))
        shown = [f"{k!r}: {_brief(v, depth + 1)}" for k, v in items[:REPR_ITEMS]]
        if len(value) > REPR_ITEMS:
            shown = [*shown[:3], f"... <{len(value)} entries>"]
        return "{" + ", ".join(shown) + "}"
    return repr(value)


def compact_repr(obj) -> str:
    """``ClassName(field=value, ...)`` of a dataclass result, of bounded length whatever the
    size of the problem.

    The dataclass ``repr`` prints every id of a tuple and every entry of a dict (and arrays
    of up to 1000 elements in full), so the repr of a result of a large problem ran to
    megabytes. Here arrays of more than :data:`REPR_ITEMS` elements show as their shape and
    dtype and long sequences and mappings as their first items and their length; fields
    whose name starts with an underscore and fields declared with ``repr=False`` are left
    out.

    Parameters
    ----------
    obj : dataclass instance

    Returns
    -------
    str
    """
    parts = [
        f"{f.name}={_brief(getattr(obj, f.name))}"
        for f in fields(obj)
        if f.repr and not f.name.startswith("_")
    ]
    return f"{type(obj).__name__}({', '.join(parts)})"


def value_key(obj) -> tuple:
    """The compared fields of dataclass ``obj`` as a tuple that ``==`` and ``hash`` can use:
    arrays as (shape, dtype, bytes) with -0.0 made 0.0 (element-wise equal arrays give equal
    keys), nested dataclasses as (class, their key).

    The generated dataclass ``==`` compares arrays with ``==`` and raises "the truth value of
    an array ... is ambiguous"; value records compare with this key instead.

    Parameters
    ----------
    obj : dataclass instance

    Returns
    -------
    tuple
    """
    out = []
    for f in fields(obj):
        if not f.compare:
            continue
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            v = (v.shape, v.dtype.str, (v + 0.0).tobytes() if v.dtype.kind == "f" else v.tobytes())
        elif hasattr(type(v), "__dataclass_fields__") and not isinstance(v, type):
            v = (type(v), value_key(v))
        out.append(v)
    return tuple(out)


def value_eq(record, other) -> bool:
    """``==`` of value records (a class's ``__eq__ = value_eq``): the same class and equal
    :func:`value_key`.

    Parameters
    ----------
    record : object
        The record compared (``self`` of ``__eq__``).
    other : object
        What it is compared with.

    Returns
    -------
    bool or NotImplemented
    """
    if type(other) is not type(record):
        return NotImplemented
    return value_key(record) == value_key(other)


def setstate_read_only(obj, state: dict) -> None:
    """``__setstate__`` of immutable models whose arrays are read-only: restore the instance
    dictionary (pickle, :func:`copy.deepcopy`), then make its arrays read-only again.

    Pickle and deepcopy rebuild arrays writable; without this a copied model could be changed
    through its arrays (and an RPC's coefficients then disagreed with the stacked copy it
    computes with, a Similarity3D's hash changed).

    Parameters
    ----------
    obj : object
        The instance being restored.
    state : dict
        Its instance dictionary as pickled.
    """
    obj.__dict__.update(state)
    for value in obj.__dict__.values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False


def read_only_fields(obj: T) -> T:
    """Make the array attributes of a result record read-only (in place) and return it.

    A writable array is replaced by a read-only view of it: the record cannot be changed
    through its arrays (nor a copy made with :func:`dataclasses.replace`, which shares them),
    and the caller's own arrays stay writable.

    Parameters
    ----------
    obj : object
        A frozen dataclass instance (its ``__dict__`` is updated directly).

    Returns
    -------
    object
        ``obj``.
    """
    d = obj.__dict__
    for name, value in d.items():
        d[name] = read_only_view(value)
    return obj


def read_only_view(value):
    """``value``, or a read-only view of it when it is a writable array (the caller's array
    stays writable).

    Parameters
    ----------
    value : object

    Returns
    -------
    object
    """
    if isinstance(value, np.ndarray) and value.flags.writeable:
        value = value.view()
        value.flags.writeable = False
    return value


def frozen_value(value):
    """``value`` made read-only all the way down: mappings as :class:`FrozenMapping`, lists
    and tuples as tuples, writable arrays as read-only views; other values as they are.

    For the nested results of a record (e.g. ``BundleFit.check``, whose arrays its
    ``summary`` and ``to_dict`` read): writing into them would change the record's later
    answers, and those of the copies :func:`dataclasses.replace` makes (which share them).

    Parameters
    ----------
    value : object

    Returns
    -------
    object
        A new container where ``value`` holds one (the caller's own stays as it is), else
        ``value`` or a read-only view of it.
    """
    if isinstance(value, np.ndarray):
        return read_only_view(value)
    if isinstance(value, Mapping):
        return FrozenMapping({k: frozen_value(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):  # not namedtuples
        return tuple(map(frozen_value, value))
    return value


def freeze_fields(obj: T, names) -> T:
    """Apply :func:`frozen_value` to the fields ``names`` of ``obj`` (in place: its
    ``__dict__``) and return it.

    Parameters
    ----------
    obj : object
        A frozen dataclass instance.
    names : iterable of str
        The fields holding nested mappings, sequences or arrays.

    Returns
    -------
    object
        ``obj``.
    """
    d = obj.__dict__
    for name in names:
        if name in d:
            d[name] = frozen_value(d[name])
    return obj


class FrozenMapping(Mapping):
    """A read-only dict that pickles and deep-copies (``types.MappingProxyType`` does not).

    For the mappings held by immutable records (e.g. ``Block.free``): shared between the
    records derived from one another, so none may change them.

    Parameters
    ----------
    data : mapping or iterable of (key, value), optional
        The entries (copied).
    """

    __slots__ = ("_data",)

    def __init__(self, data=()) -> None:
        self._data = dict(data)

    def __getitem__(self, key):
        return self._data[key]

    def __iter__(self):
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return repr(self._data)


class ReadOnlyRecord:
    """Base of result dataclasses whose array fields are read-only views.

    ``__post_init__`` applies :func:`read_only_fields` (the arrays given to the constructor
    stay the caller's and writable) and ``__setstate__`` :func:`setstate_read_only` (pickled
    and deep-copied records keep read-only arrays). :func:`build` may fill such a record's
    dictionary and call ``__post_init__``. A subclass with a ``__post_init__`` of its own
    calls this one last.
    """

    #: :func:`build` may fill the fields and call ``__post_init__``.
    _build_post_init = True

    def __post_init__(self) -> None:
        read_only_fields(self)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)
