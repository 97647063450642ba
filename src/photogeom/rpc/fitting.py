"""Fitting rational polynomial models: to a physical camera or to control points.

**Terrain-independent** (:func:`fit_rpc`): a physical sensor model (any callable
``ground (n, 3) -> image (n, 2)``, or another :class:`RPC`) projects a 3D grid of ground
points spanning the given longitude/latitude/height box; the RPC is fitted to those points and
checked on a second grid placed between the first one's nodes (check points: the fit error).

**Terrain-dependent** (:func:`fit_rpc_to_points`): the RPC is fitted to measured control
points; it needs at least as many points as coefficients per image coordinate
(``2 * terms - 1``: 7, 19 or 39 for polynomials of degree 1, 2 or 3); a fit whose
denominator comes within :data:`MIN_DENOMINATOR` of zero in the points' box (noisy points of
order 2 or 3 with a small ``regularization``) is refused (:class:`UnstableFitError`).

Estimation (both): the normalised observation equations are
``col_n = Num_S(t) / Den_S(t)``, ``row_n = Num_L(t) / Den_L(t)`` with the first denominator
coefficient fixed to 1 (``2 * terms - 1`` unknowns per coordinate, 78 for cubic RPCs).
Initial values come from the linearised equations ``Num(t) - x_n (Den(t) - 1) = x_n``
(Tao & Hu 2001), solved by :func:`photogeom.adjust.solve_linear`; the final estimate is a
nonlinear Gauss-Markov adjustment (:func:`photogeom.adjust.gauss_markov`) of the image
observations in pixels. Both are regularised (Tikhonov): with ``lambda = regularization``
the estimate minimises

    sum_i ((x_i' - x_i) / S)^2 + lambda^2 * sum_j c_j^2

for each image coordinate separately (``x`` = col with ``S = SAMP_SCALE``, row with
``S = LINE_SCALE``; the two share no coefficients)

over its free coefficients ``c_j`` (normalised units), implemented as pseudo-observations
``c_j = 0`` with weight ``(lambda S / sigma)^2`` next to the image observations'
``1 / sigma^2``: the estimate does not depend on ``sigma``. Cubic RPCs are over-parametrised
(numerator and denominator can share factors), so without regularisation the normal
equations are singular or nearly so; a small ``lambda`` picks the smallest coefficients among
the (almost) equivalent solutions and barely changes the fitted function. The reported
cofactor is that of the regularised estimate, ``Q (A^T P A) Q`` with
``Q = (A^T P A + (lambda S / sigma)^2 I)^-1`` (``P = I / sigma^2``): how the estimate varies
with the image noise (``Q`` alone, the posterior of the penalty read as a prior, is larger by
``Q (lambda S / sigma)^2 Q``: up to 14 times in the standard deviations of the coefficients
the penalty holds at ``lambda = 1e-3``); the covariance is ``sigma0^2`` times it; the
redundancy counts the image observations only (``2 n - unknowns``), and sigma0 divides
``v'Pv`` by the effective redundancy ``2 n - tr(H)`` of the regularised fit.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from ..adjust import Fit, gauss_markov, solve_linear
from ..errors import ConvergenceError, DegenerateGeometryError, InputError
from ..validation import as_points, check_count, check_same_length
from . import polynomial as poly
from .domain import longitude_difference, wrap_longitude
from .model import RPC

#: Default Tikhonov parameter (normalised units).
DEFAULT_REGULARIZATION = 1e-6

#: A terrain-dependent fit whose denominator comes closer than this to zero inside the
#: control points' box is refused (a pole: image positions near it are arbitrary).
MIN_DENOMINATOR = 0.1

#: Tikhonov parameter suggested for noisy control points (normalised units): on 0.5 px
#: noise it kept every denominator above 0.95 and the check RMSE at the noise level.
NOISY_REGULARIZATION = 1e-3


def _projector(camera) -> Callable[[np.ndarray], np.ndarray]:
    """``ground (n, 3) -> image (n, 2)`` from a callable or an object with ``project``."""
    if isinstance(camera, RPC):
        return lambda g: np.column_stack(camera.project(g[:, 0], g[:, 1], g[:, 2]))
    if callable(camera):
        return camera
    project = getattr(camera, "project", None)
    if callable(project):
        return lambda g: np.column_stack(project(g[:, 0], g[:, 1], g[:, 2]))
    raise InputError(
        "camera: expected a callable ground (n, 3) [lon deg, lat deg, h m] -> image (n, 2) "
        "[col, row px], or an object with project(lon, lat, h)"
    )


def _parameter_names(nt: int) -> list[str]:
    names = []
    for coord in ("SAMP", "LINE"):
        names += [f"{coord}_NUM_{j + 1}" for j in range(nt)]
        names += [f"{coord}_DEN_{j + 1}" for j in range(1, nt)]
    return names


def _unpack(x: np.ndarray, nt: int) -> tuple[np.ndarray, ...]:
    """Parameter vector -> samp_num, samp_den, line_num, line_den (20 each)."""
    k = 2 * nt - 1
    out = []
    for c in range(2):
        p = x[c * k : (c + 1) * k]
        num = np.zeros(poly.N_TERMS)
        den = np.zeros(poly.N_TERMS)
        num[:nt] = p[:nt]
        den[0] = 1.0
        den[1:nt] = p[nt:]
        out += [num, den]
    return tuple(out)


class _Normalisation:
    """Offsets and scales of a fit: ground from a box, image from the observations."""

    def __init__(self, ground_box: np.ndarray, image: np.ndarray) -> None:
        lo, hi = ground_box
        self.g_off = 0.5 * (lo + hi)
        self.g_off[0] = float(wrap_longitude(self.g_off[0]))
        self.g_scale = 0.5 * (hi - lo)
        ilo, ihi = image.min(axis=0), image.max(axis=0)
        self.i_off = 0.5 * (ilo + ihi)
        self.i_scale = np.maximum(0.5 * (ihi - ilo), 1.0)

    def ground(self, g: np.ndarray) -> np.ndarray:
        d = g - self.g_off
        d[:, 0] = longitude_difference(g[:, 0], self.g_off[0])
        return d / self.g_scale

    def image(self, im: np.ndarray) -> np.ndarray:
        return (im - self.i_off) / self.i_scale


def _fit_core(
    ground: np.ndarray,
    image: np.ndarray,
    norm: _Normalisation,
    order: int,
    regularization: float,
    sigma: float,
    what: str,
):
    """Regularised rational fit; returns ``(RPC, Adjustment, names, nt, N)`` with ``N`` the
    normal matrix of the image observations alone at the solution (``J^T P J``, (2k, 2k))."""
    if order not in poly.TERMS_OF_ORDER:
        raise InputError(f"{what}: order must be 1, 2 or 3, got {order!r}")
    if not (regularization >= 0 and np.isfinite(regularization)):
        raise InputError(f"{what}: regularization must be >= 0, got {regularization!r}")
    if not (sigma > 0 and np.isfinite(sigma)):
        raise InputError(f"{what}: sigma must be a positive number of pixels, got {sigma!r}")
    nt = poly.TERMS_OF_ORDER[order]
    k = 2 * nt - 1
    gn = norm.ground(ground)
    T = poly.terms(gn[:, 0], gn[:, 1], gn[:, 2])[:, :nt]
    imn = norm.image(image)
    S = norm.i_scale  # (samp, line) scales in pixels
    n = ground.shape[0]
    lam = float(regularization)

    # linearised initial values, one coordinate at a time (Tao & Hu): Num - x (Den - 1) = x
    x0 = np.empty(2 * k)
    for c in range(2):
        xn = imn[:, c]
        A = np.hstack([T, -xn[:, None] * T[:, 1:]])
        L = xn
        if lam > 0:
            A = np.vstack([A, lam * np.eye(k)])
            L = np.concatenate([L, np.zeros(k)])
        adj = solve_linear(A, L, what=f"{what} (linearised initial values)")
        x0[c * k : (c + 1) * k] = adj.x

    def split(x):
        return x[:k], x[k:]

    def model(x):
        out = np.empty(2 * n + (2 * k if lam > 0 else 0))
        for c, p in enumerate(split(x)):
            num = T @ p[:nt]
            den = 1.0 + T[:, 1:] @ p[nt:]
            out[c * n : (c + 1) * n] = S[c] * num / den + norm.i_off[c]
        if lam > 0:
            out[2 * n :] = x
        return out

    def jacobian(x):
        J = np.zeros((2 * n + (2 * k if lam > 0 else 0), 2 * k))
        for c, p in enumerate(split(x)):
            num = T @ p[:nt]
            den = 1.0 + T[:, 1:] @ p[nt:]
            rows = slice(c * n, (c + 1) * n)
            J[rows, c * k : c * k + nt] = S[c] * T / den[:, None]
            J[rows, c * k + nt : (c + 1) * k] = -S[c] * (num / den**2)[:, None] * T[:, 1:]
        if lam > 0:
            J[2 * n :, :] = np.eye(2 * k)
        return J

    observed = image.T.reshape(-1)
    weights = np.full(2 * n, 1.0 / sigma**2)
    if lam > 0:
        # lambda^2 * c^2 in normalised units = (lambda * S)^2 c^2 in pixel units
        pseudo = np.concatenate([np.full(k, (lam * S[0]) ** 2), np.full(k, (lam * S[1]) ** 2)])
        observed = np.concatenate([observed, np.zeros(2 * k)])
        weights = np.concatenate([weights, pseudo / sigma**2])
    names = _parameter_names(nt)
    try:
        adj = gauss_markov(
            model, x0, observed, jacobian=jacobian, weights=weights, sigma0_prior=1.0,
            names=names, max_iter=100, what=what,
        )  # fmt: skip
    except ConvergenceError as exc:
        raise ConvergenceError(
            f"{what}: the rational-function fit did not converge ({exc}). The points do not "
            f"determine the coefficients well: use a lower order or a larger regularization "
            f"(now {lam:g})",
            iterations=exc.iterations,
        ) from exc
    J_img = jacobian(adj.x)[: 2 * n]
    image_normal = (J_img.T @ J_img) / sigma**2
    sn, sd, ln, ld = _unpack(adj.x, nt)
    rpc = RPC(
        line_off=norm.i_off[1], samp_off=norm.i_off[0], lat_off=norm.g_off[1],
        long_off=norm.g_off[0], height_off=norm.g_off[2], line_scale=S[1], samp_scale=S[0],
        lat_scale=norm.g_scale[1], long_scale=norm.g_scale[0], height_scale=norm.g_scale[2],
        line_num=ln, line_den=ld, samp_num=sn, samp_den=sd, source=what,
    )  # fmt: skip
    return rpc, adj, names, nt, image_normal


def _make_fit(
    rpc: RPC,
    adj,
    names: list[str],
    n: int,
    method: str,
    ids: Sequence | None,
    elapsed: float,
    sigma: float,
    notes: tuple[str, ...],
    extras: dict,
    image_normal: np.ndarray,
) -> Fit:
    """A :class:`Fit` with statistics of the image observations only (no pseudo-observations).

    The cofactor of the regularised estimate: ``x = Q J^T P l`` with the regularised
    ``Q = (J^T P J + W)^-1`` (``W`` the pseudo-observations' weights) varies with the image
    noise as ``Q (J^T P J) Q`` (``image_normal = J^T P J``), not as ``Q``; ``Q`` itself (the
    posterior of the penalty read as a prior) exceeds it by ``Q W Q``, most for the
    coefficients the penalty holds.

    ``redundancy`` is ``2 n - unknowns``; sigma0 divides ``v'Pv`` by the effective
    redundancy of the regularised fit, ``2 n - tr(H)`` with ``tr(H) = u - sum_j w_j Q_jj``
    (``w_j`` the pseudo-observations' weights, ``Q`` the regularised cofactor): the penalty
    holds ``u - tr(H)`` of the coefficients, which the residuals then do not absorb
    (``extras["effective_redundancy"]``)."""
    u = len(names)
    v = adj.residuals[: 2 * n]
    residuals = v.reshape(2, n).T.copy()
    r = 2 * n - u
    vtpv = float(np.sum(v**2)) / sigma**2
    Q = adj.cofactor
    lam = float(extras.get("regularization", 0.0))
    k = u // 2
    scales = np.concatenate([np.full(k, rpc.samp_scale), np.full(k, rpc.line_scale)])
    held = float(np.sum((lam * scales / sigma) ** 2 * np.diag(Q)))  # u - tr(H)
    if lam > 0:  # the sandwich, symmetric to rounding
        Q = Q @ image_normal @ Q
        Q = 0.5 * (Q + Q.T)
    r_eff = r + held
    extras = {**extras, "effective_redundancy": r_eff}
    sigma0 = float(np.sqrt(vtpv / r_eff)) if r_eff > 0 and r > 0 else float("nan")
    w = adj.normalized_residuals
    red = adj.redundancy_numbers
    return Fit(
        model=rpc,
        method=method,
        parameter_names=tuple(names),
        parameters=adj.x.copy(),
        covariance=sigma0**2 * Q,
        cofactor=Q,
        sigma0=sigma0,
        sigma0_prior=1.0,
        redundancy=r,
        n_observations=2 * n,
        residuals=residuals,
        ids=None if ids is None else tuple(ids),
        residual_labels=("col", "row"),
        residual_unit="px",
        parameter_units={name: "1" for name in names},
        normalized_residuals=None if w is None else w[: 2 * n].reshape(2, n).T.copy(),
        redundancy_numbers=None if red is None else red[: 2 * n].reshape(2, n).T.copy(),
        iterations=adj.iterations,
        converged=adj.converged,
        message=adj.message,
        elapsed=elapsed,
        notes=notes,
        extras=extras,
    )


def _denominator_note(rpc: RPC, ground: np.ndarray) -> tuple[tuple[str, ...], float]:
    L, P, H = rpc.normalize_ground(ground[:, 0], ground[:, 1], ground[:, 2])
    V = poly.evaluate(np.stack([rpc.samp_den, rpc.line_den]), L, P, H)
    dmin = float(np.min(np.abs(V)))
    if dmin < 0.1:
        return (
            f"a denominator comes close to zero in the fitted domain (min |Den| = {dmin:.3g}); "
            "the RPC may be unstable there (raise the regularization or use a lower order)",
        ), dmin
    return (), dmin


def _box_denominator_min(rpc: RPC, nodes: int = 9) -> float:
    """Smallest ``|Den|`` of either coordinate on a ``nodes^3`` grid over the normalised
    box ``[-1, 1]^3`` (for a terrain-dependent fit: the control points' bounding box)."""
    ax = np.linspace(-1.0, 1.0, nodes)
    L, P, H = (a.ravel() for a in np.meshgrid(ax, ax, ax, indexing="ij"))
    V = poly.evaluate(np.stack([rpc.samp_den, rpc.line_den]), L, P, H)
    return float(np.min(np.abs(V)))


class UnstableFitError(DegenerateGeometryError):
    """A terrain-dependent RPC fit refused for a near-zero denominator in its box; holds
    what the message needs so that a caller can name its own settings
    (:func:`unstable_fit_message`)."""

    def __init__(self, what: str, dmin: float, n: int, order: int, regularization: float):
        self.details = (what, dmin, n, order, regularization)
        super().__init__(unstable_fit_message(*self.details))


def unstable_fit_message(
    what: str, dmin: float, n: int, order: int, regularization: float,
    option: str = "regularization", order_option: str = "order",
) -> str:  # fmt: skip
    """The refusal of a terrain-dependent fit whose denominator nearly vanishes inside the
    control points' box; ``option``/``order_option`` name the settings the caller gave
    (keyword arguments, or the command line's ``--regularization``/``--order``)."""
    k = 2 * poly.TERMS_OF_ORDER[order] - 1
    fixes = [f"a larger {option} (now {regularization:g}, e.g. {NOISY_REGULARIZATION:g})"]
    if order > 1:
        fixes.append(f"a lower {order_option} (1: 7 coefficients)")
    fixes.append("more control points spread over the whole box in 3D")
    return (
        f"{what}: unstable fit - the fitted denominator comes within {dmin:.2g} of zero "
        f"inside the control points' box (below {MIN_DENOMINATOR:g}: a pole, image positions "
        f"near it are arbitrary); {n} noisy points do not determine {k} coefficients per "
        f"image coordinate. Use {', or '.join(fixes)}"
    )


def fit_rpc(
    camera,
    bounds,
    *,
    grid: tuple[int, int, int] = (11, 11, 6),
    order: int = 3,
    regularization: float = DEFAULT_REGULARIZATION,
    image_size: tuple[int, int] | None = None,
) -> Fit:
    """Terrain-independent RPC fitted to a physical sensor model.

    Parameters
    ----------
    camera : callable or object with ``project``
        ``camera(ground)`` with ``ground`` of shape (n, 3) (lon deg, lat deg, h m) returning
        image points (n, 2) (col, row px, first pixel centre at (0, 0)); or an :class:`RPC`
        (e.g. a bias-corrected one to re-fit), or any object with ``project(lon, lat, h)``.
        Points it maps to NaN (e.g. behind the camera) are left out.
    bounds : array_like, shape (3, 2)
        ``[[lon_min, lon_max], [lat_min, lat_max], [h_min, h_max]]`` (degrees, metres): the
        ground box the RPC must be valid in (it becomes the normalised domain).
    grid : (int, int, int)
        Grid nodes along lon, lat and h (at least ``order + 1`` each, so that the terms of
        each degree are determined between the nodes; the number of points must reach the
        number of coefficients per coordinate). Check points lie between the nodes.
    order : {1, 2, 3}
        Degree of the polynomials (3 = RPC00B).
    regularization : float
        Tikhonov parameter lambda (normalised units, see the module docstring).
    image_size : (int, int), optional
        Stored in the model (``(columns, rows)``).

    Returns
    -------
    Fit
        ``model`` is the fitted :class:`RPC`; residuals (px, computed - observed) on the
        grid; ``check_residuals`` on the check grid; ``extras["check_max_px"]`` the largest
        check-point error.
    """
    t0 = time.perf_counter()
    project = _projector(camera)
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (3, 2) or not np.all(np.isfinite(b)):
        raise InputError(
            "bounds: expected [[lon_min, lon_max], [lat_min, lat_max], [h_min, h_max]] "
            f"(finite numbers), got shape {b.shape}"
        )
    if np.any(b[:, 1] <= b[:, 0]):
        axis = ["longitude", "latitude", "height"][int(np.argmax(b[:, 1] <= b[:, 0]))]
        raise DegenerateGeometryError(
            f"bounds: the {axis} range is empty (max <= min); a terrain-independent RPC needs a "
            "3D box (for the height too: at least two different heights)"
        )
    g = tuple(int(v) for v in grid)
    if len(g) != 3 or min(g) < 2:
        raise InputError(f"grid: expected three node counts >= 2, got {grid!r}")
    axes = [np.linspace(b[i, 0], b[i, 1], g[i]) for i in range(3)]
    G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    mids = [0.5 * (a[1:] + a[:-1]) for a in axes]
    Gc = np.stack(np.meshgrid(*mids, indexing="ij"), axis=-1).reshape(-1, 3)
    img = np.asarray(project(G), dtype=np.float64)
    imc = np.asarray(project(Gc), dtype=np.float64)
    for arr, name, ref in ((img, "grid", G), (imc, "check grid", Gc)):
        if arr.shape != (ref.shape[0], 2):
            raise InputError(
                f"camera returned shape {arr.shape} for {ref.shape[0]} {name} points; "
                "expected (n, 2) (col, row)"
            )
    ok = np.all(np.isfinite(img), axis=1)
    okc = np.all(np.isfinite(imc), axis=1)
    nt = poly.TERMS_OF_ORDER.get(order, 20)
    check_count(
        int(ok.sum()), 2 * nt - 1, f"terrain-independent RPC fit of order {order}",
        "use a denser grid or a box the camera sees",
    )  # fmt: skip
    norm = _Normalisation(b.T, img[ok])
    what = "terrain-independent RPC fit"
    if order in poly.TERMS_OF_ORDER:
        few = [i for i in range(3) if g[i] <= order]
        if few:
            axis = ("longitude", "latitude", "height")[few[0]]
            need = tuple(max(v, order + 1) for v in g)
            raise DegenerateGeometryError(
                f"{what} of order {order}: grid={g} has {g[few[0]]} node(s) along {axis}; a "
                f"polynomial of degree {order} needs at least {order + 1} along each axis, "
                f"else its {axis} terms are undetermined between the nodes. Give "
                f"grid={need} or a lower order"
            )
        _check_control_geometry(norm.ground(G[ok]), order, f"{what} of order {order}")
    rpc, adj, names, nt, image_normal = _fit_core(
        G[ok], img[ok], norm, order, regularization, 1.0, what
    )
    if image_size is not None:
        rpc = _with(rpc, image_size=image_size)
    cc, rc = rpc.project(Gc[okc, 0], Gc[okc, 1], Gc[okc, 2], domain_limit=None)
    check = np.column_stack([cc, rc]) - imc[okc]
    notes, dmin = _denominator_note(rpc, np.vstack([G[ok], Gc[okc]]))
    if not ok.all():
        notes = (*notes, f"{int((~ok).sum())} grid point(s) without an image position left out")
    fit = _make_fit(
        rpc, adj, names, int(ok.sum()),
        f"terrain-independent rational function fit (order {order}, Tikhonov {regularization:g})",
        None, time.perf_counter() - t0, 1.0, notes,
        {
            "regularization": regularization,
            "order": order,
            "grid": list(g),
            "check_max_px": float(np.max(np.abs(check))) if check.size else float("nan"),
            "min_denominator": dmin,
        },
        image_normal,
    )  # fmt: skip
    return fit.with_checks(check)


def fit_rpc_to_points(
    ground,
    image,
    *,
    order: int = 1,
    regularization: float = DEFAULT_REGULARIZATION,
    sigma: float = 1.0,
    ids: Sequence | None = None,
    check_ground=None,
    check_image=None,
    check_ids: Sequence | None = None,
    image_size: tuple[int, int] | None = None,
) -> Fit:
    """Terrain-dependent RPC fitted to control points.

    Parameters
    ----------
    ground : array_like, shape (n, 3)
        Control points: lon (deg), lat (deg), h (m).
    image : array_like, shape (n, 2)
        Their measured image positions: col, row (px).
    order : {1, 2, 3}
        Degree; needs ``n >= 2 * terms - 1`` points (7, 19, 39 for degree 1, 2, 3). Degree 1
        (the default) is the robust choice for measured control points; degrees 2 and 3 need
        many well-spread points and overfit noisy ones (watch the check points).
    regularization : float
        Tikhonov parameter lambda (normalised units, see the module docstring); for noisy
        points of order 2 or 3 about :data:`NOISY_REGULARIZATION` (1e-3).
    sigma : float
        A-priori standard deviation of the image measurements (px).
    ids, check_ids : sequence, optional
        Point ids of control and check points.
    check_ground, check_image : array_like, optional
        Check points (not used in the estimate).
    image_size : (int, int), optional

    Returns
    -------
    Fit
        ``model`` is the fitted :class:`RPC`; residuals in px (computed - observed).

    Raises
    ------
    UnstableFitError
        When ``|Den|`` of either coordinate falls below :data:`MIN_DENOMINATOR` at the points
        or on a grid over their box (a pole: the fit is not determined by the points).
    """
    t0 = time.perf_counter()
    what = f"terrain-dependent RPC fit of order {order}"
    if order not in poly.TERMS_OF_ORDER:
        raise InputError(f"{what}: order must be 1, 2 or 3, got {order!r}")
    G = as_points(ground, 3, "ground (lon, lat, h)")
    im = as_points(image, 2, "image (col, row)")
    check_same_length(G, im, "ground", "image")
    nt = poly.TERMS_OF_ORDER[order]
    need = 2 * nt - 1
    lower = [f"order {o} needs {2 * poly.TERMS_OF_ORDER[o] - 1}" for o in (1, 2) if o < order]
    check_count(
        G.shape[0], need, what,
        f"{need} coefficients per image coordinate" + (f"; {', '.join(lower)}" if lower else ""),
    )  # fmt: skip
    # longitudes of a scene on the antimeridian (179.9 and -179.9) taken around the first one
    lon = G[0, 0] + longitude_difference(G[:, 0], G[0, 0])
    lo = np.array([lon.min(), G[:, 1].min(), G[:, 2].min()])
    hi = np.array([lon.max(), G[:, 1].max(), G[:, 2].max()])
    span = hi - lo
    for i, axis in enumerate(("longitude", "latitude", "height")):
        if span[i] <= 0:
            raise DegenerateGeometryError(
                f"{what}: all control points have the same {axis}; the {axis} terms cannot be "
                "determined (give points spread in 3D, e.g. at different heights)"
            )
    norm = _Normalisation(np.vstack([lo, hi]), im)
    _check_control_geometry(norm.ground(G), order, what)
    rpc, adj, names, nt, image_normal = _fit_core(
        G, im, norm, order, regularization, float(sigma), what
    )
    if image_size is not None:
        rpc = _with(rpc, image_size=image_size)
    notes, dmin = _denominator_note(rpc, G)
    dmin = min(dmin, _box_denominator_min(rpc))
    if dmin < MIN_DENOMINATOR:
        raise UnstableFitError(what, dmin, G.shape[0], order, regularization)
    fit = _make_fit(
        rpc, adj, names, G.shape[0],
        f"terrain-dependent rational function fit (order {order}, Tikhonov {regularization:g})",
        ids, time.perf_counter() - t0, float(sigma), notes,
        {"regularization": regularization, "order": order, "min_denominator": dmin},
        image_normal,
    )  # fmt: skip
    return with_check_points(fit, rpc, check_ground, check_image, check_ids)


#: Smallest ratio of the extreme singular values of the polynomial terms of the control points
#: (normalised to their box) below which those terms count as undetermined by the points.
MIN_TERMS_CONDITION = 1e-8


def _check_control_geometry(gn: np.ndarray, order: int, what: str) -> None:
    """Refuse control points that cannot determine the coefficients of ``order``.

    The default Tikhonov term keeps the normal equations regular, so without this check a fit
    to too few distinct positions, or to points on a surface of degree ``order`` (one
    vertical plane, two heights for a quadratic in height), returned the smallest
    coefficients among infinitely many exact fits, with small standard deviations.

    Parameters
    ----------
    gn : ndarray, shape (n, 3)
        Control points normalised to their box (``[-1, 1]`` on each axis).
    order : int
        Polynomial degree (1, 2, 3).
    what : str
        The fit, for messages.

    Raises
    ------
    DegenerateGeometryError
        Fewer distinct positions than coefficients per image coordinate (repeated points),
        or polynomial terms that are linearly dependent at the points.
    """
    nt = poly.TERMS_OF_ORDER[order]
    k = 2 * nt - 1
    lower = "" if order == 1 else "; or a lower order (order=1 needs 7 distinct points)"
    distinct = np.unique(np.round(gn * 1e9), axis=0).shape[0]
    if distinct < k:
        raise DegenerateGeometryError(
            f"{what}: the {gn.shape[0]} control points are only {distinct} distinct ground "
            f"positions (points are repeated); the {k} coefficients per image coordinate need "
            f"at least {k} distinct points. Give more distinct control points{lower}"
        )
    T = poly.terms(gn[:, 0], gn[:, 1], gn[:, 2])[:, :nt]
    _, sv, vt = np.linalg.svd(T, full_matrices=False)
    ratio = float(sv[-1] / sv[0])
    if not ratio >= MIN_TERMS_CONDITION:
        null = np.abs(vt[-1])
        terms = [poly.TERM_NAMES[j] for j in np.flatnonzero(null >= 0.1 * null.max())]
        ok = [o for o in (1, 2) if o < order and _terms_condition(gn, o) >= MIN_TERMS_CONDITION]
        fix = f"; or a lower order (order={ok[-1]})" if ok else ""
        raise DegenerateGeometryError(
            f"{what}: the control points do not determine the polynomial terms "
            f"{', '.join(terms)} (L, P, H: normalised longitude, latitude, height): they lie "
            f"on a surface of degree {order} or lower, e.g. along one line in plan or at only "
            f"{order} height(s) (relative singular value {ratio:.1e}). Give control points "
            f"spread in longitude, latitude and height{fix}"
        )


def _terms_condition(gn: np.ndarray, order: int) -> float:
    """Ratio of the extreme singular values of the terms of ``order`` at ``gn``."""
    T = poly.terms(gn[:, 0], gn[:, 1], gn[:, 2])[:, : poly.TERMS_OF_ORDER[order]]
    sv = np.linalg.svd(T, compute_uv=False)
    return float(sv[-1] / sv[0])


def with_check_points(fit: Fit, rpc: RPC, check_ground, check_image, check_ids) -> Fit:
    """``fit`` with the image residuals (computed minus observed, px) of check points
    ``check_ground`` (lon, lat, h) / ``check_image`` (col, row) projected with ``rpc``;
    ``fit`` itself when none are given."""
    if check_ground is None and check_image is None:
        return fit
    if check_ground is None or check_image is None:
        raise InputError("check points need both check_ground and check_image")
    cg = as_points(check_ground, 3, "check_ground")
    ci = as_points(check_image, 2, "check_image")
    check_same_length(cg, ci, "check_ground", "check_image")
    cc, rc = rpc.project(cg[:, 0], cg[:, 1], cg[:, 2])
    return fit.with_checks(np.column_stack([cc, rc]) - ci, check_ids)


def _with(rpc: RPC, **changes) -> RPC:
    from dataclasses import replace

    return replace(rpc, **changes)
