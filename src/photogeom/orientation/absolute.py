"""Absolute orientation: the 3D similarity ``X = s R x + t`` from point pairs, by six methods.

>>> import photogeom as pg
>>> fit = pg.absolute_orientation(source, target, method="svd")        # doctest: +SKIP
>>> fit.scale, fit.rotation, fit.translation, fit.std_errors["kappa"]   # doctest: +SKIP

Methods (``docs/absolute-orientation.md`` has the formulas and the comparison):

=================== ===============================================================
``"closed-form"``   A: normalised unit vectors, ``R = (M M.T) inv(N M.T)`` (Afary 2024)
``"svd"``           B: Arun / Umeyama, weighted, reflection guard (the default)
``"quaternion"``    C: Horn's unit quaternion
``"dual-quaternion"`` D: Walker et al. with scale and weights
``"gauss-markov"``  E: iterative least squares, target coordinates observed
``"gauss-helmert"`` F: errors in both systems (direct, or iterative with covariances)
=================== ===============================================================

Parameters and standard deviations are named ``tx, ty, tz, scale, omega, phi, kappa``; angles
in radians in the *transposed* convention ``R = M(omega, phi, kappa).T`` (Wolf, Kraus);
:meth:`AbsoluteOrientationFit.angles` gives either convention in rad/deg/gon. Residuals are
computed minus observed, in the target system.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..adjust import Fit
from ..errors import (
    ConvergenceError,
    DegenerateGeometryError,
    InputError,
    ReflectionError,
    TooFewPointsError,
)
from ..rotation import angles_from_rotation, gimbal_lock_note, orthogonality_defect
from ..transforms import Similarity3D
from ..units import from_radians
from ..validation import as_float64, as_points, check_finite_magnitude
from . import absolute_adjust as _adj
from .absolute_direct import (
    PairMoments,
    closed_form_single,
    large_moments,
    published_angles,
    solve_closed_form,
    solve_single,
)
from .absolute_stats import (
    closed_form_statistics,
    gauss_helmert_statistics,
    linearised_statistics,
    opk_transposed,
    residual_statistics,
    rotation_derivatives,
)

#: The six methods, in the order of the specification (A-F).
METHODS: tuple[str, ...] = (
    "closed-form",
    "svd",
    "quaternion",
    "dual-quaternion",
    "gauss-markov",
    "gauss-helmert",
)
#: Methods with a direct (non-iterative) solution.
DIRECT_METHODS: tuple[str, ...] = ("closed-form", "svd", "quaternion", "dual-quaternion")
#: From this number of points on, the moments are taken in one chunked pass over the data.
LARGE_N = 65536
#: Both point sets must spread beyond a line: the second singular value of the centred
#: (weighted) coordinates above this fraction of the first, in either system.
RANK_TOLERANCE = 1e-10

_ALIASES = {
    "closedform": "closed-form",
    "closed-form": "closed-form",
    "afary": "closed-form",
    "svd": "svd",
    "umeyama": "svd",
    "quaternion": "quaternion",
    "horn": "quaternion",
    "dual-quaternion": "dual-quaternion",
    "dualquaternion": "dual-quaternion",
    "gauss-markov": "gauss-markov",
    "gaussmarkov": "gauss-markov",
    "gauss-helmert": "gauss-helmert",
    "gausshelmert": "gauss-helmert",
}

def normalize_method(method: str) -> str:
    """Canonical method name (case-insensitive; ``_`` and spaces read as ``-``)."""
    key = str(method).strip().lower().replace("_", "-").replace(" ", "-")
    if key not in _ALIASES:
        raise InputError(
            f"unknown absolute orientation method {method!r}; choose one of {', '.join(METHODS)}"
        )
    return _ALIASES[key]


@dataclass(frozen=True, eq=False, repr=False)
class AbsoluteOrientationFit(Fit):
    """Result of :func:`absolute_orientation` (a :class:`~photogeom.adjust.Fit`).

    ``parameters`` are ``(tx, ty, tz, scale, omega, phi, kappa)`` (without ``scale`` for the
    rigid model), angles in radians, transposed convention ``R = M(omega, phi, kappa).T``.
    ``model`` is the :class:`~photogeom.transforms.Similarity3D`; for the raw closed form its
    rotation is not exactly orthogonal (``orthogonality_defect`` says how far).

    ``extras`` may hold: ``"corrected_source"``, ``"corrected_target"``,
    ``"source_residuals"`` (Gauss-Helmert), ``"inliers"`` (RANSAC, bool mask over all input
    points), ``"removed"`` (data snooping), ``"start"`` (initial values of E/F).
    """

    @property
    def scale(self) -> float:
        """Scale factor ``s``."""
        return float(self.model.scale)

    @property
    def rotation(self) -> np.ndarray:
        """``R`` (3, 3), applied to source coordinates: ``X = s R x + t``."""
        return self.model.rotation

    @property
    def translation(self) -> np.ndarray:
        """``t`` (3,) in target units."""
        return self.model.translation

    def angles(self, convention: str = "transposed", unit: str = "rad") -> tuple:
        """``(omega, phi, kappa)`` of ``R`` in ``convention`` and ``unit``.

        For the raw closed-form matrix (not orthogonal) the angles are read as its paper
        reads them, ``phi = asin(m31)`` (:func:`~photogeom.orientation.absolute_direct.
        published_angles`); for a rotation by the formulas of
        :func:`~photogeom.rotation.opk_from_matrix` (omega set to zero at gimbal lock).

        Parameters
        ----------
        convention : {"transposed", "direct"}, default "transposed"
            ``"transposed"``: ``R = M.T``; ``"direct"``: ``R = M``.
        unit : str, default "rad"
            Angle unit (``"rad"``, ``"deg"``, ``"gon"``, ...).

        Returns
        -------
        tuple of float
            ``(omega, phi, kappa)`` in ``unit``.

        Raises
        ------
        InputError
            For an unknown ``convention`` or ``unit``.
        """
        if not self.model.check:
            if convention not in ("transposed", "direct"):
                raise InputError(
                    f"convention must be 'transposed' or 'direct', not {convention!r}"
                )
            return tuple(
                float(from_radians(a, unit)) for a in published_angles(self.rotation, convention)
            )
        return angles_from_rotation(
            self.rotation, convention=convention, unit=unit, on_gimbal_lock="omega-zero"
        )

    @property
    def orthogonality_defect(self) -> float:
        """``|R.T R - I|`` (Frobenius); ~1e-16 except for the raw closed form."""
        return float(orthogonality_defect(self.rotation))

    @property
    def inliers(self) -> np.ndarray | None:
        """RANSAC inlier mask over all input points (None without RANSAC)."""
        return self.extras.get("inliers")

    @property
    def corrected_source(self) -> np.ndarray | None:
        """Adjusted source coordinates (Gauss-Helmert), else None."""
        return self.extras.get("corrected_source")

    @property
    def corrected_target(self) -> np.ndarray | None:
        """Adjusted target coordinates (Gauss-Helmert), else None."""
        return self.extras.get("corrected_target")


# --- input handling ----------------------------------------------------------------------------


def _as_pair(source, target) -> tuple[np.ndarray, np.ndarray]:
    # NaN / inf show in the moments (one pass, no extra check)
    x = as_points(source, 3, "source", allow_single=False, finite=False)
    X = as_points(target, 3, "target", allow_single=False, finite=False)
    if x.shape[0] != X.shape[0]:
        raise InputError(
            f"source has {x.shape[0]} point(s) but target has {X.shape[0]}; "
            "they must correspond one to one"
        )
    if x.shape[0] < 3:
        raise TooFewPointsError(
            "absolute orientation",
            x.shape[0],
            3,
            "three non-collinear point pairs determine the 7 parameters",
        )
    return x, X


def _check_finite_pair(x: np.ndarray, X: np.ndarray) -> None:
    """Refuse NaN / infinite coordinates (naming the side and rows) and coordinates so large
    that their squares summed over the points overflow."""
    check_finite_magnitude(x, "source", "absolute orientation")
    check_finite_magnitude(X, "target", "absolute orientation")


def _finite_or_raise(x: np.ndarray, X: np.ndarray) -> None:
    """After non-finite sums: name the bad input rows, or else report the overflow."""
    _check_finite_pair(x, X)
    raise InputError(
        "absolute orientation: the sums of the coordinates overflow; the coordinates are too "
        "large (reduce them by a common offset)"
    )


@dataclass(frozen=True)
class _Precision:
    """Observation precision in normalised form."""

    point_w: np.ndarray | None = None  # (n,) isotropic per point (target / both)
    obs_w: np.ndarray | None = None  # (3n,) per target coordinate
    cov_t: np.ndarray | None = None  # (3n,3n) or (n,3,3) target covariance
    sig_s: object = None  # GH source: None, scalar, (n,), (n,3)
    sig_t: object = None
    cov_s: np.ndarray | None = None
    scalar_sigmas: bool = True  # GH: at most one sigma per system


def _sigma_array(sig, n: int, name: str):
    if sig is None:
        return None
    a = as_float64(sig, name, coordinates=False)
    if a.ndim == 0:
        v = float(a)
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v}")
        return v
    if a.shape == (n,) or a.shape == (n, 3):
        if not (np.all(np.isfinite(a)) and np.all(a > 0)):
            raise InputError(f"{name}: every standard deviation must be finite and > 0")
        return a
    raise InputError(f"{name}: expected a number, shape ({n},) or ({n}, 3); got shape {a.shape}")


def _cov_array(cov, n: int, name: str):
    if cov is None:
        return None
    c = as_float64(cov, name, coordinates=False)
    if c.shape not in ((n, 3, 3), (3 * n, 3 * n)):
        raise InputError(
            f"{name}: expected shape ({n}, 3, 3) (per point) or ({3 * n}, {3 * n}) (full), "
            f"got {c.shape}"
        )
    if not np.all(np.isfinite(c)):
        raise InputError(f"{name}: NaN or infinite values")
    return c


_NO_PRECISION = _Precision()


def _precision(method, n, weights, sigma_source, sigma_target, cov_source, cov_target,
               sigma0_prior=1.0):
    if (
        weights is None and sigma_source is None and sigma_target is None
        and cov_source is None and cov_target is None
    ):
        return _NO_PRECISION
    w = None
    if weights is not None:
        w = as_float64(weights, "weights", coordinates=False)
        if w.shape not in ((n,), (n, 3), (3 * n,)):
            raise InputError(
                f"weights: expected shape ({n},) per point, ({n}, 3) or ({3 * n},) per "
                f"coordinate; got {w.shape}"
            )
        if not (np.all(np.isfinite(w)) and np.all(w > 0)):
            raise InputError("weights: every weight must be finite and > 0")
        if sigma_target is not None or cov_target is not None:
            raise InputError("give either weights or sigma_target/covariance_target, not both")
    st = _sigma_array(sigma_target, n, "sigma_target")
    ss = _sigma_array(sigma_source, n, "sigma_source")
    ct = _cov_array(cov_target, n, "covariance_target")
    cs = _cov_array(cov_source, n, "covariance_source")
    if st is not None and ct is not None:
        raise InputError("give either sigma_target or covariance_target, not both")
    if ss is not None and cs is not None:
        raise InputError("give either sigma_source or covariance_source, not both")
    if method != "gauss-helmert" and (ss is not None or cs is not None):
        raise InputError(
            f"method {method!r} treats the source coordinates as error-free; errors in both "
            "systems (sigma_source / covariance_source) need method='gauss-helmert'"
        )
    if method == "gauss-helmert":
        if w is not None:
            if w.shape != (n,):
                raise InputError(
                    "gauss-helmert: weights are per point pair (shape (n,)); give per-coordinate "
                    "precision as sigma_source / sigma_target of shape (n, 3)"
                )
            if st is not None or ss is not None:
                raise InputError("give either weights or sigma_source/sigma_target, not both")
            # weights are P itself: sigmas with P = sigma0_prior^2 / sigma^2 = w
            ss = st = sigma0_prior / np.sqrt(w)
        scalar = (
            (ss is None or np.ndim(ss) == 0)
            and (st is None or np.ndim(st) == 0)
            and cs is None
            and ct is None
        )
        return _Precision(sig_s=ss, sig_t=st, cov_s=cs, cov_t=ct, scalar_sigmas=scalar)
    # observation equations: target precision only
    point_w = obs_w = None
    if w is not None:
        if w.shape == (n,):
            point_w = w
        else:
            obs_w = w.reshape(-1)
    elif st is not None:
        s2 = sigma0_prior**2
        if np.ndim(st) == 0:
            point_w = np.full(n, s2 / st**2)
        elif st.shape == (n,):
            point_w = s2 / st**2
        else:
            obs_w = (s2 / st**2).reshape(-1)
    if method in DIRECT_METHODS and (obs_w is not None or ct is not None):
        raise InputError(
            f"method {method!r} takes one weight per point; per-coordinate weights or "
            "covariances need method='gauss-markov' (or 'gauss-helmert')"
        )
    if method == "closed-form" and point_w is not None and np.ptp(point_w) > 0:
        raise InputError(
            "closed-form (method A) has no weights as published; use 'svd', 'quaternion', "
            "'dual-quaternion' or 'gauss-markov' for weighted points"
        )
    return _Precision(point_w=point_w, obs_w=obs_w, cov_t=ct)


# --- the public entry point ----------------------------------------------------------------


def absolute_orientation(
    source,
    target,
    method: str = "svd",
    *,
    weights=None,
    with_scale: bool = True,
    scale_method: str | None = None,
    statistics: bool = True,
    initial=None,
    sigma_source=None,
    sigma_target=None,
    covariance_source=None,
    covariance_target=None,
    covariance=None,
    sigma0_prior: float = 1.0,
    nearest_rotation: bool = False,
    coplanar_threshold: float | None = None,
    reflection: str = "raise",
    iterate: bool | None = None,
    max_iter: int = 50,
    tol: float = 1e-10,
    raise_on_failure: bool = True,
    robust: str | None = None,
    threshold: float | None = None,
    ids: Sequence | None = None,
    unit: str = "m",
    **robust_options,
) -> AbsoluteOrientationFit:
    """Estimate the 3D similarity ``X = s R x + t`` from corresponding points.

    Parameters
    ----------
    source, target : array_like, shape (n, 3)
        Corresponding points (model/source -> ground/target), n >= 3, not collinear.
    method : str
        ``"closed-form"``, ``"svd"`` (default), ``"quaternion"``, ``"dual-quaternion"``,
        ``"gauss-markov"`` or ``"gauss-helmert"``.
    weights : array_like, optional
        Point weights (n,) for every method but the closed form; per-coordinate weights
        (n, 3) or (3n,) for ``"gauss-markov"``. ``P = diag(weights)`` whatever
        ``sigma0_prior`` (weight 1: standard deviation ``sigma0_prior``); for
        ``"gauss-helmert"`` a point weight applies to the source and target coordinates of the
        pair.
    with_scale : bool
        False estimates the rigid (6-parameter) transformation, ``s = 1``.
    scale_method : {"least-squares", "symmetric"}, optional
        Scale of the SVD / quaternion / dual-quaternion methods: ``"least-squares"``
        (default; Umeyama, identical for B, C, D, E) or Horn's ``"symmetric"``
        ``sqrt(sum |X'|^2 / sum |x'|^2)``.
    statistics : bool
        Compute residuals, sigma0, covariance and normalised residuals (the linearised
        Gauss-Markov model at the solution for the direct methods). ``False`` is the fast path
        for millions of points: one pass over the data, no residuals (``fit.residuals`` is
        empty; apply ``fit.transform`` to get them).
    initial : str, Similarity3D or array_like, optional
        Start of ``"gauss-markov"`` / ``"gauss-helmert"``: a direct method name (default
        ``"svd"``; ``"gauss-helmert"`` starts from its direct solution), ``"zeros"`` (s = 1,
        R = I, t = 0), a :class:`Similarity3D`, or ``(tx, ty, tz, scale, omega, phi, kappa)``
        in radians, transposed convention.
    sigma_source, sigma_target : float or array_like, optional
        Standard deviations of the coordinates (target units): one per system, (n,) per
        point, or (n, 3) per coordinate. ``sigma_source`` only for ``"gauss-helmert"``.
    covariance_source, covariance_target, covariance : array_like, optional
        Covariances per point (n, 3, 3) or full (3n, 3n). ``covariance`` is an alias of
        ``covariance_target``.
    sigma0_prior : float
        A-priori standard deviation of unit weight: ``P = sigma0_prior^2 C^-1`` for sigmas and
        covariances (``weights`` are P itself); used by the w-test and ``std_errors_prior``.
    nearest_rotation : bool
        Closed form only: replace the raw (non-orthogonal) R by the nearest rotation.
    coplanar_threshold : float, optional
        Closed form only: augment with the plane normal when the smallest / largest singular
        value of either centred point set is below this (default
        :data:`~photogeom.orientation.absolute_direct.COPLANAR_THRESHOLD` = 0.3; 0 augments
        only for n = 3).
    reflection : {"raise", "rotation"}
        ``"raise"`` (default): a best fit that is a reflection raises :class:`ReflectionError`
        (the systems have opposite handedness). ``"rotation"`` (``"svd"`` without ``robust``
        only): keep the best proper rotation, for point sets that share their handedness by
        construction and whose mirror image fits better only because they are deformed (a
        strip chained from relative orientations and nearly coplanar control points); the
        fit's notes say so.
    iterate : bool, optional
        ``"gauss-helmert"`` without ``robust`` only (refused otherwise): ``None`` uses the exact
        direct solution for at most one sigma per system and the iterative adjustment
        otherwise; ``True`` always iterates.
    max_iter, tol : int, float
        Iteration limit and convergence tolerance of E/F (see
        :func:`photogeom.adjust.gauss_markov`).
    raise_on_failure : bool
        Non-convergence raises :class:`ConvergenceError`; with False a flagged fit
        (``converged=False``) is returned. A solution with scale <= 0 always raises.
    robust : {"ransac"}, optional
        Run :func:`~photogeom.orientation.ransac_absolute_orientation` with ``threshold``
        (target units) and ``robust_options``; ``method`` refines on the inliers with the
        other options given here (precisions and covariances selected for the inliers).
    threshold : float, optional
        With ``robust="ransac"`` (required there, refused without it): the inlier distance,
        3D, in target units.
    ids : sequence, optional
        Point ids for the residual rows.
    unit : str
        Length unit of the target system (labels only).
    **robust_options
        Further keywords of :func:`~photogeom.orientation.ransac_absolute_orientation`
        (``confidence``, ``max_trials``, ``batch_size``, ``rng``, ``max_refinements``),
        accepted only with ``robust="ransac"``; otherwise they raise :class:`InputError`.

    Returns
    -------
    AbsoluteOrientationFit

    Raises
    ------
    TooFewPointsError, InputError, DegenerateGeometryError, ReflectionError, ConvergenceError
    """
    method = normalize_method(method)
    if reflection not in ("raise", "rotation"):
        raise InputError(f"reflection must be 'raise' or 'rotation', not {reflection!r}")
    if reflection == "rotation" and (method != "svd" or robust is not None):
        raise InputError("reflection='rotation' applies to method='svd' without robust= only")
    if iterate is not None and (method != "gauss-helmert" or robust is not None):
        raise InputError(
            "iterate applies to method='gauss-helmert' without robust= only, not to "
            f"method={method!r}{' with robust=' + repr(robust) if robust is not None else ''} "
            "(a direct, always iterative or RANSAC estimate): leave iterate out"
        )
    if robust is not None:
        if str(robust).lower() != "ransac":
            raise InputError(f"robust must be 'ransac' or None, not {robust!r}")
        if threshold is None:
            raise InputError("robust='ransac' needs an inlier threshold (target units)")
        from .absolute_robust import ransac_absolute_orientation

        # the refinement on the inliers takes the precision and the method's options
        given = {
            "sigma_source": (sigma_source, None), "covariance_source": (covariance_source, None),
            "covariance_target": (covariance_target, None), "covariance": (covariance, None),
            "sigma0_prior": (sigma0_prior, 1.0), "scale_method": (scale_method, None),
            "initial": (initial, None), "nearest_rotation": (nearest_rotation, False),
            "coplanar_threshold": (coplanar_threshold, None), "max_iter": (max_iter, 50),
            "tol": (tol, 1e-10), "raise_on_failure": (raise_on_failure, True),
        }  # fmt: skip
        refine = {
            k: v for k, (v, default) in given.items()
            if v is not default and not (isinstance(v, (bool, int, float)) and v == default)
        }  # fmt: skip
        return ransac_absolute_orientation(
            source, target, threshold, method=method, with_scale=with_scale,
            statistics=statistics, weights=weights, sigma_target=sigma_target, ids=ids,
            unit=unit, **robust_options, **refine,
        )
    if robust_options:
        raise InputError(f"unexpected keyword argument(s): {', '.join(sorted(robust_options))}")
    if threshold is not None:
        raise InputError(
            "threshold is the RANSAC inlier distance and applies only with robust='ransac': "
            "add robust='ransac' or leave threshold out"
        )
    t0 = time.perf_counter()
    x, X = _as_pair(source, target)
    n = x.shape[0]
    if ids is not None and len(ids) != n:
        raise InputError(f"ids: {len(ids)} id(s) for {n} point pair(s)")
    if covariance is not None:
        if covariance_target is not None:
            raise InputError("give covariance or covariance_target (an alias), not both")
        covariance_target = covariance
    if not (math.isfinite(sigma0_prior) and sigma0_prior > 0):
        raise InputError(f"sigma0_prior must be a positive number, got {sigma0_prior!r}")
    prec = _precision(
        method, n, weights, sigma_source, sigma_target, covariance_source, covariance_target,
        sigma0_prior,
    )
    if scale_method is not None:
        if scale_method not in ("least-squares", "symmetric"):
            raise InputError(
                f"scale_method must be 'least-squares' or 'symmetric', not {scale_method!r}"
            )
        if method not in ("svd", "quaternion", "dual-quaternion"):
            raise InputError(
                f"scale_method applies to 'svd', 'quaternion' and 'dual-quaternion', not {method!r}"
            )
    if (nearest_rotation or coplanar_threshold is not None) and method != "closed-form":
        raise InputError(
            "nearest_rotation and coplanar_threshold are options of method='closed-form' only"
        )
    if initial is not None and method not in ("gauss-markov", "gauss-helmert"):
        raise InputError("initial values apply to 'gauss-markov' and 'gauss-helmert' only")
    ctx = _Context(n=n, ids=None if ids is None else tuple(ids), unit=unit, t0=t0,
                   sigma0_prior=float(sigma0_prior))
    if method == "gauss-helmert" and weights is None:
        # sigmas in object units (weights are relative: no distance to compare with)
        _check_line_within_sigmas(x, prec.sig_s, "source", "sigma_source")
        _check_line_within_sigmas(X, prec.sig_t, "target", "sigma_target")
    if method in DIRECT_METHODS:
        fit = _direct_fit(
            method, x, X, prec, with_scale, scale_method or "least-squares", statistics,
            nearest_rotation, ctx, coplanar_threshold, keep_rotation=reflection == "rotation",
        )
    elif method == "gauss-markov":
        if n >= LARGE_N and prec.obs_w is None and prec.cov_t is None:
            fit = _gauss_markov_large(
                x, X, prec.point_w, with_scale, initial, statistics, max_iter, tol,
                raise_on_failure, ctx,
            )
        else:
            fit = _gauss_markov_fit(
                x, X, prec, with_scale, initial, max_iter, tol, raise_on_failure, ctx
            )
    else:
        fit = _gauss_helmert_fit(
            x, X, prec, with_scale, initial, statistics, iterate, max_iter, tol,
            raise_on_failure, ctx,
        )
        note = _gh_default_precision_note(prec, sigma0_prior)
        if note is not None:
            fit = replace(fit, notes=(*fit.notes, note))
    lock = gimbal_lock_note(fit.parameter_names, fit.parameters, fit.covariance)
    return fit if lock is None else replace(fit, notes=(*fit.notes, lock))


def _gh_default_precision_note(prec: _Precision, sigma0_prior: float) -> str | None:
    """What the Gauss-Helmert model assumed for a system whose precision was not given while
    the other's was (weight 1: standard deviation ``sigma0_prior`` per coordinate), or None."""
    given = {
        "source": prec.sig_s is not None or prec.cov_s is not None,
        "target": prec.sig_t is not None or prec.cov_t is not None,
    }
    if given["source"] == given["target"]:
        return None
    side = "source" if not given["source"] else "target"
    other = "target" if side == "source" else "source"
    return (
        f"gauss-helmert: no precision given for the {side} coordinates, only for the "
        f"{other}: the {side} coordinates were taken with weight 1, i.e. a standard "
        f"deviation of sigma0_prior = {sigma0_prior:g} per coordinate (in their own units); "
        f"give sigma_{side} (or covariance_{side}) to state it, or use method='gauss-markov' "
        "for an error-free source"
    )


@dataclass(slots=True)
class _Context:
    n: int
    ids: tuple | None
    unit: str
    t0: float
    sigma0_prior: float = 1.0


def _check_solution(degenerate, reflection, method: str) -> None:
    if degenerate is not False and bool(np.ravel(degenerate)[0]):
        raise DegenerateGeometryError(
            f"absolute orientation ({method}): the points are collinear or coincide, so the "
            "rotation about their line (and the scale, if all coincide) is undetermined; at "
            "least three non-collinear points are needed"
        )
    if reflection is not False and bool(np.ravel(reflection)[0]):
        raise ReflectionError(
            f"absolute orientation ({method}): the best fit is a reflection (det R = -1), "
            "not a rotation: the two coordinate systems have opposite handedness (e.g. one is "
            "left-handed). Flip the sign of one axis of one system"
        )


def _check_single(sol, x, X, w, pm: PairMoments, method: str) -> None:
    """Degenerate geometry (naming the collinear side when one is), reflections, and the
    spread of both point sets for a single solve."""
    if sol.degenerate:
        _check_spread(x, X, w, pm, None, method)  # names the side when one set is a line
    _check_solution(sol.degenerate, sol.reflection, method)
    _check_spread(x, X, w, pm, sol.singular_values, method)


def _check_spread(x, X, w, pm: PairMoments, sv, method: str) -> None:
    """Raise when the source or the target points are (numerically) collinear.

    ``sigma_2(H) <= sigma_1(x') sigma_2(X')`` and ``sigma_1 <= sqrt(a)`` resp. ``sqrt(b)``:
    ``sigma_2(H) > 2 RANK_TOLERANCE sqrt(a b)`` proves both sets spread (the usual case, no
    extra work); otherwise the centred coordinates themselves decide
    (:data:`RANK_TOLERANCE`).
    """
    if sv is not None and sv[1] > 2 * RANK_TOLERANCE * math.sqrt(pm.a * pm.b):
        return
    for pts, centre, side in ((x, pm.source_centroid, "source"), (X, pm.target_centroid, "target")):
        c = pts - centre
        if w is not None:
            c = c * np.sqrt(w)[:, None]
        if c.shape[0] > 5000:
            c = np.linalg.qr(c, mode="r")
        sig = np.linalg.svd(c, compute_uv=False)
        if not np.all(np.isfinite(sig)):
            return  # NaN / inf: reported by the caller
        if not sig[1] > RANK_TOLERANCE * sig[0]:
            raise DegenerateGeometryError(
                f"absolute orientation ({method}): the {pts.shape[0]} {side} points are "
                "collinear (on one line) or coincide, so the rotation about their line is "
                "undetermined; at least three non-collinear points are needed in each system"
            )


_UNITS: dict = {}


def _param_units(with_scale: bool, unit: str) -> dict[str, str]:
    """Unit of each parameter: a new dict per Fit (a plain dict pickles, for Dask and
    multiprocessing; a shared read-only view did not)."""
    key = (with_scale, unit)
    if key not in _UNITS:
        if len(_UNITS) > 256:  # units are caller-supplied strings: keep the cache small
            _UNITS.clear()
        u = {"tx": unit, "ty": unit, "tz": unit, "omega": "rad", "phi": "rad", "kappa": "rad"}
        if with_scale:
            u["scale"] = "1"
        _UNITS[key] = u
    return dict(_UNITS[key])


_CONVENTION_NOTE = "angles: transposed convention, R = M(omega, phi, kappa).T (radians inside)"


def _bare_fit(model, method, names, params, u, r, n_obs, with_scale, ctx, notes):
    """The Fit of ``statistics=False``: parameters only (NaN covariance, no residuals)."""
    return AbsoluteOrientationFit.without_statistics({
        "model": model, "method": method, "parameter_names": names, "parameters": params,
        "sigma0_prior": 1.0, "redundancy": r, "n_observations": n_obs, "ids": ctx.ids,
        "residual_labels": ("X", "Y", "Z"), "residual_unit": ctx.unit,
        "parameter_units": _param_units(with_scale, ctx.unit), "extras": {},
        "elapsed": time.perf_counter() - ctx.t0, "notes": tuple(notes),
    }, 3)


def _direct_fit(method, x, X, prec, with_scale, scale_method, statistics, nearest, ctx,
                coplanar_threshold=None, keep_rotation=False):
    n = ctx.n
    w = prec.point_w
    notes = [_CONVENTION_NOTE]
    raw = False
    pm = None
    if method == "closed-form":
        if n < LARGE_N:
            _check_finite_pair(x, X)
        kw = {} if coplanar_threshold is None else {"coplanar_threshold": coplanar_threshold}
        sol, augmented, k = closed_form_single(
            x, X, nearest=nearest, with_scale=with_scale, **kw
        )
        if n >= LARGE_N and (sol.degenerate or not np.all(np.isfinite(sol.translation))):
            _check_finite_pair(x, X)  # NaN / inf / overflow show in the sums: name them
        raw = not nearest
        if k:
            notes.append(
                f"{k} point(s) at the centroid carry no direction: left out of the scale "
                "ratios and unit vectors (kept in centroids and residuals)"
            )
        if augmented:
            notes.append("plane-normal augmentation used (n = 3 or a nearly coplanar point set)")
        _check_solution(sol.degenerate, sol.reflection, method)
        s, R, t = sol.scale, sol.rotation, sol.translation
        if statistics and n >= LARGE_N:  # moments for the chunked statistics pass
            pm = _moments(x, X, w, True)
    else:
        pm = _moments(x, X, w, statistics)
        sol = solve_single(pm, method, with_scale=with_scale, scale_method=scale_method)
        if keep_rotation and sol.reflection:  # sol holds the best proper rotation
            sol.reflection = False
            notes.append(
                "a reflection fits better than any rotation; the best proper rotation is kept "
                "(reflection='rotation')"
            )
        _check_single(sol, x, X, w, pm, method)
        s, R, t = sol.scale, sol.rotation, sol.translation
    if raw:
        notes.append(
            f"raw closed-form R kept as published (orthogonality defect "
            f"{orthogonality_defect(R):.2e}); angles read from it"
        )
    model = Similarity3D(s, R, t, check=False) if raw else _similarity(s, R, t)
    omega, phi, kappa, gimbal = opk_transposed(R)
    clipped = raw and abs(float(R[0, 2])) > 1.0
    if raw and not gimbal:  # the raw matrix: phi read as published, asin(m31)
        omega, phi, kappa = published_angles(R, "transposed")
    if clipped:
        notes.append(
            f"the raw R has m31 = {float(R[0, 2]):.6g} outside [-1, 1]: phi = asin(m31) is "
            "undefined and set to +-90 deg, the angles have no standard deviations; the "
            "raw R is far from a rotation (nearest_rotation=True gives one)"
        )
    if gimbal:
        notes.append(_GIMBAL_NOTE)
    params = _params(t, s, (omega, phi, kappa), with_scale)
    names = _adj.names(with_scale)
    u = len(names)
    r = 3 * n - u
    if not statistics:
        return _bare_fit(model, method, names, params, u, r, 3 * n, with_scale, ctx, notes)
    if pm is not None and pm.S is not None:
        st, v = residual_statistics(
            x, X, scale=s, rotation=R, translation=t, angles=(omega, phi, kappa),
            source_centroid=pm.source_centroid, scatter=pm.S, weight_sum=pm.weight, weights=w,
            with_scale=with_scale, sigma0_prior=ctx.sigma0_prior,
        )
    else:
        xg, Xg = x.mean(axis=0), X.mean(axis=0)
        xr = x - xg
        v = s * (xr @ R.T) - (X - Xg) + (s * (R @ xg) + t - Xg)
        st = linearised_statistics(
            xr, v, scale=s, angles=(omega, phi, kappa), source_centroid=xg, weights=w,
            with_scale=with_scale, sigma0_prior=ctx.sigma0_prior,
        )
    r_eff = None
    if method == "closed-form":
        # not a least-squares estimator: its covariance, the expectation of v'Pv and the
        # residual tests are propagated through the estimator
        Qcf, r_eff, red, wn = closed_form_statistics(
            x, X, v, nearest=nearest, with_scale=with_scale, weights=w,
            coplanar_threshold=coplanar_threshold, sigma0_prior=ctx.sigma0_prior,
            out=(st.redundancy_numbers, st.normalized_residuals),
        )
        # angles not separable at gimbal lock: NaN where the linearised model has NaN
        Qcf = np.where(np.isnan(st.cofactor), np.nan, Qcf)
        if clipped:
            Qcf[-3:, :] = np.nan
            Qcf[:, -3:] = np.nan
        st = replace(st, cofactor=Qcf, redundancy_numbers=red, normalized_residuals=wn)
        notes.append(
            "standard deviations, sigma0 and residual tests propagated through the closed-form "
            f"estimator (its Jacobian with respect to the target coordinates); sigma0 divides "
            f"v'Pv by its expectation {r_eff:.4g} (not the least-squares redundancy {r})"
        )
    return _stat_fit(model, method, names, params, st, r, 3 * n, v, with_scale, ctx, notes,
                     effective_redundancy=r_eff)


def _moments(x, X, w, statistics: bool) -> PairMoments:
    """Centred moments (with the source scatter when ``statistics``)."""
    n = x.shape[0]
    # sums that overflow (coordinates too large) are caught below and reported as an
    # InputError naming the overflow, not left to numpy's RuntimeWarning
    with np.errstate(over="ignore", invalid="ignore"):
        if n >= LARGE_N:
            pm = PairMoments.from_moments(large_moments(x, X, w, scatter=statistics))
        else:
            pm = PairMoments.of(x, X, w)
    if not pm.finite():
        _finite_or_raise(x, X)
    return pm


def _similarity(s, R, t) -> Similarity3D:
    """``Similarity3D(s, R, t)`` for a rotation that is orthogonal by construction (SVD,
    quaternion, adjustment): the same object, without repeating the orthogonality and
    determinant check that would cost more than the whole small solve."""
    s = float(s)
    R = np.array(R, dtype=float)
    t = np.array(t, dtype=float)
    if not (s > 0 and math.isfinite(s) and R.shape == (3, 3) and t.shape == (3,)):
        return Similarity3D(s, R, t)  # let the constructor report the problem
    R.flags.writeable = False
    t.flags.writeable = False
    obj = object.__new__(Similarity3D)
    for name, value in (("scale", s), ("rotation", R), ("translation", t), ("check", True)):
        object.__setattr__(obj, name, value)
    return obj


def _params(t, s, angles, with_scale) -> np.ndarray:
    """``(tx, ty, tz, [scale,] omega, phi, kappa)`` (``_adj.pack`` for float inputs)."""
    tx, ty, tz = t.tolist() if isinstance(t, np.ndarray) else t
    return np.array([tx, ty, tz, float(s), *angles] if with_scale else [tx, ty, tz, *angles])


def _stat_fit(model, method, names, params, st, r, n_obs, v, with_scale, ctx, notes,
              extras=None, iterations=0, message="",
              effective_redundancy: float | None = None) -> AbsoluteOrientationFit:
    """The Fit with statistics; ``effective_redundancy`` (the expectation of ``v'Pv /
    sigma0^2`` of an estimator that is not least squares, the closed form's) divides ``v'Pv``
    instead of ``r`` and is kept in ``extras["effective_redundancy"]``."""
    if effective_redundancy is None:
        s0 = math.sqrt(max(st.vtpv, 0.0) / r) if r > 0 else math.nan
    else:
        ok = r > 0 and effective_redundancy > 0
        s0 = math.sqrt(max(st.vtpv, 0.0) / effective_redundancy) if ok else math.nan
        extras = {**(extras or {}), "effective_redundancy": float(effective_redundancy)}
    return AbsoluteOrientationFit._construct(
        model=model, method=method, parameter_names=names, parameters=params,
        covariance=s0**2 * st.cofactor, cofactor=st.cofactor, sigma0=s0,
        sigma0_prior=ctx.sigma0_prior,
        redundancy=r, n_observations=n_obs, residuals=v, ids=ctx.ids,
        residual_labels=("X", "Y", "Z"), residual_unit=ctx.unit,
        parameter_units=_param_units(with_scale, ctx.unit),
        normalized_residuals=st.normalized_residuals, redundancy_numbers=st.redundancy_numbers,
        iterations=iterations, converged=True, message=message,
        elapsed=time.perf_counter() - ctx.t0, notes=tuple(notes), extras=extras or {},
    )


# --- initial values for E / F ---------------------------------------------------------------


def _start(
    initial, x, X, with_scale, point_w, default: str
) -> tuple[float, np.ndarray, np.ndarray, str]:
    if initial is None:
        initial = default
    if isinstance(initial, str):
        key = initial.strip().lower()
        if key in ("zeros", "zero", "identity"):
            return 1.0, np.eye(3), np.zeros(3), "zeros (s = 1, R = I, t = 0)"
        meth = normalize_method(key)
        if meth == "gauss-markov":
            raise InputError("initial values: choose a direct method, 'zeros' or given values")
        if meth == "closed-form":
            sol = solve_closed_form(x[None], X[None], with_scale=with_scale)
            _check_solution(sol.degenerate, sol.reflection, f"initial values by {meth}")
            s, R, t = float(sol.scale[0]), sol.rotation[0], sol.translation[0]
        else:
            pm = PairMoments.of(x, X, None if meth == "gauss-helmert" else point_w)
            one = solve_single(pm, meth, with_scale=with_scale)
            _check_solution(one.degenerate, one.reflection, f"initial values by {meth}")
            s, R, t = one.scale, one.rotation, one.translation
        return s, R, t, f"direct method {meth}"
    if isinstance(initial, Similarity3D):
        return initial.scale, np.asarray(initial.rotation), np.asarray(initial.translation), (
            "given Similarity3D"
        )
    p = np.asarray(initial, dtype=float).reshape(-1)
    u = 7 if with_scale else 6
    if p.size != u or not np.all(np.isfinite(p)):
        raise InputError(
            f"initial values: expected {u} finite numbers (tx, ty, tz"
            + (", scale" if with_scale else "")
            + ", omega, phi, kappa; radians, transposed convention), a Similarity3D, a method "
            "name or 'zeros'"
        )
    t, s, ang = _adj.unpack(p, with_scale)
    R, _ = rotation_derivatives(*ang)
    return s, R, t, "given values"


def _min_cost(pm: PairMoments, with_scale: bool) -> float:
    """Least-squares cost ``min sum w |v|^2`` of point-weighted data from the moments."""
    S = np.linalg.svd(pm.H, compute_uv=False)
    d = np.sign(np.linalg.det(pm.H)) or 1.0
    lam = S[0] + S[1] + d * S[2]
    a, b = pm.a, pm.b
    return b - lam * lam / a if with_scale else a + b - 2 * lam


# --- E: Gauss-Markov ---------------------------------------------------------------------------


def _geometry_check(x, X, w, with_scale, method) -> None:
    """Collinear points and best-fit reflections, before any iteration."""
    pm = PairMoments.of(x, X, w)
    one = solve_single(pm, "svd", with_scale=with_scale)
    _check_single(one, x, X, w, pm, method)


def _gauss_markov_fit(x, X, prec, with_scale, initial, max_iter, tol, raise_on_failure, ctx):
    _check_finite_pair(x, X)
    _geometry_check(x, X, prec.point_w, with_scale, "gauss-markov")
    s0, R0, t0, start = _start(initial, x, X, with_scale, prec.point_w, "svd")
    prob = _adj.reduce(x, X, prec.point_w)
    R0 = _as_rotation(R0)
    p0 = _adj.to_reduced(t0, s0, R0, prob.source_ref, prob.target_ref, with_scale)
    obs_w = prec.obs_w
    if prec.point_w is not None:
        obs_w = np.repeat(prec.point_w, 3)
    cov = prec.cov_t
    what = "absolute orientation (Gauss-Markov)"
    try:
        adj = _adj.similarity_gauss_markov(
            prob, p0, with_scale=with_scale, R0=R0, weights=obs_w, covariance=cov,
            max_iter=max_iter, tol=tol, sigma0_prior=ctx.sigma0_prior,
        )
    except DegenerateGeometryError as exc:
        raise ConvergenceError(_SINGULAR.format(what=what, start=start, exc=exc)) from exc
    if not np.all(np.isfinite(adj.x)):
        raise ConvergenceError(
            f"{what}: diverged ({adj.message}) from {start}; start from a direct method "
            "(initial='svd')", iterations=adj.iterations, result=adj,
        )
    _, s, _ = _adj.unpack(adj.x, with_scale)
    if with_scale and s <= 0:
        raise ConvergenceError(
            f"{what}: the iteration from {start} ended at scale {s:.3g} <= 0, a point-reflected "
            "fit (s R with s < 0 is a reflection), not a similarity; start from a direct "
            "method (initial='svd')", iterations=adj.iterations, result=adj,
        )
    notes = [_CONVENTION_NOTE, f"start: {start}"]
    if adj.converged:
        if prec.obs_w is None and cov is None:
            pmm = PairMoments.of(x, X, prec.point_w)
            best = _min_cost(pmm, with_scale)
            if adj.vtpv > best * (1 + 1e-6) + 1e-10 * pmm.b:
                msg = (
                    f"{what}: the iteration from {start} converged to a stationary point that is "
                    f"not the least-squares minimum (v.T P v {adj.vtpv:.6g} vs {best:.6g}); "
                    "start from a direct method (initial='svd')"
                )
                if raise_on_failure:
                    raise ConvergenceError(msg, iterations=adj.iterations, result=adj)
                notes.append(msg)
                adj = _flag(adj, msg)
    else:
        msg = (
            f"{what}: {adj.message} (started from {start}); the estimate is not a least-squares "
            "solution. Start from a direct method (initial='svd') or raise max_iter"
        )
        if raise_on_failure:
            raise ConvergenceError(msg, iterations=adj.iterations, result=adj)
        notes.append("NOT CONVERGED: " + msg)
    params, J, model = _original(adj, prob, with_scale, R0, notes)
    fit = AbsoluteOrientationFit.from_adjustment(
        adj, model, "gauss-markov", point_dim=3, parameters=params,
        parameter_names=_adj.names(with_scale), jacobian=J, ids=ctx.ids,
        residual_labels=("X", "Y", "Z"), residual_unit=ctx.unit,
        parameter_units=_param_units(with_scale, ctx.unit), notes=tuple(notes),
        extras={"start": start, "cost_history": list(adj.cost_history)},
        elapsed=time.perf_counter() - ctx.t0,
    )
    return fit


#: Points per chunk of the large-n Gauss-Markov pass (temporaries stay cache-sized).
GM_CHUNK = 16384


def _gm_normal(pm: PairMoments, p: np.ndarray, with_scale: bool, R0: np.ndarray):
    """``v'Pv``, the normal matrix ``A'PA`` and ``-A'Pv`` of the point-weighted similarity at
    reduced parameters ``p``, from the centred moments alone.

    Each point's 3 x u block is ``A_i = [I, R x'_i, s dR_k x'_i]`` (linear in ``x'_i``), so
    ``sum w_i A_i.T A_i`` and ``sum w_i A_i.T v_i`` need only ``W``, the scatter ``S``, the
    cross moment ``H = sum w x' X'.T`` and ``b = sum w |X'|^2`` (``sum w x' = sum w X' = 0``):
    O(1) per iteration after one pass over the data, never an n-row array.
    """
    tr, s, _ = _adj.unpack(p, with_scale)
    R, dR = _adj._rotation(p, with_scale, R0)
    S, H, W = pm.S, pm.H, pm.weight
    u = p.size
    k = 4 if with_scale else 3
    N = np.zeros((u, u))
    b = np.zeros(u)
    N[:3, :3] = W * np.eye(3)
    b[:3] = -W * tr
    HR = float(np.trace(H @ R))
    if with_scale:
        N[3, 3] = pm.a
        b[3] = -(s * pm.a - HR)
    for i in range(3):
        dRi = dR[i]
        if with_scale:
            N[3, k + i] = N[k + i, 3] = s * float(np.trace(R.T @ dRi @ S))
        for j in range(i, 3):
            N[k + i, k + j] = N[k + j, k + i] = s * s * float(np.trace(dRi.T @ dR[j] @ S))
        b[k + i] = -s * (s * float(np.trace(dRi.T @ R @ S)) - float(np.trace(H @ dRi)))
    vtpv = W * float(tr @ tr) + s * s * pm.a + pm.b - 2 * s * HR
    return max(vtpv, 0.0), N, b


def _gm_extent(x, X, w, xg, Xg) -> tuple[float, float]:
    """Largest ``sqrt(w) |x'_i|`` and ``sqrt(w) |X'_i|`` (one chunked pass): bounds for the
    change of the whitened computed observations by a step."""
    from .absolute_direct import centred_chunk

    rx = rX = 0.0
    xt, Xt = np.tile(xg, GM_CHUNK), np.tile(Xg, GM_CHUNK)
    for i in range(0, x.shape[0], GM_CHUNK):
        j = min(i + GM_CHUNK, x.shape[0])
        nx = centred_chunk(x, i, j, xt)[1]
        nX = centred_chunk(X, i, j, Xt)[1]
        if w is not None:
            nx = nx * w[i:j]
            nX = nX * w[i:j]
        rx, rX = max(rx, float(np.max(nx))), max(rX, float(np.max(nX)))
    return math.sqrt(rx), math.sqrt(rX)


def _gauss_markov_large(x, X, w, with_scale, initial, statistics, max_iter, tol,
                        raise_on_failure, ctx):
    """Method E for many points with point weights: Gauss-Newton on normal equations
    accumulated in chunks (the 3x7 block of each point), never a dense (3n x 7) Jacobian;
    statistics by the chunked pass of the direct methods. Same estimate, criteria and
    diagnostics as the general path."""
    what = "absolute orientation (Gauss-Markov)"
    pm = _moments(x, X, w, True)
    one = solve_single(pm, "svd", with_scale=with_scale)
    _check_single(one, x, X, w, pm, "gauss-markov")
    if initial is None or (isinstance(initial, str) and initial.strip().lower() == "svd"):
        s0, R0, t0, start = one.scale, one.rotation, one.translation, "direct method svd"
    else:
        s0, R0, t0, start = _start(initial, x, X, with_scale, w, "svd")
    R0 = _as_rotation(R0)
    xg, Xg = pm.source_centroid, pm.target_centroid
    p = _adj.to_reduced(t0, s0, R0, xg, Xg, with_scale)
    u = p.size
    vtpv, N, b = _gm_normal(pm, p, with_scale, R0)
    rx, lmax = _gm_extent(x, X, w, xg, Xg)
    wmax = 1.0 if w is None else math.sqrt(float(np.max(w)))
    history = [vtpv]
    converged = False
    message = ""
    it = 0
    eps = np.finfo(float).eps
    k = 4 if with_scale else 3
    while it < max_iter:
        it += 1
        d = np.sqrt(np.diag(N))
        d[d == 0] = 1.0
        try:
            dx = np.linalg.solve(N / np.outer(d, d), b / d) / d
        except np.linalg.LinAlgError as exc:
            raise ConvergenceError(
                _SINGULAR.format(what=what, start=start, exc=exc), iterations=it
            ) from exc
        # bound of the largest whitened change |A_i dx| of the computed observations
        _, s_cur, _ = _adj.unpack(p, with_scale)
        _, dRc = _adj._rotation(p, with_scale, R0)
        rot = sum(abs(float(dx[k + i])) * float(np.linalg.norm(dRc[i], 2)) for i in range(3))
        step = (
            float(np.linalg.norm(dx[:3])) * wmax
            + (abs(float(dx[3])) if with_scale else 0.0) * rx
            + abs(s_cur) * rot * rx
        )
        rms = math.sqrt(vtpv / (3 * ctx.n))
        small = step <= tol * (1.0 + rms) + 64 * eps * lmax
        lam = 1.0
        for _ in range(31):  # step control: halve while v'Pv grows
            cand = p + lam * dx
            v_new, N_new, b_new = _gm_normal(pm, cand, with_scale, R0)
            if small or v_new <= vtpv * (1 + 1e-12) or not math.isfinite(v_new):
                break
            lam /= 2
        if not math.isfinite(v_new):
            raise ConvergenceError(f"{what}: diverged (non-finite values) from {start}",
                                   iterations=it)
        p, vtpv, N, b = cand, v_new, N_new, b_new
        history.append(vtpv)
        if small:
            converged = True
            break
    if not converged:
        message = f"not converged: iteration limit {max_iter} reached"
    tr, s, _ = _adj.unpack(p, with_scale)
    if with_scale and s <= 0:
        raise ConvergenceError(
            f"{what}: the iteration from {start} ended at scale {s:.3g} <= 0, a point-reflected "
            "fit (s R with s < 0 is a reflection), not a similarity; start from a direct "
            "method (initial='svd')", iterations=it,
        )
    notes = [_CONVENTION_NOTE, f"start: {start}",
             "normal equations from the moments (large n): no dense Jacobian"]
    if converged:
        best = _min_cost(pm, with_scale)
        if vtpv > best * (1 + 1e-6) + 1e-10 * pm.b:
            msg = (
                f"{what}: the iteration from {start} converged to a stationary point that is "
                f"not the least-squares minimum (v.T P v {vtpv:.6g} vs {best:.6g}); "
                "start from a direct method (initial='svd')"
            )
            if raise_on_failure:
                raise ConvergenceError(msg, iterations=it)
            notes.append(msg)
            converged, message = False, msg
    else:
        msg = (
            f"{what}: {message} (started from {start}); the estimate is not a least-squares "
            "solution. Start from a direct method (initial='svd') or raise max_iter"
        )
        if raise_on_failure:
            raise ConvergenceError(msg, iterations=it)
        notes.append("NOT CONVERGED: " + msg)
        message = msg
    R, _ = _adj._rotation(p, with_scale, R0)
    omega, phi, kappa, gimbal = opk_transposed(R)
    if gimbal:
        notes.append(_GIMBAL_NOTE)
    t = Xg + tr - s * (R @ xg)
    model = _similarity(s, R, t)
    params = _params(t, s, (omega, phi, kappa), with_scale)
    names = _adj.names(with_scale)
    r = 3 * ctx.n - u
    extras = {"start": start, "cost_history": history}
    if not statistics:
        fit = _bare_fit(model, "gauss-markov", names, params, u, r, 3 * ctx.n, with_scale,
                        ctx, notes)
        return replace(fit, iterations=it, converged=converged, message=message,
                       extras=extras)
    st, v = residual_statistics(
        x, X, scale=s, rotation=R, translation=t, angles=(omega, phi, kappa),
        source_centroid=xg, scatter=pm.S, weight_sum=pm.weight, weights=w,
        with_scale=with_scale, sigma0_prior=ctx.sigma0_prior,
    )
    fit = _stat_fit(model, "gauss-markov", names, params, st, r, 3 * ctx.n, v, with_scale,
                    ctx, notes, extras=extras, iterations=it, message=message)
    return replace(fit, converged=converged) if not converged else fit


_SINGULAR = (
    "{what}: the iteration from {start} stopped at a singular normal matrix ({exc}); with a "
    "good geometry this means the angles passed phi = +-90 deg relative to the start. Start "
    "from a direct method (initial='svd')"
)
_GIMBAL_NOTE = (
    "gimbal lock (phi = +-90 deg): omega set to 0, kappa holds the rotation about the "
    "vertical; omega and kappa have no separate standard deviations"
)


def _original(adj, prob, with_scale: bool, R0: np.ndarray, notes: list):
    """Parameters, their Jacobian and the model in the original systems from an adjustment
    of the reduced problem (angles relative to ``R0``); a gimbal-lock note is appended."""
    params, J, R, gimbal = _adj.to_original(
        adj.x, prob.source_ref, prob.target_ref, with_scale, R0
    )
    if gimbal:
        notes.append(_GIMBAL_NOTE)
    t, s, _ = _adj.unpack(params, with_scale)
    return params, J, _similarity(s, R, t)


def _as_rotation(R) -> np.ndarray:
    """A proper rotation for the start (the raw closed-form matrix is orthogonalised)."""
    R = np.asarray(R, dtype=float)
    if orthogonality_defect(R) > 1e-9:
        from ..rotation import nearest_rotation

        R = nearest_rotation(R)
    return R


def _flag(adj, msg):
    from dataclasses import replace

    return replace(adj, converged=False, message=msg)


# --- F: Gauss-Helmert ---------------------------------------------------------------------------


def _gh_direct_fit(x, X, prec, with_scale, statistics, ctx):
    n = ctx.n
    # a system without a stated precision has weight 1: standard deviation sigma0_prior
    sx = ctx.sigma0_prior if prec.sig_s is None else float(prec.sig_s)
    sX = ctx.sigma0_prior if prec.sig_t is None else float(prec.sig_t)
    k = sX / sx
    pm = _moments(x, X, None, statistics)
    sol = solve_single(pm, "gauss-helmert", with_scale=with_scale, ratio=k)
    _check_single(sol, x, X, None, pm, "gauss-helmert")
    s, R, t = sol.scale, sol.rotation, sol.translation
    model = _similarity(s, R, t)
    omega, phi, kappa, gimbal = opk_transposed(R)
    notes = [_CONVENTION_NOTE, "direct Gauss-Helmert solution (exact for one sigma per system)"]
    if prec.sig_s is not None or prec.sig_t is not None:
        notes.append(f"source prescaled by sigma_target / sigma_source = {k:.6g}")
    if gimbal:
        notes.append(_GIMBAL_NOTE)
    names = _adj.names(with_scale)
    params = _params(t, s, (omega, phi, kappa), with_scale)
    u = len(names)
    r = 3 * n - u
    if not statistics:
        return _bare_fit(model, "gauss-helmert", names, params, u, r, 6 * n, with_scale, ctx,
                         notes)
    # misclosures g = s R x + t - X; corrections e_x = -sx^2 s R.T g / mm, e_X = sX^2 g / mm;
    # redundancy numbers and normalised residuals of both systems (chunked, no n x 3 x 3)
    st, vX, extras = gauss_helmert_statistics(
        x, X, scale=s, rotation=R, translation=t, angles=(omega, phi, kappa),
        source_centroid=pm.source_centroid, target_centroid=pm.target_centroid,
        sigma_source=sx, sigma_target=sX, sigma0_prior=ctx.sigma0_prior, with_scale=with_scale,
    )
    return _stat_fit(model, "gauss-helmert", names, params, st, r, 6 * n, vX, with_scale, ctx,
                     notes, extras=extras)


def _gh_observation_precision(prec: _Precision, n: int, sigma0_prior: float):
    """Inverse variances (6n,) or covariance ((n, 6, 6) / (6n, 6n)) of
    ``[x_1, X_1, x_2, X_2, ...]`` in squared coordinate units; a system without a stated
    precision has weight 1, i.e. the variance ``sigma0_prior^2`` per coordinate."""

    def per_coord(sig):
        if sig is None:
            return np.full((n, 3), sigma0_prior**2)
        a = np.asarray(sig, dtype=float)
        if a.ndim == 0:
            return np.full((n, 3), float(a) ** 2)
        if a.shape == (n,):
            return np.repeat((a**2)[:, None], 3, axis=1)
        return a**2

    if prec.cov_s is None and prec.cov_t is None:
        var = np.concatenate([per_coord(prec.sig_s), per_coord(prec.sig_t)], axis=1)
        return 1.0 / var.reshape(-1), None

    def blocks(sig, cov):
        if cov is not None and cov.ndim == 3:
            return cov
        if cov is not None:
            return None
        return np.einsum("ni,ij->nij", per_coord(sig), np.eye(3))

    bs, bt = blocks(prec.sig_s, prec.cov_s), blocks(prec.sig_t, prec.cov_t)
    if bs is not None and bt is not None:
        C = np.zeros((n, 6, 6))
        C[:, :3, :3] = bs
        C[:, 3:, 3:] = bt
        return None, C
    # at least one full (3n, 3n) covariance: assemble the full (6n, 6n) matrix
    def full(sig, cov):
        if cov is not None and cov.ndim == 2:
            return cov
        b = blocks(sig, cov)
        F = np.zeros((3 * n, 3 * n))
        for j in range(3):
            for k in range(3):
                F[j::3, k::3] = np.diag(b[:, j, k])
        return F

    Fs, Ft = full(prec.sig_s, prec.cov_s), full(prec.sig_t, prec.cov_t)
    idx = np.arange(6 * n).reshape(n, 6)
    src, tgt = idx[:, :3].reshape(-1), idx[:, 3:].reshape(-1)
    C = np.zeros((6 * n, 6 * n))
    C[np.ix_(src, src)] = Fs
    C[np.ix_(tgt, tgt)] = Ft
    return None, C


#: Points whose distances from their best-fitting line are, as an RMS of the distances in
#: units of their standard deviations, at most this lie on one line as far as their accuracy
#: can tell: the rotation about that line is then set by their noise.
LINE_WITHIN_SIGMAS = 3.0


def _check_line_within_sigmas(pts: np.ndarray, sigma, side: str, option: str) -> None:
    """Raise :class:`DegenerateGeometryError` when points with standard deviations ``sigma``
    (scalar, (n,) or (n, 3), object units; None: not given, nothing checked) lie on one line
    within :data:`LINE_WITHIN_SIGMAS` of them (RMS of the whitened distances from the line)."""
    if sigma is None or not np.all(np.isfinite(pts)):
        return  # not given, or NaN / inf: reported by the other checks
    n = pts.shape[0]
    sig = np.asarray(sigma, dtype=float)
    sig = np.broadcast_to(sig[:, None] if sig.ndim == 1 else sig, (n, 3))
    c = pts - pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(c, full_matrices=False)
    if not np.all(np.isfinite(sv)) or sv[0] == 0.0:
        return  # NaN / coincident points: reported by the other checks
    off = c - np.outer(c @ vt[0], vt[0])  # distances from the line
    rms = float(np.sqrt(np.mean(np.sum((off / sig) ** 2, axis=1))))
    if rms <= LINE_WITHIN_SIGMAS:
        dist = float(np.sqrt(np.mean(np.sum(off**2, axis=1))))
        raise DegenerateGeometryError(
            f"absolute orientation (gauss-helmert): the {n} {side} points lie on one line "
            f"within their accuracy (RMS distance from the line {dist:.3g}, {rms:.2g} times "
            f"{option}; at most {LINE_WITHIN_SIGMAS:g} times leaves the rotation about the "
            "line to their noise), so that rotation is undetermined; at least three points "
            f"off a line by more than {option} are needed in each system"
        )


def _gauss_helmert_fit(x, X, prec, with_scale, initial, statistics, iterate, max_iter, tol,
                       raise_on_failure, ctx):
    if iterate is False and not prec.scalar_sigmas:
        raise InputError(
            "gauss-helmert: the direct solution needs at most one sigma per system; per-point "
            "or per-coordinate precision and covariances need the iterative adjustment "
            "(iterate=None or True)"
        )
    if prec.scalar_sigmas and not iterate:
        if initial is not None:
            raise InputError(
                "gauss-helmert: initial values apply to the iterative adjustment; pass "
                "iterate=True"
            )
        return _gh_direct_fit(x, X, prec, with_scale, statistics, ctx)
    _check_finite_pair(x, X)
    _geometry_check(x, X, None, with_scale, "gauss-helmert")
    n = ctx.n
    w_obs, cov = _gh_observation_precision(prec, n, ctx.sigma0_prior)
    if w_obs is not None:
        w_obs = w_obs * ctx.sigma0_prior**2
    if initial is None:
        # the direct solution with representative sigmas (exact for one sigma per system)
        vs = 1.0 / w_obs.reshape(n, 6) if w_obs is not None else None
        if vs is not None:
            k = math.sqrt(float(np.median(vs[:, 3:])) / float(np.median(vs[:, :3])))
        else:
            k = 1.0
        sol = solve_single(PairMoments.of(x, X), "gauss-helmert", with_scale=with_scale, ratio=k)
        _check_solution(sol.degenerate, sol.reflection, "gauss-helmert")
        s0, R0, t0 = sol.scale, sol.rotation, sol.translation
        start = "direct Gauss-Helmert solution"
    else:
        s0, R0, t0, start = _start(initial, x, X, with_scale, None, "gauss-helmert")
    prob = _adj.reduce(x, X)
    R0 = _as_rotation(R0)
    p0 = _adj.to_reduced(t0, s0, R0, prob.source_ref, prob.target_ref, with_scale)
    what = "absolute orientation (Gauss-Helmert)"
    try:
        adj = _adj.similarity_gauss_helmert(
            prob, p0, with_scale=with_scale, R0=R0, weights=w_obs, covariance=cov,
            max_iter=max_iter, tol=tol, sigma0_prior=ctx.sigma0_prior,
        )
    except DegenerateGeometryError as exc:
        raise ConvergenceError(_SINGULAR.format(what=what, start=start, exc=exc)) from exc
    _, s, _ = _adj.unpack(adj.x, with_scale)
    if not np.all(np.isfinite(adj.x)) or (with_scale and s <= 0):
        raise ConvergenceError(
            f"{what}: no valid solution from {start} ({adj.message}, scale {s:.3g}); start "
            "from a direct method", iterations=adj.iterations, result=adj,
        )
    notes = [_CONVENTION_NOTE, f"iterative Gauss-Helmert adjustment, start: {start}"]
    if not adj.converged:
        msg = f"{what}: {adj.message} (started from {start}); raise max_iter or check the data"
        if raise_on_failure:
            raise ConvergenceError(msg, iterations=adj.iterations, result=adj)
        notes.append("NOT CONVERGED: " + msg)
    params, J, model = _original(adj, prob, with_scale, R0, notes)
    v = adj.residuals.reshape(n, 6)
    corr = adj.corrected_observations.reshape(n, 6)
    extras = {
        "corrected_source": corr[:, :3] + prob.source_ref,
        "corrected_target": corr[:, 3:] + prob.target_ref,
        "source_residuals": v[:, :3],
        "start": start,
    }
    red = adj.redundancy_numbers
    wn = adj.normalized_residuals
    if red is not None:
        extras["source_redundancy_numbers"] = red.reshape(n, 6)[:, :3]
        red = red.reshape(n, 6)[:, 3:]
    if wn is not None:
        extras["source_normalized_residuals"] = wn.reshape(n, 6)[:, :3]
        wn = wn.reshape(n, 6)[:, 3:]
    Q = J @ adj.cofactor @ J.T
    s0 = adj.sigma0
    return AbsoluteOrientationFit(
        model=model, method="gauss-helmert",
        parameter_names=_adj.names(with_scale), parameters=params, covariance=s0**2 * Q,
        cofactor=Q, sigma0=s0, sigma0_prior=adj.sigma0_prior, redundancy=adj.redundancy,
        n_observations=adj.n_observations, residuals=v[:, 3:], ids=ctx.ids,
        residual_labels=("X", "Y", "Z"), residual_unit=ctx.unit,
        parameter_units=_param_units(with_scale, ctx.unit), normalized_residuals=wn,
        redundancy_numbers=red, iterations=adj.iterations, converged=adj.converged,
        message=adj.message, elapsed=time.perf_counter() - ctx.t0, notes=tuple(notes),
        extras=extras,
    )
