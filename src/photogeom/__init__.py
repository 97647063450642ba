"""photogeom: analytical photogrammetry with full least-squares statistics.

Layers (each imports only those above it):

1. :mod:`photogeom.rotation`, :mod:`photogeom.units`, :mod:`photogeom.imagecoords` - math helpers
2. :mod:`photogeom.transforms` - transformation models (no estimation)
3. :mod:`photogeom.adjust` - the least-squares engine and the :class:`Fit` result family
4. :mod:`photogeom.estimation`, :mod:`photogeom.orientation`, :mod:`photogeom.camera`,
   :mod:`photogeom.rpc` - estimators and camera models
5. :mod:`photogeom.io`, :mod:`photogeom.report`, :mod:`photogeom.cli`,
   :mod:`photogeom.datasets` - files, reports, command line, bundled data

Angles are radians unless a name or ``unit=`` says otherwise. Residuals are computed minus
observed.
"""

from . import datasets
from .adjust import Fit, data_snooping, gauss_helmert, gauss_markov, solve_linear
from .errors import (
    ConvergenceError,
    DegenerateGeometryError,
    FileFormatError,
    GimbalLockError,
    InputError,
    PhotogeomError,
    ReflectionError,
    TooFewPointsError,
)
from .rotation import (
    angles_from_rotation,
    axis_angle_from_matrix,
    euler_from_matrix,
    matrix_from_axis_angle,
    matrix_from_euler,
    matrix_from_quaternion,
    matrix_from_rodrigues,
    nearest_rotation,
    opk_from_matrix,
    opk_matrix,
    orthogonality_defect,
    quaternion_from_matrix,
    rodrigues_from_matrix,
    rotation_from_angles,
)
from .units import deg2gon, from_radians, gon2deg, to_radians

__version__ = "0.1.0"

# --- transformations and their estimation (issue: foundation) -------------------------------

# --- absolute orientation (issue: absolute orientation) -------------------------------------

# --- frame cameras (issue: camera models) ---------------------------------------------------

# --- RPC (issue: rpc) -----------------------------------------------------------------------
