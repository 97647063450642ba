"""The 8-parameter affine camera (parallel projection).

    x = a1 X + a2 Y + a3 Z + a4
    y = b1 X + b2 Y + b3 Z + b4

A linear model: estimated by :func:`~photogeom.adjust.solve_linear` on centred and scaled
object coordinates (parameters and covariance transformed back). Four non-coplanar control
points are the minimum; control at a single height leaves ``a3, b3`` undetermined.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..adjust import Fit, normalize_points, solve_linear
from ..errors import DegenerateGeometryError, InputError
from ..records import setstate_read_only
from ..validation import as_float64, as_points, check_count, check_same_length
from ._checks import with_check_points

NAMES = ("a1", "a2", "a3", "a4", "b1", "b2", "b3", "b4")


@dataclass(frozen=True, eq=False)
class AffineCamera:
    """Parallel projection ``x = a . (X, Y, Z, 1)``, ``y = b . (X, Y, Z, 1)``.

    Parameters
    ----------
    a, b : array_like, shape (4,)
        Coefficients; image units per object unit (``a4``, ``b4`` in image units).
    unit : str
        Unit of the image coordinates (e.g. ``"px"``).
    """

    a: np.ndarray
    b: np.ndarray
    unit: str = "px"

    def __post_init__(self) -> None:
        for name in ("a", "b"):
            v = np.array(getattr(self, name), dtype=float).reshape(-1)  # the camera's own
            if v.size != 4 or not np.all(np.isfinite(v)):
                raise InputError(f"affine camera: {name} must be 4 finite numbers")
            v.flags.writeable = False
            object.__setattr__(self, name, v)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: a, b stay read-only

    @property
    def matrix(self) -> np.ndarray:
        """2x4 matrix ``[[a1..a4], [b1..b4]]``."""
        return np.vstack([self.a, self.b])

    @property
    def parameters(self) -> np.ndarray:
        """``(a1, a2, a3, a4, b1, b2, b3, b4)``."""
        return np.concatenate([self.a, self.b])

    def project(self, ground_xyz) -> np.ndarray:
        """Image coordinates of ground points.

        Parameters
        ----------
        ground_xyz : array_like, shape (n, 3) or (3,)
            Object coordinates, object units.

        Returns
        -------
        numpy.ndarray, shape (n, 2) or (2,)
            Image coordinates in :attr:`unit`.

        Raises
        ------
        InputError
            When ``ground_xyz`` is not of shape (n, 3) or holds NaN/infinite values.
        """
        arr = as_float64(ground_xyz, "ground points")
        single = arr.ndim == 1
        g = as_points(arr, 3, "ground points")
        xy = g @ self.matrix[:, :3].T + self.matrix[:, 3]
        return xy[0] if single else xy

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``{"model": "affine_camera", "unit": ..., <the eight parameters by name>}``.
        """
        return {
            "model": "affine_camera",
            "unit": self.unit,
            **dict(zip(NAMES, self.parameters.tolist())),
        }

    @classmethod
    def from_dict(cls, data) -> AffineCamera:
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        data : Mapping
            The eight parameters by name and optionally ``"unit"`` (default ``"px"``).

        Returns
        -------
        AffineCamera

        Raises
        ------
        InputError
            When a parameter is missing (named in the message).
        """
        missing = [n for n in NAMES if n not in data]
        if missing:
            raise InputError(f"affine camera: missing parameter(s) {', '.join(missing)}")
        p = [float(data[n]) for n in NAMES]
        return cls(p[:4], p[4:], data.get("unit", "px"))


def estimate_affine_camera(
    ground,
    image,
    *,
    unit: str = "px",
    sigma=None,
    ids=None,
    check_ground=None,
    check_image=None,
    check_ids=None,
) -> Fit:
    """Estimate the 8-parameter affine camera from >= 4 non-coplanar control points.

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Object coordinates.
    image : array_like, shape (n, 2)
        Image coordinates in ``unit``.
    unit : str
        Unit of the image coordinates.
    sigma : float or array_like (n,) or (n, 2), optional
        Standard deviations of the image coordinates, in ``unit``.
    ids, check_ground, check_image, check_ids
        Point ids and check points (residuals reported, not in the estimate).

    Returns
    -------
    Fit
        ``model`` an :class:`AffineCamera`; residuals (n, 2) computed minus observed.
    """
    from .dlt_estimation import image_weights

    t0 = time.perf_counter()
    g = as_points(ground, 3, "ground points")
    im = as_points(image, 2, "image points")
    check_same_length(g, im, "ground points", "image points")
    n = g.shape[0]
    check_count(n, 4, "affine camera", "8 parameters, 2 observations per point")
    c = g - g.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    if s[0] == 0 or s[-1] <= 1e-7 * s[0]:
        zr = float(np.ptp(g[:, 2]))
        if zr <= 1e-7 * max(float(np.ptp(g[:, 0])), float(np.ptp(g[:, 1])), 1e-300):
            raise DegenerateGeometryError(
                f"affine camera: all control points lie at one height (Z range {zr:.3g}), so the "
                "height terms a3, b3 are undetermined; add control at different heights "
                "(at least 4 non-coplanar points)"
            )
        raise DegenerateGeometryError(
            "affine camera: the control points are coplanar (or collinear), so the system is "
            "singular; at least 4 non-coplanar points are needed"
        )
    w = image_weights(sigma, n)
    N = normalize_points(g)
    gn = N.apply(g)
    A = np.zeros((2 * n, 8))
    A[0::2, 0:3] = gn
    A[0::2, 3] = 1.0
    A[1::2, 4:7] = gn
    A[1::2, 7] = 1.0
    adj = solve_linear(A, im.reshape(-1), weights=w, names=NAMES, what="affine camera")
    # x = an . (X - c) / s + a4n  =>  a = an / s,  a4 = a4n - an . c / s
    Jrow = np.eye(4)
    Jrow[:3, :3] /= N.scale
    Jrow[3, :3] = -N.centre / N.scale
    J = np.kron(np.eye(2), Jrow)
    p = J @ adj.x
    model = AffineCamera(p[:4], p[4:], unit)
    units = {k: f"{unit}/m" for k in ("a1", "a2", "a3", "b1", "b2", "b3")}
    units.update({"a4": unit, "b4": unit})
    fit = Fit.from_adjustment(
        adj,
        model,
        "linear least squares (8-parameter affine camera)",
        point_dim=2,
        parameters=p,
        parameter_names=NAMES,
        jacobian=J,
        ids=None if ids is None else tuple(ids),
        residual_labels=("x", "y"),
        residual_unit=unit,
        parameter_units=units,
        elapsed=time.perf_counter() - t0,
    )
    return with_check_points(fit, model.project, check_ground, check_image, check_ids)
