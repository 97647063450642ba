"""Frame camera models: interior/exterior orientation, collinearity, DLT, affine camera, Brown.

* :mod:`.interior` - :class:`InteriorOrientation` (f, x0, y0 in mm or px, b1/b2, distortion,
  pixel geometry), image-variant offsets;
* :mod:`.exterior` - :class:`ExteriorOrientation` (X0, Y0, Z0, omega, phi, kappa in radians);
* :mod:`.collinearity` - :func:`project`, :func:`image_rays`, :func:`ground_at_height`,
  analytic derivatives, :class:`FrameCamera`;
* :mod:`.distortion` - :class:`BrownDistortion` (Metashape's K1-K4, P1, P2) and its inverse;
* :mod:`.metashape` - :class:`MetashapeCalibration`, its XML file and OpenCV conversion;
* :mod:`.calibration_files` - :func:`write_calibration` (Metashape XML, camera JSON, OpenCV
  YAML, COLMAP ``cameras.txt``, with standard deviations where they fit) and
  :func:`read_calibration` (the same, and OpenCV's FileStorage XML);
* :mod:`.dlt`, :mod:`.dlt_estimation` - the DLT, the camera matrix and their estimation;
* :mod:`.affine` - the 8-parameter affine camera;
* :mod:`.fiducials` - interior orientation from fiducial marks.
"""

from .affine import AffineCamera, estimate_affine_camera
from .calibration_files import read_calibration, write_calibration
from .collinearity import (
    FrameCamera,
    ground_at_height,
    image_rays,
    in_front,
    project,
    projection_derivatives,
)
from .distortion import BrownDistortion, UndistortResult
from .dlt import DLT, camera_matrix, dlt_from_orientation, orientation_from_dlt
from .dlt_estimation import DLTFit, estimate_dlt, orthogonality_conditions
from .exterior import ExteriorOrientation
from .fiducials import fit_fiducials, measured_to_fiducial
from .interior import ImageVariantInteriorOrientation, InteriorOrientation
from .metashape import (
    MetashapeCalibration,
    MetashapeXMLWarning,
    read_metashape_xml,
    write_metashape_xml,
)

__all__ = [
    "DLT",
    "AffineCamera",
    "BrownDistortion",
    "DLTFit",
    "ExteriorOrientation",
    "FrameCamera",
    "ImageVariantInteriorOrientation",
    "InteriorOrientation",
    "MetashapeCalibration",
    "MetashapeXMLWarning",
    "UndistortResult",
    "camera_matrix",
    "dlt_from_orientation",
    "estimate_affine_camera",
    "estimate_dlt",
    "fit_fiducials",
    "ground_at_height",
    "image_rays",
    "in_front",
    "measured_to_fiducial",
    "orientation_from_dlt",
    "orthogonality_conditions",
    "project",
    "projection_derivatives",
    "read_calibration",
    "read_metashape_xml",
    "write_calibration",
    "write_metashape_xml",
]
