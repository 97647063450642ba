"""Stereo intersection: ground points from their positions in two or more RPC images.

For each point the unknowns are ``(lon, lat, h)``; the observations are its image positions
``(col, row)`` in every image that sees it (``2 K`` observations in ``K`` images, redundancy
``2 K - 3``). The nonlinear Gauss-Markov model ``col_obs + v = RPC_k(lon, lat, h)`` is solved by
Gauss-Newton, vectorised over points (each point is an independent 3-unknown adjustment;
the statistics follow :mod:`photogeom.adjust`: residuals computed minus observed, weights
``1 / sigma^2``, cofactor ``(J^T P J)^-1``, ``sigma0 = sqrt(v^T P v / r)``).

Start: the point is localised in its first image at the mean height offset of the models.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConvergenceError, DegenerateGeometryError, InputError, TooFewPointsError
from ..records import ReadOnlyRecord
from ..validation import as_float64
from .domain import LocalizationWarning, wrap_longitude
from .geodesy import metres_per_degree
from .model import RPC

#: Largest accepted condition number of a point's normal matrix (columns scaled to about a
#: metre each): beyond it the rays are (nearly) parallel and the height is not determined.
#: A base-to-height ratio b gives a condition of about 1 / b^2, so this limit is b ~ 1e-6.
COND_LIMIT = 1e12



@dataclass(frozen=True, eq=False)
class RPCIntersection(ReadOnlyRecord):
    """Ground points intersected from several RPC images, with their statistics.

    Attributes
    ----------
    ground : numpy.ndarray, shape (n, 3)
        lon (deg), lat (deg), h (m); NaN where the iteration failed.
    cofactor : numpy.ndarray, shape (n, 3, 3)
        ``(J^T P J)^-1`` in (deg, deg, m) units; with weights ``1/sigma^2`` it is the a-priori
        covariance.
    sigma0 : numpy.ndarray, shape (n,)
        A-posteriori standard deviation of unit weight (NaN when the redundancy is 0).
    redundancy : numpy.ndarray of int, shape (n,)
        ``2 * (images seeing the point) - 3``.
    residuals : numpy.ndarray, shape (n, K, 2)
        Computed minus observed (px); NaN for images that do not see the point.
    converged : numpy.ndarray of bool, shape (n,)
    iterations : numpy.ndarray of int, shape (n,)
    degenerate : numpy.ndarray of bool, shape (n,)
        Points whose rays are (nearly) parallel (condition of the normal matrix above
        :data:`COND_LIMIT`, e.g. the same image twice): no position, not converged.
    """

    ground: np.ndarray
    cofactor: np.ndarray
    sigma0: np.ndarray
    redundancy: np.ndarray
    residuals: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    degenerate: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.degenerate is None:
            object.__setattr__(self, "degenerate", np.zeros(len(self.ground), dtype=bool))
        super().__post_init__()  # read-only views of the arrays

    @property
    def lon(self) -> np.ndarray:
        return self.ground[:, 0]

    @property
    def lat(self) -> np.ndarray:
        return self.ground[:, 1]

    @property
    def h(self) -> np.ndarray:
        return self.ground[:, 2]

    @property
    def covariance_prior(self) -> np.ndarray:
        """A-priori covariance (n, 3, 3) (deg^2, deg^2, m^2 and mixed): the cofactor."""
        return self.cofactor

    @property
    def covariance(self) -> np.ndarray:
        """A-posteriori covariance ``sigma0^2 Q`` (NaN where the redundancy is 0)."""
        return self.sigma0[:, None, None] ** 2 * self.cofactor

    @property
    def std_prior(self) -> np.ndarray:
        """A-priori standard deviations (n, 3): lon (deg), lat (deg), h (m)."""
        return np.sqrt(np.clip(np.diagonal(self.cofactor, axis1=1, axis2=2), 0, None))

    @property
    def std(self) -> np.ndarray:
        """A-posteriori standard deviations (n, 3): lon (deg), lat (deg), h (m)."""
        return self.sigma0[:, None] * self.std_prior

    def std_metric(self, prior: bool = True) -> np.ndarray:
        """Standard deviations in metres: east, north, up (WGS84 radii of curvature).

        Parameters
        ----------
        prior : bool, default True
            From the a-priori cofactor (``std_prior``); False scales by ``sigma0`` (``std``).

        Returns
        -------
        numpy.ndarray, shape (n, 3)
            East, north, up in m.
        """
        s = self.std_prior if prior else self.std
        east, north = metres_per_degree(self.ground[:, 1], self.ground[:, 2])
        return np.column_stack([s[:, 0] * east, s[:, 1] * north, s[:, 2]])

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN -> None).

        Returns
        -------
        dict
            ``ground`` (lon deg, lat deg, h m), ``std_prior``, ``std_prior_metric_enu_m``,
            ``sigma0``, ``redundancy``, ``converged``, ``degenerate`` per point, with the units
            and the residual convention.
        """

        def clean(a):
            a = np.asarray(a, dtype=float)
            return (
                [None if not np.isfinite(x) else float(x) for x in a.reshape(-1)]
                if a.ndim <= 1
                else [clean(row) for row in a]
            )

        return {
            "ground_units": ["deg", "deg", "m"],
            "ground": clean(self.ground),
            "std_prior": clean(self.std_prior),
            "std_prior_metric_enu_m": clean(self.std_metric(prior=True)),
            "sigma0": clean(self.sigma0),
            "redundancy": [int(r) for r in self.redundancy],
            "residual_convention": "computed minus observed (px)",
            "converged": [bool(c) for c in self.converged],
            "degenerate": [bool(d) for d in self.degenerate],
        }


def intersect_rpc(
    rpcs: Sequence[RPC],
    image_points,
    *,
    sigma=1.0,
    h0: float | None = None,
    max_iter: int = 20,
    tol: float = 1e-8,
    on_failure: str = "nan",
) -> RPCIntersection:
    """Least-squares ground points from image points in two or more RPC images.

    Parameters
    ----------
    rpcs : sequence of RPC
        The K image models.
    image_points : array_like, shape (n, K, 2)
        ``(col, row)`` (px) of each point in each image; NaN where an image does not see it
        (every point needs at least two images). A list of K arrays (n, 2) works too.
    sigma : float or array_like
        Standard deviation of the image measurements (px): one number, one per image (K,),
        or (n, K) (any value, e.g. NaN, where an image does not see the point).
    h0 : float, optional
        Starting height (m); default the mean ``HEIGHT_OFF`` of the models.
    max_iter : int
        Gauss-Newton iterations.
    tol : float
        Convergence: the last step moves every image projection by at most ``tol`` px.
    on_failure : {"nan", "raise"}
        Non-converged points: NaN with a warning, or :class:`ConvergenceError`; points whose
        rays are (nearly) parallel (``degenerate``): NaN with a warning, or
        :class:`DegenerateGeometryError`.

    Returns
    -------
    RPCIntersection
    """
    rpcs = list(rpcs)
    K = len(rpcs)
    if K < 2:
        raise TooFewPointsError("RPC intersection", K, 2, "images (RPC models) per point")
    if on_failure not in ("nan", "raise"):
        raise InputError(f"on_failure must be 'nan' or 'raise', got {on_failure!r}")
    if isinstance(image_points, np.ma.MaskedArray) and np.ma.getmaskarray(image_points).any():
        raise InputError(
            "image_points: masked array with masked values; give NaN where an image does not "
            "see a point (e.g. image_points.filled(np.nan)) - masked values are not dropped "
            "silently"
        )
    if (
        isinstance(image_points, (list, tuple))
        and len(image_points) == K
        and all(np.ndim(p) == 2 for p in image_points)
    ):
        obs = np.stack([as_float64(p, "image_points") for p in image_points], axis=1)
    else:
        obs = as_float64(image_points, "image_points")
    if obs.ndim == 2 and obs.shape == (K, 2):
        obs = obs[None]
    if obs.ndim != 3 or obs.shape[1:] != (K, 2):
        raise InputError(
            f"image_points: expected shape (n, {K}, 2) for {K} images, got {obs.shape}"
        )
    n = obs.shape[0]
    seen = np.all(np.isfinite(obs), axis=2)  # (n, K)
    if np.any(np.isinf(obs)):
        raise InputError("image_points: infinite values (use NaN for 'not seen in this image')")
    n_seen = seen.sum(axis=1)
    if np.any(n_seen < 2):
        bad = np.flatnonzero(n_seen < 2)
        raise TooFewPointsError(
            f"RPC intersection of point(s) {', '.join(str(int(i)) for i in bad[:10])}",
            int(n_seen[bad[0]]), 2, "images per point (NaN marks an image that does not see it)",
        )  # fmt: skip
    s = np.asarray(sigma, dtype=np.float64)
    if s.ndim == 0:
        s = np.full((n, K), float(s))
    elif s.shape == (K,):
        s = np.broadcast_to(s, (n, K)).copy()
    elif s.shape != (n, K):
        raise InputError(f"sigma: expected a number, ({K},) or ({n}, {K}) values, got {s.shape}")
    bad_s = seen & ~(np.isfinite(s) & (s > 0))  # only observations that exist need one
    if bad_s.any():
        i, k = (int(a[0]) for a in np.nonzero(bad_s))
        raise InputError(
            f"sigma: standard deviations must be positive numbers of pixels (point {i}, image "
            f"{k}: {s[i, k]!r}); NaN is accepted only where the image does not see the point"
        )
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(seen, 1.0 / s**2, 0.0)  # (n, K)
    obs0 = np.where(seen[..., None], obs, 0.0)

    # start: localise in the first image that sees the point
    z0 = float(np.mean([r.height_off for r in rpcs])) if h0 is None else float(h0)
    X = np.full((n, 3), np.nan)
    X[:, 2] = z0
    first = np.argmax(seen, axis=1)
    for k in range(K):  # loop over images, not points
        idx = np.flatnonzero(first == k)
        if idx.size:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LocalizationWarning)
                lon, lat = rpcs[k].localize(obs[idx, k, 0], obs[idx, k, 1], z0, domain_limit=None)
            X[idx, 0], X[idx, 1] = lon, lat
    converged = np.zeros(n, dtype=bool)
    degenerate = np.zeros(n, dtype=bool)
    iterations = np.zeros(n, dtype=np.int32)
    active = np.flatnonzero(np.all(np.isfinite(X), axis=1))
    scale = np.array([1e-5, 1e-5, 1.0])  # column scaling: degrees vs metres
    for it in range(max_iter):
        if active.size == 0:
            break
        m = active.size
        F = np.empty((m, K, 2))
        J = np.empty((m, K, 2, 3))
        for k, rpc in enumerate(rpcs):
            c, r, Jk = rpc._jacobian_flat(X[active, 0], X[active, 1], X[active, 2])
            F[:, k, 0], F[:, k, 1], J[:, k] = c, r, Jk
        v = F - obs0[active]  # computed - observed
        Wa = w[active]
        Js = J * scale  # scaled columns
        N = np.einsum("mk,mkci,mkcj->mij", Wa, Js, Js)
        b = -np.einsum("mk,mkci,mkc->mi", Wa, Js, v)
        ok = np.all(np.isfinite(N), axis=(1, 2)) & np.all(np.isfinite(b), axis=1)
        if it == 0:  # the geometry of the rays: checked once, at the start
            bad = np.zeros(m, dtype=bool)
            bad[ok] = _ill_conditioned(N[ok])
            degenerate[active[bad]] = True
            ok &= ~bad
        dx = np.full((m, 3), np.nan)
        if ok.any():
            try:
                dx[ok] = np.linalg.solve(N[ok], b[ok][..., None])[..., 0]
            except np.linalg.LinAlgError:
                for i in np.flatnonzero(ok):  # rare singular systems, one at a time
                    try:
                        dx[i] = np.linalg.solve(N[i], b[i])
                    except np.linalg.LinAlgError:
                        dx[i] = np.nan
        step_px = np.max(
            np.abs(np.einsum("mkci,mi->mkc", Js, np.nan_to_num(dx))) * seen[active][..., None],
            axis=(1, 2),
        )
        X[active] = X[active] + dx * scale
        iterations[active] += 1
        good = np.all(np.isfinite(dx), axis=1)
        done = good & (step_px <= tol)
        converged[active[done]] = True
        failed = active[~good]
        X[failed] = np.nan
        active = active[good & ~done]
    # statistics at the solution (the rays checked again there)
    okp = np.flatnonzero(converged)
    cof = np.full((n, 3, 3), np.nan)
    s0 = np.full(n, np.nan)
    res = np.full((n, K, 2), np.nan)
    if okp.size:
        F = np.empty((okp.size, K, 2))
        J = np.empty((okp.size, K, 2, 3))
        for k, rpc in enumerate(rpcs):
            c, r, Jk = rpc._jacobian_flat(X[okp, 0], X[okp, 1], X[okp, 2])
            F[:, k, 0], F[:, k, 1], J[:, k] = c, r, Jk
        v = F - obs0[okp]
        Wa = w[okp]
        Js = J * scale
        N = np.einsum("mk,mkci,mkcj->mij", Wa, Js, Js)
        bad = _ill_conditioned(N)
        if bad.any():
            degenerate[okp[bad]] = True
            converged[okp[bad]] = False
            okp, N, v, Wa = okp[~bad], N[~bad], v[~bad], Wa[~bad]
        Q = np.linalg.inv(N) * np.outer(scale, scale)
        cof[okp] = Q
        vtpv = np.einsum("mk,mkc->m", Wa, v**2)
        r_ = 2 * n_seen[okp] - 3
        with np.errstate(invalid="ignore", divide="ignore"):
            s0[okp] = np.where(r_ > 0, np.sqrt(vtpv / np.maximum(r_, 1)), np.nan)
        res[okp] = np.where(seen[okp][..., None], v, np.nan)
    X[~converged] = np.nan
    X[:, 0] = wrap_longitude(X[:, 0])  # a step may have crossed the antimeridian
    result = RPCIntersection(
        ground=X,
        cofactor=cof,
        sigma0=s0,
        redundancy=2 * n_seen - 3,
        residuals=res,
        converged=converged,
        iterations=iterations,
        degenerate=degenerate,
    )
    n_degenerate = int(np.count_nonzero(degenerate))
    if n_degenerate:
        ids = ", ".join(str(int(i)) for i in np.flatnonzero(degenerate)[:10])
        msg = (
            f"RPC intersection: the rays of {n_degenerate} of {n} point(s) (point(s) {ids}"
            f"{', ...' if n_degenerate > 10 else ''}) are parallel or nearly so (condition of "
            f"the normal equations above {COND_LIMIT:.0e}): their heights are not determined "
            "and their ground coordinates are NaN. Use images taken from different directions "
            "(not the same image or model twice)"
        )
        if on_failure == "raise":
            raise DegenerateGeometryError(msg)
        warnings.warn(msg, LocalizationWarning, stacklevel=2)
    bad = int(np.count_nonzero(~converged & ~degenerate))
    if bad:
        msg = (
            f"RPC intersection: {bad} of {n} point(s) did not converge in {max_iter} "
            "iteration(s); their ground coordinates are NaN (check the image points and that "
            "the images overlap)"
        )
        if on_failure == "raise":
            raise ConvergenceError(msg, iterations=int(iterations.max()), result=result)
        warnings.warn(msg, LocalizationWarning, stacklevel=2)
    return result


def _ill_conditioned(N: np.ndarray) -> np.ndarray:
    """Points (m,) whose normal matrices N (m, 3, 3), symmetric, have a condition number
    above :data:`COND_LIMIT` (or are not positive definite)."""
    out = np.zeros(N.shape[0], dtype=bool)
    if N.shape[0] == 0:
        return out
    # cheap screen: with eigenvalues l1 <= l2 <= l3, l1 = det / (l2 l3) >= det / (tr / 2)^2
    # and l3 <= tr, so cond <= tr^3 / (4 det); the exact test only where that bound is high
    tr = np.einsum("mii->m", N)
    det = (
        N[:, 0, 0] * (N[:, 1, 1] * N[:, 2, 2] - N[:, 1, 2] * N[:, 2, 1])
        - N[:, 0, 1] * (N[:, 1, 0] * N[:, 2, 2] - N[:, 1, 2] * N[:, 2, 0])
        + N[:, 0, 2] * (N[:, 1, 0] * N[:, 2, 1] - N[:, 1, 1] * N[:, 2, 0])
    )
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        maybe = ~(4.0 * det * COND_LIMIT > tr**3)
    idx = np.flatnonzero(maybe)
    if idx.size:
        ev = np.linalg.eigvalsh(N[idx])  # ascending
        with np.errstate(invalid="ignore"):
            out[idx] = ~(ev[:, 0] * COND_LIMIT > ev[:, -1])
    return out
