"""``Fit``: the one result family returned by every estimator of photogeom."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..records import FrozenMapping, build, compact_repr, read_only_fields, setstate_read_only
from ..units import display_angle, from_radians
from .result import NO_STATISTICS_NOTE, Adjustment, not_computed
from .snooping import SnoopingResult, data_snooping

#: Significance level of the outlier tests of a fit that records none (Baarda's 0.001:
#: critical w 3.29).
DEFAULT_ALPHA = 0.001


def propagate_covariance(C: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Covariance of ``g(x)`` from that of ``x``: ``J C J.T`` (J = dg/dx).

    Parameters
    ----------
    C : array_like, shape (u, u)
        Covariance of ``x``, in the squared units of ``x``.
    J : array_like, shape (k, u)
        Jacobian ``dg/dx`` (units of ``g`` per unit of ``x``).

    Returns
    -------
    numpy.ndarray, shape (k, k)
        Covariance of ``g``, in the squared units of ``g``.
    """
    J = np.asarray(J, dtype=float)
    return J @ np.asarray(C, dtype=float) @ J.T


def _read_only_view(value):
    """``value``, or a read-only view of it when it is a writable array."""
    if isinstance(value, np.ndarray) and value.flags.writeable:
        value = value.view()
        value.flags.writeable = False
    return value


def _own_extra(value):
    """``value`` as a Fit keeps it in ``extras``: dicts, lists and sets (also inside tuples)
    copied all the way down, writable arrays as read-only views; other values as they are.

    Each Fit (and each copy :meth:`Fit.with_crs`, :meth:`Fit.with_checks` or
    :func:`dataclasses.replace` makes) holds containers of its own, of the same types (so
    ``extras["removed"] == [3]`` still compares as a list): writing into one Fit's nested
    extras cannot change another's.
    """
    if isinstance(value, np.ndarray):
        return _read_only_view(value)
    if type(value) is dict:
        return {k: _own_extra(v) for k, v in value.items()}
    if type(value) is list:
        return [_own_extra(v) for v in value]
    if type(value) is set:
        return set(value)  # members are hashable, hence not containers to copy
    if type(value) is tuple:
        return tuple(_own_extra(v) for v in value)
    return value


def _jsonable(value):
    """``value`` with numpy arrays and scalars as Python lists and numbers, NaN and
    infinities as None (JSON has neither), mapping keys as str."""
    if isinstance(value, np.ndarray):
        if not value.ndim:
            return _jsonable(value.item())
        if value.dtype.kind in "biu":  # whole arrays at once: one row per point is common
            return value.tolist()
        if value.dtype.kind == "f":
            bad = ~np.isfinite(value)
            if not bad.any():
                return value.astype(np.float64).tolist()
            out = value.astype(np.float64).astype(object)
            out[bad] = None
            return out.tolist()
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


@dataclass(frozen=True, eq=False, repr=False)
class Fit:
    """Result of an estimation: model, parameters, statistics, residuals, diagnostics.

    Residuals are **computed minus observed**, in the target (observation) system, one row
    per control point. Check points do not enter the estimate; their residuals are reported
    separately. Angles are in radians (``parameter_units`` says so); ``summary`` can show
    them in degrees or gon.

    Attributes
    ----------
    model : object
        The fitted model (a transformation, camera, ...); also available as ``transform``.
    method : str
        Estimation method (e.g. ``"linear least squares"``, ``"svd"``).
    parameter_names : tuple of str
    parameters : numpy.ndarray
        Estimated parameters in the order of ``parameter_names``.
    covariance : numpy.ndarray
        A-posteriori covariance ``sigma0^2 Qxx`` of ``parameters`` (NaN when r = 0).
    cofactor : numpy.ndarray
        ``Qxx`` of ``parameters``.
    sigma0 : float
        A-posteriori standard deviation of unit weight (NaN when r = 0: undefined).
    sigma0_prior : float
    redundancy : int
    n_observations : int
    residuals : numpy.ndarray, shape (n, d)
    ids : tuple or None
        Point ids of the residual rows.
    residual_labels : tuple of str
        Axis names of the residual columns.
    residual_unit : str
        Unit of the residuals (e.g. ``"m"``, ``"mm"``, ``"px"``).
    parameter_units : mapping
        Unit of each parameter (``"rad"`` for angles, ``"1"`` for unitless); read-only
        (``dict(fit.parameter_units)`` is a dict of one's own).
    check_residuals, check_ids
        Residuals of check points (computed minus observed) and their ids.
    normalized_residuals : numpy.ndarray or None, shape (n, d)
        Baarda's ``w`` per residual component (a-priori sigma0).
    redundancy_numbers : numpy.ndarray or None, shape (n, d)
    iterations, converged, message
        Iteration diagnostics (0 / True / "" for direct solutions).
    elapsed : float
        Wall time of the estimation in seconds.
    notes : tuple of str
        Remarks for the user (e.g. which estimate is returned, warnings).
    extras : dict
        Estimator-specific results (e.g. corrected observations, inlier masks).
    crs, source_crs : str or None
        Coordinate reference system of the target (observation) coordinates, in which the
        residuals, check points and transformed points are, and of the source coordinates of
        a transformation: an EPSG code, WKT or PROJ string, or ``"enu:lat0,lon0,h0"`` (see
        :meth:`with_crs`); None when not given. Recorded, never used to compute.

    Notes
    -----
    The arrays are read-only views (``parameters``, ``covariance``, ``cofactor``,
    ``residuals``, ...): they agree with ``model`` and with each other, and copies made by
    :meth:`with_checks`, :meth:`with_crs` or :func:`dataclasses.replace` share them. Take a
    copy (``np.array(fit.residuals)``) to change one. ``extras`` is a dict of each Fit's own,
    its nested dicts and lists too (``extras["removed"]`` is a list, compared as one), whose
    arrays (e.g. the inlier mask of RANSAC) are read-only views.
    """

    model: object
    method: str
    parameter_names: tuple[str, ...]
    parameters: np.ndarray
    covariance: np.ndarray
    cofactor: np.ndarray
    sigma0: float
    sigma0_prior: float
    redundancy: int
    n_observations: int
    residuals: np.ndarray
    ids: tuple | None = None
    residual_labels: tuple[str, ...] = ()
    residual_unit: str = ""
    parameter_units: Mapping[str, str] = field(default_factory=dict)
    check_residuals: np.ndarray | None = None
    check_ids: tuple | None = None
    normalized_residuals: np.ndarray | None = None
    redundancy_numbers: np.ndarray | None = None
    iterations: int = 0
    converged: bool = True
    message: str = ""
    elapsed: float = 0.0
    notes: tuple[str, ...] = ()
    extras: Mapping[str, object] = field(default_factory=dict)
    crs: str | None = None
    source_crs: str | None = None

    #: What ``crs`` is the system of, in reports ("target CRS"; "ground CRS" of a resection).
    crs_role = "target"
    #: :func:`photogeom.records.build` may fill the fields and call ``__post_init__``.
    _build_post_init = True

    def __repr__(self) -> str:
        # bounded (records.compact_repr): the dataclass repr printed every id and extra
        return compact_repr(self)

    def __post_init__(self) -> None:
        read_only_fields(self)
        # extras: a dict of its own, its nested dicts, lists and sets too (copies made by
        # replace do not share them: a list written through a with_crs copy changed the
        # original's), whose arrays are read-only views (an inlier mask written through a
        # copy changed the original's)
        d = self.__dict__
        extras = d.get("extras")
        if isinstance(extras, Mapping):
            d["extras"] = {k: _own_extra(v) for k, v in extras.items()}
        # parameter_units: read-only (the parameter table, summary and to_dict read it; a
        # unit written into a with_crs copy's dict changed the original's table)
        units = d.get("parameter_units")
        if isinstance(units, Mapping) and not isinstance(units, FrozenMapping):
            d["parameter_units"] = FrozenMapping(units)

    def __setstate__(self, state: dict) -> None:
        # pickle / deepcopy rebuild arrays writable: read-only again (those of extras too)
        setstate_read_only(self, state)
        extras = self.__dict__.get("extras")
        if isinstance(extras, Mapping):  # nested arrays too
            self.__dict__["extras"] = {k: _own_extra(v) for k, v in extras.items()}

    # --- construction ----------------------------------------------------------------------

    @classmethod
    def _construct(cls, **values) -> Fit:
        """``cls(**values)``, the same object, without the per-field cost of the frozen
        dataclass constructor (:func:`photogeom.records.build`). For estimators returning
        many small results."""
        return build(cls, values)

    @classmethod
    def without_statistics(cls, values: dict, point_dim: int) -> Fit:
        """The Fit of ``statistics=False``: the estimate without its statistics.

        Parameters
        ----------
        values : dict
            Field name -> value of the estimate and its labels (at least ``parameters``);
            completed in place with the stand-ins for what was not computed: NaN
            ``covariance``, ``cofactor`` (shared read-only arrays) and ``sigma0``, no
            ``residuals`` and :data:`NO_STATISTICS_NOTE` after the given ``notes``.
        point_dim : int
            Columns of the (empty) residual array, shape (0, ``point_dim``).

        Returns
        -------
        Fit
            An instance of ``cls`` built from ``values``.
        """
        u = len(values["parameters"])
        nan = not_computed((u, u))
        values["covariance"] = values["cofactor"] = nan
        values["sigma0"] = math.nan
        values["residuals"] = not_computed((0, point_dim))
        values["notes"] = (*values.get("notes", ()), NO_STATISTICS_NOTE)
        return build(cls, values)

    @classmethod
    def from_adjustment(
        cls,
        adjustment: Adjustment,
        model: object,
        method: str,
        *,
        point_dim: int,
        parameters: np.ndarray | None = None,
        parameter_names: Sequence[str] | None = None,
        jacobian: np.ndarray | None = None,
        **kwargs,
    ) -> Fit:
        """Build a Fit from an :class:`Adjustment`.

        ``parameters`` / ``parameter_names`` / ``jacobian`` re-express the adjusted unknowns
        in another parametrisation (e.g. back from normalised coordinates, or textbook form):
        the cofactor is propagated as ``J Qxx J.T``. Residuals are reshaped to
        ``(n, point_dim)``.

        Parameters
        ----------
        adjustment : Adjustment
            The least-squares solution: unknowns, cofactor, sigma0, redundancy, residuals
            (with normalised residuals and redundancy numbers when computed), iterations.
        model : object
            The fitted model (``Fit.model``).
        method : str
            Name of the estimation method (``Fit.method``).
        point_dim : int
            Coordinates per point: the residuals, normalised residuals and redundancy
            numbers are reshaped to (n, ``point_dim``).
        parameters : numpy.ndarray, optional
            Parameters in the other parametrisation; default the adjusted unknowns
            ``adjustment.x``.
        parameter_names : sequence of str, optional
            Their names; default ``adjustment.names``.
        jacobian : numpy.ndarray, optional
            ``J``, shape (n_parameters, n_unknowns): derivatives of the reported parameters
            by the adjusted unknowns. Without it the cofactor is taken unchanged.
        **kwargs
            Further fields of the Fit (e.g. ``ids``, ``residual_unit``, ``parameter_units``,
            ``notes``, ``extras``).

        Returns
        -------
        Fit
            An instance of ``cls`` with covariance ``sigma0^2 Q``.
        """
        Q = adjustment.cofactor
        if jacobian is not None:
            Q = propagate_covariance(Q, jacobian)
        params = adjustment.x if parameters is None else np.asarray(parameters, dtype=float)
        names = adjustment.names if parameter_names is None else tuple(parameter_names)
        s0 = adjustment.sigma0

        def shaped(a):
            return None if a is None else np.asarray(a).reshape(-1, point_dim)

        return cls(
            model=model,
            method=method,
            parameter_names=tuple(names),
            parameters=np.asarray(params, dtype=float),
            covariance=s0**2 * Q,
            cofactor=Q,
            sigma0=s0,
            sigma0_prior=adjustment.sigma0_prior,
            redundancy=adjustment.redundancy,
            n_observations=adjustment.n_observations,
            residuals=shaped(adjustment.residuals),
            normalized_residuals=shaped(adjustment.normalized_residuals),
            redundancy_numbers=shaped(adjustment.redundancy_numbers),
            iterations=adjustment.iterations,
            converged=adjustment.converged,
            message=adjustment.message,
            **kwargs,
        )

    def with_checks(self, check_residuals: np.ndarray, check_ids: Sequence | None = None) -> Fit:
        """A copy with check-point residuals attached.

        Parameters
        ----------
        check_residuals : array_like, shape (m, d)
            Residuals of the check points (computed minus observed), in ``residual_unit``;
            copied.
        check_ids : sequence, optional
            Their point ids (stored as a tuple); default None.

        Returns
        -------
        Fit
            The copy; ``self`` is not modified.
        """
        return replace(
            self,
            check_residuals=np.array(check_residuals, dtype=float),  # the Fit's own copy
            check_ids=None if check_ids is None else tuple(check_ids),
        )

    def with_crs(self, crs=None, source_crs=None) -> Fit:
        """A copy recording the CRS of the target and source coordinates.

        Each is validated by PROJ (pyproj) and refused when geographic (degrees: the
        estimate was computed as if the coordinates were Cartesian), see
        :func:`photogeom.crs.cartesian_crs`; the dimension checked is the number of residual
        columns (3 without 2-D residuals).

        Parameters
        ----------
        crs : str, int, pyproj.CRS or LocalFrame, optional
            CRS of the target (observation) coordinates: an EPSG code, WKT or PROJ string,
            or ``"enu:lat0,lon0,h0"``. None leaves the record as it is.
        source_crs : str, int, pyproj.CRS or LocalFrame, optional
            CRS of the source coordinates of a transformation, as ``crs``.

        Returns
        -------
        Fit
            The copy with the validated CRS texts, or ``self`` when both are None.

        Raises
        ------
        InputError
            A CRS that :func:`photogeom.crs.cartesian_crs` refuses (unknown, geographic,
            vertical alone, ...).
        """
        from ..crs import cartesian_crs

        dim = int(np.asarray(self.residuals).shape[1]) if np.ndim(self.residuals) == 2 else 3
        changes = {}
        for key, value in (("crs", crs), ("source_crs", source_crs)):
            if value is not None:
                changes[key] = cartesian_crs(value, what=key, dim=dim).text
        return replace(self, **changes) if changes else self

    # --- derived quantities ---------------------------------------------------------------

    @property
    def transform(self) -> object:
        """The fitted model (alias of ``model``)."""
        return self.model

    @property
    def std_errors(self) -> dict[str, float]:
        """A-posteriori standard deviations by parameter name (units of ``parameter_units``)."""
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        return {n: float(s) for n, s in zip(self.parameter_names, sd)}

    @property
    def std_errors_prior(self) -> dict[str, float]:
        """Standard deviations from ``sigma0_prior^2 Qxx``."""
        sd = self.sigma0_prior * np.sqrt(np.clip(np.diag(self.cofactor), 0.0, None))
        return {n: float(s) for n, s in zip(self.parameter_names, sd)}

    @property
    def covariance_prior(self) -> np.ndarray:
        """A-priori covariance ``sigma0_prior^2 Qxx``."""
        return self.sigma0_prior**2 * self.cofactor

    @property
    def params(self) -> dict[str, float]:
        """Parameters by name."""
        return {n: float(v) for n, v in zip(self.parameter_names, self.parameters)}

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters."""
        d = np.sqrt(np.clip(np.diag(self.cofactor), 1e-300, None))
        return self.cofactor / np.outer(d, d)

    @property
    def rmse(self) -> float:
        """Per-point RMSE of the control residuals: ``sqrt(sum |v_i|^2 / n_points)``."""
        return _rmse(self.residuals)

    @property
    def rms_per_axis(self) -> np.ndarray:
        """RMS of the control residuals per coordinate axis."""
        return _rms_axes(self.residuals)

    @property
    def check_rmse(self) -> float | None:
        """Per-point RMSE of check-point residuals (None without check points)."""
        return None if self.check_residuals is None else _rmse(self.check_residuals)

    @property
    def check_rms_per_axis(self) -> np.ndarray | None:
        """RMS per axis of check-point residuals."""
        return None if self.check_residuals is None else _rms_axes(self.check_residuals)

    @property
    def test_level(self) -> float:
        """Significance level of the fit's outlier tests (unitless): the level its estimator
        tested at when it records one (``extras["alpha"]``, e.g.
        :func:`photogeom.relative_orientation` with ``alpha=``), else :data:`DEFAULT_ALPHA`.
        The residual tables, ``to_dict()["snooping"]`` and :meth:`snooping` use it."""
        value = self.extras.get("alpha") if isinstance(self.extras, Mapping) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool) and 0 < value < 1:
            return float(value)
        return DEFAULT_ALPHA

    def snooping(self, alpha: float | None = None, sigma: str = "prior") -> SnoopingResult:
        """Baarda's w-test (``sigma="prior"``) or Pope's tau-test (``"posterior"``) per residual.

        Parameters
        ----------
        alpha : float, optional
            Significance level of each single test; default :attr:`test_level`, the level
            the fit was tested at (0.001 unless its estimator recorded another). Before, the
            default was always 0.001, so a fit of ``relative_orientation(alpha=0.01)`` was
            tested at 0.001 here and at 0.01 in its own tables.
        sigma : {"prior", "posterior"}, default "prior"
            A-priori sigma0 (w-test) or a-posteriori sigma0 (tau-test); see
            :func:`photogeom.adjust.data_snooping`.

        Returns
        -------
        SnoopingResult
            One statistic per residual component, in the row-major order of ``residuals``,
            with the redundancy numbers and minimal detectable biases when the fit has
            redundancy numbers.

        Raises
        ------
        InputError
            The fit has no normalised residuals, or as :func:`data_snooping` (bad ``alpha``
            or ``sigma``, no finite sigma0 or redundancy below 2 for the tau-test).
        """
        if self.normalized_residuals is None:
            from ..errors import InputError

            raise InputError(f"{self.method}: normalised residuals were not computed for this fit")
        if alpha is None:
            alpha = self.test_level
        adj = Adjustment(
            x=self.parameters,
            names=self.parameter_names,
            residuals=self.residuals.reshape(-1),
            cofactor=self.cofactor,
            redundancy=self.redundancy,
            n_observations=self.n_observations,
            vtpv=self.sigma0**2 * self.redundancy if self.redundancy > 0 else 0.0,
            sigma0_prior=self.sigma0_prior,
            normalized_residuals=self.normalized_residuals.reshape(-1),
            redundancy_numbers=None
            if self.redundancy_numbers is None
            or np.size(self.redundancy_numbers) != np.size(self.normalized_residuals)
            else np.asarray(self.redundancy_numbers, dtype=float).reshape(-1),
        )
        return data_snooping(adj, alpha=alpha, sigma=sigma)

    # --- output ------------------------------------------------------------------------------

    def _snooping_summary(self) -> dict:
        """The tests of the reports for ``to_dict``: alpha, and per test (``"w"``,
        ``"tau"``; None when it cannot be formed) the critical value and the flagged
        components by id and label; the poorly controlled components with their redundancy
        number and minimal detectable bias (a-priori sigmas)."""
        from ..errors import InputError
        from ..report.format import snooping_alpha

        res = np.asarray(self.residuals, dtype=float)
        shape = res.shape if res.ndim == 2 else (res.size, 1)
        ids = list(self.ids) if self.ids is not None else [str(k + 1) for k in range(shape[0])]
        labels = list(self.residual_labels)
        if len(labels) != shape[1]:
            labels = [f"v{j}" for j in range(shape[1])]

        def where(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return np.nonzero(np.asarray(mask, dtype=bool).reshape(shape))

        alpha = snooping_alpha(self)
        out: dict = {"alpha": alpha}
        first = None
        for name, sigma in (("w", "prior"), ("tau", "posterior")):
            try:
                sn = self.snooping(alpha=alpha, sigma=sigma)
            except InputError:  # e.g. the tau-test below a redundancy of 2
                out[name] = None
                continue
            first = first or sn
            stat = np.asarray(sn.statistic, dtype=float).reshape(shape)
            rows, cols = where(sn.flagged)
            out[name] = {
                "critical_value": sn.critical_value,
                "flagged": [
                    {"id": ids[k], "component": labels[j], "statistic": float(stat[k, j])}
                    for k, j in zip(rows.tolist(), cols.tolist())  # flagged only
                ],
                "not_tested": int(np.sum(~np.isfinite(stat))),
            }
        if first is not None and first.mdb is not None:
            red = np.asarray(first.redundancy_numbers, dtype=float).reshape(shape)
            mdb = np.asarray(first.mdb, dtype=float).reshape(shape)
            rows, cols = where(first.poorly_controlled)
            out["poorly_controlled"] = [
                {
                    "id": ids[k],
                    "component": labels[j],
                    "redundancy_number": float(red[k, j]),
                    "mdb": float(mdb[k, j]) if np.isfinite(mdb[k, j]) else None,
                }
                for k, j in zip(rows.tolist(), cols.tolist())  # poorly controlled only
            ]
        return out

    def parameter_table(
        self, angle_unit: str = "deg", *, prior: bool = False
    ) -> list[tuple[str, float, float, str]]:
        """Rows ``(name, value, std, unit)`` of the parameters.

        Angles (parameters of unit ``"rad"``) are converted to ``angle_unit`` and normalised
        for printing (:func:`photogeom.units.display_angle`: kappa in [0, one turn), other
        angles in [-half turn, +half turn)); other parameters keep their value and unit.

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the angles and their standard deviations (e.g. ``"rad"``, ``"gon"``).
        prior : bool, default False
            ``std`` a priori (``sigma0_prior`` times the square roots of the cofactors)
            instead of a posteriori.

        Returns
        -------
        list of tuple (str, float, float, str)
            One row per parameter, in the order of ``parameter_names``.
        """
        rows = []
        std = self.std_errors_prior if prior else self.std_errors
        for name, value in zip(self.parameter_names, self.parameters):
            unit = self.parameter_units.get(name, "")
            s = std[name]
            if unit == "rad":
                value, s, unit = (
                    display_angle(from_radians(value, angle_unit), angle_unit, name),
                    float(from_radians(s, angle_unit)),
                    angle_unit,
                )
            rows.append((name, float(value), float(s), unit))
        return rows

    def shown_parameter_table(
        self, angle_unit: str = "deg"
    ) -> list[tuple[str, float, float, str, bool]]:
        """Rows ``(name, value, std, unit, a_priori)`` as tables print them.

        ``std`` is the a-posteriori standard deviation, or the a-priori one (``a_priori``
        True) where the a-posteriori one is not finite (redundancy 0) and the a-priori one is.

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the angles, as in :meth:`parameter_table`.

        Returns
        -------
        list of tuple (str, float, float, str, bool)
            One row per parameter, in the order of ``parameter_names``.
        """
        prior = [r[2] for r in self.parameter_table(angle_unit, prior=True)]
        rows = []
        for (name, value, s, unit), p in zip(self.parameter_table(angle_unit), prior):
            use_prior = not math.isfinite(s) and math.isfinite(p)
            rows.append((name, value, p if use_prior else s, unit, use_prior))
        return rows

    def summary(self, angle_unit: str = "deg") -> str:
        """Plain-text report: parameters with standard deviations, statistics, residuals.

        Parameters
        ----------
        angle_unit : str, default "deg"
            Unit of the angles in the parameter table.

        Returns
        -------
        str
            The report: parameters (:meth:`shown_parameter_table`), sigma0 a posteriori and
            a priori, residuals in ``residual_unit`` with RMSE, check points, CRS and notes.
        """
        lines = [f"{type(self.model).__name__} estimated by {self.method}"]
        if self.message:
            lines.append(f"  {self.message}")
        lines.append(
            f"  observations {self.n_observations}, unknowns {len(self.parameter_names)}, "
            f"redundancy {self.redundancy}"
        )
        s0 = "undefined (redundancy 0)" if not math.isfinite(self.sigma0) else f"{self.sigma0:.6g}"
        lines.append(f"  sigma0 (a posteriori) {s0}   sigma0 (a priori) {self.sigma0_prior:g}")
        lines.append(f"  {'parameter':<16} {'value':>18} {'std. dev.':>18} {'unit':>8}")
        for name, value, s, unit, a_priori in self.shown_parameter_table(angle_unit):
            sd = "-" if not math.isfinite(s) else f"{s:.6g}" + (" (a priori)" if a_priori else "")
            lines.append(f"  {name:<16} {value:>18.10g} {sd:>18} {unit:>8}")
        unit = f" {self.residual_unit}" if self.residual_unit else ""
        labels = self.residual_labels or tuple(f"v{j}" for j in range(self.residuals.shape[1]))
        if self.residuals.shape[0] == 0 and self.n_observations > 0:
            lines.append("  residuals: not computed")
        else:
            lines.append(
                "  residuals v = computed - observed" + (f" [{self.residual_unit}]" if unit else "")
            )
            head = "  " + f"{'id':<10}" + "".join(f"{lab:>14}" for lab in labels)
            lines.append(head)
            ids = self.ids or tuple(range(1, self.residuals.shape[0] + 1))
            for pid, row in zip(ids, self.residuals):
                lines.append("  " + f"{pid!s:<10}" + "".join(f"{x:>14.6g}" for x in row))
            lines.append(
                f"  RMSE (per point) {self.rmse:.6g}{unit}; RMS per axis "
                + ", ".join(f"{lab} {x:.6g}" for lab, x in zip(labels, self.rms_per_axis))
                + unit
            )
        if self.check_residuals is not None:
            lines.append("  check points (not in the estimate), v = computed - observed")
            cids = self.check_ids or tuple(range(1, self.check_residuals.shape[0] + 1))
            for pid, row in zip(cids, self.check_residuals):
                lines.append("  " + f"{pid!s:<10}" + "".join(f"{x:>14.6g}" for x in row))
            lines.append(f"  check RMSE (per point) {self.check_rmse:.6g}{unit}")
        for label, value in crs_rows(self):
            lines.append(f"  {label}: {value}")
        for note in self.notes:
            lines.append(f"  note: {note}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN becomes None; angles stay in radians).

        Returns
        -------
        dict
            Model name, method, ``parameters`` by name with ``value``, ``std`` (a
            posteriori: undefined at redundancy 0), ``std_prior`` (``sigma0_prior`` times the
            cofactor's) and ``unit``; sigma0, redundancy, covariance, residuals with ids,
            RMSE and unit, iteration diagnostics, ``elapsed_s`` (s), notes; the CRS, the
            normalised residuals, the check points, ``model_parameters`` (the model's own
            ``to_dict``) and the plain-valued ``extras`` when present.
        """
        std = self.std_errors
        prior = self.std_errors_prior
        out = {
            "model": type(self.model).__name__,
            "method": self.method,
            "residual_convention": "computed minus observed",
            "parameters": {
                n: {
                    "value": float(v),
                    "std": std[n],
                    "std_prior": prior[n],
                    "unit": self.parameter_units.get(n, ""),
                }
                for n, v in zip(self.parameter_names, self.parameters)
            },
            "sigma0": self.sigma0,
            "sigma0_prior": self.sigma0_prior,
            "redundancy": self.redundancy,
            "n_observations": self.n_observations,
            "covariance": self.covariance,
            "residual_unit": self.residual_unit,
            "residual_labels": list(self.residual_labels),
            "residuals": self.residuals,
            "ids": list(self.ids) if self.ids is not None else None,
            "rmse": self.rmse,
            "rms_per_axis": self.rms_per_axis,
            "iterations": self.iterations,
            "converged": self.converged,
            "message": self.message,
            "elapsed_s": self.elapsed,
            "notes": list(self.notes),
        }
        if self.crs is not None or self.source_crs is not None:
            out["crs"] = self.crs
            out["source_crs"] = self.source_crs
        if self.normalized_residuals is not None:
            out["normalized_residuals"] = self.normalized_residuals
            out["snooping"] = self._snooping_summary()
        if self.check_residuals is not None:
            out["check_residuals"] = self.check_residuals
            out["check_ids"] = list(self.check_ids) if self.check_ids is not None else None
            out["check_rmse"] = self.check_rmse
            out["check_rms_per_axis"] = self.check_rms_per_axis
        model_dict = getattr(self.model, "to_dict", None)
        if callable(model_dict):
            out["model_parameters"] = model_dict()
        if self.extras:
            out["extras"] = {k: v for k, v in self.extras.items() if _is_plain(v)}
        return _jsonable(out)


def crs_rows(fit) -> list[tuple[str, str]]:
    """``(label, readable name)`` of the CRS records of a fit (none when there are none)."""
    rows = []
    crs, src = getattr(fit, "crs", None), getattr(fit, "source_crs", None)
    if crs is None and src is None:
        return rows
    from ..crs import crs_label

    if src is not None:
        rows.append(("source CRS", crs_label(src)))
    if crs is not None:
        rows.append((f"{getattr(fit, 'crs_role', 'target')} CRS", crs_label(crs)))
    return rows


def _is_plain(v) -> bool:
    return isinstance(v, (int, float, str, bool, list, tuple, dict, np.ndarray, np.generic))


def _rmse(v: np.ndarray) -> float:
    v = np.asarray(v, dtype=float)
    if v.size == 0:
        return float("nan")
    return float(np.sqrt(np.sum(v * v) / v.shape[0]))


def _rms_axes(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.size == 0:
        return np.full(v.shape[1] if v.ndim == 2 else 0, np.nan)
    return np.sqrt(np.mean(v * v, axis=0))
