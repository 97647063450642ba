"""Brown lens distortion as Agisoft Metashape defines it (radial K1-K4, tangential P1, P2).

The terms act on *normalised camera coordinates in Metashape's axes* (x right, y down,
z forward): ``x = X / Z``, ``y = Y / Z``, ``r^2 = x^2 + y^2`` and

    x' = x (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + P1 (r^2 + 2 x^2) + 2 P2 x y
    y' = y (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + P2 (r^2 + 2 y^2) + 2 P1 x y

All coefficients are dimensionless. The affinity and shear terms B1, B2 of Metashape act on
pixel coordinates and live in :class:`~photogeom.camera.interior.InteriorOrientation`
(``b1``, ``b2``) and :class:`~photogeom.camera.metashape.MetashapeCalibration`.

The inverse (:meth:`BrownDistortion.undistort`) is a vectorised Newton iteration with an
analytic 2x2 Jacobian; it returns a per-point status instead of silently wrong values.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError
from ..records import ReadOnlyRecord
from ..validation import as_finite_scalar, as_points, as_points_single, one_or_many

#: Status codes of :class:`UndistortResult`.
STATUS_CONVERGED = 0
STATUS_MAX_ITER = 1
STATUS_SINGULAR = 2
STATUS_FOLDED = 3
STATUS_TEXT = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "iteration limit reached before the tolerance was met",
    STATUS_SINGULAR: "singular Jacobian (distortion model folds over here) or non-finite values",
    STATUS_FOLDED: "solution on a branch where the distortion is not one-to-one (fold-over)",
}

COEFFICIENTS = ("k1", "k2", "k3", "k4", "p1", "p2")

#: Points per block in the vectorised loops (keeps the temporaries in cache).
CHUNK = 1 << 14


@dataclass(frozen=True, eq=False)
class UndistortResult(ReadOnlyRecord):
    """Result of an iterative undistortion.

    Attributes
    ----------
    points : numpy.ndarray, shape (n, 2)
        Undistorted coordinates (same kind as the input: normalised, or pixels when returned
        by a camera's pixel method). Points that did not converge hold the last iterate.
    status : numpy.ndarray of int, shape (n,)
        0 converged; 1 iteration limit; 2 singular Jacobian / non-finite; 3 solution where
        the distortion is not one-to-one. See :data:`STATUS_TEXT`.
    iterations : int
        Newton iterations performed (for the slowest point).
    residual : numpy.ndarray, shape (n,)
        ``|distort(points) - observed|`` in the units of the tolerance.
    """

    points: np.ndarray
    status: np.ndarray
    iterations: int
    residual: np.ndarray

    @property
    def converged(self) -> np.ndarray:
        """Boolean mask of points with status 0."""
        return self.status == STATUS_CONVERGED

    @property
    def all_converged(self) -> bool:
        """True when every point converged."""
        return bool(np.all(self.status == STATUS_CONVERGED))

    def describe_failures(self, limit: int = 5) -> str:
        """One line naming the failed points and why (empty when all converged).

        Parameters
        ----------
        limit : int, default 5
            Failed points named at most; the others are counted.

        Returns
        -------
        str
        """
        bad = np.flatnonzero(self.status != STATUS_CONVERGED)
        if bad.size == 0:
            return ""
        parts = [f"{int(i)}: {STATUS_TEXT[int(self.status[i])]}" for i in bad[:limit]]
        more = f" (and {bad.size - limit} more)" if bad.size > limit else ""
        return f"{bad.size} point(s) not undistorted: " + "; ".join(parts) + more


@dataclass(frozen=True)
class BrownDistortion:
    """Radial (K1-K4) and tangential (P1, P2) distortion in Metashape's definition.

    Parameters
    ----------
    k1, k2, k3, k4 : float
        Radial coefficients of ``r^2, r^4, r^6, r^8`` (dimensionless; r in normalised units).
    p1, p2 : float
        Tangential (decentring) coefficients, Metashape's order (``P1`` multiplies
        ``r^2 + 2 x^2`` in x'). OpenCV's ``p1, p2`` are Metashape's ``P2, P1``.
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = as_finite_scalar(getattr(self, f.name), f"distortion coefficient {f.name}")
            object.__setattr__(self, f.name, v)

    # --- helpers ------------------------------------------------------------------------------

    @property
    def is_zero(self) -> bool:
        """True when every coefficient is zero (no distortion)."""
        return all(getattr(self, n) == 0.0 for n in COEFFICIENTS)

    def to_dict(self) -> dict:
        """Coefficients by name.

        Returns
        -------
        dict
            ``{"k1", "k2", "k3", "k4", "p1", "p2"}`` (unitless).
        """
        return {n: getattr(self, n) for n in COEFFICIENTS}

    @classmethod
    def from_dict(cls, data: dict) -> BrownDistortion:
        """Inverse of :meth:`to_dict` (missing coefficients are zero; unknown keys refused).

        Parameters
        ----------
        data : dict
            Coefficients by name.

        Returns
        -------
        BrownDistortion

        Raises
        ------
        InputError
            For an unknown key (the message lists the known ones).
        """
        unknown = set(data) - set(COEFFICIENTS)
        if unknown:
            raise InputError(
                f"unknown distortion coefficient(s) {', '.join(sorted(unknown))}; "
                f"known: {', '.join(COEFFICIENTS)}"
            )
        return cls(**{k: float(v) for k, v in data.items()})

    # --- forward ------------------------------------------------------------------------------

    def distort(self, xy) -> np.ndarray:
        """Apply the distortion to normalised coordinates (Metashape axes: x right, y down).

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Ideal normalised coordinates ``(X/Z, Y/Z)`` (dimensionless).

        Returns
        -------
        numpy.ndarray, shape like ``xy``
            Distorted normalised coordinates ``(x', y')``.

        Raises
        ------
        InputError
            When the last axis of ``xy`` is not of length 2.
        """
        a = np.asarray(xy, dtype=float)
        if a.ndim == 0 or a.shape[-1] != 2:
            raise InputError(
                f"normalised coordinates: expected an array of shape (n, 2) (or (2,) for one "
                f"point), got shape {a.shape}"
            )
        x, y = a[..., 0], a[..., 1]
        xd, yd = self._distort_xy(x, y)
        return np.stack([xd, yd], axis=-1)

    def _radial(self, r2: np.ndarray) -> np.ndarray:
        return 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * (self.k3 + r2 * self.k4)))

    def _distort_xy(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r2 = x * x + y * y
        rad = self._radial(r2)
        xy2 = 2.0 * x * y
        xd = x * rad + self.p1 * (r2 + 2.0 * x * x) + self.p2 * xy2
        yd = y * rad + self.p2 * (r2 + 2.0 * y * y) + self.p1 * xy2
        return xd, yd

    def jacobian(self, xy) -> np.ndarray:
        """Derivative of the distorted w.r.t. the ideal normalised coordinates.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Ideal normalised coordinates, unitless.

        Returns
        -------
        numpy.ndarray, shape (n, 2, 2) (or (2, 2) for a single point (2,))
            ``[[dx'/dx, dx'/dy], [dy'/dx, dy'/dy]]`` per point.

        Raises
        ------
        InputError
            When ``xy`` is not of shape (n, 2) or (2,).
        """
        a, single = as_points_single(xy, 2, "normalised coordinates", finite=False)
        j00, j01, j10, j11 = self._jacobian_xy(a[:, 0], a[:, 1])
        J = np.stack([np.stack([j00, j01], -1), np.stack([j10, j11], -1)], axis=-2)
        return one_or_many(J, single)

    def _jacobian_xy(self, x, y):
        r2 = x * x + y * y
        rad = self._radial(r2)
        drad = self.k1 + r2 * (2.0 * self.k2 + r2 * (3.0 * self.k3 + r2 * 4.0 * self.k4))
        two_drad = 2.0 * drad
        cross = two_drad * x * y + 2.0 * (self.p1 * y + self.p2 * x)
        j00 = rad + two_drad * x * x + 6.0 * self.p1 * x + 2.0 * self.p2 * y
        j11 = rad + two_drad * y * y + 6.0 * self.p2 * y + 2.0 * self.p1 * x
        return j00, cross, cross, j11

    def coefficient_jacobian(self, xy, names=COEFFICIENTS) -> np.ndarray:
        """Derivative of ``(x', y')`` w.r.t. the named coefficients.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Ideal normalised coordinates, unitless.
        names : sequence of str, default COEFFICIENTS
            Coefficients to differentiate, from ``("k1", "k2", "k3", "k4", "p1", "p2")``.

        Returns
        -------
        numpy.ndarray, shape (n, 2, len(names)) (or (2, len(names)) for a single point (2,))
            Unitless.

        Raises
        ------
        InputError
            For an unknown coefficient name, or ``xy`` not of shape (n, 2) or (2,).
        """
        a, single = as_points_single(xy, 2, "normalised coordinates", finite=False)
        x, y = a[:, 0], a[:, 1]
        r2 = x * x + y * y
        out = np.empty((a.shape[0], 2, len(names)))
        for j, name in enumerate(names):  # loop over coefficients, not points
            if name in ("k1", "k2", "k3", "k4"):
                pw = r2 ** int(name[1])
                out[:, 0, j], out[:, 1, j] = x * pw, y * pw
            elif name == "p1":
                out[:, 0, j], out[:, 1, j] = r2 + 2.0 * x * x, 2.0 * x * y
            elif name == "p2":
                out[:, 0, j], out[:, 1, j] = 2.0 * x * y, r2 + 2.0 * y * y
            else:
                raise InputError(f"unknown distortion coefficient {name!r}")
        return one_or_many(out, single)

    # --- inverse ------------------------------------------------------------------------------

    def undistort(
        self,
        xy_distorted,
        *,
        tol: float = 1e-12,
        max_iter: int = 30,
        scale=(1.0, 1.0),
    ) -> UndistortResult:
        """Invert :meth:`distort` by Newton iteration (vectorised over points).

        Parameters
        ----------
        xy_distorted : array_like, shape (n, 2) or (2,)
            Distorted normalised coordinates ``(x', y')``.
        tol : float
            Convergence tolerance on ``|distort(x) - x'|`` measured after multiplying the two
            components by ``scale`` (e.g. the focal length in pixels, to give ``tol`` in px).
        max_iter : int
            Iteration limit.
        scale : (float, float)
            Factors applied to the x and y misclosure before comparing with ``tol``.

        Returns
        -------
        UndistortResult
            ``points`` are the ideal normalised coordinates; ``residual`` is in the units of
            ``tol``; ``status`` flags points that did not converge. The arrays keep the point
            axis, also for a single point (2,) (n = 1).

        Raises
        ------
        InputError
            When ``xy_distorted`` is not of shape (n, 2) or (2,).
        """
        t = as_points(xy_distorted, 2, "distorted normalised coordinates", finite=False)
        n = t.shape[0]
        out = np.empty((n, 2))
        status = np.empty(n, dtype=np.int8)
        resid = np.empty(n)
        if self.is_zero:
            out[:] = t
            finite = np.all(np.isfinite(t), axis=1)
            status[:] = np.where(finite, STATUS_CONVERGED, STATUS_SINGULAR)
            resid[:] = np.where(finite, 0.0, np.nan)
            return UndistortResult(out, status, 0, resid)
        iterations = 0
        for s in range(0, n, CHUNK):  # chunks keep the work in cache; loop is not per point
            sl = slice(s, min(s + CHUNK, n))
            it = self._undistort_chunk(
                t[sl, 0],
                t[sl, 1],
                out[sl],
                status[sl],
                resid[sl],
                tol,
                max_iter,
                float(scale[0]),
                float(scale[1]),
            )
            iterations = max(iterations, it)
        return UndistortResult(out, status, iterations, resid)

    def _undistort_chunk(self, tx, ty, out, status, resid, tol, max_iter, sx, sy) -> int:
        k1, k2, k3, k4, p1, p2 = self.k1, self.k2, self.k3, self.k4, self.p1, self.p2
        r2 = tx * tx + ty * ty
        rad0 = self._radial(r2)
        ok0 = rad0 > 0.1
        x = np.where(ok0, tx / np.where(ok0, rad0, 1.0), tx)
        y = np.where(ok0, ty / np.where(ok0, rad0, 1.0), ty)
        it = 0
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            while True:
                xx, yy, xy = x * x, y * y, x * y
                r2 = xx + yy
                rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
                ex = x * rad + p1 * (r2 + 2.0 * xx) + 2.0 * p2 * xy - tx
                ey = y * rad + p2 * (r2 + 2.0 * yy) + 2.0 * p1 * xy - ty
                ex *= sx
                ey *= sy
                res = np.sqrt(ex * ex + ey * ey)
                if it >= max_iter or not np.any(res > tol):  # NaN compares False: stops too
                    break
                ex /= sx
                ey /= sy
                two_drad = 2.0 * (k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + r2 * 4.0 * k4)))
                j01 = two_drad * xy + 2.0 * (p1 * y + p2 * x)
                j00 = rad + two_drad * xx + 6.0 * p1 * x + 2.0 * p2 * y
                j11 = rad + two_drad * yy + 6.0 * p2 * y + 2.0 * p1 * x
                det = j00 * j11 - j01 * j01
                x = x - (j11 * ex - j01 * ey) / det
                y = y - (j00 * ey - j01 * ex) / det
                it += 1
            out[:, 0] = x
            out[:, 1] = y
            resid[:] = res
            status[:] = STATUS_MAX_ITER
            status[res <= tol] = STATUS_CONVERGED
            status[~np.isfinite(res)] = STATUS_SINGULAR
            conv = status == STATUS_CONVERGED
            if np.any(conv):
                # The Jacobian is symmetric; the main branch has it positive definite (a solution
                # on an outer branch of the polynomial can still have det > 0: both negative).
                j00, j01, _, j11 = self._jacobian_xy(x[conv], y[conv])
                folded = ~(((j00 * j11 - j01 * j01) > 0) & ((j00 + j11) > 0))
                idx = np.flatnonzero(conv)[folded]
                status[idx] = STATUS_FOLDED
        return it
