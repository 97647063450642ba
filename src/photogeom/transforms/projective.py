"""Projective transformations: 2D (8 parameters) and 3D (15 parameters).

Both are homogeneous matrices ``H`` of size ``(d + 1, d + 1)`` normalised to ``H[d, d] = 1``:
``[X, w] = H @ [x, 1]``, point ``X / w``. The textbook and parametric forms coincide (the
matrix elements); the homogeneous result is available through ``apply_homogeneous``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import DegenerateGeometryError, InputError
from ._common import Parametric, divide_homogeneous, fmt_params, frozen, invertible, vector
from .base import Transform


def _normalise(H: np.ndarray, what: str) -> np.ndarray:
    h = H[-1, -1]
    scale = np.max(np.abs(H))
    if not np.isfinite(h) or abs(h) <= 1e-14 * scale:
        raise DegenerateGeometryError(
            f"{what}: the last element of the homogeneous matrix is 0 (the origin maps to "
            "infinity), so it cannot be normalised to 1; shift the source coordinates"
        )
    return H / h


@dataclass(frozen=True, eq=False, repr=False)
class _Projective(Parametric, Transform):
    """Common code; subclasses fix ``dim`` and the parameter names."""

    matrix: np.ndarray
    names: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        d = self.dim
        H = np.array(self.matrix, dtype=float)
        if H.shape != (d + 1, d + 1):
            raise InputError(
                f"{type(self).__name__}: expected a {d + 1}x{d + 1} homogeneous matrix, got "
                f"shape {H.shape}"
            )
        if not np.all(np.isfinite(H)):
            raise InputError(f"{type(self).__name__}: parameters must be finite")
        object.__setattr__(self, "matrix", frozen(_normalise(H, type(self).__name__)))

    @classmethod
    def from_parameters(cls, values) -> _Projective:
        """From the ``(d + 1)^2 - 1`` parameters in the order of :attr:`parameter_names`.

        Parameters
        ----------
        values : array_like, shape ((d + 1)^2 - 1,)
            8 values in 2D, 15 in 3D; the last matrix element is 1.

        Returns
        -------
        Projective2D or Projective3D

        Raises
        ------
        InputError
            For another number of values, or values that are not finite.
        """
        d = cls.dim
        v = vector(values, (d + 1) ** 2 - 1, cls.__name__)
        return cls(np.append(v, 1.0).reshape(d + 1, d + 1))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.names

    @property
    def parameters(self) -> np.ndarray:
        return self.matrix.reshape(-1)[:-1].copy()

    def with_parameters(self, values) -> _Projective:
        """The same model with other parameter values (see :meth:`from_parameters`).

        Parameters
        ----------
        values : array_like, shape ((d + 1)^2 - 1,)
            In the order of :attr:`parameter_names`.

        Returns
        -------
        Projective2D or Projective3D
        """
        return type(self).from_parameters(values)

    def textbook_jacobian(self) -> np.ndarray:
        """Identity: the textbook and parametric forms coincide.

        Returns
        -------
        numpy.ndarray, shape (p, p)
            ``p`` = number of parameters.
        """
        return np.eye(len(self.names))

    def apply_homogeneous(self, points) -> np.ndarray:
        """``H @ [x, 1]`` for points: homogeneous results.

        Parameters
        ----------
        points : array_like, shape (n, d) or (d,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, d + 1) or (d + 1,)
        """
        p, single = self._points(points)
        out = p @ self.matrix[:, :-1].T + self.matrix[:, -1]
        return out[0] if single else out

    def apply(self, points) -> np.ndarray:
        """Transform points (n, d) or one point (d,).

        Parameters
        ----------
        points : array_like, shape (n, d) or (d,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, d) or (d,)
            Target coordinates (target units).

        Raises
        ------
        InputError
            For points of another shape or not finite, or points mapped to infinity (on
            the vanishing line/plane; their rows are named).
        """
        p, single = self._points(points)
        h = p @ self.matrix[:, :-1].T + self.matrix[:, -1]
        out = divide_homogeneous(h[:, :-1], h[:, -1], type(self).__name__)
        return out[0] if single else out

    def inverse(self) -> _Projective:
        """Closed form: the inverse matrix, normalised.

        Returns
        -------
        Projective2D or Projective3D

        Raises
        ------
        DegenerateGeometryError
            When the matrix is singular, or its inverse maps the origin to infinity.
        """
        return type(self)(invertible(self.matrix, type(self).__name__))

    def to_dict(self) -> dict:
        return {"model": self.name, **self.parametric(), "matrix": self.matrix.tolist()}

    @classmethod
    def from_dict(cls, data: dict) -> _Projective:
        """From :meth:`to_dict` output: ``matrix`` or the named parameters.

        Parameters
        ----------
        data : dict
            ``matrix``, else the parameters by name (:attr:`parameter_names`).

        Returns
        -------
        Projective2D or Projective3D

        Raises
        ------
        InputError
            For a matrix of the wrong shape or not finite.
        KeyError
            When a named parameter is missing.
        """
        if "matrix" in data:
            return cls(data["matrix"])
        return cls.from_parameters([data[n] for n in cls.names])

    def __repr__(self) -> str:
        return f"{type(self).__name__}({fmt_params(self.names, self.parameters)})"


@dataclass(frozen=True, eq=False, repr=False)
class Projective2D(_Projective):
    """2D projective transformation (8 parameters)::

        x = (a1 x' + a2 y' + a3) / (c1 x' + c2 y' + 1)
        y = (b1 x' + b2 y' + b3) / (c1 x' + c2 y' + 1)

    Parameters
    ----------
    matrix : array_like, shape (3, 3)
        ``[[a1, a2, a3], [b1, b2, b3], [c1, c2, c3]]``; divided by ``c3`` on construction.
        Use :meth:`from_parameters` for the 8 values ``a1, a2, a3, b1, b2, b3, c1, c2``.
    """

    name = "projective2d"
    dim = 2
    names: ClassVar[tuple[str, ...]] = ("a1", "a2", "a3", "b1", "b2", "b3", "c1", "c2")


@dataclass(frozen=True, eq=False, repr=False)
class Projective3D(_Projective):
    """3D projective transformation (15 parameters): a homogeneous 4x4 matrix with ``h44 = 1``::

        X = (h11 x + h12 y + h13 z + h14) / (h41 x + h42 y + h43 z + 1),  same for Y, Z

    Parameters
    ----------
    matrix : array_like, shape (4, 4)
        Divided by its last element on construction. Use :meth:`from_parameters` for the
        15 values ``h11 .. h14, h21 .. h24, h31 .. h34, h41, h42, h43``.
    """

    name = "projective3d"
    dim = 3
    names: ClassVar[tuple[str, ...]] = tuple(
        f"h{i}{j}" for i in range(1, 5) for j in range(1, 5)
    )[:-1]
