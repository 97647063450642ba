"""Transformation models (apply, inverse, parameters); estimation is in :mod:`photogeom.estimation`.

2D: :class:`Similarity2D`, :class:`Affine2D`, :class:`Projective2D`, :class:`Polynomial2D`;
3D: :class:`Rigid3D`, :class:`Similarity3D`, :class:`Affine3D`, :class:`Projective3D`,
:class:`Polynomial3D`. Every model has ``apply``, ``inverse``, ``to_dict`` / :func:`from_dict`
and, except the 3D similarity (see its own accessors), ``parameter_names``, ``parameters``,
``with_parameters`` (parametric form) and ``textbook()`` (textbook form).
"""

from .affine2d import Affine2D
from .affine3d import Affine3D, AffineDecomposition
from .base import Transform, from_dict, registered_models
from .polynomial import (
    InverseResult,
    Polynomial2D,
    Polynomial2DInverse,
    Polynomial3D,
    Polynomial3DInverse,
    polynomial_exponents,
    polynomial_term_count,
    polynomial_terms,
)
from .projective import Projective2D, Projective3D
from .rigid3d import Rigid3D
from .similarity2d import Similarity2D
from .similarity3d import Similarity3D

__all__ = [
    "Affine2D",
    "Affine3D",
    "AffineDecomposition",
    "InverseResult",
    "Polynomial2D",
    "Polynomial2DInverse",
    "Polynomial3D",
    "Polynomial3DInverse",
    "Projective2D",
    "Projective3D",
    "Rigid3D",
    "Similarity2D",
    "Similarity3D",
    "Transform",
    "from_dict",
    "polynomial_exponents",
    "polynomial_term_count",
    "polynomial_terms",
    "registered_models",
]
