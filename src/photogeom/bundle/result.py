"""The result of a bundle adjustment: adjusted block, statistics, diagnostics."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..adjust.schur import (
    CovarianceBlocks,
    covariance_blocks,
    observation_cofactors,
    point_covariances,
)
from ..adjust.snooping import POORLY_CONTROLLED, noncentrality
from ..adjust.sparse import CGNotConvergedError
from ..camera.frame_kernel import opk_from_increment_jacobian
from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..records import compact_repr, freeze_fields, read_only_fields, setstate_read_only
from ..rotation import LOCK_COS_PHI
from ._angles import opk_from_rotations
from .adjustment import NCAL, Problem
from .block import CALIBRATION_NAMES, EO_NAMES, Block
from .determined import check_determined, singular_error
from .residuals import reprojection_residuals
from .robust import (
    covariance_weights,
    image_point_leverage,
    point_trace_correction,
    score_slopes,
    stein_redundancy,
)

#: The fields of :class:`BundleFit` holding nested mappings, sequences and arrays (frozen by
#: :func:`photogeom.records.freeze_fields`).
_NESTED_FIELDS = (
    "calibration",
    "calibration_std",
    "calibration_correlation",
    "high_correlations",
    "check",
    "snooping",
    "variance_components",
    "chi2",
    "solver",
    "control",
    "effective_redundancy",
    "_cal_cov",
)

CAL_UNITS = {n: ("px" if n in ("f", "cx", "cy", "b1", "b2") else "1") for n in CALIBRATION_NAMES}


def _cal_number(value: float, unit: str) -> str:
    """A calibration value or standard deviation for the summary's table.

    Parameters
    ----------
    value : float
        The number, in ``unit``.
    unit : str
        ``"px"`` (f, cx, cy, b1, b2: 4 decimals, 0.0001 px) or ``"1"`` (the dimensionless
        distortion coefficients: 9 decimals; a non-zero magnitude below 1e-5 in
        scientific notation with 4 significant digits, so that no digit is lost).

    Returns
    -------
    str
        Fixed-point text, so that the decimal points of a unit's rows line up.
    """
    if unit == "px":
        return f"{value:.4f}"
    if value != 0 and abs(value) < 1e-5:
        return f"{value:.3e}"
    return f"{value:.9f}"


@dataclass(frozen=True, eq=False, repr=False)
class BundleFit:
    """Adjusted block and the statistics of a bundle adjustment.

    Attributes
    ----------
    block : Block
        The adjusted block (exterior orientations, calibrations, points; check points
        triangulated from their image observations with the adjusted cameras).
    sigma0, sigma0_prior : float
        A-posteriori ``sqrt(v'Pv / r)`` and a-priori standard deviation of unit weight, with
        ``P = sigma0_prior^2 / sigma^2`` for observations of standard deviation ``sigma``.
        With a robust loss ``sqrt(v'PWv / r_s)``, ``r_s`` the Stein redundancy
        (:func:`photogeom.bundle.robust.stein_redundancy`, whose expectation times the
        variance factor is that of ``v'PWv`` under normal errors), so that sigma0 is about
        ``sigma0_prior`` (1 by default) on clean data with correct a-priori sigmas.
        With an ``effective_redundancy``, ``v'Pv`` is divided by it instead of ``r``.
    redundancy, n_observations, n_unknowns : int
        ``r = n_observations - n_unknowns`` (scalar observations: 2 per image point, 3 per
        control point, GNSS position and IMU attitude).
    effective_redundancy : mapping or None
        Set by :func:`photogeom.calibration.readjust` when its grids were fitted to these
        same observations: the expectation of ``v'Pv / sigma^2`` over the whole chain
        (first adjustment, grid fit, re-adjustment), ``"value"`` (unitless), ``"method"``
        (``"exact"`` or ``"estimated"``), ``"probes"``, ``"seed"``, ``"std"`` (standard error
        of the estimate) and ``"observations"``
        (:func:`photogeom.calibration.chain.chain_redundancy`). sigma0, every standard
        deviation and covariance scaled by it and the chi-square test (its degrees of
        freedom) use this value. None otherwise.
    converged, iterations, message, cost_history
        Convergence diagnostics (cost = v'Pv after each accepted step).
    residuals : numpy.ndarray (n, 2)
        Image residuals, computed minus observed, pixels, in the order of
        ``block.observations`` (check-point rows with their triangulated points).
    in_adjustment : numpy.ndarray (n,) bool
        Rows that entered the adjustment (not check points).
    calibration, calibration_std : mapping group -> mapping name -> value
        Calibration of each camera group and the standard deviations of the free parameters
        (pixels; distortion terms dimensionless); NaN for fixed parameters.
    calibration_correlation : mapping group -> (names, matrix)
        Correlation matrix of the free calibration parameters of each group.
    high_correlations : tuple of (group, name, name, rho)
        Calibration correlations above the threshold of the options.
    correlation_threshold : float
        That threshold (``BundleOptions.correlation_threshold``).
    exterior_std : numpy.ndarray (m, 6)
        Standard deviations of X0, Y0, Z0 (object units) and omega, phi, kappa (radians); 0
        for components held fixed (``fix_exterior``).
    image_calibration_std : numpy.ndarray (m, 3)
        Standard deviations (pixels) of the per-image offsets of f, cx, cy of image-variant
        calibration (``block.image_variant``; each image's value is its group's plus the
        offset in ``block.calibration_offset``, the group's value being held); NaN where a
        parameter is not estimated per image.
    point_std : numpy.ndarray (p, 3) or None
        Standard deviations of every point's coordinates (``point_covariance=True``).
    check : mapping
        Check-point ids, errors ``adjusted - surveyed`` (k, 3), RMSE X, Y, Z (object units
        and GSD); in a free network after the 7-parameter similarity transformation of the
        check points onto their survey (:func:`similarity_residuals`), their ``point_std``
        in that datum (:func:`free_check_point_covariance`).
    control : mapping
        Control-point ids, their adjusted minus surveyed coordinates (k, 3), RMSE X, Y, Z
        (object units and GSD) and the surveyed standard deviations (k, 3).
    snooping : mapping or None
        Baarda's w per observation (n, 2), the critical value and the flagged observations
        as (image id, point id, w); ``"mdb"`` (n, 2), the minimal detectable bias of every
        coordinate in units of its a-priori sigma (power 80 %), and ``"poorly_controlled"``,
        the (image id, point id) of observations with a redundancy number below 0.1.
    variance_components : mapping or None
        Estimated standard deviation factor of each observation group.
    chi2 : mapping
        Global test of ``v'Pv / sigma0_prior^2`` against chi-square with r degrees of freedom
        (with a robust loss ``v'Pv`` of the least-squares solution of the final
        linearisation, all observations at full weight: :func:`least_squares_square_sum`;
        it fails on blunders the robust weights have muted).
    notes : tuple of str
    gsd : float
        Mean ground sample distance of the adjusted block (object units per pixel,
        :meth:`Block.gsd`).
    elapsed : float (s)
    solver : mapping
        The sparse backend and sizes of the reduced system, the loss (``"loss"``) and the
        scale of a robust loss in a-priori sigmas (``"loss_scale"``, None for the squared
        loss).

    Notes
    -----
    The array attributes (``residuals``, ``in_adjustment``, ``exterior_std``,
    ``point_std``, ...) are read-only views, as the block's arrays: take a copy to change
    one. The nested results (``calibration``, ``check``, ``control``, ``snooping``,
    ``chi2``, ...) are read-only too, all the way down: their mappings are read-only
    mappings (``dict(fit.check)`` is a dict of one's own), their lists tuples and their
    arrays read-only views, so that ``summary``, ``to_dict`` and the reports of a fit, and
    of the copies :func:`dataclasses.replace` makes, always show the adjustment's numbers.
    """

    block: Block
    sigma0: float
    sigma0_prior: float
    redundancy: int
    n_observations: int
    n_unknowns: int
    converged: bool
    iterations: int
    message: str
    cost_history: tuple
    residuals: np.ndarray
    in_adjustment: np.ndarray
    calibration: Mapping
    calibration_std: Mapping
    calibration_correlation: Mapping
    high_correlations: tuple
    exterior_std: np.ndarray
    point_std: np.ndarray | None
    check: Mapping
    snooping: Mapping | None
    variance_components: Mapping | None
    chi2: Mapping
    gsd: float
    notes: tuple = ()
    elapsed: float = 0.0
    solver: Mapping = field(default_factory=dict)
    control: Mapping = field(default_factory=lambda: {"ids": []})
    correlation_threshold: float = 0.9
    image_calibration_std: np.ndarray | None = None
    effective_redundancy: Mapping | None = None
    _image_cov: np.ndarray | None = None
    _point_cov: np.ndarray | None = None
    _cal_cov: Mapping | None = None

    def __repr__(self) -> str:
        # bounded (records.compact_repr): the dataclass repr printed every flagged
        # observation and the covariance arrays of up to 1000 elements in full
        return compact_repr(self)

    def __post_init__(self) -> None:
        # read-only views: the residuals agree with the block, copies share the arrays; the
        # nested results (read by summary, to_dict and the reports) read-only all the way down
        read_only_fields(self)
        freeze_fields(self, _NESTED_FIELDS)

    def __setstate__(self, state: dict) -> None:
        # pickle / deepcopy rebuild arrays writable: read-only again (the nested ones too)
        setstate_read_only(self, state)
        freeze_fields(self, _NESTED_FIELDS)

    # --- queries -----------------------------------------------------------------------------

    def image_covariance(self, image_id) -> np.ndarray:
        """Covariance (6, 6) of X0, Y0, Z0, omega, phi, kappa of one image (a-posteriori).

        Parameters
        ----------
        image_id : hashable
            Id of the image in ``block.image_ids``.

        Returns
        -------
        numpy.ndarray, shape (6, 6)
            A copy; object units squared for the position, rad^2 for the angles.

        Raises
        ------
        InputError
            For an unknown image id.
        """
        try:
            i = {k: n for n, k in enumerate(self.block.image_ids.tolist())}[image_id]
        except KeyError:
            raise InputError(f"unknown image id {image_id!r}") from None
        return self._image_cov[i].copy()

    def point_covariance(self, point_id) -> np.ndarray:
        """Marginal covariance (3, 3) of one point (a-posteriori).

        Parameters
        ----------
        point_id : hashable
            Id of the point in ``block.point_ids``.

        Returns
        -------
        numpy.ndarray, shape (3, 3)
            A copy, object units squared.

        Raises
        ------
        InputError
            When the adjustment ran without ``point_covariance=True``, or for an unknown
            point id.
        """
        if self._point_cov is None:
            raise InputError(
                "point covariances were not computed: run bundle_adjust(..., point_covariance=True)"
            )
        try:
            j = {k: n for n, k in enumerate(self.block.point_ids.tolist())}[point_id]
        except KeyError:
            raise InputError(f"unknown point id {point_id!r}") from None
        return self._point_cov[j].copy()

    def calibration_covariance(self, group) -> tuple[tuple[str, ...], np.ndarray]:
        """Names of the free calibration parameters of ``group`` and their covariance.

        Parameters
        ----------
        group : hashable
            Camera group id (``block.camera_ids``).

        Returns
        -------
        names : tuple of str
            The free calibration parameters of the group (empty when none is free).
        covariance : numpy.ndarray, shape (k, k)
            Their a-posteriori covariance (px^2 for f, cx, cy, b1, b2; distortion terms
            dimensionless), in the order of ``names``; the stored array, not a copy, so
            read-only.

        Raises
        ------
        KeyError
            For an unknown group (the lookup is not checked).
        """
        return self._cal_cov[group]

    def image_calibration(self) -> dict:
        """Image-variant calibration of each group, summarised over the group's images.

        The per-image values are ``block.calibration_offset`` and
        :attr:`image_calibration_std`.

        Returns
        -------
        dict
            ``{group: {name: {"rms_offset", "rms_std"}}}``, pixels, for the names estimated
            per image (offsets of f, cx, cy from the group's value). Groups without a
            parameter estimated per image are left out; empty when
            ``image_calibration_std`` is None.
        """
        from .block import IMAGE_VARIANT_NAMES

        out: dict = {}
        std = self.image_calibration_std
        if std is None:
            return out
        b = self.block
        for gi, g in enumerate(b.camera_ids.tolist()):
            rows = b.image_camera == gi
            names = {}
            for c, n in enumerate(IMAGE_VARIANT_NAMES):
                s = std[rows, c]
                if n in b.image_variant[g] and np.any(np.isfinite(s)):
                    names[n] = {
                        "rms_offset": float(np.sqrt(np.mean(b.calibration_offset[rows, c] ** 2))),
                        "rms_std": float(np.sqrt(np.nanmean(s**2))),
                    }
            if names:
                out[g] = names
        return out

    @property
    def crs(self) -> str | None:
        """The CRS of the adjusted object coordinates (``block.crs``: an EPSG code, WKT,
        ``"enu:lat0,lon0,h0"``, ...), None when the block records none."""
        return self.block.crs

    def positions_in(self, crs, *, allow_ballpark: bool = False) -> np.ndarray:
        """Adjusted projection centres in another CRS, from the block's CRS.

        See :func:`photogeom.bundle.georef.positions_in`.

        Parameters
        ----------
        crs : str, int or LocalFrame
            The target CRS (e.g. ``"EPSG:4979"``: lon, lat, h) or a local ENU frame
            (``"enu:lat0,lon0,h0"``).
        allow_ballpark : bool, default False
            Accept an approximate ("ballpark") datum shift.

        Returns
        -------
        numpy.ndarray, shape (m, 3)
            One row per image, x/easting/longitude first.

        Raises
        ------
        InputError
            The block records no CRS; an unknown CRS; a conversion PROJ can only do
            approximately (unless ``allow_ballpark``).
        """
        from .georef import positions_in

        return positions_in(self.block, crs, allow_ballpark=allow_ballpark)

    def points_in(self, crs, *, allow_ballpark: bool = False) -> np.ndarray:
        """Adjusted object points in another CRS (see :meth:`positions_in`).

        Parameters
        ----------
        crs : str, int or LocalFrame
            The target CRS, as in :meth:`positions_in`.
        allow_ballpark : bool, default False
            Accept an approximate ("ballpark") datum shift.

        Returns
        -------
        numpy.ndarray, shape (p, 3)
            One row per point of ``block.point_ids``, x/easting/longitude first.

        Raises
        ------
        InputError
            As :meth:`positions_in`.
        """
        from .georef import points_in

        return points_in(self.block, crs, allow_ballpark=allow_ballpark)

    @property
    def rms_per_image(self) -> dict:
        """RMS of the image residual lengths per image (px), adjusted observations only."""
        b = self.block
        v = self.residuals[self.in_adjustment]
        i = b.obs_image[self.in_adjustment]
        s = np.bincount(i, weights=np.einsum("nd,nd->n", v, v), minlength=b.n_images)
        c = np.bincount(i, minlength=b.n_images)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.sqrt(s / c)
        return dict(zip(b.image_ids.tolist(), rms.tolist()))

    @property
    def rmse(self) -> float:
        """RMS of the image residual lengths over the adjusted observations (px)."""
        v = self.residuals[self.in_adjustment]
        return float(np.sqrt(np.mean(np.einsum("nd,nd->n", v, v)))) if v.size else math.nan

    # --- reports -----------------------------------------------------------------------------

    @property
    def gnss_residuals(self) -> np.ndarray:
        """(m, 3) GNSS residuals per image, computed minus observed: the adjusted projection
        centre minus the GNSS position (object units); NaN for images without GNSS."""
        b = self.block
        return b.exterior[:, :3] - b.gnss

    @property
    def imu_residuals(self) -> np.ndarray:
        """(m, 3) IMU residuals per image, computed minus observed: the adjusted omega, phi,
        kappa minus the IMU's, wrapped to [-pi, pi) (radians); NaN for images without IMU."""
        from ..units import wrap_angle

        b = self.block
        return wrap_angle(b.exterior[:, 3:6] - b.imu)

    def orientation_residual_rms(self) -> dict:
        """RMS per axis of the GNSS and IMU residuals over the images that have them.

        Returns
        -------
        dict
            ``{"gnss": (3,), "gnss_images": k, "imu": (3,), "imu_images": k}``: the RMS of
            X, Y, Z (object units) and of omega, phi, kappa (rad), and the number of images
            with the observation; a group without observations is left out.
        """
        out: dict = {}
        for key, r in (("gnss", self.gnss_residuals), ("imu", self.imu_residuals)):
            has = np.all(np.isfinite(r), axis=1)
            if np.any(has):
                out[key] = np.sqrt(np.mean(r[has] ** 2, axis=0))
                out[f"{key}_images"] = int(has.sum())
        return out

    def summary(self, angle_unit: str = "deg", unit: str = "m") -> str:
        """A text report: convergence, sigma0, calibration, check points, outliers.

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the angles shown (IMU residual RMS, standard deviations of the
            exterior orientation angles).
        unit : str, default "m"
            Name of the object-space length unit that labels the GSD, the GNSS residuals,
            the standard deviations of the projection centres and points and the check-point
            RMSE (a label only: the block's coordinates are not converted).

        Returns
        -------
        str
            The report, one line per item.
        """
        from ..units import from_radians

        b = self.block
        L = [
            "Bundle adjustment with self-calibration",
            b.summary(),
            f"{self.message} after {self.iterations} iteration(s), {self.elapsed:.2f} s "
            f"(solver: {self.solver.get('backend', '?')})",
            f"observations {self.n_observations}, unknowns {self.n_unknowns}, redundancy "
            f"{self.redundancy}"
            + _effective_redundancy_text(self.effective_redundancy),
            _loss_line(self.solver),
            f"sigma0 a posteriori {self.sigma0:.4f} (a priori {self.sigma0_prior:g}); chi-square "
            f"test: {'passed' if self.chi2.get('passed') else 'failed'} "
            f"(p = {self.chi2.get('p_value', math.nan):.3g})",
            f"image residuals (computed - observed): RMS {self.rmse:.3f} px; GSD "
            f"{self.gsd:.4g} {unit} per px",
            *([f"object coordinates: {_crs_label(self.crs)}"] if self.crs else []),
            "",
            "calibration (px; distortion dimensionless), standard deviations a posteriori:",
        ]
        per_image = self.image_calibration()
        for g, vals in self.calibration.items():
            L.append(f"  camera {g}")
            L.append(f"    {'parameter':<9}{'value':>17}{'std. dev.':>15}  unit")
            iv = per_image.get(g, {})
            for n in CALIBRATION_NAMES:
                s = self.calibration_std[g][n]
                std = _cal_number(s, CAL_UNITS[n]) if math.isfinite(s) else "fixed"
                if n in iv:
                    std = "per image"
                L.append(
                    f"    {n:<9}{_cal_number(vals[n], CAL_UNITS[n]):>17}{std:>15}  {CAL_UNITS[n]}"
                )
            if iv:
                L.append(
                    "    estimated per image (value = the above + the image's offset), RMS of "
                    "the offsets / of their standard deviations: "
                    + ", ".join(
                        f"{n} {v['rms_offset']:.4g} / {v['rms_std']:.4g} px" for n, v in iv.items()
                    )
                )
        if self.high_correlations:
            L.append("high calibration correlations (|rho| > threshold):")
            for g, a, c, r in self.high_correlations:
                L.append(f"  camera {g}: {a} / {c}: {r:+.3f}")
        es = self.exterior_std
        orr = self.orientation_residual_rms()
        if "gnss" in orr:
            g = orr["gnss"]
            L.append(
                f"GNSS residuals (adjusted - GNSS), RMS over {orr['gnss_images']} image(s): "
                f"X0 {g[0]:.4g}, Y0 {g[1]:.4g}, Z0 {g[2]:.4g} {unit}"
            )
        if "imu" in orr:
            a = np.asarray(from_radians(orr["imu"], angle_unit))
            L.append(
                f"IMU residuals (adjusted - IMU), RMS over {orr['imu_images']} image(s): "
                f"omega {a[0]:.3g}, phi {a[1]:.3g}, kappa {a[2]:.3g} {angle_unit}"
            )
        if es.size and not np.any(es):
            L.append("exterior orientation: held fixed (no standard deviations)")
        elif es.size:
            rms_pos = np.sqrt(np.nanmean(es[:, :3] ** 2, axis=0))
            rms_ang = np.sqrt(
                np.nanmean(np.asarray(from_radians(es[:, 3:], angle_unit)) ** 2, axis=0)
            )
            L.append(
                "exterior orientation, RMS of the standard deviations: "
                f"X0 {rms_pos[0]:.4g}, Y0 {rms_pos[1]:.4g}, Z0 {rms_pos[2]:.4g} {unit}; omega "
                f"{rms_ang[0]:.3g}, phi {rms_ang[1]:.3g}, kappa {rms_ang[2]:.3g} {angle_unit}"
            )
        if self.point_std is not None:
            ps = self.point_std[b.role != "check"]
            r = np.sqrt(np.nanmean(ps**2, axis=0))
            L.append(
                "points, RMS of the standard deviations: "
                f"X {r[0]:.4g}, Y {r[1]:.4g}, Z {r[2]:.4g} {unit}"
            )
        c = self.check
        if c.get("ids"):
            r = c["rmse"]
            g = c["rmse_gsd"]
            how = "triangulated minus surveyed"
            if "similarity" in c.get("convention", ""):
                how += " after the similarity transformation onto the survey"
            L.append(
                f"check points ({len(c['ids'])}), {how}: RMSE X {r[0]:.4g}, "
                f"Y {r[1]:.4g}, Z {r[2]:.4g} {unit} ({g[0]:.2f}, {g[1]:.2f}, {g[2]:.2f} GSD)"
            )
        if self.snooping is not None:
            fl = self.snooping["flagged"]
            L.append(
                f"data snooping (w-test, alpha {self.snooping['alpha']}, critical "
                f"{self.snooping['critical_value']:.2f}): {len(fl)} observation(s) flagged"
            )
            for img, pt, w in fl[:SUMMARY_FLAGGED]:
                L.append(f"  image {img} point {pt}: |w| = {w:.1f}")
            if len(fl) > SUMMARY_FLAGGED:
                L.append(
                    f"  ... and {len(fl) - SUMMARY_FLAGGED} more with smaller |w| (all of "
                    "them in snooping['flagged'] of the result)"
                )
        if self.variance_components:
            L.append("variance components (estimated sigma = factor x a-priori sigma):")
            held = self.variance_components.get("not_estimated", {})
            for k, v in self.variance_components["factors"].items():
                L.append(f"  {k}: {v:.4f}" + (" (not estimated: a-priori)" if k in held else ""))
        for n in self.notes:
            L.append(f"note: {n}")
        return "\n".join(L)

    def to_dict(self, angle_unit: str = "deg") -> dict:
        """JSON-ready summary (without the per-observation arrays).

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the exterior orientation angles, their standard deviations and the IMU
            residuals and their RMS.

        Returns
        -------
        dict
            Convergence, sigma0, redundancy, chi-square test, RMSE (px), GSD, calibrations
            and their standard deviations, check and control points, snooping, variance
            components, solver and CRS. Per image (``"images"``): the exterior orientation,
            its standard deviations, the RMS image residual (px) and the GNSS and IMU
            residuals (computed minus observed; object units and ``angle_unit``, None without
            the observation); ``orientation_residual_rms`` their RMS per axis.
        """
        from ..adjust.fit import _jsonable
        from ..units import from_radians

        b = self.block
        es = self.exterior_std.copy()
        ext = b.exterior.copy()
        ext[:, 3:] = np.asarray(from_radians(ext[:, 3:], angle_unit))
        es[:, 3:] = np.asarray(from_radians(es[:, 3:], angle_unit))
        rms = self.rms_per_image  # once: the property scans every observation
        per_image = self.image_calibration()
        vg = self.gnss_residuals
        va = np.asarray(from_radians(self.imu_residuals, angle_unit))
        images = [
            {
                "id": i,
                **{n: float(v) for n, v in zip(EO_NAMES, ext[k])},
                **{f"s{n}": float(v) for n, v in zip(EO_NAMES, es[k])},
                "rms_px": float(rms[i]),
                "gnss_residual": [float(x) for x in vg[k]],
                "imu_residual": [float(x) for x in va[k]],
            }
            for k, i in enumerate(b.image_ids.tolist())
        ]
        orr = {
            k: (np.asarray(from_radians(v, angle_unit)) if k == "imu" else v)
            for k, v in self.orientation_residual_rms().items()
        }
        if per_image:
            from .block import IMAGE_VARIANT_NAMES

            off, ostd = b.calibration_offset, self.image_calibration_std
            for k, row in enumerate(images):
                for c, n in enumerate(IMAGE_VARIANT_NAMES):
                    row[f"{n}_offset"] = float(off[k, c])
                    row[f"s{n}_offset"] = float(ostd[k, c])
        return _jsonable(
            {
                "converged": self.converged,
                "iterations": self.iterations,
                "message": self.message,
                "sigma0": self.sigma0,
                "sigma0_prior": self.sigma0_prior,
                "redundancy": self.redundancy,
                "effective_redundancy": (
                    None if self.effective_redundancy is None else dict(self.effective_redundancy)
                ),
                "n_observations": self.n_observations,
                "n_unknowns": self.n_unknowns,
                "chi2": dict(self.chi2),
                "rmse_px": self.rmse,
                "orientation_residual_rms": orr,
                "gsd": self.gsd,
                "angle_unit": angle_unit,
                "residual_convention": "computed minus observed, pixels",
                "calibration": {str(g): v for g, v in self.calibration.items()},
                "calibration_std": {str(g): v for g, v in self.calibration_std.items()},
                "image_calibration": {str(g): v for g, v in per_image.items()},
                "high_correlations": [list(x) for x in self.high_correlations],
                "images": images,
                "check": dict(self.check),
                "control": dict(self.control),
                "snooping": None
                if self.snooping is None
                else {
                    "alpha": self.snooping["alpha"],
                    "critical_value": self.snooping["critical_value"],
                    "flagged": [list(x) for x in self.snooping["flagged"]],
                    "poorly_controlled": [
                        list(x) for x in self.snooping.get("poorly_controlled", [])
                    ],
                },
                "variance_components": self.variance_components,
                "cost_history": list(self.cost_history),
                "notes": list(self.notes),
                "elapsed_s": self.elapsed,
                "solver": dict(self.solver),
                "crs": self.crs,
                "crs_name": None if self.crs is None else _crs_label(self.crs),
            }
        )


def _effective_redundancy_text(eff: Mapping | None) -> str:
    """The effective redundancy of :meth:`BundleFit.summary`'s redundancy line, if any."""
    if eff is None:
        return ""
    how = (
        "exact"
        if eff.get("method") == "exact"
        else f"estimated from {eff.get('probes')} probes, seed {eff.get('seed')}, "
        f"standard error {eff.get('std', math.nan):.3g}"
    )
    return f"; effective redundancy of the chain {eff.get('value', math.nan):.1f} ({how})"


def _loss_line(solver: Mapping) -> str:
    """The loss of the adjustment for :meth:`BundleFit.summary`: with a robust one its
    scale and how sigma0 and the standard deviations are made consistent with it."""
    loss = solver.get("loss", "squared")
    if loss == "squared":
        return "loss: squared (least squares)"
    return (
        f"loss: {loss}, scale {solver.get('loss_scale', math.nan):g} a-priori sigmas "
        "(sigma0: weighted square sum over its expectation under normal errors; "
        "covariance: M-estimator sandwich)"
    )


#: Flagged observations the summary lists (largest |w| first); the rest are counted.
SUMMARY_FLAGGED = 20

#: Largest standard deviation of the focal length (px) not flagged as poorly determined: an
#: error of the focal length of df px moves the heights by about df GSD.
F_STD_MAX = 10.0

#: What separates a focal length from the flying height (the notes on poorly determined f).
F_SEPARATES = (
    "oblique images, a second flying height, height differences in the terrain, or both GNSS "
    "positions and control points"
)


def _f_poorly_determined(std, f):
    """Whether a focal length's standard deviation ``std`` (px) exceeds :data:`F_STD_MAX` px
    or 5 % of the focal length ``f`` (px): one the block does not determine."""
    return (std > F_STD_MAX) | (std > 0.05 * np.abs(f))

#: sigma0 above this many times its a-priori value, at convergence, gets a note naming the
#: causes (blunders, sigmas, a local minimum from poor start values).
SIGMA0_FAR = 3.0


def _image_focal_notes(block, state, f_std: np.ndarray) -> list[str]:
    """Notes on image-variant focal lengths the block does not determine: per camera group
    whose images' offsets of f have a standard deviation above :data:`F_STD_MAX` px or 5 %
    of f (the bound of the group's own focal length).

    Parameters
    ----------
    block : Block
        The adjusted block's input.
    state : _State
        The unknowns at the solution (``cal`` the groups' values, ``offset`` the images' offsets).
    f_std : numpy.ndarray, shape (m,)
        Standard deviations of the images' offsets of f, px; NaN where held.

    Returns
    -------
    list of str
    """
    notes = []
    f = state.cal[block.image_camera, 0] + state.offset[:, 0]  # each image's f, px
    weak = np.isfinite(f_std) & _f_poorly_determined(f_std, f)
    for gi in np.unique(block.image_camera[weak]).tolist():
        rows = block.image_camera == gi
        k, n = int(np.sum(weak & rows)), int(np.sum(np.isfinite(f_std) & rows))
        lo, hi = float(np.min(f_std[weak & rows])), float(np.max(f_std[weak & rows]))
        std = f"{lo:.3g} px" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g} to {hi:.3g} px"
        notes.append(
            f"camera {block.camera_ids[gi]}: the focal lengths estimated per image (image-variant "
            f"f) are poorly determined in {k} of its {n} images (std of their offsets {std} "
            f"of {float(np.median(f[rows])):.6g} px: heights uncertain by about "
            f"{hi:.3g} GSD): the block's geometry cannot separate them from the flying "
            "height; hold f (leave it out of the free parameters) or add what separates "
            f"it: {F_SEPARATES}"
        )
    return notes


def _near_gimbal_lock_note(
    ids: np.ndarray,
    phi: np.ndarray,
    ext_std: np.ndarray,
    image_cov: np.ndarray,
    rotation_cov: np.ndarray,
    free: np.ndarray,
) -> str | None:
    """The note on images near phi = +-90 degrees, or None.

    Parameters
    ----------
    ids : numpy.ndarray, shape (m,)
        Image ids.
    phi : numpy.ndarray, shape (m,)
        Adjusted phi, radians.
    ext_std : numpy.ndarray, shape (m, 6)
        Standard deviations of X0, Y0, Z0 (object units), omega, phi, kappa (radians).
    image_cov : numpy.ndarray, shape (m, 6, 6)
        Their covariances.
    rotation_cov : numpy.ndarray, shape (m, 3, 3)
        Covariances of the small rotations the adjustment estimates (radians squared).
    free : numpy.ndarray of bool, shape (m, 3)
        Which of omega, phi, kappa are estimated.

    Returns
    -------
    str or None
        The note naming the images, the inflation ``1 / cos(phi)`` and the attitude's own
        precision, when an estimated attitude has ``cos(phi)`` below
        :data:`photogeom.rotation.LOCK_COS_PHI`.
    """
    near = (np.cos(phi) < LOCK_COS_PHI) & free.all(axis=1)
    if not np.any(near):
        return None
    k = np.flatnonzero(near)
    listed = ", ".join(map(str, ids[k[:5]].tolist())) + (
        f" and {k.size - 5} more" if k.size > 5 else ""
    )
    margin = float(np.degrees(0.5 * np.pi - np.abs(phi[k])).min())
    inflation = float(1.0 / max(float(np.cos(phi[k]).min()), 1e-300))
    big = float(np.degrees(np.max(ext_std[k][:, [3, 5]])))
    own = float(np.degrees(np.sqrt(np.max(np.linalg.eigvalsh(rotation_cov[k])))))
    c = image_cov[k]
    rho = c[:, 3, 5] / np.maximum(np.sqrt(c[:, 3, 3] * c[:, 5, 5]), 1e-300)
    worst = float(rho[np.argmax(np.abs(rho))])
    return (
        f"{k.size} image(s) ({listed}) are near the gimbal lock of omega, phi, kappa (phi "
        f"within {margin:.3g} deg of +-90 deg): omega and kappa turn about nearly the same "
        f"axis there, so their standard deviations (up to {big:.3g} deg) are up to "
        f"1/cos(phi) = {inflation:.3g} times the attitude's own precision ({own:.3g} deg, the "
        f"largest standard deviation of a small rotation) and correlated {worst:+.4f}; use "
        "the angles' covariance together (image_covariance), not their separate standard "
        "deviations, or angles in an object system whose z axis is nearer the viewing "
        "direction"
    )


#: The route to start values of a block without GNSS/IMU, named in the notes of a run that
#: did not converge or stopped far above its a-priori sigmas.
START_ROUTE = (
    "start values from relative orientations and the control points "
    "(photogeom.bundle.start_from_relative_orientation; on the command line bundle adjust "
    "--start relative)"
)


def observed_control(block: Block) -> int:
    """The number of the block's control points observed in at least one of its images."""
    return int(np.intersect1d(np.flatnonzero(block.role == "control"), block.obs_point).size)


def start_route(block: Block) -> str:
    """:data:`START_ROUTE`, said with what the block lacks for it when fewer than three of
    its control points are observed in its images (the route orients the strips to them:
    a block read from a BAL or Bundler file or a COLMAP model has none)."""
    n = observed_control(block)
    if n >= 3:
        return START_ROUTE
    return (
        f"{START_ROUTE}, which needs 3 control points observed in the images, and the block "
        f"has {n} (BAL and Bundler files and COLMAP models hold none: add them in a CSV block)"
    )


def _crs_label(crs: str) -> str:
    from ..crs import crs_label

    return crs_label(crs)


# --- construction ----------------------------------------------------------------------------


def _chi2(vtpv: float, r: float, s0: float, alpha: float = 0.05) -> dict:
    from scipy import special

    if r <= 0:
        return {"statistic": vtpv, "dof": r, "p_value": math.nan, "passed": None}
    t = vtpv / s0**2
    p = float(2 * min(special.chdtr(r, t), special.chdtrc(r, t)))
    return {
        "statistic": float(t),
        "dof": int(r) if float(r).is_integer() else float(r),
        "p_value": p,
        "alpha": alpha,
        "lower": float(special.chdtri(r, 1 - alpha / 2)),
        "upper": float(special.chdtri(r, alpha / 2)),
        "passed": bool(p >= alpha),
    }


def statistics_pass(
    problem: Problem, state, weights, *, pairs: bool, cofactors: bool, run=None
):
    """Final linearisation, factor and the covariance blocks the result needs.

    ``run`` (the iteration's outcome, optional) names a run that stopped, unconverged or
    converged, where its last iterate leaves points undetermined by their rays (they were
    determined at the start, or the iteration would have failed there): a
    :class:`ConvergenceError` with those points, their rays, the residuals there and the
    route to start values, instead of the normal equations' error with a row number. A
    singular reduced system keeps its advice (an undetermined calibration parameter or
    datum also stops the iteration).
    """
    lin = problem.linearize(state, weights)
    try:
        ne = problem.sys.normal_equations(lin)
    except DegenerateGeometryError as exc:
        named = None if run is None else _stopped_with_undetermined_points(problem, state, run)
        if named is None:
            raise
        raise named from exc
    try:
        F = ne.factor()
        Q = covariance_blocks(ne, F, pairs=pairs)  # a dense inverse may fail where F did not
    except CGNotConvergedError:
        raise
    except DegenerateGeometryError as exc:
        named = singular_error(problem, lin, exc)
        if named is not None:
            raise named from exc
        raise DegenerateGeometryError(
            "the observations do not determine all free parameters at the solution "
            f"({exc}): fix calibration parameters the geometry cannot separate (e.g. "
            "free=('f', 'cx', 'cy', 'k1', 'k2', 'k3', 'p1', 'p2') without b1/b2/k4, or f on a "
            "flat block without GNSS/oblique images) or add control"
        ) from exc
    Qpp = point_covariances(ne, Q) if pairs else None
    Cobs = observation_cofactors(ne, Q, Qpp) if cofactors else None
    return lin, ne, F, Q, Qpp, Cobs


def _stopped_with_undetermined_points(problem: Problem, state, run) -> ConvergenceError | None:
    """The error of a run that stopped where its cameras leave points undetermined; None
    for a converged run where no point is (the normal equations' own error stands)."""
    block = problem.block
    _, e2, _ = problem.cost(state)
    pts = np.arange(problem.p)
    weak = pts[problem._weak_points(state, pts, state.X, e2)]
    rows = problem.adj_points[weak]
    ids = block.point_ids[rows].tolist()
    if run.converged and not ids:
        return None
    first = ""
    if ids:
        own = np.flatnonzero(problem.obs_j == weak[0])  # the first point's image rows
        seen = block.image_ids[problem.obs_i[own]].tolist()
        far = float(np.max(np.linalg.norm(state.X[weak[0]] - state.C[problem.obs_i[own]], axis=1)))
        spread = float(np.max(np.ptp(state.C, axis=0)))
        where = (
            f", whose {own.size} rays meet {far / spread:.3g} times the spread of the "
            "projection centres away from their cameras"
            if spread > 0
            else ""
        )
        first = f", e.g. point {ids[0]} (seen in image(s) {', '.join(map(str, seen[:6]))}){where}"
    rms = math.sqrt(float(np.mean(e2)) / 2.0) if e2.size else float("nan")
    how = (
        f"converged ({run.message.removeprefix('converged: ')}) to a state"
        if run.converged
        else f"stopped unconverged ({run.message})"
    )
    return ConvergenceError(
        f"the adjustment {how} where its cameras leave "
        f"{len(ids) or 'some'} point(s) undetermined by their rays (nearly parallel or "
        f"crossing far away){first}, with image residuals of {rms:.3g} times their "
        "standard deviations (RMS), so that no standard deviations exist there: the "
        "start values are too far off for the iteration (a block without GNSS/IMU: "
        f"{start_route(block)})",
        iterations=run.iterations,
    )


def _check_point_rays(problem: Problem, state, xyz: np.ndarray):
    """``N^-1`` (k, 3, 3) of the check points' rays and, per check point, the columns of
    the camera unknowns its rays depend on with ``B = P'A`` (3, cols) over them (whitened
    derivatives by the point, ``P``, and by the free camera unknowns, ``A``)."""
    block = problem.block
    cp = problem.check_points
    k = cp.size
    kmap = np.full(block.n_points, -1, dtype=np.int64)
    kmap[cp] = np.arange(k)
    rows = np.flatnonzero(kmap[block.obs_point] >= 0)
    kr = kmap[block.obs_point[rows]]
    A, G, P = problem.jacobians_at(state, rows, xyz[kr])
    Pt = P.transpose(0, 2, 1)
    N = np.zeros((k, 3, 3))
    np.add.at(N, kr, Pt @ P)
    Ninv = np.linalg.inv(N)
    b, nl = problem.b, problem.m * problem.b
    img = block.obs_image[rows]
    grp = block.image_camera[img]
    # derivatives of the normal equations' right side by the free camera unknowns only
    PA = Pt @ A * problem.local_free[img][:, None, :]
    gfree = problem.global_free.reshape(problem.ng, NCAL)
    PG = Pt @ G * gfree[grp][:, None, :]
    order = np.argsort(kr, kind="stable")
    starts = np.searchsorted(kr[order], np.arange(k + 1))
    terms = []
    for j in range(k):  # over the (few) check points, not over observations
        sel = order[starts[j] : starts[j + 1]]
        ims, ipos = np.unique(img[sel], return_inverse=True)
        gs, gpos = np.unique(grp[sel], return_inverse=True)
        local_cols = (ims[:, None] * b + np.arange(b)).ravel()
        global_cols = (nl + gs[:, None] * NCAL + np.arange(NCAL)).ravel()
        cols = np.concatenate([local_cols, global_cols])
        B = np.zeros((3, cols.size))
        li = ipos[:, None] * b + np.arange(b)
        gi = ims.size * b + (gpos[:, None] * NCAL + np.arange(NCAL))
        for t in range(sel.size):  # the check point's rays
            B[:, li[t]] += PA[sel[t]]
            B[:, gi[t]] += PG[sel[t]]
        terms.append((ims, gs, cols, B))
    return Ninv, terms


def check_point_covariance(
    problem: Problem,
    state,
    factor,
    xyz: np.ndarray,
    var: float,
    *,
    cameras: bool = True,
    blocks: CovarianceBlocks | None = None,
) -> np.ndarray:
    """Covariance (k, 3, 3) of the check points triangulated with the adjusted cameras.

    A check point ``X`` minimises its own image residuals with the cameras ``c`` held at
    their estimates, so ``dX = -N^-1 P'(A dc - e)`` and

        Cov(X) = sigma0^2 (N^-1 + N^-1 B Q_cc B' N^-1),   N = P'P,  B = P'A,

    ``P`` and ``A`` the whitened derivatives of its observations by the point and by the
    cameras' unknowns (orientations and calibrations of the images that see it), ``Q_cc``
    their cofactor block from the adjustment. The first term alone (``cameras=False``) is
    the triangulation with exact cameras.

    ``Q_cc`` is assembled from ``blocks`` (the images' diagonal blocks, the blocks of
    image pairs that share a point, and the calibration's), which the adjustment has
    computed for the points' covariances; only a check point seen by two images that share
    no adjusted point needs a solve with the factor (its images' and groups' columns).

    Parameters
    ----------
    problem, state
        The adjustment and its solution.
    factor
        The factor of the reduced camera system at the solution.
    blocks : CovarianceBlocks, optional
        Blocks of its inverse with ``pairs`` (:func:`covariance_blocks` with
        ``pairs=True``); without them every check point takes a solve.
    xyz : (k, 3)
        The triangulated check points (object coordinates), in ``problem.check_points``
        order.
    var : float
        sigma0^2 a posteriori.
    """
    if not cameras:
        block = problem.block
        cp = problem.check_points
        kmap = np.full(block.n_points, -1, dtype=np.int64)
        kmap[cp] = np.arange(cp.size)
        rows = np.flatnonzero(kmap[block.obs_point] >= 0)
        kr = kmap[block.obs_point[rows]]
        _, _, P = problem.jacobians_at(state, rows, xyz[kr])
        N = np.zeros((cp.size, 3, 3))
        np.add.at(N, kr, P.transpose(0, 2, 1) @ P)
        return var * np.linalg.inv(N)
    Ninv, terms = _check_point_rays(problem, state, xyz)
    out = Ninv.copy()
    pair_index = None
    if blocks is not None and blocks.pairs is not None:
        pairs = problem.sys.blocks
        pair_index = {(int(a), int(c)): t for t, (a, c) in enumerate(pairs.tolist())}
    for j, (ims, gs, cols, B) in enumerate(terms):  # over the (few) check points
        try:
            Qs = _camera_cofactors(problem, blocks, pair_index, ims, gs)
        except LookupError:  # calibrations held in images that share no point
            Qs = None
        if Qs is None:  # an image pair without a common point: its block by a solve
            E = np.zeros((problem.sys.nc, cols.size))
            E[cols, np.arange(cols.size)] = 1.0
            Qs = factor.solve(E)[cols]
        T = Ninv[j] @ B
        out[j] += T @ Qs @ T.T
    return var * 0.5 * (out + out.transpose(0, 2, 1))


def similarity_generators(xyz: np.ndarray) -> np.ndarray:
    """(3k, 7) derivatives of the points ``xyz`` (k, 3) by a small similarity
    transformation about their centroid: 3 shifts, 3 rotations, the scale (columns scaled
    to the points' spread, for conditioning)."""
    d = xyz - xyz.mean(axis=0)
    s = max(float(np.sqrt(np.mean(np.sum(d * d, axis=1)))), 1e-300)
    k = xyz.shape[0]
    G = np.zeros((k, 3, 7))
    G[:, :, :3] = np.eye(3)
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        G[:, :, 3 + a] = np.cross(e, d) / s
    G[:, :, 6] = d / s
    return G.reshape(3 * k, 7)


def similarity_residuals(xyz: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``T(xyz) - target`` (k, 3) for the 7-parameter similarity ``T`` that fits the points
    ``xyz`` best to ``target`` (least squares, equal weights; closed form by the SVD of the
    cross-covariance: the absolute orientation's :func:`~photogeom.orientation.
    absolute_direct.solve_svd`). NaN when fewer than 3 points or all on a line."""
    from ..orientation.absolute_direct import batch_moments, solve_svd

    k = xyz.shape[0]
    if k < 3:
        return np.full((k, 3), np.nan)
    a = xyz - xyz.mean(axis=0)
    sv = np.linalg.svd(a, compute_uv=False)
    if float(np.sum(a * a)) <= 0 or sv[1] <= 1e-9 * sv[0]:
        return np.full((k, 3), np.nan)
    fit = solve_svd(batch_moments(xyz[None], target[None]))
    return fit.scale[0] * xyz @ fit.rotation[0].T + fit.translation[0] - target


def free_check_point_covariance(
    problem: Problem, state, factor, xyz: np.ndarray, var: float
) -> np.ndarray:
    """Covariance (k, 3, 3) of a free network's check points in their own datum: the
    coordinates after the similarity transformation that fits them best to their survey
    (equal weights), the check points' errors' part from the network.

    The joint covariance ``C`` (3k, 3k) of the triangulated check points (their rays'
    ``N^-1`` and the cameras' part ``T Q_cc T'`` with the cross terms of points seen by the
    same images; ``T = N^-1 B`` of every check point, ``Q_cc T'`` by 3k solves with the
    factor) is S-transformed onto the check points, ``P C P'`` with ``P = I - G (G'G)^-1
    G'`` and ``G`` the points' similarity derivatives (:func:`similarity_generators`): the
    result is the same in every datum of the network. The survey's own errors add
    ``P C_survey P'`` to the errors' covariance; they are not included.
    """
    Ninv, terms = _check_point_rays(problem, state, xyz)
    k = Ninv.shape[0]
    # the cameras' part T Q_cc T' with T (3k, nc) the points' N^-1 B: 3k solves
    Tt = np.zeros((problem.sys.nc, 3 * k))
    for j, (_, _, c, B) in enumerate(terms):  # over the (few) check points
        Tt[c, 3 * j : 3 * j + 3] = (Ninv[j] @ B).T
    C = Tt.T @ factor.solve(Tt)
    for j in range(k):
        C[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] += Ninv[j]
    G = similarity_generators(xyz)
    Pm = np.eye(3 * k) - G @ np.linalg.solve(G.T @ G, G.T)
    CS = Pm @ C @ Pm.T
    out = np.stack([CS[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] for j in range(k)])
    return var * 0.5 * (out + out.transpose(0, 2, 1))


def _camera_cofactors(problem: Problem, blocks, pair_index, ims, gs) -> np.ndarray | None:
    """``Q_cc`` of images ``ims`` (their local unknowns) and camera groups ``gs`` (their
    calibrations), in that order, from the covariance blocks; None when a pair of the
    images has no block (they share no adjusted point) or there are no blocks (a
    LookupError where the calibration of such an image is held in its local block)."""
    if pair_index is None:
        return None
    b = problem.b
    ni = ims.size
    gcols = (gs[:, None] * NCAL + np.arange(NCAL)).ravel()
    n = ni * b + gcols.size
    Qs = np.zeros((n, n))
    for a in range(ni):  # over the few images of one check point
        sa = slice(a * b, (a + 1) * b)
        Qs[sa, sa] = blocks.local[ims[a]]
        Qs[sa, ni * b :] = blocks.local_global_block(ims[a], gcols)
        for c in range(a + 1, ni):
            t = pair_index.get((int(ims[a]), int(ims[c])))
            if t is None:
                return None
            sc = slice(c * b, (c + 1) * b)
            Qs[sa, sc] = blocks.pairs[t]
            Qs[sc, sa] = blocks.pairs[t].T
    Qs[ni * b :, : ni * b] = Qs[: ni * b, ni * b :].T
    Qs[ni * b :, ni * b :] = blocks.global_block(gcols, gcols)
    return Qs


def least_squares_square_sum(problem: Problem, state) -> float:
    """``v'Pv`` (whitened by the a-priori sigmas and the variance factors) of the
    least-squares solution of the model linearised at ``state``, all image observations at
    full weight: the linearisation's cost minus the decrease of one undamped Gauss-Newton
    step. At a robust solution on clean data this is the least-squares minimum to second
    order, chi-square with ``r`` degrees of freedom under normal errors whatever the
    geometry; blunders (which the robust weights had muted) raise it."""
    lin = problem.linearize(state, np.ones(problem.obs_i.size))
    ne = problem.sys.normal_equations(lin)
    dc, dp, _ = ne.solve()
    return float(lin.cost - ne.predicted_decrease(dc, dp, 0.0))


def build_result(
    problem: Problem, run, opts, vce, elapsed: float, effective_redundancy: Mapping | None = None
) -> BundleFit:
    from scipy import special

    block = problem.block
    state = run.state
    # a robust loss needs the redundancy numbers for a consistent sigma0 (robust.py)
    cofactors = bool(opts.snooping or opts.loss != "squared")
    need_pairs = bool(opts.point_covariance or cofactors)
    lin, ne, F, Q, Qpp, Cobs = statistics_pass(
        problem, state, run.weights, pairs=need_pairs, cofactors=cofactors, run=run
    )
    check_determined(problem, lin, Q)  # a singular system that rounding let factorise
    m = problem.m
    n_obs, n_unk = problem.counts()
    red = n_obs - n_unk
    vtpv = float(lin.cost)
    s0p = opts.sigma0_prior
    # with a robust loss v'PWv is divided by its Stein redundancy, whose expectation times
    # the variance factor is that of v'PWv under normal errors (robust.stein_redundancy)
    leverage = None if Cobs is None else image_point_leverage(Cobs, run.weights)
    var = vtpv / red if red > 0 else math.nan
    if opts.loss != "squared" and red > 0:
        sw = np.sqrt(run.weights)
        e = lin.r / sw[:, None]  # whitened residuals without the robust weights
        slopes = score_slopes(opts.loss, opts.scale, np.einsum("nd,nd->n", e, e))
        _, _, _, _, _, Cd = statistics_pass(problem, state, slopes, pairs=True, cofactors=True)
        r_s = stein_redundancy(red, slopes, Cd) + point_trace_correction(
            opts.loss, opts.scale, e, lin.P / sw[:, None, None], problem.obs_j, lin.point_info
        )
        var = vtpv / r_s
    # a redundancy counted over a chain of estimates (calibration.readjust with grids fitted
    # to these observations): the variance over it instead of over this adjustment's own
    r_test: float = red
    if effective_redundancy is not None and red > 0:
        r_test = float(effective_redundancy["value"])
        var *= red / r_test
    # the observations are whitened by their a-priori sigmas (weights 1 / sigma^2, in which
    # every cofactor, var and v'Pv here are); with P = sigma0_prior^2 / sigma^2 (the library's
    # convention) sigma0 is sigma0_prior sqrt(var), the global test v'Pv / sigma0_prior^2 and
    # the w-test do not depend on sigma0_prior, and the covariances are var times the cofactors
    sigma0 = s0p * math.sqrt(var) if red > 0 else math.nan
    # the global test: with a robust loss v'PWv / kappa neither has expectation r (kappa's
    # model is a few per cent off) nor the spread of chi-square(r) (kappa is evaluated at
    # the estimated variance); the least-squares v'Pv of the final linearisation has both
    test_vtpv = vtpv
    if opts.loss != "squared" and red > 0:
        test_vtpv = least_squares_square_sum(problem, state)
        # the covariance of an M-estimator is the sandwich H^-1 B H^-1, not the inverse of
        # the IRLS-weighted normal matrix (whose standard deviations were up to 10 % too
        # large with Cauchy's loss): the normal matrix with the points' sandwich
        # weights (robust.covariance_weights) instead; the w-test keeps the redundancy
        # numbers of the weighted adjustment (Cobs, lin)
        cw = covariance_weights(leverage, opts.loss, opts.scale, var)
        _, ne, F, Q, Qpp, _ = statistics_pass(problem, state, cw, pairs=need_pairs, cofactors=False)
    notes = []
    # exterior orientation covariance in X0..kappa
    angles = opk_from_rotations(state.M)
    T = opk_from_increment_jacobian(angles)
    Jm = np.zeros((m, 6, 6))
    Jm[:, :3, :3] = np.eye(3)
    Jm[:, 3:, 3:] = T
    Ql6 = Q.local[:, :6, :6]
    if problem.free_datum is not None:
        Ql6, Qpp = _inner_constraint_centres(problem, ne, F, Q, state, Qpp)
        notes.append(
            "free network: covariances of the exterior orientation and the points in the "
            "inner-constraint (minimum-trace) datum of the projection centres"
        )
    image_cov = var * np.einsum("mij,mjk,mlk->mil", Jm, Ql6, Jm)
    ext_std = np.sqrt(np.clip(np.einsum("mii->mi", image_cov), 0, None))
    fixed6 = ~problem.local_free[:, :6]
    if problem.free_datum is not None and not opts.fix_exterior:
        # the minimal constraints are only a computational datum: after the transformation
        # to inner constraints every image has its (non-zero) standard deviations
        fixed6 = np.zeros_like(fixed6)
    ext_std[fixed6] = 0.0
    lock_note = _near_gimbal_lock_note(
        block.image_ids, angles[:, 1], ext_std, image_cov, var * Ql6[:, 3:, 3:], ~fixed6[:, 3:]
    )
    if lock_note:
        notes.append(lock_note)
    # image-variant calibration: the images' offsets of f, cx, cy (datum-invariant)
    iv_std = np.full((m, 3), np.nan)
    if problem.b > 6:
        d = np.sqrt(np.clip(var * np.einsum("mii->mi", Q.local[:, 6:9, 6:9]), 0, None))
        est = problem.local_free[:, 6:9]
        iv_std[est] = d[est]
        notes.extend(_image_focal_notes(block, state, iv_std[:, 0]))
    # calibration
    calib, cal_std, cal_corr, cal_cov, high = {}, {}, {}, {}, []
    for gi, gid in enumerate(block.camera_ids.tolist()):
        sl = slice(gi * NCAL, (gi + 1) * NCAL)
        free = problem.global_free[sl]
        gcols = np.arange(sl.start, sl.stop)
        Qg = Q.global_block(gcols, gcols)
        calib[gid] = {n: float(state.cal[gi, k]) for k, n in enumerate(CALIBRATION_NAMES)}
        std = np.sqrt(np.clip(np.diag(Qg) * var, 0, None))
        cal_std[gid] = {
            n: (float(std[k]) if free[k] else math.nan) for k, n in enumerate(CALIBRATION_NAMES)
        }
        names = tuple(n for k, n in enumerate(CALIBRATION_NAMES) if free[k])
        C = Qg[np.ix_(free, free)] * var
        d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
        R = C / np.outer(d, d)
        cal_corr[gid] = (names, R)
        C.flags.writeable = False  # returned as stored by calibration_covariance
        cal_cov[gid] = (names, C)
        for a in range(len(names)):
            for c in range(a + 1, len(names)):
                if abs(R[a, c]) > opts.correlation_threshold:
                    high.append((gid, names[a], names[c], float(R[a, c])))
        # weak determinability. An error df of f moves the depths by df / f: by df GSD
        # (GSD = depth / f), the points' heights where GNSS holds the cameras, the cameras'
        # where control holds the ground. A std above F_STD_MAX px (or 5 % of f) is a focal
        # length the block does not determine
        if free[0] and _f_poorly_determined(std[0], state.cal[gi, 0]):
            notes.append(
                f"camera {gid}: the focal length is poorly determined (std {std[0]:.3g} px of "
                f"{state.cal[gi, 0]:.6g} px: heights uncertain by about {std[0]:.3g} GSD): "
                "the block's geometry cannot separate it from the flying height; hold f (leave "
                "it out of the free parameters, at a known calibration) or add what separates "
                f"it: {F_SEPARATES}"
            )
    if problem.unused_groups:
        notes.append(
            f"camera group(s) {', '.join(map(str, problem.unused_groups))} have no images: "
            "their calibration is not adjusted (it stays at its given values)"
        )
    if high:
        worst = sorted(high, key=lambda h: -abs(h[3]))[:4]
        pairs = ", ".join(f"{n1} / {n2} {rho:+.3f} (camera {g})" for g, n1, n2, rho in worst)
        more = f" and {len(high) - len(worst)} more" if len(high) > len(worst) else ""
        notes.append(
            f"{len(high)} calibration correlation(s) above {opts.correlation_threshold}: "
            f"{pairs}{more}; those parameters are not separated well by this block: hold one "
            "of each pair (leave it out of the free parameters) or add images that separate "
            "them (oblique images, a second flying height, points out to the image corners)"
        )
    # points: adjusted and check points
    adjusted = problem.to_block(state)
    point_std = None
    point_cov = None
    if Qpp is not None:
        point_cov = np.full((block.n_points, 3, 3), np.nan)
        point_cov[problem.adj_points] = Qpp * var
    check = {"ids": []}
    check_xyz = None
    if problem.check_points.size:
        from .triangulate import triangulate

        tri = triangulate(adjusted, block.point_ids[problem.check_points], covariance=True)
        if not np.all(tri.ok):
            bad = tri.point_ids[~tri.ok]
            text = (
                f"check point(s) {', '.join(map(str, bad[:5]))} cannot be triangulated from "
                f"their image observations ({tri.describe_failures()})"
            )
            if not run.converged:  # with cameras far from a solution the cause is the run
                raise ConvergenceError(
                    f"{text}: the adjustment stopped ({run.message}) far from a solution; the "
                    "start values may be too far off (a block without GNSS/IMU: "
                    f"{start_route(block)})",
                    iterations=run.iterations,
                )
            raise InputError(text)
        X0 = block.surveyed_xyz[problem.check_points]
        check_xyz = tri.xyz
        err = check_xyz - X0
        convention = (
            "triangulated from the image observations with the adjusted cameras, minus surveyed"
        )
        if problem.free_datum is not None:
            # a free network's datum is arbitrary: compare its shape, after the similarity
            # transformation that fits the check points best to their survey
            err = similarity_residuals(check_xyz, X0)
            convention = (
                "triangulated from the image observations with the adjusted cameras, "
                "transformed by the 7-parameter similarity that fits them best to their "
                "survey (free network), minus surveyed"
            )
            if np.isnan(err).all():
                notes.append(
                    "free network: the check points are not compared with their survey: the "
                    "similarity transformation onto it needs at least 3 check points not on "
                    "a line"
                )
        gsd = adjusted.gsd()
        rm = np.sqrt(np.mean(err**2, axis=0))
        check = {
            "ids": block.point_ids[problem.check_points].tolist(),
            "errors": err,
            "rmse": rm,
            "rmse_gsd": rm / gsd,
            "convention": convention,
        }
        if point_cov is not None and problem.free_datum is None:
            point_cov[problem.check_points] = check_point_covariance(
                problem, state, F, check_xyz, var, blocks=Q
            )
        elif point_cov is not None and not np.isnan(err).all():
            point_cov[problem.check_points] = free_check_point_covariance(
                problem, state, F, check_xyz, var
            )
            notes.append(
                "free network: check points compared with their survey after a similarity "
                "transformation onto it; their standard deviations in that datum"
            )
    adjusted = problem.to_block(state, check_xyz)
    control = {"ids": []}
    if problem.control.size:
        ci = problem.adj_points[problem.control]
        cerr = adjusted.xyz[ci] - block.surveyed_xyz[ci]
        crm = np.sqrt(np.mean(cerr**2, axis=0))
        control = {
            "ids": block.point_ids[ci].tolist(),
            "errors": cerr,
            "rmse": crm,
            "rmse_gsd": crm / adjusted.gsd(),
            "sigma": block.point_sigma[ci],
            "convention": "adjusted minus surveyed",
        }
    if point_cov is not None:
        point_std = np.sqrt(np.clip(np.einsum("pii->pi", point_cov), 0, None))
    residuals = reprojection_residuals(adjusted, behind="nan")
    in_adj = np.zeros(block.n_observations, dtype=bool)
    in_adj[problem.obs_rows] = True
    snoop = None
    if Cobs is not None and opts.snooping:
        # Baarda's w of each coordinate: the unweighted normalised residual e (whitened by
        # the a-priori sigma, without the robust weight) over its standard deviation. With
        # robust weight w_i and h = (J Q J')_ii the leverage in the weighted adjustment, the
        # prediction moves with the observation by h and varies by about h / w_i (its
        # leverage at unit weight, an upper bound), so var(e) = 1 - 2 h + h / w_i. Without a
        # robust loss (w_i = 1) this is the classical 1 - h; with one, 1 - h / w_i (as if the
        # observation had its full weight) gave 4.4 (Huber) and 6.5 (Cauchy) times alpha
        # false alarms on clean data. Down-weighted blunders keep their large w.
        wt = np.clip(run.weights, 1e-12, None)[:, None]
        h = np.clip(np.einsum("ndd->nd", Cobs), 0.0, None)
        qvv = 1.0 - 2.0 * h + h / wt
        rw = lin.r / np.sqrt(wt)  # whitened residuals without the robust weights
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(qvv > 1e-10, rw / np.sqrt(np.clip(qvv, 1e-300, None)), np.nan)
        crit = float(special.ndtri(1 - opts.alpha / 2))
        wall = np.full((block.n_observations, 2), np.nan)
        wall[problem.obs_rows] = w
        red_num = np.full((block.n_observations, 2), np.nan)
        red_num[problem.obs_rows] = qvv
        mx = np.nanmax(np.abs(wall), axis=1, initial=0)
        order = np.argsort(-np.nan_to_num(mx, nan=0.0))
        flagged = [
            (
                block.observations.image_ids[k].item(),
                block.observations.point_ids[k].item(),
                float(mx[k]),
            )
            for k in order
            if mx[k] > crit
        ]
        # internal reliability: the minimal detectable bias of every coordinate (units of its
        # a-priori sigma) and the poorly controlled observations, where a blunder hardly
        # shows in the residuals (e.g. along the base of a point seen in two images)
        d0 = noncentrality(opts.alpha)
        with np.errstate(invalid="ignore", divide="ignore"):
            mdb = np.where(red_num > 1e-14, d0 / np.sqrt(np.abs(red_num)), np.inf)
            poor = np.any(red_num < POORLY_CONTROLLED, axis=1)
        mdb[np.isnan(red_num)] = np.nan
        poor_rows = np.flatnonzero(poor)
        snoop = {
            "w": wall,
            "redundancy_numbers": red_num,
            "alpha": opts.alpha,
            "critical_value": crit,
            "flagged": flagged,
            "mdb": mdb,
            "poorly_controlled": [
                (block.observations.image_ids[k].item(), block.observations.point_ids[k].item())
                for k in poor_rows.tolist()  # observations with r < 0.1 only
            ],
        }
        if flagged:
            notes.append(
                f"{len(flagged)} image observation(s) fail the w-test (largest |w| "
                f"{flagged[0][2]:.1f} at image {flagged[0][0]}, point {flagged[0][1]}); they "
                "are listed, not removed"
            )
        if poor_rows.size:
            rays = np.bincount(block.obs_point[in_adj], minlength=block.n_points)
            two = int(np.sum(rays[block.obs_point[poor_rows]] <= 2))
            notes.append(
                f"{poor_rows.size} image observation(s) are poorly controlled (a redundancy "
                f"number below {POORLY_CONTROLLED:g} in u or v: the smallest blunder the "
                f"w-test finds there exceeds {d0 / math.sqrt(POORLY_CONTROLLED):.0f} sigma, "
                f"smaller ones pass unnoticed), {two} of them of points seen in two images "
                "(an error along the base moves the point instead); they are listed in "
                "snooping['poorly_controlled']: measure those points in more images"
            )
    if not run.converged:
        # a start degrees and tens of metres off (no GNSS/IMU) ends here or at a wrong
        # minimum: 12 of 21 simulated blocks 20 m and 10 degrees off, none from START_ROUTE
        notes.append(
            f"{run.message}: the start values may be too far off (a block without GNSS/IMU: "
            f"{start_route(block)}), or the cost still falls (more iterations)"
        )
    elif sigma0 > SIGMA0_FAR * s0p:
        # a converged run far above the a-priori sigmas: blunders, sigmas too small, or a
        # local minimum (a start with the calibration free and the attitudes 5 degrees off
        # stopped at sigma0 24 where the calibration held first reached 1.04, before the
        # point-only steps of tie points whose own step raised their cost)
        notes.append(
            f"sigma0 {sigma0:.3g} is more than {SIGMA0_FAR:g} times its a-priori "
            f"{s0p:g}: blunders (see the w-test), a-priori sigmas too small, or start values "
            "so far off that the adjustment stopped in a local minimum; for the last, adjust "
            "with the calibration held first (no free parameters) and then free it from "
            f"that result, or (a block without GNSS/IMU) take {start_route(block)}"
        )
    vc = None
    if vce is not None:
        vc = vce
        if not vce.get("converged", True):
            notes.append(
                f"variance components did not converge in {vce.get('rounds')} round(s) (the "
                "factors still changed by more than the tolerance): the factors and the "
                "standard deviations depend on where the iteration stopped; a group with few "
                "observations (a handful of control points) may be collapsing toward factor 0: "
                "hold it at its a-priori sigmas, or adjust without variance components"
            )
        for k, why in vce.get("not_estimated", {}).items():
            notes.append(
                f"variance components: the group '{k}' is not estimated ({why}); it keeps "
                "its a-priori sigmas (factor 1)"
            )
    solver = {
        "backend": F.backend,
        "reduced_system_size": int(ne.S.shape[0]),  # as solved (own groups in the images)
        "reduced_system_nonzeros": int(ne.S.nnz),
        "loss": opts.loss,
        # the scale of a robust loss, in a-priori sigmas of the image coordinates
        "loss_scale": None if opts.loss == "squared" else float(opts.scale),
    }
    return BundleFit(
        block=adjusted,
        sigma0=sigma0,
        sigma0_prior=s0p,
        redundancy=int(red),
        n_observations=int(n_obs),
        n_unknowns=n_unk,
        converged=bool(run.converged),
        iterations=int(run.iterations),
        message=run.message,
        cost_history=tuple(run.history),
        residuals=residuals,
        in_adjustment=in_adj,
        calibration=calib,
        calibration_std=cal_std,
        calibration_correlation=cal_corr,
        high_correlations=high,
        exterior_std=ext_std,
        point_std=point_std,
        check=check,
        snooping=snoop,
        variance_components=vc,
        # v'Pv / sigma0_prior^2 with P = sigma0_prior^2 / sigma^2
        chi2=_chi2(test_vtpv, r_test, 1.0),
        gsd=float(adjusted.gsd()),
        notes=tuple(notes),
        elapsed=elapsed,
        solver=solver,
        control=control,
        correlation_threshold=float(opts.correlation_threshold),
        image_calibration_std=iv_std,
        _image_cov=image_cov,
        _point_cov=point_cov,
        _cal_cov=cal_cov,
        effective_redundancy=None if effective_redundancy is None else dict(effective_redundancy),
    )


def _inner_constraint_centres(problem: Problem, ne, F, Q, state, Qpp=None):
    """Cofactor blocks (m, 6, 6) of the exterior orientations, and (p, 3, 3) of the points
    when ``Qpp`` (minimal datum) is given, transformed from the minimal datum to inner
    constraints on the projection centres (S-transformation).

    The null space of the free network is spanned by 3 shifts, 3 rotations and the scale
    acting on the centres and points (and rotations on the attitudes). ``Q_inner = P Q P'``
    with ``P = I - G (G' H G)^-1 G' H`` and ``H`` selecting the centres; only the diagonal
    blocks are formed, from ``Q H G`` (7 solves of the reduced system; its point rows
    ``Q_pc H G = -V^-1 W' Q_cc H G`` by back-substitution).
    """
    m, b, nc = problem.m, problem.b, problem.sys.nc
    C = state.C
    G = np.zeros((nc, 7))
    for a in range(3):
        G[np.arange(m) * b + a, a] = 1.0  # shifts
    # rotations: dC = w x C, attitude increment dtheta = -M w (left increment of M)
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        dC = np.cross(e, C)
        G[(np.arange(m) * b)[:, None] + np.arange(3), 3 + a] = dC
        G[(np.arange(m) * b)[:, None] + 3 + np.arange(3), 3 + a] = -(state.M @ e)
    G[(np.arange(m) * b)[:, None] + np.arange(3), 6] = C  # scale
    free = np.concatenate([problem.local_free.ravel(), problem.global_free])
    H = np.zeros(nc)
    H[(np.arange(m) * b)[:, None] + np.arange(3)] = 1.0
    # P Q P' with P = I - G K, K = (G' H G)^-1 G' H; Q K' = Q H G (G' H G)^-1
    K = np.linalg.solve(G.T @ (H[:, None] * G), (G * H[:, None]).T)  # (7, nc)
    A7 = np.linalg.inv(G.T @ (H[:, None] * G))
    QHG = F.solve((H[:, None] * G) * free[:, None])
    QHG[~free] = 0.0
    QK = QHG @ A7  # (nc, 7) = Q K'
    KQK = K @ QK  # (7, 7)
    for_rows = (np.arange(m) * b)[:, None] + np.arange(6)
    Gi = G[for_rows]  # (m, 6, 7)
    QKi = QK[for_rows]  # (m, 6, 7)
    out = (
        Q.local[:, :6, :6]
        - np.einsum("mik,mjk->mij", Gi, QKi)
        - np.einsum("mik,mjk->mij", QKi, Gi)
        + np.einsum("mik,kl,mjl->mij", Gi, KQK, Gi)
    )
    out = 0.5 * (out + out.transpose(0, 2, 1))
    if Qpp is None:
        return out, None
    # point rows of Q H G: back-substitution is affine in the camera-side vector
    zero = ne.back_substitute(np.zeros(nc))
    QHGp = np.stack([ne.back_substitute(QHG[:, k]) - zero for k in range(7)], axis=2)
    QKp = QHGp @ A7  # (p, 3, 7)
    X = state.X
    Gp = np.zeros((X.shape[0], 3, 7))
    Gp[:, :, :3] = np.eye(3)
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        Gp[:, :, 3 + a] = np.cross(e, X)
    Gp[:, :, 6] = X
    pts = (
        Qpp
        - np.einsum("pik,pjk->pij", Gp, QKp)
        - np.einsum("pik,pjk->pij", QKp, Gp)
        + np.einsum("pik,kl,pjl->pij", Gp, KQK, Gp)
    )
    return out, 0.5 * (pts + pts.transpose(0, 2, 1))
