"""The stereo model of a relative orientation: model coordinates and y-parallaxes.

Model coordinates are intersected from the observed image coordinates of both images
(:func:`~photogeom.orientation.intersection.space_intersection`, least squares over the four
coordinates of each point). Their covariance has two parts:

    C_X = sigma0^2 (Q_int + H Qxx H.T)

``Q_int = (G.T P G)^-1`` is the intersection's cofactor (orientation held fixed, ``G`` the
derivatives of the four image coordinates by X, Y, Z) and ``H = -Q_int G.T P F`` carries the
cofactor ``Qxx`` of the five orientation elements (``F`` the derivatives of the image
coordinates by them). The cross term vanishes: a point's own observations enter the
orientation only through their component across the epipolar line (``b Q``), which the
intersection ignores (``G.T b.T = 0``). The covariance is that of the model datum of the
parameterisation (dependent: image 1 and bx fixed; independent: the base fixed).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..camera.collinearity import projection_derivatives
from ..errors import InputError
from ..records import ReadOnlyRecord

__all__ = ["ModelPoints", "ParallaxReport", "model_points", "parallax_report"]

#: Columns of the exterior-orientation derivatives (X0, Y0, Z0, omega, phi, kappa) that the
#: parameters of each method move, per image: (image, column) for each parameter.
_PARAMETER_COLUMNS = {
    "dependent": ((1, 1), (1, 2), (1, 3), (1, 4), (1, 5)),
    "independent": ((0, 4), (0, 5), (1, 3), (1, 4), (1, 5)),
}


@dataclass(frozen=True, eq=False)
class ModelPoints(ReadOnlyRecord):
    """Model coordinates of the points of a relative orientation.

    Attributes
    ----------
    ids : tuple of str
    points : (n, 3) model coordinates (unit of the model: bx or the base length).
    cofactor : (n, 3, 3) ``Q_int + H Qxx H.T`` (orientation uncertainty included).
    cofactor_conditional : (n, 3, 3) ``Q_int`` (orientation held fixed).
    sigma0 : float, a-posteriori sigma0 of the relative orientation (NaN when r = 0).
    sigma0_prior : float
    """

    ids: tuple
    points: np.ndarray
    cofactor: np.ndarray
    cofactor_conditional: np.ndarray
    sigma0: float
    sigma0_prior: float

    @property
    def covariance(self) -> np.ndarray:
        """(n, 3, 3) a-posteriori covariance ``sigma0^2 Q``."""
        return self.sigma0**2 * self.cofactor

    @property
    def covariance_prior(self) -> np.ndarray:
        """(n, 3, 3) a-priori covariance ``sigma0_prior^2 Q``."""
        return self.sigma0_prior**2 * self.cofactor

    @property
    def std(self) -> np.ndarray:
        """(n, 3) a-posteriori standard deviations of the model coordinates."""
        return np.sqrt(np.einsum("nii->ni", self.covariance))

    def as_dict(self) -> dict:
        """``{id: xyz}``.

        Returns
        -------
        dict
            Point id -> model coordinates (3,), model unit.
        """
        return dict(zip(self.ids, self.points))


#: Gauss-Newton iterations of the weighted model-point intersection (it converges in 2-3).
MODEL_POINT_ITERATIONS = 10


def model_points(fit, which: str = "inliers") -> ModelPoints:
    """Model coordinates by intersection, with covariance.

    The intersection is weighted as the orientation (``sigma`` of the four measured
    coordinates of each point), so that the reported covariance is that of the points.

    Parameters
    ----------
    fit : RelativeOrientationFit
    which : {"inliers", "all"}, default "inliers"
        The points used in the adjustment, or every input point (wrong matches may then fail
        to intersect in front of the images).

    Returns
    -------
    ModelPoints
        Ids, model coordinates (n, 3) in the model unit (bx or the base length) and their
        cofactors (n, 3, 3).

    Raises
    ------
    InputError
        For another ``which``.
    """
    from .intersection import space_intersection
    from .relative import _ideal_and_derivative

    if which not in ("inliers", "all"):
        raise InputError(f"which must be 'inliers' or 'all', not {which!r}")
    pair = fit.pair
    mask = fit.inliers if which == "inliers" else np.ones_like(fit.inliers)
    L = fit.extras["ideal_observations"][mask]
    W = fit.extras["weights"]
    W = np.ones_like(L) if W is None else W[mask]
    io1 = replace(pair.interior1, distortion=None)
    io2 = replace(pair.interior2, distortion=None)
    cams = [(io1, pair.exterior1), (io2, pair.exterior2)]
    res = space_intersection(np.stack([L[:, :2], L[:, 2:]]), cams)
    # the weights W are those of the measured coordinates: Jm = d(measured)/d(ideal) carries
    # the design matrices through the distortion, so that P is that of the observations
    obs = fit.extras.get("observations")
    Jm: list[np.ndarray | None] = [None, None]
    if obs is not None:
        for img, io in enumerate((pair.interior1, pair.interior2)):
            _, K = _ideal_and_derivative(io, obs[mask][:, 2 * img : 2 * img + 2], f"xy{img + 1}")
            Jm[img] = None if K is None else np.linalg.inv(K)

    def design(X: np.ndarray):
        """Weighted-space residuals (n, 4), d/dX (n, 4, 3) and d/d(orientation) (n, 4, 5)."""
        d1 = projection_derivatives(X, io1, pair.exterior1)
        d2 = projection_derivatives(X, io2, pair.exterior2)
        v = np.concatenate([d1.xy, d2.xy], axis=1) - L
        G = np.concatenate([d1.d_ground, d2.d_ground], axis=1)  # (n, 4, 3)
        deo = (d1.d_eo, d2.d_eo)
        F = np.zeros((X.shape[0], 4, 5))
        for k, (img, col) in enumerate(_PARAMETER_COLUMNS[pair.method]):
            F[:, 2 * img : 2 * img + 2, k] = deo[img][:, :, col]
        for img in (0, 1):
            if Jm[img] is not None:
                rows = slice(2 * img, 2 * img + 2)
                v[:, rows] = np.einsum("nij,nj->ni", Jm[img], v[:, rows])
                G[:, rows] = Jm[img] @ G[:, rows]
                F[:, rows] = Jm[img] @ F[:, rows]
        return v, G, F

    # the least-squares intersection with the weights of the orientation (the image
    # coordinates of the two images may have different sigma): Gauss-Newton from the
    # unweighted intersection
    X = res.points
    for _ in range(MODEL_POINT_ITERATIONS):
        v, G, F = design(X)
        GP = G * W[:, :, None]  # P G (diagonal P)
        N = np.einsum("nki,nkj->nij", G, GP)
        dX = -np.linalg.solve(N, np.einsum("nki,nk->ni", GP, v)[..., None])[..., 0]
        X = X + dX
        if np.all(np.abs(dX) <= 1e-12 * (1.0 + np.abs(X))):
            break
    v, G, F = design(X)
    GP = G * W[:, :, None]
    N = np.einsum("nki,nkj->nij", G, GP)
    Qi = np.linalg.inv(N)
    H = -Qi @ np.einsum("nki,nkj->nij", GP, F)
    Q = Qi + H @ fit.cofactor @ np.swapaxes(H, 1, 2)
    ids = tuple(i for i, k in zip(fit.all_ids, mask) if k)
    return ModelPoints(ids, X, Q, Qi, fit.sigma0, fit.sigma0_prior)


@dataclass(frozen=True, eq=False)
class ParallaxReport(ReadOnlyRecord):
    """Residual y-parallaxes of a relative orientation.

    Attributes
    ----------
    ids : tuple of str, every input point.
    parallax : (n,) residual y-parallax (image unit).
    used : (n,) bool, points in the adjustment.
    statistic : (n,) test statistic (w or tau) per point.
    critical_value : float
    test : str, name of the test statistic (``"w"`` or ``"tau"``).
    rms : float, RMS of the y-parallaxes of the points used.
    unit : str
    worst : tuple of int, indices of the largest |parallax|, largest first.
    """

    ids: tuple
    parallax: np.ndarray
    used: np.ndarray
    statistic: np.ndarray
    critical_value: float
    test: str
    rms: float
    unit: str
    worst: tuple

    def to_dict(self) -> dict:
        """JSON-ready report.

        Returns
        -------
        dict
            ``unit``, ``rms``, ``max_abs``, ``test``, ``critical_value``, ``points`` (id,
            parallax, statistic, used per point) and ``worst`` (ids); non-finite numbers as None.
        """

        def num(v):
            return float(v) if np.isfinite(v) else None

        return {
            "unit": self.unit,
            "rms": num(self.rms),
            "max_abs": num(np.max(np.abs(self.parallax[self.used]))) if self.used.any() else None,
            "test": self.test,
            "critical_value": num(self.critical_value),
            "points": [
                {
                    "id": i,
                    "parallax": num(p),
                    "statistic": num(s),
                    "used": bool(u),
                }
                for i, p, s, u in zip(self.ids, self.parallax, self.statistic, self.used)
            ],
            "worst": [self.ids[k] for k in self.worst],
        }

    def text(self) -> str:
        """The table a photogrammetrist reads: RMS, then the worst points.

        Returns
        -------
        str
        """
        lines = [
            f"residual y-parallaxes [{self.unit}]: RMS {self.rms:.4g} over {int(self.used.sum())} "
            f"point(s); {int((~self.used).sum())} left out as wrong matches",
            f"  {'id':<10} {'py':>12} {self.test:>8}  status",
        ]
        for k in self.worst:
            st = self.statistic[k]
            sts = f"{st:8.2f}" if np.isfinite(st) else "       -"
            flag = "used" if self.used[k] else "left out"
            lines.append(f"  {self.ids[k]!s:<10} {self.parallax[k]:12.5g} {sts}  {flag}")
        return "\n".join(lines)


def parallax_report(fit, worst: int = 10) -> ParallaxReport:
    """Per-point residual y-parallaxes, their RMS over the points used and the worst points.

    Parameters
    ----------
    fit : RelativeOrientationFit
        A relative orientation.
    worst : int, default 10
        Points listed in :attr:`ParallaxReport.worst` at most (largest ``|parallax|`` first).

    Returns
    -------
    ParallaxReport
        Parallaxes in the image unit of the fit.
    """
    p = np.asarray(fit.parallax)
    used = np.asarray(fit.inliers)
    rms = float(np.sqrt(np.mean(p[used] ** 2))) if used.any() else float("nan")
    order = tuple(int(k) for k in np.argsort(-np.abs(p))[: max(int(worst), 0)])
    return ParallaxReport(
        ids=fit.all_ids,
        parallax=p,
        used=used,
        statistic=np.asarray(fit.statistic),
        critical_value=float(fit.extras["critical_value"]),
        test=str(fit.extras["test"]),
        rms=rms,
        unit=fit.residual_unit,
        worst=order,
    )
