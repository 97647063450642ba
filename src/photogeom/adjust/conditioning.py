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
    """

    centre: np.ndarray
    scale: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Normalise points (n, dim)."""
        return (np.asarray(points, dtype=float) - self.centre) / self.scale

    def undo(self, points_n: np.ndarray) -> np.ndarray:
        """Back from normalised to original coordinates."""
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
    """Normalisation of ``points`` (n, dim), optionally with per-point weights for the centroid."""
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
