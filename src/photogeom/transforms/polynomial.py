"""Polynomial transformations of any order, 2D and 3D, and their iterative inverse.

A polynomial of order ``k`` maps each output coordinate as a sum of monomials of total degree
``<= k`` in *reduced* source coordinates ``u = (x - centre) / scale``::

    x_out = sum_e a_e u^e,   u^e = u_1^e1 u_2^e2 (u_3^e3)

* **parametric form**: the coefficients in reduced coordinates (what is estimated; well
  conditioned whatever the size of the coordinates);
* **textbook form**: the plain coefficients of ``x'^i y'^j`` (``centre = 0``, ``scale = 1``),
  available through :meth:`to_plain`. For coordinates far from the origin the plain form is
  numerically poor (cancellation), which is why the reduction is part of the model.

Monomials are ordered by total degree, then by descending power of the first coordinate:
``1, x, y, x^2, x y, y^2, ...`` (2D) and ``1, x, y, z, x^2, x y, x z, y^2, y z, z^2, ...`` (3D).
Coefficient names are the output letter (``a``, ``b``, ``c`` for x, y, z) followed by the
exponents: ``a10`` multiplies ``x'`` in x, ``b01`` multiplies ``y'`` in y (exponents above 9
are separated by ``_``).

There is no closed-form inverse; :meth:`inverse` returns an iterative (Newton) inverse with a
tolerance, which reports points that do not converge.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import ClassVar, NamedTuple

import numpy as np

from ..errors import ConvergenceError, InputError
from ..validation import as_float64
from ._common import Parametric, frozen, vector
from .base import Transform

_LETTERS = "abc"


@lru_cache(maxsize=64)
def _exponents_cached(order: int, dim: int) -> tuple[tuple[int, ...], ...]:
    out: list[tuple[int, ...]] = []
    for deg in range(order + 1):
        if dim == 2:
            out.extend((deg - j, j) for j in range(deg + 1))
        else:
            for i in range(deg, -1, -1):
                out.extend((i, deg - i - k, k) for k in range(deg - i + 1))
    return tuple(out)


def polynomial_exponents(order: int, dim: int) -> np.ndarray:
    """Exponents of the monomials of total degree ``<= order``.

    Parameters
    ----------
    order : int
        Highest total degree, >= 1.
    dim : {2, 3}
        Number of coordinates.

    Returns
    -------
    numpy.ndarray of int, shape (n_terms, dim)
        One row of exponents per monomial, in the module's monomial order.

    Raises
    ------
    InputError
        For ``dim`` other than 2 or 3, or ``order`` not an integer >= 1.
    """
    if dim not in (2, 3):
        raise InputError(f"polynomial: dimension must be 2 or 3, got {dim}")
    if int(order) != order or order < 1:
        raise InputError(f"polynomial: order must be an integer >= 1, got {order!r}")
    return np.array(_exponents_cached(int(order), dim), dtype=int)


def polynomial_term_count(order: int, dim: int) -> int:
    """Number of monomials: ``(k+1)(k+2)/2`` in 2D, ``(k+1)(k+2)(k+3)/6`` in 3D.

    Parameters
    ----------
    order : int
        Highest total degree ``k``.
    dim : {2, 3}
        Number of coordinates.

    Returns
    -------
    int

    Raises
    ------
    InputError
        For a ``dim`` other than 2 or 3, or a negative ``order``.
    """
    if dim not in (2, 3):
        raise InputError(f"polynomial_term_count: dim must be 2 or 3, not {dim!r}")
    k = int(order)
    if k < 0:
        raise InputError(f"polynomial_term_count: order must be >= 0, not {order!r}")
    return (k + 1) * (k + 2) // 2 if dim == 2 else (k + 1) * (k + 2) * (k + 3) // 6


def polynomial_terms(u: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Monomials ``u^e`` of points ``u``.

    Parameters
    ----------
    u : numpy.ndarray, shape (n, dim)
        (Reduced) coordinates.
    exponents : numpy.ndarray of int, shape (n_terms, dim)
        From :func:`polynomial_exponents`.

    Returns
    -------
    numpy.ndarray, shape (n, n_terms)
        Design-matrix rows, one per point.
    """
    n, dim = u.shape
    kmax = int(exponents.max()) if exponents.size else 0
    powers = np.empty((dim, kmax + 1, n))
    powers[:, 0] = 1.0
    for p in range(1, kmax + 1):
        powers[:, p] = powers[:, p - 1] * u.T
    out = powers[0, exponents[:, 0]]
    for a in range(1, dim):
        out = out * powers[a, exponents[:, a]]
    return out.T


def _names(exponents: np.ndarray, dim: int) -> tuple[str, ...]:
    wide = exponents.max() > 9
    names = []
    for letter in _LETTERS[:dim]:
        for e in exponents:
            names.append(letter + ("_".join(map(str, e)) if wide else "".join(map(str, e))))
    return tuple(names)


def _rereduction(exponents: np.ndarray, alpha: float, beta: np.ndarray) -> np.ndarray:
    """Matrix T with ``coef_new = coef_old @ T`` when ``u_old = alpha u_new + beta``."""
    import scipy.special  # imported here: applying a transformation needs no scipy

    E = exponents[:, None, :]
    K = exponents[None, :, :]
    valid = np.all(K <= E, axis=2)
    diff = np.where(valid[..., None], E - K, 0)
    with np.errstate(invalid="ignore"):
        factors = scipy.special.comb(E, K) * alpha**K * np.where(diff > 0, beta**diff, 1.0)
    T = np.prod(factors, axis=2)
    return np.where(valid, T, 0.0)


@dataclass(frozen=True, eq=False, repr=False)
class _Polynomial(Parametric, Transform):
    order: int
    coefficients: np.ndarray
    centre: np.ndarray | None = None
    scale: float = 1.0

    inverse_class: ClassVar[type] = object

    def __post_init__(self) -> None:
        d = self.dim
        try:
            whole = int(self.order) == self.order
        except (TypeError, ValueError, OverflowError):
            whole = False
        if not whole or self.order < 1:
            raise InputError(f"polynomial: order must be an integer >= 1, got {self.order!r}")
        # the shape is checked against the closed-form term count before the exponents of
        # the order are built (a corrupt order of 1e300 must not enumerate monomials)
        n_terms = polynomial_term_count(self.order, d)
        C = np.array(self.coefficients, dtype=float)
        if C.shape == (d * n_terms,):
            C = C.reshape(d, -1)
        if C.shape != (d, n_terms):
            raise InputError(
                f"{type(self).__name__} of order {self.order}: expected coefficients of shape "
                f"({d}, {n_terms}), got {C.shape}"
            )
        centre = np.zeros(d) if self.centre is None else vector(self.centre, d, "centre")
        scale = float(self.scale)
        if not np.all(np.isfinite(C)):
            raise InputError(f"{type(self).__name__}: coefficients must be finite")
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"{type(self).__name__}: scale must be > 0, got {scale}")
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "coefficients", frozen(C))
        object.__setattr__(self, "centre", frozen(centre))
        object.__setattr__(self, "scale", scale)

    # --- structure -----------------------------------------------------------------------------

    @property
    def exponents(self) -> np.ndarray:
        """Exponents (n_terms, dim) of the monomials, in coefficient order."""
        return polynomial_exponents(self.order, self.dim)

    @property
    def n_terms(self) -> int:
        """Monomials per output coordinate."""
        return polynomial_term_count(self.order, self.dim)

    def reduce(self, points: np.ndarray) -> np.ndarray:
        """Reduced coordinates ``(x - centre) / scale``.

        Parameters
        ----------
        points : numpy.ndarray, shape (n, dim)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, dim)
            Unitless.
        """
        return (points - self.centre) / self.scale

    def design(self, points) -> np.ndarray:
        """Monomials of the reduced points.

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, n_terms)
        """
        p, _ = self._points(points)
        return polynomial_terms(self.reduce(p), self.exponents)

    @classmethod
    def identity(cls, order: int = 1, centre=None, scale: float = 1.0) -> _Polynomial:
        """The identity mapping written as a polynomial of ``order`` with the given reduction.

        Parameters
        ----------
        order : int, default 1
            Highest total degree (>= 1).
        centre : array_like, shape (dim,), optional
            Reduction centre (source units); default 0.
        scale : float, default 1.0
            Reduction scale (source units).

        Returns
        -------
        Polynomial2D or Polynomial3D
        """
        d = cls.dim
        exps = polynomial_exponents(order, d)
        c0 = np.zeros(d) if centre is None else vector(centre, d, "centre")
        C = np.zeros((d, exps.shape[0]))
        C[:, 0] = c0
        for a in range(d):
            C[a, 1 + a] = scale
        return cls(order, C, c0, scale)

    # --- parameter forms ------------------------------------------------------------------------

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return _names(self.exponents, self.dim)

    @property
    def parameters(self) -> np.ndarray:
        return self.coefficients.reshape(-1).copy()

    def with_parameters(self, values) -> _Polynomial:
        """The same model with other coefficients (same order and reduction).

        Parameters
        ----------
        values : array_like, shape (dim * n_terms,)
            Coefficients, row by row (``a..`` then ``b..`` (then ``c..``)).

        Returns
        -------
        Polynomial2D or Polynomial3D
        """
        v = vector(values, self.dim * self.n_terms, type(self).__name__)
        return type(self)(self.order, v.reshape(self.dim, -1), self.centre, self.scale)

    def reduction_matrix(self, centre=None, scale: float = 1.0) -> np.ndarray:
        """``T`` with ``coefficients_new = coefficients @ T`` for another reduction.

        The same mapping with reduction (``centre``, ``scale``); linear in the coefficients.

        Parameters
        ----------
        centre : array_like, shape (dim,), optional
            New reduction centre (source units); default 0.
        scale : float, default 1.0
            New reduction scale (source units), > 0.

        Returns
        -------
        numpy.ndarray, shape (n_terms, n_terms)

        Raises
        ------
        InputError
            For a scale that is not > 0.
        """
        d = self.dim
        c_new = np.zeros(d) if centre is None else vector(centre, d, "centre")
        s_new = float(scale)
        if not (np.isfinite(s_new) and s_new > 0):
            raise InputError(f"scale must be > 0, got {scale}")
        alpha = s_new / self.scale
        beta = (c_new - self.centre) / self.scale
        return _rereduction(self.exponents, alpha, beta)

    def with_reduction(self, centre=None, scale: float = 1.0) -> _Polynomial:
        """The same mapping with coefficients for another reduction ``(x - centre) / scale``.

        Parameters
        ----------
        centre : array_like, shape (dim,), optional
            New reduction centre (source units); default 0.
        scale : float, default 1.0
            New reduction scale (source units), > 0.

        Returns
        -------
        Polynomial2D or Polynomial3D

        Raises
        ------
        InputError
            For a scale that is not > 0.
        """
        T = self.reduction_matrix(centre, scale)
        c_new = np.zeros(self.dim) if centre is None else centre
        return type(self)(self.order, self.coefficients @ T, c_new, scale)

    def to_plain(self) -> _Polynomial:
        """The same mapping in plain coefficients (``centre = 0``, ``scale = 1``).

        The textbook form ``x = sum a_ij x'^i y'^j``.

        Returns
        -------
        Polynomial2D or Polynomial3D
        """
        return self.with_reduction(None, 1.0)

    def textbook(self) -> dict[str, float]:
        """Plain coefficients of ``x'^i y'^j (z'^k)`` by name (see :meth:`to_plain`).

        Returns
        -------
        dict of str to float
        """
        plain = self.to_plain()
        return dict(zip(plain.parameter_names, (float(v) for v in plain.parameters)))

    @property
    def textbook_units(self) -> dict[str, str]:
        return dict.fromkeys(self.parameter_names, "")

    def textbook_jacobian(self) -> np.ndarray:
        """Exact derivatives of the plain coefficients by the reduced ones (a linear map).

        Returns
        -------
        numpy.ndarray, shape (dim * n_terms, dim * n_terms)
        """
        T = self.reduction_matrix(None, 1.0)
        return np.kron(np.eye(self.dim), T.T)

    # --- Transform interface ------------------------------------------------------------------

    def apply(self, points) -> np.ndarray:
        """Transform points (n, dim) or one point (dim,).

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, dim) or (dim,)
            Target coordinates (target units).

        Raises
        ------
        InputError
            For points of another shape or not finite.
        """
        p, single = self._points(points)
        out = polynomial_terms(self.reduce(p), self.exponents) @ self.coefficients.T
        return out[0] if single else out

    def jacobian(self, points) -> np.ndarray:
        """Derivatives ``d out / d in`` at points.

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Source coordinates (source units).

        Returns
        -------
        numpy.ndarray, shape (n, dim, dim) or (dim, dim)
            Target units per source unit.
        """
        p, single = self._points(points)
        u = self.reduce(p)
        E = self.exponents
        J = np.empty((p.shape[0], self.dim, self.dim))
        for a in range(self.dim):
            Ea = E.copy()
            fac = Ea[:, a].astype(float)
            Ea[:, a] = np.maximum(Ea[:, a] - 1, 0)
            dT = polynomial_terms(u, Ea) * fac  # d(u^e)/du_a
            J[:, :, a] = (dT @ self.coefficients.T) / self.scale
        return J[0] if single else J

    def inverse(self, tol: float = 1e-9, max_iter: int = 50) -> _PolynomialInverse:
        """Iterative (Newton) inverse; see :class:`Polynomial2DInverse`.

        Parameters
        ----------
        tol : float, default 1e-9
            Convergence tolerance, target units (> 0).
        max_iter : int, default 50
            Newton iterations at most (>= 1).

        Returns
        -------
        Polynomial2DInverse or Polynomial3DInverse
        """
        return self.inverse_class(self, tol, max_iter)

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``model, order, coefficients, centre, scale, names``.
        """
        return {
            "model": self.name,
            "order": self.order,
            "coefficients": self.coefficients.tolist(),
            "centre": self.centre.tolist(),
            "scale": self.scale,
            "names": list(self.parameter_names),
        }

    @classmethod
    def from_dict(cls, data: dict) -> _Polynomial:
        """From :meth:`to_dict` output (``centre``/``scale`` optional: plain form).

        Parameters
        ----------
        data : dict
            ``order``, ``coefficients`` and optionally ``centre``, ``scale``.

        Returns
        -------
        Polynomial2D or Polynomial3D

        Raises
        ------
        InputError
            For coefficients of the wrong shape or not finite, or a bad order or scale.
        KeyError
            When ``order`` or ``coefficients`` is missing.
        """
        return cls(int(data["order"]), data["coefficients"], data.get("centre"),
                   data.get("scale", 1.0))

    def __repr__(self) -> str:
        red = f"centre={np.array2string(self.centre, precision=6)}, scale={self.scale:.6g}"
        linear = np.tile(self.exponents.sum(axis=1) <= 1, self.dim)
        lin = ", ".join(f"{n}={v:.6g}" for n, v, keep in
                        zip(self.parameter_names, self.parameters, linear) if keep)
        return (f"{type(self).__name__}(order={self.order}, {self.dim * self.n_terms} "
                f"coefficients, {red}; {lin}, ...)")


class InverseResult(NamedTuple):
    """Result of an iterative inverse: ``points`` (n, dim), ``converged`` (n,) bool,
    ``residual`` (n,) = ``|forward(points) - target|`` in target units, ``iterations``."""

    points: np.ndarray
    converged: np.ndarray
    residual: np.ndarray
    iterations: int


@dataclass(frozen=True, eq=False, repr=False)
class _PolynomialInverse(Transform):
    forward: _Polynomial
    tol: float = 1e-9
    max_iter: int = 50

    def __post_init__(self) -> None:
        if not (np.isfinite(self.tol) and self.tol > 0):
            raise InputError(f"tol must be > 0, got {self.tol}")
        if int(self.max_iter) < 1:
            raise InputError(f"max_iter must be >= 1, got {self.max_iter}")

    def apply_with_status(self, points) -> InverseResult:
        """Solve ``forward(x) = X`` for every point by damped Newton iteration.

        Starts from the inverse of the linearisation at the reduction centre; a point has
        converged when ``|forward(x) - X|_inf <= tol + 16 eps (|X|_inf + 1)`` (target units).
        Points that do not converge are flagged, not dropped.

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Target points (target units).

        Returns
        -------
        InverseResult
            ``points`` (n, dim) in source units, ``converged`` (n,), ``residual`` (n,) in
            target units, ``iterations``.

        Raises
        ------
        ConvergenceError
            When the Jacobian at the reduction centre is singular.
        """
        X, _ = self._points(points, "target points")
        f = self.forward
        c = f.centre[None, :]
        J0 = f.jacobian(c)[0]
        try:
            x = c + np.linalg.solve(J0, (X - f.apply(c)).T).T
        except np.linalg.LinAlgError as exc:
            raise ConvergenceError(
                f"{type(f).__name__} inverse: the Jacobian at the centre is singular; the "
                "polynomial is not invertible there", iterations=0
            ) from exc
        lim = self.tol + 16 * np.finfo(float).eps * (np.max(np.abs(X), axis=1) + 1.0)
        r = f.apply(x) - X
        err = np.max(np.abs(r), axis=1)
        done = err <= lim
        it = 0
        while it < int(self.max_iter):
            active = ~done & np.isfinite(err)
            if not np.any(active):
                break
            it += 1
            xa, ra = x[active], r[active]
            Ja = f.jacobian(xa)
            try:
                dx = np.linalg.solve(Ja, ra[..., None])[..., 0]
            except np.linalg.LinAlgError:  # a singular Jacobian somewhere: least-norm steps
                dx = (np.linalg.pinv(Ja) @ ra[..., None])[..., 0]
            step = np.ones(xa.shape[0])
            ea = err[active]
            xn, rn, en = xa, ra, ea
            for _ in range(12):  # step halving where the residual grows
                cand = xa - step[:, None] * dx
                rc = f.apply(cand) - X[active]
                ec = np.max(np.abs(rc), axis=1)
                better = ec < ea
                xn = np.where(better[:, None], cand, xn)
                rn = np.where(better[:, None], rc, rn)
                en = np.where(better, ec, en)
                if np.all(better):
                    break
                step = np.where(better, step, step / 2)
            stalled = en >= ea
            x[active], r[active], err[active] = xn, rn, en
            done[active] = en <= lim[active]
            if np.all(stalled):
                break
        return InverseResult(x, done.copy(), err, it)

    def apply(self, points) -> np.ndarray:
        """Inverse-transform points.

        Parameters
        ----------
        points : array_like, shape (n, dim) or (dim,)
            Target points (target units).

        Returns
        -------
        numpy.ndarray, shape (n, dim) or (dim,)
            Source coordinates (source units).

        Raises
        ------
        ConvergenceError
            Naming rows that do not converge (the full :class:`InverseResult` is in the
            error's ``result``).
        """
        arr = as_float64(points, "points")
        res = self.apply_with_status(arr)
        if not np.all(res.converged):
            bad = np.flatnonzero(~res.converged)
            rows = ", ".join(str(int(i)) for i in bad[:10])
            raise ConvergenceError(
                f"{type(self.forward).__name__} inverse: {bad.size} point(s) did not converge to "
                f"tol {self.tol:g} (row index {rows}{' ...' if bad.size > 10 else ''}; largest "
                f"residual {np.nanmax(res.residual[bad]):.3g}). They may lie outside the region "
                "where the polynomial is invertible; use apply_with_status to keep the others",
                iterations=res.iterations,
                result=res,
            )
        return res.points[0] if arr.ndim == 1 else res.points

    def inverse(self) -> _Polynomial:
        """The forward polynomial.

        Returns
        -------
        Polynomial2D or Polynomial3D
        """
        return self.forward

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``model``, ``forward`` (its :meth:`to_dict`), ``tol``, ``max_iter``.
        """
        return {"model": self.name, "forward": self.forward.to_dict(), "tol": self.tol,
                "max_iter": int(self.max_iter)}

    @classmethod
    def from_dict(cls, data: dict) -> _PolynomialInverse:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : dict
            ``forward`` and optionally ``tol`` (default 1e-9), ``max_iter`` (default 50).

        Returns
        -------
        Polynomial2DInverse or Polynomial3DInverse
        """
        fwd_cls = Polynomial2D if cls.dim == 2 else Polynomial3D
        return cls(fwd_cls.from_dict(data["forward"]), float(data.get("tol", 1e-9)),
                   int(data.get("max_iter", 50)))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(forward={self.forward!r}, tol={self.tol:g})"


@dataclass(frozen=True, eq=False, repr=False)
class Polynomial2DInverse(_PolynomialInverse):
    """Iterative inverse of a :class:`Polynomial2D` (Newton with step halving).

    ``apply`` raises :class:`~photogeom.errors.ConvergenceError` for points that do not
    converge; ``apply_with_status`` returns an :class:`InverseResult` with a per-point status.

    Parameters
    ----------
    forward : Polynomial2D
        The polynomial to invert.
    tol : float, default 1e-9
        Convergence tolerance, target units; > 0.
    max_iter : int, default 50
        Newton iterations at most; >= 1.
    """

    name = "polynomial2d_inverse"
    dim = 2


@dataclass(frozen=True, eq=False, repr=False)
class Polynomial3DInverse(_PolynomialInverse):
    """Iterative inverse of a :class:`Polynomial3D`; see :class:`Polynomial2DInverse`.

    Parameters
    ----------
    forward : Polynomial3D
        The polynomial to invert.
    tol : float, default 1e-9
        Convergence tolerance, target units; > 0.
    max_iter : int, default 50
        Newton iterations at most; >= 1.
    """

    name = "polynomial3d_inverse"
    dim = 3


@dataclass(frozen=True, eq=False, repr=False)
class Polynomial2D(_Polynomial):
    """2D polynomial transformation of order ``k`` (2 x (k+1)(k+2)/2 coefficients).

    Parameters
    ----------
    order : int
        Highest total degree (1 = affine).
    coefficients : array_like, shape (2, n_terms)
        Row 0 for x (``a..``), row 1 for y (``b..``), in monomial order (module docstring).
    centre : array_like, shape (2,), optional
        Reduction centre (source units); default 0.
    scale : float
        Reduction scale (source units); default 1.
    """

    name = "polynomial2d"
    dim = 2
    inverse_class: ClassVar[type] = Polynomial2DInverse


@dataclass(frozen=True, eq=False, repr=False)
class Polynomial3D(_Polynomial):
    """3D polynomial transformation of order ``k`` (3 x (k+1)(k+2)(k+3)/6 coefficients).

    See :class:`Polynomial2D`.

    Parameters
    ----------
    order : int
        Highest total degree (1 = affine).
    coefficients : array_like, shape (3, n_terms)
        Rows ``a``, ``b``, ``c`` for X, Y, Z, in monomial order (module docstring).
    centre : array_like, shape (3,), optional
        Reduction centre (source units); default 0.
    scale : float
        Reduction scale (source units); default 1.
    """

    name = "polynomial3d"
    dim = 3
    inverse_class: ClassVar[type] = Polynomial3DInverse
