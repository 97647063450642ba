"""Interior orientation of film images from fiducial marks.

The marks are measured in a comparator (mm, right-handed) or in a scanned image (pixels,
left-handed: rows down); their calibrated positions in the fiducial system (mm, right-handed)
come from the camera's calibration certificate. A 2D similarity, affine or projective
transformation fitted from measured to calibrated positions maps every measured image point
into the fiducial system; with the principal point ``(x0, y0)`` and principal distance ``f``
of the certificate this completes the interior orientation (:class:`InteriorOrientation`).
"""

from __future__ import annotations

import numpy as np

from ..adjust import Fit
from ..errors import InputError
from ..validation import as_points, as_points_single, one_or_many

MODELS = {"similarity": "similarity2d", "affine": "affine2d", "projective": "projective2d"}


def fit_fiducials(
    measured,
    calibrated,
    *,
    model: str = "affine",
    measured_system: str = "comparator",
    check=None,
    ids=None,
    weights=None,
    sigma0_prior: float = 1.0,
    unit: str = "mm",
) -> Fit:
    """Fit the transformation from measured to calibrated fiducial marks.

    Parameters
    ----------
    measured : array_like, shape (n, 2)
        Measured positions: comparator coordinates (mm) or pixels ``(col, row)``.
    calibrated : array_like, shape (n, 2)
        Calibrated positions in the fiducial system (mm, x along flight, y up).
    model : {"similarity", "affine", "projective"}
        Transformation (>= 2, 3, 4 control marks).
    measured_system : {"comparator", "pixel"}
        ``"pixel"`` coordinates are left-handed: their row is negated before the fit (the
        returned transformation expects the negated row; see ``fit.notes``) so that no
        reflection is fitted.
    check : array_like of bool, shape (n,), optional
        ``True`` marks check marks: excluded from the fit, residuals reported.
    ids : sequence, optional
        Mark ids.
    weights : array_like, optional
        Per mark (n,) or per coordinate (n, 2).
    sigma0_prior : float
        A-priori standard deviation of unit weight (in ``unit``).
    unit : str
        Unit of the calibrated coordinates (residual labels).

    Returns
    -------
    Fit
        ``fit.model.apply(measured)`` gives fiducial coordinates; residuals (computed minus
        calibrated) in ``unit``; ``check_residuals`` for check marks.
    """
    from ..estimation.transforms import estimate_transform

    if model not in MODELS:
        raise InputError(f"fiducial model must be one of {', '.join(MODELS)}, not {model!r}")
    if measured_system not in ("comparator", "pixel"):
        raise InputError("measured_system must be 'comparator' (mm, right-handed) or 'pixel'")
    m = as_points(measured, 2, "measured fiducial marks")
    c = as_points(calibrated, 2, "calibrated fiducial marks")
    return estimate_transform(
        MODELS[model],
        m,
        c,
        check=check,
        ids=ids,
        weights=weights,
        sigma0_prior=sigma0_prior,
        source_system=measured_system,
        target_system="fiducial",
        unit=unit,
    )


def measured_to_fiducial(fit: Fit, points) -> np.ndarray:
    """Apply a fiducial fit to measured points (negating pixel rows as the fit did).

    Parameters
    ----------
    fit : Fit
        From :func:`fit_fiducials`.
    points : array_like, shape (n, 2) or (2,)
        Measured coordinates in the same system as the fiducial marks.

    Returns
    -------
    numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
        Fiducial coordinates (mm, right-handed).

    Raises
    ------
    InputError
        When ``points`` is not of shape (n, 2) or (2,) or holds NaN/infinite values.
    """
    p, single = as_points_single(points, 2, "measured points")
    p = p.copy()
    hand = fit.extras.get("handedness") or {}
    if hand.get("source_flip_y", False):
        p[:, 1] = -p[:, 1]
    return one_or_many(fit.model.apply(p), single)
