"""Localisation: the ground point (lon, lat) of an image point at a given height.

The RPC gives ``(col, row)`` as a function of ``(lon, lat, h)``; localisation inverts it for
``(lon, lat)`` at a known ``h``. The method, vectorised over points:

1. **Approximate inverse** (built once per model and cached): a grid of image points over the
   normalised image domain at several normalised heights is solved by *continuation* from the
   image centre (the target moves from the centre to each grid point in small steps, each
   solved by Newton from the previous solution), then a cubic polynomial
   ``(col_n, row_n, h_n) -> (L, P)`` is fitted to the solutions by least squares. It gives
   each point a start close to its solution.
2. **Newton iteration** on the exact projection in normalised coordinates, with the analytic
   2x2 Jacobian and step halving whenever a step does not reduce the image residual.
3. Points that do not converge from the approximate inverse are solved again by continuation
   from the image centre (robust far outside the image or where the RPC bends strongly).

Per-point status: :attr:`LocalizationStatus.CONVERGED` (the projection of the result matches
the image point within ``tol`` pixels), :attr:`~LocalizationStatus.LIMIT_REACHED` (iteration
limit reached, or no step reduces the residual any more, while above ``tol``),
:attr:`~LocalizationStatus.DIVERGED` (non-finite values, a singular Jacobian, or the estimate
leaving the region of normalised coordinates ``|L|, |P| <= 100``). Non-converged points get NaN.
"""

from __future__ import annotations

import enum
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..records import ReadOnlyRecord
from . import polynomial as poly
from .domain import DOMAIN_LIMIT, LocalizationWarning, check_domain, wrap_longitude

if TYPE_CHECKING:  # pragma: no cover
    from .model import RPC

#: Normalised ground coordinates beyond which an iterate counts as diverged.
DIVERGENCE_BOUND = 100.0
#: Step halvings tried before a point counts as stalled.
MAX_HALVINGS = 12
#: Steps of the continuation from the image centre.
CONTINUATION_STEPS = 16
#: Grid of the approximate inverse: points per image axis and heights.
INVERSE_GRID = (11, 11, 7)


class LocalizationStatus(enum.IntEnum):
    """Outcome of localising one point."""

    CONVERGED = 0
    LIMIT_REACHED = 1
    DIVERGED = 2


@dataclass(frozen=True, eq=False)
class LocalizationResult(ReadOnlyRecord):
    """Localisation of a set of image points.

    Attributes
    ----------
    lon, lat : numpy.ndarray
        Degrees; NaN where the point did not converge.
    status : numpy.ndarray of int
        :class:`LocalizationStatus` per point.
    iterations : numpy.ndarray of int
        Newton iterations spent per point (all stages).
    residual : numpy.ndarray
        Largest image residual (pixels) of the returned point (NaN where diverged).
    tol : float
        Tolerance used (pixels).
    """

    lon: np.ndarray
    lat: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    tol: float

    @property
    def converged(self) -> np.ndarray:
        """Boolean mask of converged points."""
        return self.status == LocalizationStatus.CONVERGED

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))

    def counts(self) -> dict[str, int]:
        """Number of points per status.

        Returns
        -------
        dict of str to int
            Lower-case :class:`LocalizationStatus` name -> count (every status present, 0 too).
        """
        return {s.name.lower(): int(np.count_nonzero(self.status == s)) for s in LocalizationStatus}


# --- evaluation in normalised coordinates ----------------------------------------------------


def _image_and_jacobian(C: np.ndarray, L, P, H):
    """Normalised image coordinates (s, l) and d(s, l)/d(L, P) (four arrays)."""
    V, dV = poly.evaluate_with_derivatives(C, L, P, H, wrt="LP")
    s = V[0] / V[1]
    li = V[2] / V[3]
    dL, dP = dV["L"], dV["P"]
    s_L = (dL[0] - s * dL[1]) / V[1]
    s_P = (dP[0] - s * dP[1]) / V[1]
    l_L = (dL[2] - li * dL[3]) / V[3]
    l_P = (dP[2] - li * dP[3]) / V[3]
    return s, li, s_L, s_P, l_L, l_P


def newton(
    C: np.ndarray,
    scales: tuple[float, float],
    sn: np.ndarray,
    ln: np.ndarray,
    hn: np.ndarray,
    L0: np.ndarray,
    P0: np.ndarray,
    tol: float,
    max_iter: int,
):
    """Vectorised damped Newton iteration for ``image(L, P, hn) = (sn, ln)``.

    Parameters
    ----------
    C : numpy.ndarray, shape (4, 20)
        samp_num, samp_den, line_num, line_den.
    scales : (float, float)
        SAMP_SCALE, LINE_SCALE: converts normalised residuals to pixels.
    sn, ln, hn : numpy.ndarray, shape (n,)
        Normalised image targets and heights.
    L0, P0 : numpy.ndarray, shape (n,)
        Starting values (normalised ground).
    tol : float
        Pixels.
    max_iter : int

    Returns
    -------
    L, P, status, iterations, residual_px
    """
    n = sn.size
    ss, sl = abs(scales[0]), abs(scales[1])
    L = L0.astype(np.float64, copy=True)
    P = P0.astype(np.float64, copy=True)
    status = np.full(n, LocalizationStatus.LIMIT_REACHED, dtype=np.int8)
    iterations = np.zeros(n, dtype=np.int32)
    with np.errstate(all="ignore"):
        s, li, sL, sP, lL, lP = _image_and_jacobian(C, L, P, hn)
        rs, rl = s - sn, li - ln
        res = np.maximum(np.abs(rs) * ss, np.abs(rl) * sl)
        active = np.arange(n)
        for it in range(max_iter + 1):
            r_a = res[active]
            bad = ~np.isfinite(r_a)
            status[active[bad]] = LocalizationStatus.DIVERGED
            conv = r_a <= tol
            status[active[conv]] = LocalizationStatus.CONVERGED
            active = active[~bad & ~conv]
            if active.size == 0 or it == max_iter:
                break
            a, b, c, d = sL[active], sP[active], lL[active], lP[active]
            det = a * d - b * c
            singular = ~(np.abs(det) > 1e-14 * (np.abs(a * d) + np.abs(b * c)))
            status[active[singular]] = LocalizationStatus.DIVERGED
            keep = ~singular
            active, a, b, c, d, det = active[keep], a[keep], b[keep], c[keep], d[keep], det[keep]
            e, f = rs[active], rl[active]
            dLs = (d * e - b * f) / det
            dPs = (a * f - c * e) / det
            iterations[active] += 1
            # damped step: halve until the residual decreases (or the tolerance is met)
            cur = np.arange(active.size)
            t = np.ones(active.size)
            for _ in range(MAX_HALVINGS):
                idx = active[cur]
                Lt = L[idx] - t[cur] * dLs[cur]
                Pt = P[idx] - t[cur] * dPs[cur]
                s_t, l_t, sL_t, sP_t, lL_t, lP_t = _image_and_jacobian(C, Lt, Pt, hn[idx])
                rs_t, rl_t = s_t - sn[idx], l_t - ln[idx]
                res_t = np.maximum(np.abs(rs_t) * ss, np.abs(rl_t) * sl)
                ok = np.isfinite(res_t) & ((res_t < res[idx]) | (res_t <= tol))
                j = idx[ok]
                L[j], P[j] = Lt[ok], Pt[ok]
                s[j], li[j], rs[j], rl[j], res[j] = s_t[ok], l_t[ok], rs_t[ok], rl_t[ok], res_t[ok]
                sL[j], sP[j], lL[j], lP[j] = sL_t[ok], sP_t[ok], lL_t[ok], lP_t[ok]
                cur = cur[~ok]
                if cur.size == 0:
                    break
                t[cur] *= 0.5
            stalled = active[cur]  # no step reduced the residual: stays LIMIT_REACHED
            far = (np.abs(L[active]) > DIVERGENCE_BOUND) | (np.abs(P[active]) > DIVERGENCE_BOUND)
            status[active[far]] = LocalizationStatus.DIVERGED
            drop = np.zeros(n, dtype=bool)
            drop[stalled] = True
            drop[active[far]] = True
            active = active[~drop[active]]
    res[status == LocalizationStatus.DIVERGED] = np.nan
    return L, P, status, iterations, res


def _continuation(C, scales, sn, ln, hn, start, tol, max_iter, steps=CONTINUATION_STEPS):
    """Solve by moving the target from a solved start point to ``(sn, ln, hn)`` in steps.

    ``start`` = (s0, l0, h0, L0, P0): a solved point (normalised image, height, ground).
    """
    s0, l0, h0, L0, P0 = start
    n = sn.size
    L = np.full(n, L0, dtype=np.float64)
    P = np.full(n, P0, dtype=np.float64)
    iters = np.zeros(n, dtype=np.int32)
    ok = np.ones(n, dtype=bool)
    failed = np.full(n, LocalizationStatus.DIVERGED, dtype=np.int8)
    coarse = max(tol, 1e-3)
    for k in range(1, steps + 1):
        w = k / steps
        st = s0 + w * (sn - s0)
        lt = l0 + w * (ln - l0)
        ht = h0 + w * (hn - h0)
        last = k == steps
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            break
        Ln, Pn, status, it, res = newton(
            C, scales, st[idx], lt[idx], ht[idx], L[idx], P[idx],
            tol if last else coarse, max_iter,
        )  # fmt: skip
        iters[idx] += it
        good = status == LocalizationStatus.CONVERGED
        L[idx[good]], P[idx[good]] = Ln[good], Pn[good]
        ok[idx[~good]] = False
        failed[idx[~good]] = status[~good]
        if last:
            final_status = failed.copy()
            final_res = np.full(n, np.nan)
            final_status[idx] = status
            final_res[idx] = res
            L[idx[~good]], P[idx[~good]] = Ln[~good], Pn[~good]
            return L, P, final_status, iters, final_res
    return L, P, failed, iters, np.full(n, np.nan)


# --- the approximate inverse ----------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ApproximateInverse(ReadOnlyRecord):
    """Cubic polynomials ``(col_n, row_n, h_n) -> (L, P)`` and the centre solution.

    Cached on its RPC (:func:`approximate_inverse`) and shared by every later localisation,
    so its coefficients are read-only.

    Attributes
    ----------
    coefficients : numpy.ndarray, shape (2, 20)
        For L and P (RPC00B term order, col_n in the place of L, row_n of P).
    centre : tuple
        ``(s0, l0, h0, L0, P0)``: a solved point near the image centre.
    max_error_px : float
        Largest image error (pixels) of the polynomial's ground points on the fitting grid.
    n_points : int
        Grid points used in the fit.
    """

    coefficients: np.ndarray
    centre: tuple
    max_error_px: float
    n_points: int

    def __call__(self, sn, ln, hn):
        V = poly.evaluate(self.coefficients, sn, ln, hn)
        return V[0], V[1]


def _image_domain(rpc: RPC) -> tuple[float, float, float, float]:
    """Normalised image domain (s_min, s_max, l_min, l_max) of the inverse grid."""
    c0, c1, r0, r1 = rpc.image_bounds
    s = sorted(((c0 - rpc.samp_off) / rpc.samp_scale, (c1 - rpc.samp_off) / rpc.samp_scale))
    li = sorted(((r0 - rpc.line_off) / rpc.line_scale, (r1 - rpc.line_off) / rpc.line_scale))
    return s[0], s[1], li[0], li[1]


def approximate_inverse(rpc: RPC) -> ApproximateInverse:
    """The (cached) approximate inverse of ``rpc``'s projection (uncorrected model).

    Parameters
    ----------
    rpc : RPC
        The model; the result is cached on it.

    Returns
    -------
    ApproximateInverse
        Cubic polynomials ``(col_n, row_n, h_n) -> (L, P)`` and a solved centre point.

    Raises
    ------
    DegenerateGeometryError
        When the projection is undefined at the ground offsets or no centre solution is
        found (the coefficients are probably wrong).
    """
    cached = rpc._cache.get("inverse")
    if cached is not None:
        return cached
    C = rpc.coefficients
    scales = (rpc.samp_scale, rpc.line_scale)
    s_min, s_max, l_min, l_max = _image_domain(rpc)
    sc, lc = 0.5 * (s_min + s_max), 0.5 * (l_min + l_max)
    # centre: Newton from the ground offsets, then by continuation from the ground offsets'
    # own image position if that fails
    L0 = np.zeros(1)
    one = np.ones(1)
    Lc, Pc, st, _, _ = newton(C, scales, sc * one, lc * one, 0 * one, L0, L0, 1e-9, 50)
    if st[0] != LocalizationStatus.CONVERGED:
        with np.errstate(all="ignore"):
            V = poly.evaluate(C, L0, L0, L0)
        s00, l00 = float(V[0, 0] / V[1, 0]), float(V[2, 0] / V[3, 0])
        if not (np.isfinite(s00) and np.isfinite(l00)):
            raise DegenerateGeometryError(
                "RPC: the projection is undefined at the ground offsets (a denominator is "
                "zero); the coefficients are probably wrong"
            )
        Lc, Pc, st, _, _ = _continuation(
            C, scales, sc * one, lc * one, 0 * one, (s00, l00, 0.0, 0.0, 0.0), 1e-9, 50, steps=64
        )
        if st[0] != LocalizationStatus.CONVERGED:
            raise DegenerateGeometryError(
                "RPC: cannot find the ground point of the image centre at HEIGHT_OFF; the "
                "model cannot be inverted (check the coefficients)"
            )
    centre = (sc, lc, 0.0, float(Lc[0]), float(Pc[0]))
    ns, nl, nh = INVERSE_GRID
    S, Lg, Hg = np.meshgrid(
        np.linspace(s_min, s_max, ns), np.linspace(l_min, l_max, nl), np.linspace(-1, 1, nh),
        indexing="ij",
    )  # fmt: skip
    S, Lg, Hg = S.ravel(), Lg.ravel(), Hg.ravel()
    Lsol, Psol, status, _, _ = _continuation(C, scales, S, Lg, Hg, centre, 1e-6, 30)
    good = status == LocalizationStatus.CONVERGED
    if np.count_nonzero(good) < 2 * poly.N_TERMS:
        raise DegenerateGeometryError(
            f"RPC: only {np.count_nonzero(good)} of {S.size} grid points over the image could be "
            "localised; the model cannot be inverted over its domain (check the coefficients)"
        )
    T = poly.terms(S[good], Lg[good], Hg[good])
    scale_cols = np.linalg.norm(T, axis=0)
    coef, *_ = np.linalg.lstsq(
        T / scale_cols, np.column_stack([Lsol[good], Psol[good]]), rcond=None
    )
    coef = (coef / scale_cols[:, None]).T
    inv = ApproximateInverse(coef, centre, 0.0, int(np.count_nonzero(good)))
    Li, Pi = inv(S[good], Lg[good], Hg[good])
    with np.errstate(all="ignore"):
        V = poly.evaluate(C, Li, Pi, Hg[good])
    err = np.maximum(
        np.abs(V[0] / V[1] - S[good]) * abs(rpc.samp_scale),
        np.abs(V[2] / V[3] - Lg[good]) * abs(rpc.line_scale),
    )
    inv = ApproximateInverse(coef, centre, float(np.nanmax(err)), inv.n_points)
    rpc._cache["inverse"] = inv
    return inv


# --- public entry point ----------------------------------------------------------------------


def localize(
    rpc: RPC,
    col,
    row,
    h,
    *,
    tol: float = 1e-6,
    max_iter: int = 20,
    on_failure: str = "nan",
    full_output: bool = False,
    domain_limit: float | None = DOMAIN_LIMIT,
):
    """Localise image points at heights; see :meth:`photogeom.rpc.RPC.localize`."""
    from .model import _prepare, _shaped

    if on_failure not in ("nan", "raise"):
        raise InputError(f"on_failure must be 'nan' or 'raise', got {on_failure!r}")
    if not (tol > 0 and np.isfinite(tol)):
        raise InputError(f"tol must be a positive number of pixels, got {tol!r}")
    if int(max_iter) < 1:
        raise InputError(f"max_iter must be at least 1, got {max_iter!r}")
    max_iter = int(max_iter)
    col, row, h, shape = _prepare(("col", col), ("row", row), ("h", h), what="RPC localisation")
    if rpc.correction is not None:
        col, row = rpc._undo_correction(col, row)
    sn = (col - rpc.samp_off) / rpc.samp_scale
    ln = (row - rpc.line_off) / rpc.line_scale
    hn = (h - rpc.height_off) / rpc.height_scale
    check_domain({"column": sn, "row": ln, "height": hn}, domain_limit, "RPC localisation")
    C = rpc.coefficients
    scales = (rpc.samp_scale, rpc.line_scale)
    inv = approximate_inverse(rpc)
    L0, P0 = inv(sn, ln, hn)
    L, P, status, iters, res = newton(C, scales, sn, ln, hn, L0, P0, tol, max_iter)
    retry = np.flatnonzero(status != LocalizationStatus.CONVERGED)
    if retry.size:
        L2, P2, st2, it2, res2 = _continuation(
            C, scales, sn[retry], ln[retry], hn[retry], inv.centre, tol, max_iter
        )
        iters[retry] += it2
        L[retry], P[retry], status[retry], res[retry] = L2, P2, st2, res2
    ok = status == LocalizationStatus.CONVERGED
    lon = np.where(ok, wrap_longitude(L * rpc.long_scale + rpc.long_off), np.nan)
    lat = np.where(ok, P * rpc.lat_scale + rpc.lat_off, np.nan)
    result = LocalizationResult(
        lon=_shaped(lon, shape),
        lat=_shaped(lat, shape),
        status=_shaped(status.astype(np.int8), shape),
        iterations=_shaped(iters, shape),
        residual=_shaped(res, shape),
        tol=float(tol),
    )
    n_bad = int(np.count_nonzero(~ok))
    if n_bad:
        counts = result.counts()
        msg = (
            f"RPC localisation: {n_bad} of {ok.size} point(s) did not converge to {tol:g} px "
            f"({counts['limit_reached']} reached the limit of {max_iter} iterations or stalled, "
            f"{counts['diverged']} diverged); their lon/lat are NaN. Check that the points lie "
            "in the image and the heights in the model's range, or raise max_iter / tol"
        )
        if on_failure == "raise":
            raise ConvergenceError(msg, iterations=int(iters.max()), result=result)
        if not full_output:
            warnings.warn(msg, LocalizationWarning, stacklevel=3)
    if full_output:
        return result
    return result.lon, result.lat
