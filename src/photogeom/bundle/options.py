"""Options of the bundle adjustment: one frozen record with defaults and a validity check."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ..errors import InputError

LOSSES = ("squared", "huber", "cauchy")
DATUMS = ("auto", "weighted", "free")
#: Default loss scales in units of the observations' standard deviation: the constants of
#: 95 % efficiency of a one-dimensional residual under normal errors. Applied to the 2-D norm
#: of an image point's whitened residual, their efficiency is 93.4 % (Huber) and 94.2 %
#: (Cauchy), the radial M-estimator's ``E[psi'/2 + psi/(2 r)]^2 / (E[psi^2] / 2)`` over the
#: chi distribution with 2 degrees of freedom.
DEFAULT_LOSS_SCALE = {"huber": 1.345, "cauchy": 2.385}


@dataclass(frozen=True)
class BundleOptions:
    """Settings of :func:`photogeom.bundle_adjust`.

    Attributes
    ----------
    max_iterations : int
        Levenberg-Marquardt iterations at most.
    ftol : float
        Convergence when an accepted step lowers the cost by less than ``ftol`` times the cost.
    xtol : float
        Convergence when every step component is below ``xtol`` relative to its scale
        (the block's extent for coordinates, 1 rad for angles, the value for calibration).
    initial_damping : float
        Initial Marquardt damping (relative to the diagonal of the normal matrix). The
        default 1e-8 starts with nearly Gauss-Newton steps, as GTSAM does: on the simulated
        benchmark blocks 6, 6 and 7 iterations for 50, 250 and 2000 images where 1e-4 took
        15, 8 and 21 (the damping then falls at most tenfold per step); from a poorer start
        (5 m, 2 degrees, 250 images) 12 instead of 9, each failed step raising the damping.
    loss : {"squared", "huber", "cauchy"}
        Loss of the image observations (iteratively reweighted least squares).
    loss_scale : float or None
        Scale of the robust loss in units of each observation's sigma (default 1.345 for
        Huber, 2.385 for Cauchy).
    datum : {"auto", "weighted", "free"}
        ``"weighted"``: by control points and/or GNSS/IMU observations (refused with the
        missing datum elements named when they do not fix all seven); ``"free"``: a free
        network with inner constraints on the projection centres (covariances in the
        minimum-trace datum of the centres); ``"auto"``: weighted when control or GNSS is
        present, else refused with advice.
    fix_exterior : bool
        Keep every exterior orientation at its value (as when re-adjusting with corrected
        observations: only points, and free calibration, move).
    free : tuple of str or None
        Calibration parameters to estimate for every camera group (overrides the block's).
    point_covariance : bool
        Compute the marginal 3x3 covariance of every point.
    snooping : bool
        Redundancy numbers and Baarda's w-test for every image observation.
    alpha : float
        Significance level of each single w-test.
    variance_components : bool
        Estimate one variance factor per observation group (Förstner/Helmert, iterated).
    sigma0_prior : float
        A-priori standard deviation of unit weight: the weights are
        ``P = sigma0_prior^2 / sigma^2`` for observations of standard deviation ``sigma``, so
        sigma0 is about ``sigma0_prior`` when the sigmas are right; the standard deviations,
        the global test and the w-test do not depend on it.
    backend : {"auto", "cholmod", "superlu", "dense", "cg"}
        Solver of the reduced camera system (:mod:`photogeom.adjust.sparse`): ``"auto"``
        takes a dense Cholesky for small systems, else CHOLMOD (or SuperLU); ``"cg"``
        (preconditioned conjugate gradients) for blocks too large to factorise.
    correlation_threshold : float
        Calibration correlations above this (absolute) are flagged.
    verbose : bool
        Print one line per iteration (the CLI shows a progress display instead).
    """

    max_iterations: int = 100
    ftol: float = 1e-10
    xtol: float = 1e-12
    initial_damping: float = 1e-8
    loss: str = "squared"
    loss_scale: float | None = None
    datum: str = "auto"
    fix_exterior: bool = False
    free: tuple[str, ...] | None = None
    point_covariance: bool = False
    snooping: bool = True
    alpha: float = 0.001
    variance_components: bool = False
    sigma0_prior: float = 1.0
    backend: str = "auto"
    correlation_threshold: float = 0.9
    verbose: bool = False

    def validate(self) -> BundleOptions:
        """Check every setting.

        Returns
        -------
        BundleOptions
            ``self``, unchanged.

        Raises
        ------
        InputError
            Naming the bad setting: ``max_iterations`` not a positive integer; ``ftol``,
            ``xtol``, ``initial_damping`` or ``sigma0_prior`` not positive and finite; an
            unknown ``loss``, ``datum`` or ``backend``; ``loss_scale`` not positive and
            finite; ``free`` a single string or with unknown calibration parameter names;
            ``alpha`` not in (0, 0.5); ``correlation_threshold`` not in (0, 1].
        """
        if int(self.max_iterations) != self.max_iterations or self.max_iterations < 1:
            raise InputError(
                f"max_iterations must be a positive integer, not {self.max_iterations}"
            )
        for name in ("ftol", "xtol", "initial_damping", "sigma0_prior"):
            v = getattr(self, name)
            if not (v > 0 and v < float("inf")):
                raise InputError(f"{name} must be positive and finite, not {v!r}")
        if self.loss not in LOSSES:
            raise InputError(f"loss must be one of {', '.join(LOSSES)}, not {self.loss!r}")
        if self.loss_scale is not None and not (0 < self.loss_scale < float("inf")):
            raise InputError(f"loss_scale must be positive, not {self.loss_scale!r}")
        if self.datum not in DATUMS:
            raise InputError(f"datum must be one of {', '.join(DATUMS)}, not {self.datum!r}")
        from ..adjust.sparse import BACKENDS
        from .block import CALIBRATION_NAMES

        if self.free is not None:
            if isinstance(self.free, str):
                raise InputError(
                    f"free must be a sequence of parameter names, not the string {self.free!r}"
                )
            bad = [n for n in self.free if n not in CALIBRATION_NAMES]
            if bad:
                raise InputError(
                    f"free: unknown calibration parameter(s) {', '.join(map(repr, bad))}; "
                    f"choose from {', '.join(CALIBRATION_NAMES)}"
                )

        if self.backend not in BACKENDS:
            raise InputError(
                f"backend must be one of {', '.join(BACKENDS)}, not {self.backend!r}"
            )
        if not (0 < self.alpha < 0.5):
            raise InputError(f"alpha must be in (0, 0.5), not {self.alpha!r}")
        if not (0 < self.correlation_threshold <= 1):
            raise InputError("correlation_threshold must be in (0, 1]")
        return self

    @property
    def scale(self) -> float:
        """The robust loss scale in use."""
        if self.loss_scale is not None:
            return float(self.loss_scale)
        return DEFAULT_LOSS_SCALE.get(self.loss, 1.0)

    def updated(self, **changes) -> BundleOptions:
        """A copy with some settings changed.

        Parameters
        ----------
        **changes
            New values of fields of :class:`BundleOptions` by name; ``free`` may be any
            sequence of calibration parameter names (stored as a tuple).

        Returns
        -------
        BundleOptions
            The changed copy, validated (:meth:`validate`); ``self`` is not modified.

        Raises
        ------
        InputError
            An unknown option name, ``free`` given as a single string, or any setting that
            :meth:`validate` refuses.
        """
        names = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise InputError(
                f"unknown bundle adjustment option(s) {', '.join(unknown)}; valid: "
                f"{', '.join(sorted(names))}"
            )
        if "free" in changes and changes["free"] is not None:
            if isinstance(changes["free"], str):
                raise InputError(
                    f"free must be a sequence of parameter names, not the string "
                    f"{changes['free']!r} (e.g. free=('f', 'cx', 'cy'))"
                )
            changes["free"] = tuple(changes["free"])
        return replace(self, **changes).validate()
