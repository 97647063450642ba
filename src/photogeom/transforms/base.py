"""Common interface of the transformation models."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from ..errors import InputError
from ..records import setstate_read_only, value_key
from ..validation import as_float64, as_points

_REGISTRY: dict[str, type[Transform]] = {}


class Transform(ABC):
    """A point transformation ``target = T(source)``.

    Subclasses are small immutable objects: parameters, :meth:`apply`, :meth:`inverse`,
    :meth:`to_dict` / :func:`from_dict` (JSON round trip). No estimation code lives here.
    """

    #: Registry key and JSON ``"model"`` value, e.g. ``"similarity3d"``.
    name: ClassVar[str] = ""
    #: Coordinate dimension of source and target points.
    dim: ClassVar[int] = 0

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if cls.name:
            _REGISTRY[cls.name] = cls

    def _points(self, points, name: str = "points") -> tuple[np.ndarray, bool]:
        arr = as_float64(points, name)
        single = arr.ndim == 1
        return as_points(arr, self.dim, name), single

    def __call__(self, points) -> np.ndarray:
        return self.apply(points)

    def _key(self) -> tuple:
        """The compared fields (:func:`photogeom.records.value_key`)."""
        return value_key(self)

    def __eq__(self, other: object) -> bool:
        """Same model class and the same values (arrays compared element by element).

        The generated dataclass ``==`` compared arrays with ``==`` and raised "the truth
        value of an array ... is ambiguous" for every model holding arrays.
        """
        if type(other) is not type(self):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        """Consistent with ``==`` (the model's arrays are read-only)."""
        return hash((type(self), self._key()))

    def __setstate__(self, state: dict) -> None:
        # pickle / deepcopy: the arrays stay read-only (records.setstate_read_only)
        setstate_read_only(self, state)

    @abstractmethod
    def apply(self, points) -> np.ndarray:
        """Transform points of shape ``(n, dim)`` (or one point ``(dim,)``).

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, dim) or (dim,)
            Target coordinates (target units).
        """

    @abstractmethod
    def inverse(self) -> Transform:
        """The inverse transformation (closed form where one exists).

        Returns
        -------
        Transform
            Maps target coordinates back to source coordinates.
        """

    @abstractmethod
    def to_dict(self) -> dict:
        """JSON-ready parameters, with ``"model": name``.

        Returns
        -------
        dict
        """

    @classmethod
    @abstractmethod
    def from_dict(cls, data: dict) -> Transform:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            Output of :meth:`to_dict` (the subclass documents its other accepted forms).

        Returns
        -------
        Transform
        """


def from_dict(data: dict) -> Transform:
    """Rebuild any transformation from :meth:`Transform.to_dict` output.

    Parameters
    ----------
    data : dict
        Parameters with a ``"model"`` entry naming one of :func:`registered_models`.

    Returns
    -------
    Transform
        An instance of the named model.

    Raises
    ------
    InputError
        Without a ``"model"`` entry, for an unknown model (the known ones are listed), or
        without a parameter the model needs (named).
    """
    try:
        name = data["model"]
    except (KeyError, TypeError) as exc:
        raise InputError("transformation parameters need a 'model' entry") from exc
    if name not in _REGISTRY:
        raise InputError(
            f"unknown transformation model {name!r}; known: {', '.join(sorted(_REGISTRY))}"
        )
    try:
        return _REGISTRY[name].from_dict(data)
    except KeyError as exc:
        key = exc.args[0] if exc.args else "?"
        raise InputError(
            f"{name} parameters without the entry {key!r}: give every parameter of the model "
            "(as to_dict() writes them)"
        ) from None


def registered_models() -> list[str]:
    """Names of all transformation models.

    Returns
    -------
    list of str
        Sorted; the values accepted as ``"model"`` by :func:`from_dict`.
    """
    return sorted(_REGISTRY)
