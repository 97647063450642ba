"""2D affine (6-parameter) transformation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..units import from_radians, to_radians
from ._common import Parametric, fmt_params, homogeneous, invertible, scalars, vector
from .base import Transform

_NAMES = ("a1", "a2", "a3", "b1", "b2", "b3")


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True, eq=False, repr=False)
class Affine2D(Parametric, Transform):
    """2D affine transformation.

    Parametric (linear) form, stored::

        x = a1 x' + a2 y' + a3
        y = b1 x' + b2 y' + b3

    Textbook form: two scales ``sx``, ``sy``, a rotation ``theta``, a non-orthogonality
    (shear) angle ``e`` and two shifts::

        [x, y] = [[1, sin e], [0, cos e]] @ diag(sx, sy) @ R(theta) @ [x', y'] + [x0, y0]

    with ``R(theta) = [[cos, -sin], [sin, cos]]``. The decomposition back is unique with
    ``sy > 0`` and ``|e| < 90 deg``; a reflection (``det < 0``) gives ``sx < 0``.

    Parameters
    ----------
    a1, a2, a3, b1, b2, b3 : float
        ``a1, a2, b1, b2`` unitless (target per source unit); ``a3, b3`` in target units.
    """

    name = "affine2d"
    dim = 2
    _linear_indices = (0, 1, 3, 4)

    a1: float
    a2: float
    a3: float
    b1: float
    b2: float
    b3: float

    def __post_init__(self) -> None:
        v = scalars([self.a1, self.a2, self.a3, self.b1, self.b2, self.b3], 6, "Affine2D")
        for key, val in zip(_NAMES, v):
            object.__setattr__(self, key, val)

    # --- parameter forms ------------------------------------------------------------------------

    @classmethod
    def from_textbook(
        cls,
        sx: float,
        sy: float,
        theta: float,
        e: float,
        x0: float,
        y0: float,
        *,
        unit: str = "rad",
    ) -> Affine2D:
        """From scales, rotation ``theta``, non-orthogonality ``e`` (both in ``unit``), shifts.

        Parameters
        ----------
        sx, sy : float
            Scales along x and y (unitless).
        theta : float
            Rotation, in ``unit``.
        e : float
            Non-orthogonality (shear angle) of the axes, in ``unit``.
        x0, y0 : float
            Shifts, target units.
        unit : str, default "rad"
            Unit of ``theta`` and ``e``.

        Returns
        -------
        Affine2D
        """
        t = float(to_radians(theta, unit))
        ee = float(to_radians(e, unit))
        S = np.array([[1.0, np.sin(ee)], [0.0, np.cos(ee)]])
        A = S @ np.diag([sx, sy]) @ _rot(t)
        return cls(A[0, 0], A[0, 1], x0, A[1, 0], A[1, 1], y0)

    @classmethod
    def from_matrix(cls, A, translation) -> Affine2D:
        """From the 2x2 linear part and the shift vector.

        Parameters
        ----------
        A : array_like, shape (2, 2)
            Linear part ``[[a1, a2], [b1, b2]]``.
        translation : array_like, shape (2,)
            Shifts ``(a3, b3)``, target units.

        Returns
        -------
        Affine2D
        """
        A = np.asarray(A, dtype=float)
        t = vector(translation, 2, "Affine2D translation")
        return cls(A[0, 0], A[0, 1], t[0], A[1, 0], A[1, 1], t[1])

    @property
    def linear(self) -> np.ndarray:
        """The 2x2 linear part ``[[a1, a2], [b1, b2]]``."""
        return np.array([[self.a1, self.a2], [self.b1, self.b2]])

    @property
    def translation(self) -> np.ndarray:
        """``[a3, b3]``."""
        return np.array([self.a3, self.b3])

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 3x3 matrix."""
        return homogeneous(self.linear, self.translation)

    @property
    def det(self) -> float:
        """``det`` of the linear part: the area scale (negative for a reflection)."""
        return float(self.a1 * self.b2 - self.a2 * self.b1)

    @property
    def singular(self) -> bool:
        """``True`` when the linear part is singular to rounding (``|det(A)| <= 1e-14
        max|A|^2``): the transformation maps the plane onto a line (e.g. fitted to collinear
        target points) and has no inverse; its textbook ``sx`` is then 0."""
        big = max(abs(self.a1), abs(self.a2), abs(self.b1), abs(self.b2))
        return abs(self.det) <= 1e-14 * max(big * big, 1e-300)

    def textbook(self) -> dict[str, float]:
        """``sx``, ``sy``, ``theta`` (rad), ``e`` (rad), ``x0``, ``y0``.

        Returns
        -------
        dict of str to float
            Scales unitless, angles in rad, shifts in target units.
        """
        theta = float(np.arctan2(self.b1, self.b2))
        T = self.linear @ _rot(theta).T  # [[sx, sy sin e], [0, sy cos e]]
        sy = float(np.hypot(T[0, 1], T[1, 1]))
        e = float(np.arctan2(T[0, 1], T[1, 1]))
        return {"sx": float(T[0, 0]), "sy": sy, "theta": theta, "e": e,
                "x0": self.a3, "y0": self.b3}

    @property
    def textbook_units(self) -> dict[str, str]:
        return {"sx": "1", "sy": "1", "theta": "rad", "e": "rad", "x0": "", "y0": ""}

    def textbook_jacobian(self) -> np.ndarray:
        """``d(sx, sy, theta, e, x0, y0) / d(a1, a2, a3, b1, b2, b3)`` in closed form.

        With ``rho = hypot(b1, b2)``, ``t = (a1 b1 + a2 b2) / rho`` (``= sy sin e``) and
        ``D = a1 b2 - a2 b1``: ``theta = atan2(b1, b2)``, ``sx = D / rho``,
        ``e = atan2(t, rho)``, ``sy = hypot(t, rho)``.

        Returns
        -------
        numpy.ndarray, shape (6, 6)
            Rows ``sx, sy, theta, e, x0, y0`` (angles in rad), columns ``a1 .. b3``.
        """
        a1, a2, b1, b2 = self.a1, self.a2, self.b1, self.b2
        rho2 = b1 * b1 + b2 * b2
        rho = np.sqrt(rho2)
        dot = a1 * b1 + a2 * b2
        det = a1 * b2 - a2 * b1
        t = dot / rho
        # rows: derivatives by (a1, a2, b1, b2)
        d_rho = np.array([0.0, 0.0, b1 / rho, b2 / rho])
        d_theta = np.array([0.0, 0.0, b2 / rho2, -b1 / rho2])
        d_t = np.array([b1, b2, a1, a2]) / rho - dot * d_rho / rho2
        d_sx = np.array([b2, -b1, -a2, a1]) / rho - det * d_rho / rho2
        sy2 = t * t + rho2
        d_e = (rho * d_t - t * d_rho) / sy2
        d_sy = (t * d_t + rho * d_rho) / np.sqrt(sy2)
        J = np.zeros((6, 6))
        cols = [0, 1, 3, 4]  # a1, a2, b1, b2 in the parameter order a1 a2 a3 b1 b2 b3
        for row, d in ((0, d_sx), (1, d_sy), (2, d_theta), (3, d_e)):
            J[row, cols] = d
        J[4, 2] = 1.0
        J[5, 5] = 1.0
        return J

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return _NAMES

    @property
    def parameters(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in _NAMES])

    def with_parameters(self, values) -> Affine2D:
        """The same model with other parameter values.

        Parameters
        ----------
        values : array_like, shape (6,)
            ``a1, a2, a3, b1, b2, b3``.

        Returns
        -------
        Affine2D
        """
        return Affine2D(*vector(values, 6, "Affine2D"))

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
        out = p @ self.linear.T + self.translation
        return out[0] if single else out

    def inverse(self) -> Affine2D:
        """Closed form ``x' = A^-1 (x - t)``.

        Returns
        -------
        Affine2D

        Raises
        ------
        DegenerateGeometryError
            When the linear part is singular.
        """
        Ai = invertible(self.linear, "Affine2D")
        return Affine2D.from_matrix(Ai, -Ai @ self.translation)

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"model": "affine2d", "a1", ..., "b3", "textbook": {...}}`` (see :meth:`textbook`).
        """
        return {"model": self.name, **self.parametric(), "textbook": self.textbook()}

    @classmethod
    def from_dict(cls, data: dict) -> Affine2D:
        """From :meth:`to_dict` output or textbook ``sx, sy, theta, e, x0, y0`` (radians).

        Parameters
        ----------
        data : dict
            ``a1 .. b3`` (when ``a1`` is present), else ``sx, sy, theta, e, x0, y0``.

        Returns
        -------
        Affine2D

        Raises
        ------
        KeyError
            When a parameter of the chosen form is missing.
        """
        if "a1" in data:
            return cls(*(data[n] for n in _NAMES))
        return cls.from_textbook(data["sx"], data["sy"], data["theta"], data["e"],
                                 data["x0"], data["y0"])

    def __repr__(self) -> str:
        tb = self.textbook()
        return (
            f"Affine2D({fmt_params(_NAMES, self.parameters)}; sx={tb['sx']:.9g}, "
            f"sy={tb['sy']:.9g}, theta={float(from_radians(tb['theta'], 'deg')):.7f} deg, "
            f"e={float(from_radians(tb['e'], 'deg')):.7f} deg)"
        )
