"""Helpers shared by the transformation models: parameter vectors and input checks."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from ..errors import DegenerateGeometryError, InputError
from ..rotation import orthogonality_defect

#: Largest orthogonality defect ``|R.T R - I|`` accepted for a rotation given by the user.
ROTATION_TOLERANCE = 1e-6


class Parametric:
    """Mixin of the models with a flat parameter vector (the *parametric* form).

    Subclasses define :attr:`parameter_names`, :attr:`parameters` and :meth:`with_parameters`,
    and :meth:`textbook` / :attr:`textbook_units` for the textbook form (angles in radians).
    """

    @property
    def parameter_names(self) -> tuple[str, ...]:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def parameters(self) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def with_parameters(self, values) -> Parametric:  # pragma: no cover - abstract
        """The same model type and structure with another parametric vector."""
        raise NotImplementedError

    def textbook(self) -> dict[str, float]:
        """Textbook parameters by name (angles in radians); the parametric ones by default."""
        return dict(zip(self.parameter_names, (float(v) for v in self.parameters)))

    @property
    def textbook_units(self) -> dict[str, str]:
        """Unit of each textbook parameter: ``"rad"`` for angles, ``"1"`` for ratios, ``""``
        for values in the units of the coordinates."""
        return {}

    def parametric(self) -> dict[str, float]:
        """Parametric (linear-form) parameters by name."""
        return dict(zip(self.parameter_names, (float(v) for v in self.parameters)))

    #: Indices (into :attr:`parameters`) of the elements of the linear part (unitless); used
    #: to choose difference steps in :meth:`textbook_jacobian`.
    _linear_indices: ClassVar[tuple[int, ...]] = ()

    def textbook_jacobian(self) -> np.ndarray:
        """Derivatives of the textbook parameters (see :meth:`numeric_textbook_jacobian`)."""
        return self.numeric_textbook_jacobian()

    def numeric_textbook_jacobian(self) -> np.ndarray:
        """Derivatives of the textbook parameters (in :meth:`textbook` order, angles in
        radians) with respect to the parametric ones: shape (n_textbook, n_parametric).

        Central differences of the exact conversion; steps ``1e-6 * max|linear part|`` for
        elements of the linear part and ``1e-6 * max(|p_j|, 1)`` for shifts. Differences of
        angles are wrapped to (-pi, pi]. Used for error propagation of standard deviations,
        for which this is accurate to far more digits than needed.
        """
        p0 = np.asarray(self.parameters, dtype=float)
        names = list(self.textbook())
        units = self.textbook_units
        angle = np.array([units.get(n) == "rad" for n in names])
        lin = np.zeros(p0.size, dtype=bool)
        lin[list(self._linear_indices)] = True
        ref = np.max(np.abs(p0[lin])) if lin.any() else 1.0
        steps = np.where(lin, 1e-6 * max(ref, 1e-300), 1e-6 * np.maximum(np.abs(p0), 1.0))
        J = np.empty((len(names), p0.size))
        for j in range(p0.size):  # loop over parameters (few), not points
            dp = np.zeros_like(p0)
            dp[j] = steps[j]
            hi = np.array(list(self.with_parameters(p0 + dp).textbook().values()))
            lo = np.array(list(self.with_parameters(p0 - dp).textbook().values()))
            diff = hi - lo
            diff[angle] = (diff[angle] + np.pi) % (2 * np.pi) - np.pi
            J[:, j] = diff / (2 * steps[j])
        return J


class MatrixShift3D(Parametric):
    """Mixin of the 3D models ``X = L x + t`` stored as a 3x3 matrix ``L`` and a shift ``t``
    (``translation``), built as ``cls(L, t)``.

    Parametric form: the nine elements of ``L`` row by row and ``tx, ty, tz``. Subclasses
    name ``L`` by :attr:`_matrix3` and the parameters by :attr:`parameter_names`.
    """

    @property
    def _matrix3(self) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 matrix."""
        return homogeneous(self._matrix3, self.translation)

    @property
    def parameters(self) -> np.ndarray:
        return np.concatenate([self._matrix3.reshape(-1), self.translation])

    def with_parameters(self, values) -> MatrixShift3D:
        v = vector(values, 12, type(self).__name__)
        return type(self)(v[:9].reshape(3, 3), v[9:])

    def apply(self, points) -> np.ndarray:
        """``L x + t`` for points (n, 3) or one point (3,)."""
        p, single = self._points(points)
        out = p @ self._matrix3.T + self.translation
        return out[0] if single else out


def homogeneous(linear: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The homogeneous (d+1, d+1) matrix of ``X = linear @ x + translation``."""
    d = len(translation)
    T = np.eye(d + 1)
    T[:d, :d] = linear
    T[:d, d] = translation
    return T


def matrix_and_shift(linear, translation, what: str, part: str) -> tuple[np.ndarray, np.ndarray]:
    """A 3x3 matrix and a shift of length 3 as float arrays (copies), both finite.

    ``part`` names the matrix in the message (e.g. ``"rotation"``).
    """
    L = np.array(linear, dtype=float)
    t = np.array(translation, dtype=float).reshape(-1)
    if L.shape != (3, 3) or t.shape != (3,):
        raise InputError(f"{what}: {part} must be 3x3 and translation of length 3")
    if not (np.all(np.isfinite(L)) and np.all(np.isfinite(t))):
        raise InputError(f"{what}: parameters must be finite")
    return L, t


def check_proper_rotation(R: np.ndarray, what: str, fix: str = "") -> None:
    """:class:`InputError` unless ``R`` is a proper rotation (orthogonality defect <=
    :data:`ROTATION_TOLERANCE`, det > 0); ``fix`` is appended to the message."""
    defect = orthogonality_defect(R)
    if defect > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise InputError(
            f"{what}: rotation is not a proper rotation (orthogonality defect {defect:.2e}, "
            f"det {np.linalg.det(R):.6f}){fix}"
        )


def vector(values, n: int, what: str) -> np.ndarray:
    """``values`` as a finite float vector of length ``n``."""
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise InputError(f"{what}: expected {n} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what}: parameters must be finite")
    return arr


def scalars(values: list, n: int, what: str) -> list[float]:
    """``values`` (a list of ``n`` scalars) as finite Python floats: :func:`vector`'s checks,
    without the round trip through an array when every value already is a float (Python or
    numpy float; the parameters of an estimate)."""
    if len(values) == n and all(isinstance(v, float) for v in values):
        if not all(map(math.isfinite, values)):
            raise InputError(f"{what}: parameters must be finite")
        return [float(v) for v in values]
    return vector(values, n, what).tolist()


def matrix(values, shape: tuple[int, int], what: str) -> np.ndarray:
    """``values`` as a finite float matrix of ``shape`` (read-only copy)."""
    arr = np.array(values, dtype=float)
    if arr.shape != shape:
        raise InputError(f"{what}: expected a matrix of shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what}: parameters must be finite")
    arr.flags.writeable = False
    return arr


def frozen(arr: np.ndarray) -> np.ndarray:
    """A read-only copy."""
    out = np.array(arr, dtype=float)
    out.flags.writeable = False
    return out


def invertible(A: np.ndarray, what: str) -> np.ndarray:
    """Inverse of a small square matrix, or :class:`DegenerateGeometryError` when singular."""
    s = np.linalg.svd(A, compute_uv=False)
    if s[-1] <= 1e-14 * max(s[0], 1e-300):
        sv = np.array2string(s, precision=3)
        raise DegenerateGeometryError(
            f"{what}: the linear part is singular (singular values {sv}); "
            "the transformation has no inverse"
        )
    return np.linalg.inv(A)


def divide_homogeneous(h: np.ndarray, w: np.ndarray, what: str) -> np.ndarray:
    """``h / w`` row-wise; :class:`InputError` naming rows with ``w == 0`` (points mapped to
    infinity by a projective transformation)."""
    bad = w == 0
    if np.any(bad):
        rows = ", ".join(str(int(i)) for i in np.flatnonzero(bad)[:10])
        raise InputError(
            f"{what}: point(s) at row index {rows} lie on the vanishing line/plane "
            "(denominator 0) and map to infinity"
        )
    return h / w[:, None]


def fmt_params(names: Sequence[str], values: Sequence[float], digits: int = 9) -> str:
    """``name=value, ...`` for ``repr``."""
    return ", ".join(f"{n}={v:.{digits}g}" for n, v in zip(names, values))
