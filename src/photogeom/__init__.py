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

# --- transformations and their estimation ----------------------------------------------------
# --- frame cameras ----------------------------------------------------------------------------
# --- RPC satellite camera models ---------------------------------------------------------------
from . import bundle, camera, imagecoords, rpc, simulate, transforms
from .bundle import Block, BundleFit, BundleOptions, bundle_adjust
from .camera import (
    DLT,
    AffineCamera,
    BrownDistortion,
    ExteriorOrientation,
    FrameCamera,
    ImageVariantInteriorOrientation,
    InteriorOrientation,
    MetashapeCalibration,
    camera_matrix,
    dlt_from_orientation,
    estimate_affine_camera,
    estimate_dlt,
    fit_fiducials,
    ground_at_height,
    image_rays,
    in_front,
    orientation_from_dlt,
    project,
    read_metashape_xml,
    write_metashape_xml,
)
from .estimation.transforms import estimate_transform

# --- absolute orientation ---------------------------------------------------------------------
from .orientation import (
    AbsoluteOrientationFit,
    BatchOrientation,
    MethodComparison,
    absolute_orientation,
    absolute_orientation_batch,
    compare_absolute_methods,
    ransac_absolute_orientation,
    snooping_absolute_orientation,
)
from .orientation.intersection import IntersectionResult, space_intersection
from .orientation.relative import ImagePair, RelativeOrientationFit, relative_orientation
from .orientation.resection import (
    BatchResection,
    ResectionFit,
    p3p,
    space_resection,
    space_resection_batch,
)
from .orientation.strip import BlockStart, block_start, orient_strip, points_from_exteriors
from .rpc import (
    RPC,
    LocalizationResult,
    LocalizationStatus,
    LocalizationWarning,
    RPCExtrapolationWarning,
    RPCIntersection,
    fit_rpc,
    fit_rpc_to_points,
    intersect_rpc,
    read_rpc,
    refine_rpc,
    write_rpc,
)
from .transforms import (
    Affine2D,
    Affine3D,
    Polynomial2D,
    Polynomial3D,
    Projective2D,
    Projective3D,
    Rigid3D,
    Similarity2D,
    Similarity3D,
)

__all__ = [
    "DLT",
    "RPC",
    "AbsoluteOrientationFit",
    "Affine2D",
    "Affine3D",
    "AffineCamera",
    "BatchOrientation",
    "BatchResection",
    "Block",
    "BlockStart",
    "BrownDistortion",
    "BundleFit",
    "BundleOptions",
    "ConvergenceError",
    "DegenerateGeometryError",
    "ExteriorOrientation",
    "FileFormatError",
    "Fit",
    "FrameCamera",
    "GimbalLockError",
    "ImagePair",
    "ImageVariantInteriorOrientation",
    "InputError",
    "InteriorOrientation",
    "IntersectionResult",
    "LocalizationResult",
    "LocalizationStatus",
    "LocalizationWarning",
    "MetashapeCalibration",
    "MethodComparison",
    "PhotogeomError",
    "Polynomial2D",
    "Polynomial3D",
    "Projective2D",
    "Projective3D",
    "RPCExtrapolationWarning",
    "RPCIntersection",
    "ReflectionError",
    "RelativeOrientationFit",
    "ResectionFit",
    "Rigid3D",
    "Similarity2D",
    "Similarity3D",
    "TooFewPointsError",
    "__version__",
    "absolute_orientation",
    "absolute_orientation_batch",
    "angles_from_rotation",
    "axis_angle_from_matrix",
    "block_start",
    "bundle",
    "bundle_adjust",
    "calibration",
    "camera",
    "camera_matrix",
    "compare_absolute_methods",
    "data_snooping",
    "datasets",
    "deg2gon",
    "dlt_from_orientation",
    "estimate_affine_camera",
    "estimate_dlt",
    "estimate_transform",
    "euler_from_matrix",
    "fit_fiducials",
    "fit_rpc",
    "fit_rpc_to_points",
    "from_radians",
    "gauss_helmert",
    "gauss_markov",
    "gon2deg",
    "ground_at_height",
    "image_rays",
    "imagecoords",
    "in_front",
    "intersect_rpc",
    "matrix_from_axis_angle",
    "matrix_from_euler",
    "matrix_from_quaternion",
    "matrix_from_rodrigues",
    "nearest_rotation",
    "opk_from_matrix",
    "opk_matrix",
    "orient_strip",
    "orientation_from_dlt",
    "orthogonality_defect",
    "p3p",
    "points_from_exteriors",
    "project",
    "quaternion_from_matrix",
    "ransac_absolute_orientation",
    "read_metashape_xml",
    "read_rpc",
    "refine_rpc",
    "relative_orientation",
    "rodrigues_from_matrix",
    "rotation_from_angles",
    "rpc",
    "simulate",
    "snooping_absolute_orientation",
    "solve_linear",
    "space_intersection",
    "space_resection",
    "space_resection_batch",
    "to_radians",
    "transforms",
    "write_metashape_xml",
    "write_rpc",
]


def __getattr__(name: str):
    """Sub-packages loaded on first use (``pg.calibration``), to keep ``import photogeom``
    light."""
    if name == "calibration":
        import importlib

        return importlib.import_module(f"{__name__}.calibration")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
