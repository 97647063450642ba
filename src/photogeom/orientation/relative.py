"""Relative orientation of an image pair: the coplanarity condition in a Gauss-Helmert model.

For every tie point the base ``b = O2 - O1`` and the two rays ``r1 = M1.T d1``,
``r2 = M2.T d2`` (``d = (x - x0, y - y0, -f) / f``, in each camera frame) lie in one plane:

    g = b . (r1 x r2) = 0

The four image coordinates of each point are the observations (errors in both images), the
five orientation elements the unknowns. Two parameterisations of the model system:

* ``"dependent"`` (image 1 fixed): ``O1 = 0``, ``M1 = I``, ``O2 = (bx, by, bz)`` with
  ``bx = +1`` (``-1`` when image 2 lies on the -x side of image 1), unknowns
  ``by, bz, omega2, phi2, kappa2``; the model system is the camera frame of image 1, its
  unit the x component of the base.
* ``"independent"`` (base fixed): ``O1 = 0``, ``O2 = (1, 0, 0)``, ``M1 = M(0, phi1,
  kappa1)``, ``M2 = M(omega2, phi2, kappa2)``; the model x axis is the base, its unit the
  base length.

Start values come from the essential matrix (five-point solver in RANSAC,
:mod:`.relative_start`); the adjustment then decides: matches rejected by RANSAC rejoin when
their test statistic passes, and Baarda's data snooping (or Pope's tau-test without an
a-priori sigma) removes the largest flagged point one at a time. The observations are the
measured image coordinates: the conditions remove lens distortion from them (iteratively)
and carry the derivative through it, so that ``sigma`` is that of the measured coordinates
and the residuals are measured image coordinates, computed minus observed.

The residual **y-parallax** of a point is its coplanarity misclosure expressed in the image
unit: ``py = -sqrt(2) g / |dg/dl|``, which in the normal case (vertical images, base along x,
one principal distance) is ``y1 - y2``. It is the sum of the distances by which the two
image points miss each other's epipolar lines when both images are measured alike.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse

from ..adjust import Fit, gauss_helmert
from ..adjust.snooping import tau_critical_value
from ..camera.exterior import ExteriorOrientation
from ..camera.interior import InteriorOrientation
from ..errors import (
    ConvergenceError,
    DegenerateGeometryError,
    InputError,
    PhotogeomError,
    TooFewPointsError,
)
from ..rotation import opk_from_matrix, opk_matrix, opk_matrix_and_derivatives
from ..validation import as_points
from .relative_start import (
    PointsBehindError,
    check_base,
    check_not_collinear,
    essential_start,
    plane_inliers,
)

__all__ = [
    "METHODS",
    "ImagePair",
    "RelativeOrientationFit",
    "relative_orientation",
]

METHODS = ("dependent", "independent")
PARAMETER_NAMES = {
    "dependent": ("by", "bz", "omega2", "phi2", "kappa2"),
    "independent": ("phi1", "kappa1", "omega2", "phi2", "kappa2"),
}
#: ``|bx| / |b|`` below which the dependent parameterisation (bx fixed) is refused.
MIN_BX_RATIO = 0.05
#: A start base closer than this (degrees) to image 1's viewing axis whose adjustment fails
#: is refused as forward motion (the elements are singular on the axis).
FORWARD_MOTION_DEG = 5.0
#: Relative (to the principal distance) image noise below which data count as noise-free
#: in the tau-test.
NUMERICAL_FLOOR = 1e-10
#: Condition number of the parameters' correlation matrix above which the points are taken
#: to lie on a critical surface.
CRITICAL_CONDITION = 1e10


@dataclass(frozen=True)
class ImagePair:
    """Two images oriented in a model system (the model of a relative orientation).

    Attributes
    ----------
    interior1, interior2 : InteriorOrientation
    exterior1, exterior2 : ExteriorOrientation
        Exterior orientations in the model system (angles in radians).
    method : str
        ``"dependent"`` or ``"independent"`` (which elements define the model system).
    """

    interior1: InteriorOrientation
    interior2: InteriorOrientation
    exterior1: ExteriorOrientation
    exterior2: ExteriorOrientation
    method: str

    @property
    def base(self) -> np.ndarray:
        """``O2 - O1`` in the model system (3,)."""
        return self.exterior2.position - self.exterior1.position

    @property
    def relative_rotation(self) -> np.ndarray:
        """``M2 M1.T``: camera-1 frame -> camera-2 frame (3, 3)."""
        return self.exterior2.matrix @ self.exterior1.matrix.T

    @property
    def base_in_camera1(self) -> np.ndarray:
        """Unit base direction in the camera frame of image 1 (3,)."""
        b = self.exterior1.matrix @ self.base
        return b / np.linalg.norm(b)

    def to_dict(self, angle_unit: str = "rad") -> dict:
        """JSON-ready exterior orientations of both images in the model system.

        Parameters
        ----------
        angle_unit : str, default "rad"
            Unit of the angles (any unit of :meth:`ExteriorOrientation.angles_in`, e.g.
            ``"deg"``).

        Returns
        -------
        dict
            ``{"method", "exterior1", "exterior2"}``, each exterior orientation as by
            :meth:`ExteriorOrientation.to_dict` (projection centre in the model unit).
        """
        return {
            "method": self.method,
            "exterior1": self.exterior1.to_dict(angle_unit),
            "exterior2": self.exterior2.to_dict(angle_unit),
        }


@dataclass(frozen=True, eq=False, repr=False)
class RelativeOrientationFit(Fit):
    """Result of :func:`relative_orientation` (a :class:`~photogeom.adjust.Fit`).

    ``parameters`` are ``by, bz, omega2, phi2, kappa2`` (dependent; by, bz in units of bx)
    or ``phi1, kappa1, omega2, phi2, kappa2`` (independent), angles in radians.
    ``residuals`` are the corrections of the image coordinates (adjusted minus observed,
    columns x1, y1, x2, y2) of the points used (``ids``). ``extras`` holds per input point:
    ``"parallax"``, ``"inliers"``, ``"statistic"`` (w or tau), ``"all_ids"``; and
    ``"epipolar_normal1"`` (unit normals of the epipolar lines in image 1: the parallax
    vector of a point is ``parallax * normal``); ``"start"`` (the essential-matrix start),
    ``"critical_value"``, ``"alpha"`` (the significance level of the tests, which the
    residual tables of the reports and ``to_dict()["snooping"]`` use too), ``"test"``,
    ``"removed"`` (ids removed by data snooping, in order).
    """

    @property
    def pair(self) -> ImagePair:
        """The oriented image pair."""
        return self.model

    @property
    def exterior1(self) -> ExteriorOrientation:
        """Image 1 in the model system."""
        return self.model.exterior1

    @property
    def exterior2(self) -> ExteriorOrientation:
        """Image 2 in the model system."""
        return self.model.exterior2

    @property
    def parallax(self) -> np.ndarray:
        """(n,) residual y-parallaxes of every input point (image unit), at the adjusted
        orientation and the observed coordinates (see the module docstring)."""
        return self.extras["parallax"]

    @property
    def inliers(self) -> np.ndarray:
        """(n,) bool: the points used in the final adjustment."""
        return self.extras["inliers"]

    @property
    def flagged(self) -> np.ndarray:
        """(n,) bool: points left out as wrong matches (``~inliers``)."""
        return ~self.extras["inliers"]

    @property
    def statistic(self) -> np.ndarray:
        """(n,) test statistic of every point (Baarda's w with ``sigma=``, else Pope's tau)."""
        return self.extras["statistic"]

    @property
    def all_ids(self) -> tuple:
        """Ids of every input point (``ids`` are those used)."""
        return self.extras["all_ids"]

    def model_points(self, which: str = "inliers"):
        """Model coordinates by intersection, with covariance.

        See :func:`photogeom.orientation.stereo_model.model_points`.

        Parameters
        ----------
        which : {"inliers", "all"}, default "inliers"
            The points used in the adjustment, or every input point.

        Returns
        -------
        ModelPoints
            Ids, model coordinates (n, 3) in the model unit and their cofactors (n, 3, 3).

        Raises
        ------
        InputError
            For another ``which``.
        """
        from .stereo_model import model_points

        return model_points(self, which=which)

    def parallax_report(self, worst: int = 10):
        """Residual y-parallaxes per point, RMS and the worst points.

        See :func:`photogeom.orientation.stereo_model.parallax_report`.

        Parameters
        ----------
        worst : int, default 10
            Points listed as the worst at most (largest ``|parallax|`` first; a negative
            value lists none).

        Returns
        -------
        ParallaxReport
            Parallaxes of every input point in the image unit of the fit, their RMS over
            the points used, the test statistics and critical value.
        """
        from .stereo_model import parallax_report

        return parallax_report(self, worst=worst)


# --- geometry of the parameterisations --------------------------------------------------------


class _Geometry:
    """Base, rotations and their derivatives for one parameterisation."""

    def __init__(self, method: str, sx: float) -> None:
        self.method = method
        self.sx = sx

    def elements(self, x: np.ndarray):
        """``b, M1, M2`` and the derivatives ``db (5, 3)``, ``dM1 (5, 3, 3)``, ``dM2``."""
        db = np.zeros((5, 3))
        dM1 = np.zeros((5, 3, 3))
        dM2 = np.zeros((5, 3, 3))
        if self.method == "dependent":
            b = np.array([self.sx, x[0], x[1]])
            db[0, 1] = db[1, 2] = 1.0
            M1 = np.eye(3)
            M2, d2 = opk_matrix_and_derivatives(x[2], x[3], x[4])
            dM2[2:] = d2
        else:
            b = np.array([1.0, 0.0, 0.0])
            M1, d1 = opk_matrix_and_derivatives(0.0, x[0], x[1])
            dM1[0], dM1[1] = d1[1], d1[2]
            M2, d2 = opk_matrix_and_derivatives(x[2], x[3], x[4])
            dM2[2:] = d2
        return b, M1, M2, db, dM1, dM2

    def exteriors(self, x: np.ndarray) -> tuple[ExteriorOrientation, ExteriorOrientation]:
        if self.method == "dependent":
            return (
                ExteriorOrientation(0.0, 0.0, 0.0),
                ExteriorOrientation(self.sx, x[0], x[1], x[2], x[3], x[4]),
            )
        return (
            ExteriorOrientation(0.0, 0.0, 0.0, 0.0, x[0], x[1]),
            ExteriorOrientation(1.0, 0.0, 0.0, x[2], x[3], x[4]),
        )


def _direction_jacobian(io: InteriorOrientation) -> np.ndarray:
    """``dd/d(x, y)`` (3, 2) of ``d = (xn, -yn, -1)`` for ideal image coordinates."""
    return np.array([[1.0 / io.fx, io.b2 / (io.f * io.fx)], [0.0, 1.0 / io.f], [0.0, 0.0]])


def _directions(io: InteriorOrientation, xy: np.ndarray) -> np.ndarray:
    """``d = (xn, -yn, -1)`` of ideal image coordinates (n, 2) (linear in x, y)."""
    yn = (io.y0 - xy[:, 1]) / io.f
    xn = (xy[:, 0] - io.x0 - io.b2 * yn) / io.fx
    return np.column_stack([xn, -yn, -np.ones(len(xy))])


class _Coplanarity:
    """Conditions ``g`` (n,), ``dg/dx`` (n, 5) and ``dg/dl`` (n, 4) at one evaluation.

    ``l`` are measured image coordinates (with distortion); they are undistorted at every
    evaluation and ``dg/dl`` includes the derivative of the undistortion.
    """

    def __init__(self, geom: _Geometry, io1, io2) -> None:
        self.geom = geom
        self.io1, self.io2 = io1, io2
        self.J1 = _direction_jacobian(io1)
        self.J2 = _direction_jacobian(io2)
        self._key: tuple | None = None
        self._val = None

    def evaluate(self, x: np.ndarray, l4: np.ndarray):
        key = (x.tobytes(), l4.tobytes())
        if key == self._key:
            return self._val
        b, M1, M2, db, dM1, dM2 = self.geom.elements(x)
        q1, K1 = _ideal_and_derivative(self.io1, l4[:, :2], "xy1")
        q2, K2 = _ideal_and_derivative(self.io2, l4[:, 2:], "xy2")
        d1 = _directions(self.io1, q1)
        d2 = _directions(self.io2, q2)
        r1 = d1 @ M1  # rows M1.T d1
        r2 = d2 @ M2
        c = np.cross(r1, r2)
        g = c @ b
        # dg/dx: b' . (r1 x r2) + b . (r1' x r2) + b . (r1 x r2')
        A = c @ db.T
        rb2 = np.cross(r2, b)  # b . (a x r2) = a . (r2 x b)
        br1 = np.cross(b, r1)  # b . (r1 x a) = a . (b x r1)
        for k in range(5):
            if np.any(dM1[k]):
                A[:, k] += np.sum((d1 @ dM1[k]) * rb2, axis=1)
            if np.any(dM2[k]):
                A[:, k] += np.sum((d2 @ dM2[k]) * br1, axis=1)
        # dg/dd1 = M1 (r2 x b), dg/dd2 = M2 (b x r1); chain to image coordinates
        g1 = rb2 @ M1.T
        g2 = br1 @ M2.T
        B1 = g1 @ self.J1
        B2 = g2 @ self.J2
        if K1 is not None:
            B1 = np.einsum("ni,nij->nj", B1, K1)
        if K2 is not None:
            B2 = np.einsum("ni,nij->nj", B2, K2)
        B = np.concatenate([B1, B2], axis=1)
        self._key = key
        self._val = (g, A, B)
        return self._val


def _block_diagonal(B: np.ndarray) -> scipy.sparse.csr_matrix:
    n = B.shape[0]
    return scipy.sparse.csr_matrix(
        (B.reshape(-1), np.arange(4 * n), np.arange(0, 4 * n + 1, 4)), shape=(n, 4 * n)
    )


# --- start values ------------------------------------------------------------------------------


def _start_parameters(method: str, R: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, float]:
    """Parameters and the sign of bx from the relative rotation ``M2 M1.T`` and the base
    direction in the camera-1 frame."""
    b = base / np.linalg.norm(base)
    what = "relative orientation"
    if method == "dependent":
        if abs(b[0]) < MIN_BX_RATIO:
            raise DegenerateGeometryError(
                f"{what}: the base is (nearly) perpendicular to the x axis of image 1 (bx/|b| "
                f"= {b[0]:.3g}), so the dependent parameterisation, which fixes bx, cannot "
                "describe it; use method='independent' (any base direction) or rotate the "
                "image coordinates so that x runs along the base"
            )
        sx = float(np.sign(b[0]))
        w, p, k = opk_from_matrix(R)
        return np.array([b[1] / abs(b[0]), b[2] / abs(b[0]), w, p, k]), sx
    # independent: first column of M1 = M(0, phi1, kappa1) is the base in camera 1
    p1 = math.asin(float(np.clip(b[2], -1.0, 1.0)))
    if abs(math.cos(p1)) < 1e-6:
        raise DegenerateGeometryError(
            f"{what}: the base runs along the viewing axis of image 1 (phi1 = +-90 degrees), "
            "where kappa1 of the independent parameterisation is undefined"
        )
    k1 = math.atan2(-b[1], b[0])
    M1 = opk_matrix(0.0, p1, k1)
    w2, p2, k2 = opk_from_matrix(R @ M1)
    return np.array([p1, k1, w2, p2, k2]), 1.0


# --- the estimator -----------------------------------------------------------------------------


def _sigmas(sigma, n: int) -> np.ndarray | None:
    if sigma is None:
        return None
    s = np.asarray(sigma, dtype=float)
    if s.ndim == 0:
        s = np.full((n, 4), float(s))
    elif s.shape == (n,):
        s = np.repeat(s[:, None], 4, axis=1)
    elif s.shape != (n, 4):
        raise InputError(
            f"sigma: expected one value, one per point (n,) or one per coordinate (n, 4) with "
            f"n = {n}, got shape {s.shape}"
        )
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError("sigma: standard deviations must be finite and > 0")
    return s


def _ideal_and_derivative(
    io: InteriorOrientation, xy: np.ndarray, name: str
) -> tuple[np.ndarray, np.ndarray | None]:
    """Distortion-free image coordinates (n, 2) of measured ones, and their derivative.

    Returns
    -------
    ideal : (n, 2) image coordinates without distortion (unit of ``io``).
    K : (n, 2, 2) or None
        ``d(ideal) / d(measured)`` per point; None without distortion (identity).
    """
    if io.distortion is None:
        return xy, None
    res = io.undistort_image(xy)
    if not res.all_converged:
        raise InputError(f"{name}: undistortion failed: {res.describe_failures()}")
    xn = res.points
    ideal = np.column_stack([io.x0 + io.fx * xn[:, 0] + io.b2 * xn[:, 1], io.y0 - io.f * xn[:, 1]])
    # image offsets = S (normalised), S = [[fx, b2], [0, -f]]: d(measured)/d(ideal) = S D S^-1
    S = np.array([[io.fx, io.b2], [0.0, -io.f]])
    K = np.linalg.inv(S @ io.distortion.jacobian(xn) @ np.linalg.inv(S))
    return ideal, K


def _ideal(io: InteriorOrientation, xy: np.ndarray, name: str) -> np.ndarray:
    return _ideal_and_derivative(io, xy, name)[0]


def _distinct_pairs(
    p1: np.ndarray, p2: np.ndarray, rel_tol: float = 1e-9
) -> tuple[np.ndarray, np.ndarray]:
    """Distinct tie points: rows of ``(p1, p2)`` (image units) that differ by more than
    ``rel_tol`` times the extent of the coordinates (on a grid of that spacing).

    Returns
    -------
    first : ndarray of int
        Index of one row of each distinct tie point.
    group : ndarray of int, shape (n,)
        For every row, the position in ``first`` of its distinct tie point.
    """
    both = np.column_stack([p1, p2])
    lo = both.min(axis=0)
    extent = float(np.max(both.max(axis=0) - lo))
    if not extent > 0.0:
        return np.zeros(1, dtype=np.intp), np.zeros(both.shape[0], dtype=np.intp)
    cells = np.round((both - lo) / (rel_tol * extent))
    _, first, group = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    return first, group.reshape(-1)


def relative_orientation(
    xy1,
    xy2,
    io1: InteriorOrientation,
    io2: InteriorOrientation | None = None,
    method: str = "dependent",
    *,
    sigma=None,
    ids=None,
    initial: tuple[ExteriorOrientation, ExteriorOrientation] | None = None,
    robust: bool = True,
    threshold: float | None = None,
    alpha: float = 0.001,
    max_removed: float = 0.5,
    seed: int | None = 0,
    max_iter: int = 50,
    tol: float = 1e-10,
) -> RelativeOrientationFit:
    """Relative orientation of an image pair from >= 5 tie points (coplanarity condition).

    Parameters
    ----------
    xy1, xy2 : array_like, shape (n, 2)
        Image coordinates of the same points in image 1 and image 2, in the photogrammetric
        image system of each camera (unit of its interior orientation; right-handed, y up).
    io1, io2 : InteriorOrientation
        Interior orientations (``io2`` defaults to ``io1``); both in one unit.
    method : {"dependent", "independent"}
        Parameterisation of the model system (see the module docstring).
    sigma : float or array_like (n,) or (n, 4), optional
        A-priori standard deviation of the measured image coordinates (image unit; with
        distortion it is carried through the undistortion). With it,
        ``sigma0`` should be about 1 and data snooping is Baarda's w-test; without it the
        weights are 1, ``sigma0`` estimates the image noise and the tau-test is used.
    ids : sequence of hashable, optional
        Point ids, kept as given (default the strings ``"1" .. "n"``).
    initial : (ExteriorOrientation, ExteriorOrientation), optional
        Start values: both images' orientations in any common system (e.g. from GNSS/IMU).
        Default: the essential matrix (five-point solver in RANSAC).
    robust : bool
        Start from RANSAC inliers and remove wrong matches by data snooping (default).
        False adjusts every point and only reports the test statistics.
    threshold : float, optional
        RANSAC inlier threshold on the distance to the epipolar line (image unit). Default
        ``5 sigma`` with a scalar ``sigma``, else 1/1000 of the principal distance.
    alpha : float
        Significance level of each point's test (0.001: critical w 3.29).
    max_removed : float
        Largest fraction of the points that may be left out (RANSAC and data snooping
        together) before data snooping gives up and the pair is refused.
    seed : int or None
        Seed of the RANSAC generator (reproducible results): an integer in 0..2**31 - 1
        (OpenCV's generator takes a C int), or None to leave the generator as it is.
    max_iter, tol
        Gauss-Helmert controls (see :func:`~photogeom.adjust.gauss_helmert`).

    Returns
    -------
    RelativeOrientationFit

    Raises
    ------
    TooFewPointsError
        Fewer than 5 points (or fewer than 5 left after removing wrong matches).
    DegenerateGeometryError
        Points on a line or on a critical surface, no base (pure rotation), several
        solutions (five points), a base the chosen parameterisation cannot describe.
    InputError
        Mismatched shapes, NaN, different image units, unknown method, ``alpha`` not in
        (0, 1), ``seed`` not an integer in 0..2**31 - 1.
    """
    t0 = time.perf_counter()
    what = "relative orientation"
    if method not in METHODS:
        raise InputError(f"method must be 'dependent' or 'independent', not {method!r}")
    io2 = io1 if io2 is None else io2
    for k, io in ((1, io1), (2, io2)):
        if not isinstance(io, InteriorOrientation):
            raise InputError(f"io{k} must be an InteriorOrientation")
    if io1.unit != io2.unit:
        raise InputError(
            f"{what}: the images use different units ({io1.unit}, {io2.unit}); give both image "
            "coordinate sets and interior orientations in one unit"
        )
    p1 = as_points(xy1, 2, "xy1")
    p2 = as_points(xy2, 2, "xy2")
    if p1.shape != p2.shape:
        raise InputError(f"xy1 and xy2 differ in shape: {p1.shape} vs {p2.shape}")
    n = p1.shape[0]
    if n < 5:
        raise TooFewPointsError(what, n, 5, "five orientation elements, one condition per point")
    all_ids = tuple(str(i) for i in range(1, n + 1)) if ids is None else tuple(ids)
    if len(all_ids) != n:
        raise InputError(f"ids: {len(all_ids)} id(s) for {n} point(s)")
    if len(set(all_ids)) != n:
        raise InputError("ids: duplicate point ids")
    first, group = _distinct_pairs(p1, p2)
    n_distinct = first.size
    if n_distinct < 5:
        raise TooFewPointsError(
            what, n_distinct, 5,
            f"the {n} tie points are only {n_distinct} distinct pairs of image positions: "
            "points are repeated; give five or more different tie points",
        )  # fmt: skip
    sig = _sigmas(sigma, n)
    if seed is not None and not (
        isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and 0 <= seed < 2**31
    ):
        raise InputError(f"seed must be an integer in 0..{2**31 - 1} or None, got {seed!r}")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha}")
    q1, q2 = _ideal(io1, p1, "xy1"), _ideal(io2, p2, "xy2")
    d1, d2 = _directions(io1, q1), _directions(io2, q2)
    xn1 = np.column_stack([d1[:, 0], -d1[:, 1]])
    xn2 = np.column_stack([d2[:, 0], -d2[:, 1]])
    check_not_collinear(xn1, xn2, what)
    fmean = 0.5 * (io1.f + io2.f)
    user_threshold = threshold is not None
    if threshold is None:
        scalar_sigma = sig is not None and np.all(sig == sig.flat[0])
        threshold = 5.0 * float(sig.flat[0]) if scalar_sigma else 1e-3 * fmean
    if not (math.isfinite(threshold) and threshold > 0):
        raise InputError(f"threshold must be a positive number, got {threshold!r}")
    thr_n = threshold / fmean

    # --- start values, adjustment, wrong matches ----------------------------------------------
    check_base(d1, d2, thr_n, what)
    start_info: dict = {}
    L_all = np.column_stack([p1, p2])  # measured: the conditions undistort them
    W_all = None if sig is None else 1.0 / sig**2

    def solve(R, base, inl):
        """Adjustment from one start: data snooping, checks; everything the Fit needs."""
        x0, sx = _start_parameters(method, R, base)
        geom = _Geometry(method, sx)
        cop = _Coplanarity(geom, io1, io2)

        def adjust(mask: np.ndarray, x_start: np.ndarray):
            if int(mask.sum()) < 5:
                raise TooFewPointsError(
                    what, int(mask.sum()), 5, "after removing the matches flagged as wrong"
                )
            L = L_all[mask].reshape(-1)
            m = int(mask.sum())

            def cond(x, l):
                return cop.evaluate(x, l.reshape(m, 4))[0]

            def jx(x, l):
                return cop.evaluate(x, l.reshape(m, 4))[1]

            def jl(x, l):
                return _block_diagonal(cop.evaluate(x, l.reshape(m, 4))[2])

            try:
                return gauss_helmert(
                    cond,
                    x_start,
                    L,
                    jacobian_x=jx,
                    jacobian_l=jl,
                    weights=None if W_all is None else W_all[mask].reshape(-1),
                    names=PARAMETER_NAMES[method],
                    max_iter=max_iter,
                    tol=tol,
                    what=what,
                    dense_limit=0,
                )
            except (DegenerateGeometryError, ConvergenceError) as exc:
                forward = _forward_motion_error(base, exc, what)
                if forward is not None:
                    raise forward from exc
                if isinstance(exc, ConvergenceError):
                    raise
                raise DegenerateGeometryError(
                    f"{what}: the points do not determine the orientation ({exc}); they lie on a "
                    "critical surface (e.g. a cylinder through both projection centres, or a "
                    "plane containing the base) or on a line: add points off that surface"
                ) from exc

        def statistics(adj, mask):
            """Test statistic of every point, and the critical value."""
            # points in the adjustment: w = b.v / sqrt(b Q b.T - a Qxx a.T) at (x, L + v);
            # the others: their misclosure g over sqrt(b Q b.T + a Qxx a.T) (independent of x)
            Lc = L_all.copy()
            Lc[mask] += adj.residuals.reshape(-1, 4)
            g, A, B = cop.evaluate(adj.x, L_all)
            _, Ac, Bc = cop.evaluate(adj.x, Lc)
            A = np.where(mask[:, None], Ac, A)
            B = np.where(mask[:, None], Bc, B)
            num = -g
            num[mask] = np.sum(Bc[mask] * adj.residuals.reshape(-1, 4), axis=1)
            S2 = np.ones((n, 4)) if sig is None else sig**2
            Mi = np.sum(B * B * S2, axis=1)  # b Q b.T per point
            qa = np.einsum("nk,kl,nl->n", A, adj.cofactor, A)
            var = np.where(mask, Mi - qa, Mi + qa)
            with np.errstate(invalid="ignore", divide="ignore"):
                w = np.where(var > 1e-14 * Mi, num / np.sqrt(np.abs(var)), np.nan)
            red = adj.redundancy
            if sig is not None:
                crit = _norm_critical(alpha)
                return w, crit, "w"
            s0 = adj.sigma0
            if red <= 1 or not np.isfinite(s0):
                return np.full(n, np.nan), np.inf, "tau"
            # data consistent to rounding: test against the rounding level, not against zero
            s0 = max(s0, NUMERICAL_FLOOR * fmean)
            return w / s0, tau_critical_value(alpha, red), "tau"

        mask = inl.copy()
        adj = adjust(mask, x0)
        removed: list[str] = []
        if robust:
            # matches rejected by RANSAC rejoin when the adjusted orientation accepts them
            for _ in range(2):
                stat, crit, test = statistics(adj, mask)
                back = ~mask & (np.abs(stat) <= crit)
                if not back.any():
                    break
                mask |= back
                adj = adjust(mask, adj.x)
            # Baarda's data snooping: remove the largest flagged point, one at a time
            limit = int(max_removed * n)
            while True:
                stat, crit, test = statistics(adj, mask)
                s_in = np.where(mask, np.abs(stat), -np.inf)
                s_in = np.where(np.isfinite(s_in), s_in, -np.inf)
                j = int(np.argmax(s_in))
                if not s_in[j] > crit:
                    break
                if int((~mask).sum()) + 1 > limit:
                    raise DegenerateGeometryError(
                        f"{what}: more than {max_removed:.0%} of the {n} matches are flagged as "
                        "wrong; the matches are unreliable or the a-priori sigma is too small"
                    )
                mask[j] = False
                removed.append(all_ids[j])
                adj = adjust(mask, adj.x)
        stat, crit, test = statistics(adj, mask)
        try:
            _check_conditioning(adj, what)
        except DegenerateGeometryError as exc:
            forward = _forward_motion_error(base, exc, what)
            if forward is not None:
                raise forward from exc
            raise
        if method == "dependent":
            # the start may allow bx and the adjustment still run to a base across x (by, bz
            # in units of bx growing without bound): refused as for such a start
            _start_parameters(method, np.eye(3), np.array([sx, adj.x[0], adj.x[1]]))
        g, _A, B = cop.evaluate(adj.x, L_all)
        parallax = -math.sqrt(2.0) * g / np.linalg.norm(B, axis=1)
        # unit normal of the epipolar line in image 1, oriented so that parallax * normal is
        # (0, y1 - y2) in the normal case: the parallax vector drawn on image 1
        with np.errstate(invalid="ignore", divide="ignore"):
            normal1 = -B[:, :2] / np.linalg.norm(B[:, :2], axis=1, keepdims=True)
        e1, e2 = geom.exteriors(adj.x)
        pair = ImagePair(io1, io2, e1, e2, method)
        _check_in_front(pair, q1[mask], q2[mask], what)
        return adj, mask, stat, crit, test, removed, sx, x0, pair, parallax, normal1, cop

    if initial is not None:
        try:
            e1, e2 = initial
        except (TypeError, ValueError):
            raise InputError("initial must be a pair (exterior1, exterior2)") from None
        if not isinstance(e1, ExteriorOrientation) or not isinstance(e2, ExteriorOrientation):
            raise InputError("initial must be a pair of ExteriorOrientation")
        R = e2.matrix @ e1.matrix.T
        base = e1.matrix @ (e2.position - e1.position)
        if np.linalg.norm(base) == 0:
            raise DegenerateGeometryError(f"{what}: the initial orientations share one position")
        start_info["source"] = "initial"
        result = solve(R, base, np.ones(n, dtype=bool))
    else:
        # a start that the adjustment cannot use (points behind the images, most matches
        # flagged: RANSAC chose a wrong solution because the threshold was below the real
        # misfit, e.g. of a start calibration) is retried with a 3 and 9 times larger threshold
        ladder = (thr_n,) if user_threshold else (thr_n, 3 * thr_n, 9 * thr_n)
        # when every start of the five-point solver puts points behind the images, the
        # decompositions of the homography of a plane: RANSAC may return only the twin of a
        # plane's essential matrix (flat terrain, a facade), which does that
        attempts = [(t, False) for t in ladder] + [(t, True) for t in ladder]
        first_error = None
        behind = False
        no_essential = False  # the five-point solver gave nothing usable: no larger threshold
        for t, planar in attempts:
            if (planar and not behind) or (not planar and no_essential):
                continue
            try:
                if n_distinct == 5 < n and not planar:
                    # repeated points add no geometry; the five-point solver lists all the
                    # solutions only when given exactly five points
                    ess = essential_start(xn1[first], xn2[first], t, seed=seed, what=what)
                    ess = replace(
                        ess,
                        inliers=ess.inliers[group],
                        alternatives=tuple((R, b, i[group]) for R, b, i in ess.alternatives),
                    )
                else:
                    ess = essential_start(xn1, xn2, t, seed=seed, what=what, homography=planar)
            except DegenerateGeometryError as exc:
                behind |= isinstance(exc, PointsBehindError)
                no_essential |= not planar
                first_error = first_error or exc
                continue
            check_base(d1[ess.inliers], d2[ess.inliers], thr_n, what)
            results = []
            for R_k, b_k, inl_k in ((ess.rotation, ess.base, ess.inliers), *ess.alternatives):
                try:
                    results.append(solve(R_k, b_k, inl_k if robust else np.ones(n, bool)))
                except (DegenerateGeometryError, ConvergenceError) as exc:
                    behind |= isinstance(exc, PointsBehindError)
                    first_error = first_error or exc
            if not results:
                continue
            if len(results) > 1 and n_distinct == 5:
                repeated = f" (the {n} tie points repeat five)" if n > 5 else ""
                raise DegenerateGeometryError(
                    f"{what}: {len(results)} relative orientations fit the five points"
                    f"{repeated} exactly, each with every point in front of both images; add "
                    "points or pass start values (initial=)"
                )
            # several solutions: the one keeping the most points, then the smaller misfit;
            # between the decompositions of a plane's homography (and in a nearly planar
            # scene, between them and the five-point solver's), see _least_misfit
            if planar:
                result = _least_misfit(results)
            else:
                result = min(results, key=lambda r: (-int(r[1].sum()), r[0].vtpv))
                if n > 5 and plane_inliers(xn1, xn2, t) >= 0.9 * int(result[1].sum()):
                    # a (nearly) planar scene: the five-point solver's start may be a
                    # distorted twin that a sigma0 of its own lets keep a few wrong matches
                    # (tau-test); the plane's decompositions compete with it
                    rivals = []
                    try:
                        pess = essential_start(xn1, xn2, t, seed=seed, what=what, homography=True)
                        for R_k, b_k, inl_k in (
                            (pess.rotation, pess.base, pess.inliers),
                            *pess.alternatives,
                        ):
                            try:
                                rivals.append(
                                    solve(R_k, b_k, inl_k if robust else np.ones(n, bool))
                                )
                            except (DegenerateGeometryError, ConvergenceError):
                                pass
                    except DegenerateGeometryError:
                        pass
                    if rivals:
                        chosen = _least_misfit([result, *rivals])
                        planar = chosen is not result
                        result = chosen
            start_info.update(
                source="homography of a plane (decomposition)"
                if planar
                else "essential matrix (five-point RANSAC)",
                candidates=ess.candidates,
                threshold=t * fmean,
            )
            break
        else:
            raise first_error
    adj, mask, stat, crit, test, removed, sx, x0, pair, parallax, normal1, cop = result
    start_info["parameters"] = dict(zip(PARAMETER_NAMES[method], map(float, x0)))
    used_ids = tuple(i for i, k in zip(all_ids, mask) if k)
    units = {nm: ("1" if nm in ("by", "bz") else "rad") for nm in PARAMETER_NAMES[method]}
    notes = []
    if method == "dependent":
        notes.append(f"model system: image 1 frame, unit bx (bx = {sx:+.0f})")
    else:
        notes.append("model system: x along the base, unit the base length")
    if removed:
        notes.append(f"removed by data snooping: {', '.join(map(str, removed[:30]))}")
    n_out = int((~mask).sum())
    if n_out:
        notes.append(f"{n_out} of {n} point(s) left out as wrong matches")
    # per-observation normalised residuals: each coordinate of a point carries its w
    with np.errstate(invalid="ignore", divide="ignore"):
        v4 = adj.residuals.reshape(-1, 4)
        _, Am, Bm = cop.evaluate(adj.x, L_all[mask] + v4)
        wobs = np.where(np.abs(v4) > 0, np.sign(v4) * np.abs(stat[mask])[:, None], np.nan)
        if test == "tau":
            wobs = wobs * max(adj.sigma0, NUMERICAL_FLOOR * fmean) / adj.sigma0_prior
        S2m = np.ones_like(Bm) if sig is None else sig[mask] ** 2
        Mi = np.sum(Bm * Bm * S2m, axis=1)
        qa = np.einsum("nk,kl,nl->n", Am, adj.cofactor, Am)
        rnum = (Bm * Bm * S2m) / Mi[:, None] * ((Mi - qa) / Mi)[:, None]
    fit = RelativeOrientationFit.from_adjustment(
        adj,
        pair,
        f"relative orientation ({method}, coplanarity, Gauss-Helmert)",
        point_dim=4,
        ids=used_ids,
        residual_labels=("x1", "y1", "x2", "y2"),
        residual_unit=io1.unit,
        parameter_units=units,
        elapsed=time.perf_counter() - t0,
        notes=tuple(notes),
        extras={
            "parallax": parallax,
            "inliers": mask,
            "statistic": stat,
            "test": test,
            "critical_value": crit,
            "alpha": float(alpha),
            "all_ids": all_ids,
            "removed": tuple(removed),
            "start": start_info,
            "bx": sx if method == "dependent" else None,
            "ideal_observations": np.column_stack([q1, q2]),
            "observations": L_all,
            "epipolar_normal1": normal1,
            "weights": W_all,
        },
    )
    return replace(fit, normalized_residuals=wobs, redundancy_numbers=rnum)


def _least_misfit(results: list) -> tuple:
    """Among adjusted candidates keeping at least 90 % of the most points, the one with the
    smallest sigma0 (the twin of a plane keeps a few wrong matches more under the tau-test,
    its own larger sigma0 accepting them)."""
    most = max(int(r[1].sum()) for r in results)
    pool = [r for r in results if int(r[1].sum()) >= 0.9 * most]
    return min(pool, key=lambda r: r[0].vtpv / max(r[0].redundancy, 1))


def _norm_critical(alpha: float) -> float:
    from scipy import stats

    return float(stats.norm.ppf(1 - alpha / 2))


def _forward_motion_error(base, exc: Exception, what: str) -> DegenerateGeometryError | None:
    """The named error of a start base within :data:`FORWARD_MOTION_DEG` of image 1's
    viewing axis whose adjustment failed with ``exc`` (None for other bases): on that axis
    the elements of both methods are singular, whichever way the failure shows (no
    convergence, or a correlation matrix near singular after it)."""
    b = np.asarray(base, dtype=float)
    off_axis = math.degrees(math.acos(min(1.0, abs(float(b[2])) / float(np.linalg.norm(b)))))
    if off_axis >= FORWARD_MOTION_DEG:
        return None
    return DegenerateGeometryError(
        f"{what}: the base runs {off_axis:.2g} degrees from the viewing axis of image 1 "
        "(forward or backward motion), where the elements of both methods are singular "
        "(kappa1 of the independent ones, bx of the dependent ones) and the adjustment fails "
        f"({exc}); orient a pair whose base runs across the viewing direction"
    )


def _check_conditioning(adj, what: str) -> None:
    Q = adj.cofactor
    d = np.sqrt(np.clip(np.diag(Q), 1e-300, None))
    C = Q / np.outer(d, d)
    cond = np.linalg.cond(C)
    if not np.isfinite(cond) or cond > CRITICAL_CONDITION:
        raise DegenerateGeometryError(
            f"{what}: the points do not determine the orientation (condition number of the "
            f"parameters' correlation matrix {cond:.3g}); they lie on or near a critical "
            "surface (e.g. a cylinder through both projection centres, or a plane containing "
            "the base): add points off that surface"
        )


def _check_in_front(pair: ImagePair, q1, q2, what: str) -> None:
    from .intersection import space_intersection

    try:
        space_intersection(
            np.stack([q1, q2]),
            [
                (replace(pair.interior1, distortion=None), pair.exterior1),
                (replace(pair.interior2, distortion=None), pair.exterior2),
            ],
            max_iter=5,
        )
    except PhotogeomError as exc:
        raise PointsBehindError(
            f"{what}: the adjusted orientation does not put every point in front of both "
            f"images ({exc}); start from better values (initial=) or check the matches"
        ) from exc
