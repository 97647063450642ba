"""Robust losses of the bundle adjustment: the statistics that make sigma0, the variance
components and the covariance consistent under normal errors (the global test uses the
least-squares ``v'Pv`` instead, :func:`photogeom.bundle.result.least_squares_square_sum`).

With iteratively reweighted least squares the adjustment minimises ``sum w_i e_i^2`` with
weights ``w(e^2)`` of the squared whitened 2-D residual norm of each image point
(:meth:`photogeom.bundle.adjustment.Problem.robust_weights`). Under normal errors
``v'PWv`` is then smaller than with unit weights, since the tails are down-weighted, and
``v'PWv / r`` underestimates the variance factor: by 10 % (sigma0) for Huber's loss at
1.345 and 16 % for Cauchy's at 2.385 on a simulated UAV block.

* :func:`score_slopes`, :func:`stein_redundancy`, :func:`score_derivatives`,
  :func:`point_trace_correction` - sigma0: ``v'PWv`` over its Stein redundancy, whose
  expectation times the variance factor is that of ``v'PWv`` under normal errors,
  computed from the realised residuals (before, a normal model of each point's residual,
  ``N(0, r_i s^2 I)``, gave sigma0^2 6-7 % high with Cauchy's loss);
* :func:`influence_factors`, :func:`covariance_weights` - the covariance of the robust
  estimate, the M-estimator's sandwich ``H^-1 B H^-1``: per image point the expected slope
  and spread of its score, and the weight ``slope^2 / spread`` with which it enters the
  normal matrix whose inverse times ``s^2`` is the reported covariance (the IRLS weights
  gave standard deviations up to 10 % too large with Cauchy's loss).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

__all__ = [
    "covariance_weights",
    "image_point_leverage",
    "influence_factors",
    "point_trace_correction",
    "point_trace_shares",
    "score_slopes",
    "stein_redundancy",
]


def _cauchy_rest(x: np.ndarray) -> np.ndarray:
    """``1 - x e^x E1(x)`` for ``x > 0`` (the asymptotic series from ``x = 50`` on)."""
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    small = x < 50.0
    xs = x[small]
    out[small] = 1.0 - xs * np.exp(xs) * special.exp1(xs)
    # 1 - x e^x E1(x) ~ sum_k (-1)^(k+1) k! / x^k, relative error below 1e-13
    xl = x[~small]
    out[~small] = sum((-1) ** (k + 1) * math.factorial(k) / xl**k for k in range(1, 20))
    return out


def influence_factors(loss: str, scale: float, a) -> tuple[np.ndarray, np.ndarray]:
    """Slope and spread of the robust score ``psi(e) = w(|e|^2) e`` of an image point whose
    whitened residual ``e`` is ``N(0, a I)`` (closed forms).

    The covariance of an M-estimator is the sandwich ``H^-1 B H^-1`` with ``H`` from the
    derivative of the score and ``B`` from its variance; per image point, in expectation
    under normal errors, ``H = slope J'J`` and ``B = spread J'J`` (``J`` whitened, ``q =
    |e|^2 / a`` chi-square with 2 degrees of freedom):

    * ``slope = E[w + w'(|e|^2) |e|^2]`` (half the trace of ``d psi / d e``);
    * ``spread = E[w^2 |e|^2] / (2 a)``.

    Huber (``w = min(1, c / |e|)``, ``t = c^2 / a``): ``spread = 1 - exp(-t / 2)``, ``slope =
    spread + sqrt(pi t / 8) erfc(sqrt(t / 2))``. Cauchy (``w = 1 / (1 + |e|^2 / c^2)``, ``x =
    c^2 / (2 a)``, ``R = 1 - x e^x E1(x)``): ``slope = x R``, ``spread = x (1 - R) - x^2 R``
    (its asymptotic series ``sum_m (-1)^(m+1) m m! / x^(m-1)`` from ``x = 50`` on).

    Parameters
    ----------
    loss : {"squared", "huber", "cauchy"}
    scale : float
        The loss scale ``c`` (whitened units).
    a : float or array_like
        Variance of each whitened coordinate of the residual.

    Returns
    -------
    (slope, spread) : numpy.ndarray, each of the shape of ``a``
        Both 1 for the squared loss (and ``a <= 0``), below 1 for a robust one; the
        point's weight in the covariance is ``slope^2 / spread`` (:func:`covariance_weights`).
    """
    if loss not in ("squared", "huber", "cauchy"):
        raise ValueError(f"unknown loss {loss!r}")
    a = np.asarray(a, dtype=float)
    slope = np.ones(a.shape)
    spread = np.ones(a.shape)
    pos = a > 0
    if loss != "squared" and np.any(pos):
        if loss == "huber":
            t = scale * scale / a[pos]
            sp = -np.expm1(-0.5 * t)
            spread[pos] = sp
            slope[pos] = sp + np.sqrt(math.pi * t / 8.0) * special.erfc(np.sqrt(0.5 * t))
        else:
            x = 0.5 * scale * scale / a[pos]
            r = _cauchy_rest(x)
            slope[pos] = x * r
            sp = np.empty_like(x)
            small = x < 50.0
            xs, rs = x[small], r[small]
            sp[small] = xs * (1.0 - rs) - xs * xs * rs
            xl = x[~small]
            sp[~small] = sum(
                (-1) ** (m + 1) * m * math.factorial(m) / xl ** (m - 1) for m in range(1, 20)
            )
            spread[pos] = sp
    return slope, spread


def covariance_weights(leverage, loss: str, scale: float, s2: float = 1.0) -> np.ndarray:
    """Per image point, the weight ``slope^2 / spread`` (:func:`influence_factors`) with
    which it enters the normal matrix whose inverse, times ``sigma0^2``, is the covariance
    of a robust estimate.

    The sandwich ``H^-1 B H^-1`` with ``H = sum slope_i J_i'J_i + N_prior`` and ``B = sum
    spread_i J_i'J_i + N_prior`` is replaced by ``(sum (slope_i^2 / spread_i) J_i'J_i +
    N_prior)^-1``: equal to it when the image points or the prior observations dominate,
    smaller in variance by at most 4 % (Cauchy) and 1.3 % (Huber) in between (a scalar
    problem, points of redundancy 1), and a single inverse of the block structure the
    adjustment already factorises. The expectations are taken at the point's residual
    variance ``r_i s^2`` (``r_i = 1 - h_i`` the point's redundancy number).

    Parameters
    ----------
    leverage : array_like (k,)
        Per image point, the leverage ``h_i`` at unit weight.
    loss, scale
        As in :func:`influence_factors`.
    s2 : float
        The variance factor (sigma0^2).

    Returns
    -------
    numpy.ndarray (k,)
        Positive weights; 1 for the squared loss.
    """
    r = 1.0 - np.clip(np.asarray(leverage, dtype=float), 0.0, 1.0)
    slope, spread = influence_factors(loss, scale, r * s2)
    return np.where(spread > 0, slope * slope / np.where(spread > 0, spread, 1.0), 1.0)


def image_point_leverage(cofactors: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n,) leverage of each image point at unit weight, the mean of its two coordinates:
    ``tr(J Q J') / (2 w)`` from the observation cofactors ``J Q J'`` (n, 2, 2) of the
    weighted adjustment and the IRLS weights (n,)."""
    return np.einsum("ndd->n", cofactors) / (2.0 * np.clip(weights, 1e-12, None))


def score_slopes(loss: str, scale: float, e2) -> np.ndarray:
    """Per image point, half the trace of the derivative of its score ``psi(e) = w(|e|^2) e``
    by its whitened residual ``e``: ``w + w'(|e|^2) |e|^2``.

    Parameters
    ----------
    loss : {"squared", "huber", "cauchy"}
    scale : float
        The loss scale ``c`` (whitened units).
    e2 : array_like (k,)
        Squared whitened norms ``|e|^2`` of the image points' residuals.

    Returns
    -------
    numpy.ndarray (k,)
        Positive: 1 for the squared loss; Huber ``1`` for ``|e| <= c``, else ``c / (2 |e|)``;
        Cauchy ``c^4 / (c^2 + |e|^2)^2``.
    """
    if loss not in ("squared", "huber", "cauchy"):
        raise ValueError(f"unknown loss {loss!r}")
    e2 = np.asarray(e2, dtype=float)
    if loss == "squared":
        return np.ones(e2.shape)
    c = float(scale)
    if loss == "huber":
        e = np.sqrt(e2)
        return np.where(e <= c, 1.0, 0.5 * c / np.maximum(e, 1e-300))
    return c**4 / (c * c + e2) ** 2


def stein_redundancy(redundancy: float, slopes, cofactors) -> float:
    """The redundancy ``r_s`` whose expectation times the variance factor is the
    expectation of the robust ``v'PWv`` under normal errors (Stein's identity).

    At the solution of the linearised problem the estimating equations ``A' psi = 0`` (all
    observations stacked, whitened; ``psi`` the image points' scores ``w e`` and the prior
    observations' residuals) make ``v'PWv = psi' v = psi' eps``, ``eps`` the true errors.
    For normal ``eps`` of variance ``s^2`` Stein's identity gives ``E[psi' eps] = s^2
    E[div psi]`` and ``div psi = tr D - tr((A'DA)^-1 A'D^2 A)``, ``D`` the derivative of
    the scores by the residuals (1 for the prior observations; per image point ``d_i I``,
    ``d_i`` from :func:`score_slopes`). With ``C_i`` the image point's cofactors in the
    adjustment weighted by ``D`` this is ``r - sum_i (1 - d_i) (2 - tr C_i)``: ``r`` for the
    squared loss, positive, and evaluated at the realised residuals (no model of their
    distribution). ``v'PWv / r_s`` is then the variance factor: over Monte-Carlo redraws
    of a 6-image block 0.983 (Cauchy) and 0.98 (Huber) times its true value (see
    ``docs/bundle-adjustment.md``).

    Parameters
    ----------
    redundancy : float
        ``r = n - u``.
    slopes : array_like (k,)
        Per image point ``d_i`` (:func:`score_slopes` at the solution).
    cofactors : numpy.ndarray (k, 2, 2)
        ``d_i J_i Q_D J_i'``, the image observations' cofactors with ``Q_D`` the inverse of
        the normal matrix whose image points are weighted by ``d_i``.

    Returns
    -------
    float
    """
    d = np.asarray(slopes, dtype=float)
    tr = np.einsum("ndd->n", np.asarray(cofactors, dtype=float))
    return float(redundancy) - float(np.sum((1.0 - d) * (2.0 - tr)))


def score_derivatives(loss: str, scale: float, e) -> np.ndarray:
    """(k, 2, 2) derivative ``w I + 2 w'(|e|^2) e e'`` of the score ``psi(e) = w(|e|^2) e``
    of each image point by its whitened residual ``e`` (k, 2); half its trace is
    :func:`score_slopes`. Cauchy's is indefinite beyond ``|e| = c`` (its score redescends),
    Huber's of rank 1 beyond ``|e| = c``."""
    e = np.asarray(e, dtype=float)
    q = np.einsum("nd,nd->n", e, e)
    c = float(scale)
    if loss == "squared":
        w, dw = np.ones(q.shape), np.zeros(q.shape)
    elif loss == "huber":
        out = q > c * c
        qs = np.where(out, q, 1.0)
        w = np.where(out, c / np.sqrt(qs), 1.0)
        dw = np.where(out, -0.5 * c / qs**1.5, 0.0)
    elif loss == "cauchy":
        w = c * c / (c * c + q)
        dw = -c * c / (c * c + q) ** 2
    else:
        raise ValueError(f"unknown loss {loss!r}")
    return w[:, None, None] * np.eye(2) + 2.0 * dw[:, None, None] * np.einsum("ni,nj->nij", e, e)


def point_trace_correction(loss: str, scale: float, e, P, obs_point, point_info) -> float:
    """The points' share of ``tr((A'DA)^-1 A'D^2 A)`` in :func:`stein_redundancy` with
    each image point's isotropic ``d_i I`` minus that with its full derivative ``D_i``
    (:func:`score_derivatives`), the cameras held: add it to the redundancy.

    For each object point ``H = sum P_i' D_i P_i + N_p`` and ``B = sum P_i' D_i^2 P_i + N_p``
    (``P_i`` the whitened derivatives of its image points by its coordinates, ``N_p`` its
    prior information, control points only) and the share ``tr(H^-1 B)``. A point seen by
    few images has its residuals along a few directions, which ``d_i I`` misses: for tie
    points of 2 (5) rays alone the isotropic redundancy is 14-17 % (5-6 %) too large.
    Points whose ``H`` is not positive definite (not at a minimum) add nothing.

    Parameters
    ----------
    loss, scale
        As in :func:`score_slopes`.
    e : numpy.ndarray (n, 2)
        Whitened residuals of the image points (without the robust weights).
    P : numpy.ndarray (n, 2, 3)
        Their whitened derivatives by the coordinates of their object points.
    obs_point : numpy.ndarray (n,)
        Index of each image point's object point.
    point_info : numpy.ndarray (p, 3, 3)
        Prior information of each object point (zeros for tie points).

    Returns
    -------
    float
    """
    per_obs, per_point = point_trace_shares(loss, scale, e, P, obs_point, point_info)
    return float(np.sum(per_obs) + np.sum(per_point))


def point_trace_shares(
    loss: str, scale: float, e, P, obs_point, point_info
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`point_trace_correction` split by observation: per image point ``tr(H^-1 P_i'
    D_i^2 P_i)`` and per object point ``tr(H^-1 N_p)`` (its prior), each with ``d_i I``
    minus with ``D_i``; zero for points whose ``H`` is not positive definite.

    Returns
    -------
    (per_observation, per_point) : numpy.ndarray (n,), numpy.ndarray (p,)
        Redundancy to add to each image point and to each object point's prior.
    """
    D = score_derivatives(loss, scale, e)
    d = 0.5 * np.einsum("nii->n", D)
    PtP = np.einsum("nai,naj->nij", P, P)
    pinfo = np.asarray(point_info, dtype=float)
    per_obs = np.zeros(d.shape)
    per_point = np.zeros(pinfo.shape[0])
    terms = []
    for Dn, D2n in (
        (d[:, None, None] * PtP, (d * d)[:, None, None] * PtP),
        (
            np.einsum("nai,nab,nbj->nij", P, D, P),
            np.einsum("nai,nab,nbc,ncj->nij", P, D, D, P),
        ),
    ):
        H = pinfo.copy()
        np.add.at(H, obs_point, Dn)
        terms.append((H, D2n))
    (Hi, Bi), (He, Be) = terms
    tiny = 1e-12 * np.maximum(np.einsum("pii->p", He), 1e-300)[:, None]
    ok = np.all(np.linalg.eigvalsh(He) > tiny, axis=1) & (np.linalg.det(Hi) > 0)
    Ii = np.zeros(Hi.shape)
    Ie = np.zeros(He.shape)
    Ii[ok] = np.linalg.inv(Hi[ok])
    Ie[ok] = np.linalg.inv(He[ok])
    per_obs = np.einsum("nij,nji->n", Ii[obs_point], Bi) - np.einsum(
        "nij,nji->n", Ie[obs_point], Be
    )
    per_point = np.einsum("pij,pji->p", Ii - Ie, pinfo)
    return per_obs, per_point
