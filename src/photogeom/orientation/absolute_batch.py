"""Many independent absolute orientations in one vectorised call.

>>> import numpy as np
>>> src = np.random.default_rng(0).normal(size=(4, 10, 3))    # B = 4 problems of 10 points
>>> dst = 2.0 * src + 1.0
>>> res = absolute_orientation_batch(src, dst, method="svd")  # src, dst: (B, n, 3)
>>> res.scale.round(12).tolist(), res.valid.tolist()
([2.0, 2.0, 2.0, 2.0], [True, True, True, True])
>>> res.rotation.shape, res.translation.shape
((4, 3, 3), (4, 3))

Used for Monte-Carlo studies, RANSAC hypotheses and per-tile registrations: the direct methods
of :mod:`.absolute_direct` run on all B problems at once (no Python loop over problems).
Problems whose rotation is undetermined (collinear or coincident points) or whose best fit is a
reflection are *flagged*, not raised, and their parameters are NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, TooFewPointsError
from ..records import ReadOnlyRecord
from ..rotation import angles_from_rotation, orthogonality_defect
from ..transforms import Similarity3D
from ..validation import as_float64
from .absolute import normalize_method
from .absolute_direct import (
    DirectSolution,
    batch_moments,
    solve_closed_form,
    solve_dual_quaternion,
    solve_gauss_helmert_direct,
    solve_quaternion,
    solve_svd,
    solve_three_points,
)

#: Methods available in batches (the iterative ones equal "svd" / "gauss-helmert" there).
BATCH_METHODS = ("closed-form", "svd", "quaternion", "dual-quaternion", "gauss-helmert")


@dataclass(frozen=True, eq=False)
class BatchOrientation(ReadOnlyRecord):
    """Results of :func:`absolute_orientation_batch`.

    Attributes
    ----------
    method : str
    scale : numpy.ndarray, shape (B,)
    rotation : numpy.ndarray, shape (B, 3, 3)
    translation : numpy.ndarray, shape (B, 3)
        Target units. All three are NaN for invalid problems.
    degenerate : numpy.ndarray of bool, shape (B,)
        Collinear or coincident points: rotation undetermined.
    reflection : numpy.ndarray of bool, shape (B,)
        The best fit is a reflection (never returned as a rotation).
    rms : numpy.ndarray, shape (B,) or None
        Per-point RMSE ``sqrt(sum |v_i|^2 / n)`` of the transfer residuals
        ``v_i = s R x_i + t - X_i`` of each problem (``residual_rms=True``).
    """

    method: str
    scale: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    degenerate: np.ndarray
    reflection: np.ndarray
    rms: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        """Problems with a usable estimate."""
        return ~(self.degenerate | self.reflection)

    def __len__(self) -> int:
        return self.scale.shape[0]

    @property
    def orthogonality_defect(self) -> np.ndarray:
        """``|R.T R - I|`` per problem (non-zero only for the raw closed form)."""
        return orthogonality_defect(self.rotation)

    def angles(self, convention: str = "transposed", unit: str = "rad") -> tuple:
        """``(omega, phi, kappa)`` of every problem in ``convention`` and ``unit``.

        Parameters
        ----------
        convention : {"transposed", "direct"}, default "transposed"
            As in :func:`photogeom.rotation_from_angles`.
        unit : str, default "rad"
            Angle unit.

        Returns
        -------
        tuple of three numpy.ndarray, shape (B,)
            ``omega, phi, kappa`` in ``unit``; NaN for invalid problems (omega 0 at gimbal lock).
        """
        R = np.where(self.valid[:, None, None], self.rotation, np.eye(3))
        w, p, k = angles_from_rotation(R, convention=convention, unit=unit,
                                       on_gimbal_lock="omega-zero")
        bad = ~self.valid
        return tuple(np.where(bad, np.nan, np.asarray(a, dtype=float)) for a in (w, p, k))

    def transform(self, i: int) -> Similarity3D:
        """Problem ``i`` as a :class:`Similarity3D`.

        Parameters
        ----------
        i : int
            Index of the problem, ``0 <= i < B``.

        Returns
        -------
        Similarity3D
            With ``check=False`` for a closed-form matrix that is not orthogonal.

        Raises
        ------
        InputError
            When problem ``i`` has no valid estimate (degenerate points or a reflection).
        """
        if not bool(self.valid[i]):
            why = "collinear or coincident points" if self.degenerate[i] else "a reflection"
            raise InputError(f"problem {i} has no valid estimate ({why})")
        check = self.method != "closed-form" or orthogonality_defect(self.rotation[i]) < 1e-6
        return Similarity3D(self.scale[i], self.rotation[i], self.translation[i], check=check)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``s R x + t`` of every problem.

        Parameters
        ----------
        points : array_like, shape (B, m, 3) or (m, 3)
            Source points per problem, or the same points for every problem (source units).

        Returns
        -------
        numpy.ndarray, shape (B, m, 3)
            Target coordinates (target units); NaN rows for invalid problems.
        """
        p = np.asarray(points, dtype=float)
        out = np.matmul(p, np.swapaxes(self.rotation, 1, 2))
        return self.scale[:, None, None] * out + self.translation[:, None, :]


def _as_batch(values, name: str) -> np.ndarray:
    a = as_float64(values, name)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"{name}: expected shape (B, n, 3) for B problems, got {a.shape}")
    return a


def _check_finite_batch(a: np.ndarray, name: str) -> None:
    ok = np.isfinite(a).all(axis=(1, 2))
    if not ok.all():
        bad = np.flatnonzero(~ok)
        shown = ", ".join(str(int(i)) for i in bad[:10])
        raise InputError(
            f"{name}: {bad.size} problem(s) contain NaN or infinite values (problem index "
            f"{shown}{' ...' if bad.size > 10 else ''})"
        )


def solve_batch(
    method: str,
    x: np.ndarray,
    X: np.ndarray,
    w: np.ndarray | None = None,
    *,
    with_scale: bool = True,
    scale_method: str = "least-squares",
    ratio: float = 1.0,
    nearest_rotation: bool = False,
) -> DirectSolution:
    """Dispatch B problems (validated arrays) to the direct solver of ``method``."""
    if method == "closed-form":
        if w is not None:
            raise InputError("closed-form (method A) has no weights as published")
        return solve_closed_form(x, X, nearest=nearest_rotation, with_scale=with_scale)
    if x.shape[1] == 3 and w is None and method in ("svd", "gauss-helmert") and (
        method == "gauss-helmert" or scale_method == "least-squares"
    ):
        return solve_three_points(
            x, X, with_scale=with_scale, gh_ratio=ratio if method == "gauss-helmert" else None
        )
    m = batch_moments(x, X, w)
    if method == "svd":
        return solve_svd(m, with_scale=with_scale, scale_method=scale_method)
    if method == "quaternion":
        return solve_quaternion(m, with_scale=with_scale, scale_method=scale_method)
    if method == "dual-quaternion":
        return solve_dual_quaternion(m, with_scale=with_scale, scale_method=scale_method)
    if method == "gauss-helmert":
        return solve_gauss_helmert_direct(m, with_scale=with_scale, ratio=ratio)
    raise InputError(
        f"method {method!r} is not available in batches; choose one of {', '.join(BATCH_METHODS)} "
        "(the Gauss-Markov estimate equals 'svd' for point weights)"
    )


def absolute_orientation_batch(
    source,
    target,
    method: str = "svd",
    *,
    weights=None,
    with_scale: bool = True,
    scale_method: str = "least-squares",
    sigma_source: float | None = None,
    sigma_target: float | None = None,
    nearest_rotation: bool = False,
    residual_rms: bool = False,
) -> BatchOrientation:
    """Solve B independent absolute orientations ``X = s R x + t`` at once.

    Parameters
    ----------
    source, target : array_like, shape (B, n, 3)
        B problems of n >= 3 point pairs each.
    method : str
        ``"svd"`` (default), ``"quaternion"``, ``"dual-quaternion"``, ``"closed-form"``
        or ``"gauss-helmert"`` (the direct solution).
    weights : array_like, shape (B, n) or (n,), optional
        Point weights (not for the closed form).
    with_scale : bool
        False: rigid transformations (s = 1).
    scale_method : {"least-squares", "symmetric"}
        As in :func:`~photogeom.orientation.absolute_orientation`.
    sigma_source, sigma_target : float, optional
        ``"gauss-helmert"``: one standard deviation per system, in the units of the source
        and the target coordinates (prescaling).
    nearest_rotation : bool
        Closed form: orthogonalise R.
    residual_rms : bool
        Also compute the per-point RMSE of every problem (one more pass over the data).

    Returns
    -------
    BatchOrientation
        Degenerate problems and reflections are flagged (``valid`` False) with NaN parameters.
    """
    method = normalize_method(method)
    x = _as_batch(source, "source")
    X = _as_batch(target, "target")
    if x.shape != X.shape:
        raise InputError(f"source {x.shape} and target {X.shape} must have the same shape")
    if x.shape[1] < 3:
        raise TooFewPointsError(
            "absolute orientation (batch)", x.shape[1], 3,
            "three non-collinear point pairs per problem",
        )
    _check_finite_batch(x, "source")
    _check_finite_batch(X, "target")
    w = None
    if weights is not None:
        w = as_float64(weights, "weights", coordinates=False)
        if w.ndim == 1:
            w = np.broadcast_to(w, x.shape[:2])
        if w.shape != x.shape[:2] or not (np.all(np.isfinite(w)) and np.all(w > 0)):
            raise InputError(f"weights: expected positive values of shape {x.shape[:2]} or "
                             f"({x.shape[1]},), got {np.shape(weights)}")
    if scale_method not in ("least-squares", "symmetric"):
        raise InputError(
            f"scale_method must be 'least-squares' or 'symmetric', not {scale_method!r}"
        )
    ratio = 1.0
    if sigma_source is not None or sigma_target is not None:
        if method != "gauss-helmert":
            raise InputError("sigma_source / sigma_target apply to method='gauss-helmert'")
        ratio = (sigma_target or 1.0) / (sigma_source or 1.0)
    sol = solve_batch(
        method, x, X, w, with_scale=with_scale, scale_method=scale_method, ratio=ratio,
        nearest_rotation=nearest_rotation,
    )
    bad = sol.degenerate | sol.reflection | ~np.isfinite(sol.scale)
    s = np.where(bad, np.nan, sol.scale)
    R = np.where(bad[:, None, None], np.nan, sol.rotation)
    t = np.where(bad[:, None], np.nan, sol.translation)
    rms = None
    if residual_rms:
        v = s[:, None, None] * np.matmul(x, np.swapaxes(R, 1, 2)) + t[:, None, :] - X
        rms = np.sqrt(np.einsum("bni,bni->b", v, v) / x.shape[1])
    return BatchOrientation(method, s, R, t, sol.degenerate | (bad & ~sol.reflection),
                            sol.reflection, rms)
