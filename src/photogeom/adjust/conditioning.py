"""Centroid reduction and isotropic scaling of point sets for well-conditioned solves."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..records import ReadOnlyRecord


@dataclass(frozen=True, eq=False)
class PointNormalization(ReadOnlyRecord):
    """``p_n = (p - centre) / scale``: centroid reduction and one isotropic scale.

    ``scale`` is the RMS distance of the points from their centroid divided by
    ``sqrt(dim)`` (so normalised coordinates have unit RMS per axis); 1 when all points coincide.

    Attributes
    ----------
    centre : numpy.ndarray, shape (dim,)
        The (weighted) centroid, units of the points.
    scale : float
        The isotropic scale, units of the points.
    """

    centre: np.ndarray
    scale: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Normalise points.

        Parameters
        ----------
        points : array_like, shape (n, dim)
            Points in their own units.

        Returns
        -------
        numpy.ndarray, shape (n, dim)
            ``(points - centre) / scale``, unitless.
        """
        return (np.asarray(points, dtype=float) - self.centre) / self.scale

    def undo(self, points_n: np.ndarray) -> np.ndarray:
        """Back from normalised to original coordinates.

        Parameters
        ----------
        points_n : array_like, shape (n, dim)
            Normalised points, unitless.

        Returns
        -------
        numpy.ndarray, shape (n, dim)
            ``points_n * scale + centre``, in the units of the original points.
        """
        return np.asarray(points_n, dtype=float) * self.scale + self.centre

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous ``(dim+1, dim+1)`` matrix of :meth:`apply`."""
        d = self.centre.shape[0]
        T = np.eye(d + 1) / self.scale
        T[:d, d] = -self.centre / self.scale
        T[d, d] = 1.0
        return T


def normalize_points(points: np.ndarray, weights: np.ndarray | None = None) -> PointNormalization:
    """The normalisation of a point set: centroid reduction and one isotropic scale.

    Parameters
    ----------
    points : array_like, shape (n, dim)
        Points in any unit.
    weights : array_like, shape (n,), optional
        Per-point weights of the centroid (unitless).

    Returns
    -------
    PointNormalization
        ``centre`` and ``scale`` (units of the points); normalised points have unit RMS
        per axis.
    """
    p = np.asarray(points, dtype=float)
    n, dim = p.shape
    if weights is None:
        centre = np.add.reduce(p, axis=0) / n
    else:
        w = np.asarray(weights, dtype=float)
        centre = (w[:, None] * p).sum(axis=0) / w.sum()
    d = p - centre
    rms = math.sqrt(float(np.einsum("ij,ij->", d, d)) / (n * dim)) if n else math.nan
    if not math.isfinite(rms) or rms <= 0.0:
        rms = 1.0
    return PointNormalization(centre=centre, scale=rms)
