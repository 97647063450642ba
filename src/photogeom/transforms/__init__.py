"""Transformation models (apply, inverse, parameters); estimation lives in :mod:`photogeom.estimation`."""

from .base import Transform, from_dict, registered_models
from .similarity3d import Similarity3D

__all__ = ["Similarity3D", "Transform", "from_dict", "registered_models"]
