"""2D similarity (conformal, 4-parameter Helmert) transformation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError
from ..units import from_radians, to_radians
from ._common import Parametric, fmt_params, scalars, vector
from .base import Transform


@dataclass(frozen=True, eq=False, repr=False)
class Similarity2D(Parametric, Transform):
    """2D similarity ``[x, y] = s R(theta) [x', y'] + [x0, y0]``.

    Parametric (linear) form, stored::

        x =  a x' + b y' + c
        y = -b x' + a y' + d

    with ``a = s cos(theta)``, ``b = -s sin(theta)``, ``c = x0``, ``d = y0``; back
    ``s = hypot(a, b)``, ``theta = atan2(-b, a)``. ``R(theta)`` rotates counter-clockwise by
    ``theta`` (radians) in a right-handed system.

    Parameters
    ----------
    a, b : float
        Unitless (target units per source unit).
    c, d : float
        Shifts in target units.
    """

    name = "similarity2d"
    dim = 2
    _linear_indices = (0, 1)

    a: float
    b: float
    c: float
    d: float

    def __post_init__(self) -> None:
        v = scalars([self.a, self.b, self.c, self.d], 4, "Similarity2D")
        for key, val in zip("abcd", v):
            object.__setattr__(self, key, val)

    # --- parameter forms ------------------------------------------------------------------------

    @classmethod
    def from_textbook(
        cls, scale: float, theta: float, x0: float, y0: float, *, unit: str = "rad"
    ) -> Similarity2D:
        """From scale, rotation ``theta`` (in ``unit``) and shifts ``x0``, ``y0``.

        Parameters
        ----------
        scale : float
            Scale factor (unitless).
        theta : float
            Rotation, in ``unit``.
        x0, y0 : float
            Shifts, target units.
        unit : str, default "rad"
            Unit of ``theta``.

        Returns
        -------
        Similarity2D
        """
        t = float(to_radians(theta, unit))
        return cls(scale * np.cos(t), -scale * np.sin(t), x0, y0)

    @property
    def scale(self) -> float:
        """``s = hypot(a, b)``."""
        return float(np.hypot(self.a, self.b))

    @property
    def theta(self) -> float:
        """Rotation angle in radians, ``atan2(-b, a)`` in (-pi, pi]."""
        return float(np.arctan2(-self.b, self.a))

    def textbook(self) -> dict[str, float]:
        """``scale``, ``theta`` (rad), ``x0``, ``y0``.

        Returns
        -------
        dict of str to float
            Scale unitless, ``theta`` in rad, shifts in target units.
        """
        return {"scale": self.scale, "theta": self.theta, "x0": self.c, "y0": self.d}

    @property
    def textbook_units(self) -> dict[str, str]:
        return {"scale": "1", "theta": "rad", "x0": "", "y0": ""}

    def textbook_jacobian(self) -> np.ndarray:
        """``d(scale, theta, x0, y0) / d(a, b, c, d)`` (closed form).

        ``ds = (a da + b db) / s``, ``dtheta = (b da - a db) / s^2``.

        Returns
        -------
        numpy.ndarray, shape (4, 4)
            Rows ``scale, theta (rad), x0, y0``, columns ``a, b, c, d``.
        """
        a, b = self.a, self.b
        s2 = a * a + b * b
        s = np.sqrt(s2)
        return np.array([
            [a / s, b / s, 0.0, 0.0],
            [b / s2, -a / s2, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ])

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("a", "b", "c", "d")

    @property
    def parameters(self) -> np.ndarray:
        return np.array([self.a, self.b, self.c, self.d])

    def with_parameters(self, values) -> Similarity2D:
        """The same model with other parameter values.

        Parameters
        ----------
        values : array_like, shape (4,)
            ``a, b, c, d``.

        Returns
        -------
        Similarity2D
        """
        return Similarity2D(*vector(values, 4, "Similarity2D"))

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 3x3 matrix."""
        return np.array([[self.a, self.b, self.c], [-self.b, self.a, self.d], [0.0, 0.0, 1.0]])

    # --- Transform interface ------------------------------------------------------------------

    def apply(self, points) -> np.ndarray:
        """Transform points (n, 2) or one point (2,).

        Parameters
        ----------
        points : array_like, shape (n, 2) or (2,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            Target coordinates (target units); one point for one point.

        Raises
        ------
        InputError
            When ``points`` is not of shape (n, 2) or (2,) or holds NaN/infinite values.
        """
        p, single = self._points(points)
        x, y = p[:, 0], p[:, 1]
        out = np.column_stack([self.a * x + self.b * y + self.c, -self.b * x + self.a * y + self.d])
        return out[0] if single else out

    def inverse(self) -> Similarity2D:
        """Closed form: ``a' = a / s^2``, ``b' = -b / s^2``, shifts ``-A^-1 [c, d]``.

        Returns
        -------
        Similarity2D

        Raises
        ------
        DegenerateGeometryError
            For scale 0.
        """
        s2 = self.a**2 + self.b**2
        if s2 == 0.0:
            raise DegenerateGeometryError("Similarity2D: scale 0; no inverse exists")
        a, b = self.a / s2, -self.b / s2
        c = -(a * self.c + b * self.d)
        d = -(-b * self.c + a * self.d)
        return Similarity2D(a, b, c, d)

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"model": "similarity2d", "a", "b", "c", "d", "textbook": {...}}``
            (see :meth:`textbook`).
        """
        return {"model": self.name, **self.parametric(), "textbook": self.textbook()}

    @classmethod
    def from_dict(cls, data: dict) -> Similarity2D:
        """From :meth:`to_dict` output (``a``..``d``) or textbook ``scale, theta (rad), x0, y0``.

        Parameters
        ----------
        data : dict
            ``a, b, c, d`` (when ``a`` is present), else ``scale, theta, x0, y0``.

        Returns
        -------
        Similarity2D

        Raises
        ------
        KeyError
            When a parameter of the chosen form is missing.
        """
        if "a" in data:
            return cls(data["a"], data["b"], data["c"], data["d"])
        return cls.from_textbook(data["scale"], data["theta"], data["x0"], data["y0"])

    def __repr__(self) -> str:
        deg = float(from_radians(self.theta, "deg"))
        return (
            f"Similarity2D({fmt_params('abcd', self.parameters)}; scale={self.scale:.9g}, "
            f"theta={deg:.7f} deg)"
        )
