"""Bias compensation of vendor RPCs in image space with a few control points.

Vendor RPCs are accurate in shape but biased in position (pointing and ephemeris errors), by
a few to tens of pixels. A low-order correction in image space removes most of it
(Grodecki & Dial 2003; Fraser & Hanley 2005). With ``(col, row)`` the RPC's projection of a
control point and ``(col', row')`` the corrected position:

* ``"shift"``: ``col' = col + a0``, ``row' = row + b0`` (1 point minimum);
* ``"shift+drift"``: ``col' = col + a0 + a2 row``, ``row' = row + b0 + b2 row`` -- the row is
  time for a pushbroom sensor, so ``a2``, ``b2`` are drifts (pixels per pixel of row)
  (2 points at different rows);
* ``"affine"``: ``col' = col + a0 + a1 col + a2 row``, ``row' = row + b0 + b1 col + b2 row``
  (3 points, not on one line).

The observation equations ``col_obs + v = col + a0 + a1 col + a2 row`` are linear and are
solved by :func:`photogeom.adjust.solve_linear` with weights ``1 / sigma^2``; the result is a
:class:`~photogeom.adjust.Fit` whose model is the corrected :class:`~photogeom.rpc.RPC`
(``rpc.with_correction(...)``) and whose standard deviations are those of
``a0, a1, a2, b0, b1, b2`` (pixels and pixels per pixel). Ground coordinates of the control
points are taken as exact unless ``ground_sigma`` gives their standard deviations (metres east,
north, up): they are then propagated into image space through the RPC's Jacobian ``J``
(px/deg, px/m), each point's image covariance becoming
``diag(sigma_col^2, sigma_row^2) + J diag(s_lon^2, s_lat^2, s_h^2) J^T`` (a full 2 x 2 block),
so that the standard deviations, sigma0 and the w-test account for errors of the ground
survey too.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from ..adjust import Fit, solve_linear
from ..errors import DegenerateGeometryError, InputError
from ..validation import as_points, check_count, check_same_length
from .fitting import with_check_points
from .geodesy import metres_per_degree
from .model import RPC

#: Correction models and the parameters they estimate (of a0, a1, a2, b0, b1, b2).
MODELS: dict[str, tuple[str, ...]] = {
    "shift": ("a0", "b0"),
    "shift+drift": ("a0", "a2", "b0", "b2"),
    "affine": ("a0", "a1", "a2", "b0", "b1", "b2"),
}
_ALIASES = {"drift": "shift+drift", "shift-drift": "shift+drift", "translation": "shift"}
_MIN_POINTS = {"shift": 1, "shift+drift": 2, "affine": 3}
_UNITS = {"a0": "px", "b0": "px", "a1": "1", "a2": "1", "b1": "1", "b2": "1"}


def _sigmas(sigma, n: int) -> np.ndarray:
    """Per-observation standard deviations, shape (n, 2), from a scalar, (n,) or (n, 2)."""
    s = np.asarray(sigma, dtype=np.float64)
    if s.ndim == 0:
        s = np.full((n, 2), float(s))
    elif s.shape == (n,):
        s = np.repeat(s[:, None], 2, axis=1)
    elif s.shape != (n, 2):
        raise InputError(f"sigma: expected a number, ({n},) or ({n}, 2) values (px), got {s.shape}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError("sigma: standard deviations must be positive numbers of pixels")
    return s


def _ground_sigmas_deg(ground_sigma, G: np.ndarray) -> np.ndarray:
    """Ground standard deviations (n, 3) in lon (deg), lat (deg), h (m) from metres
    east, north, up: one number (all three), (3,) or (n, 3)."""
    n = G.shape[0]
    g = np.asarray(ground_sigma, dtype=np.float64)
    if g.ndim == 0:
        g = np.full((n, 3), float(g))
    elif g.shape == (3,):
        g = np.broadcast_to(g, (n, 3)).copy()
    elif g.shape != (n, 3):
        raise InputError(
            f"ground_sigma: expected a number, (3,) or ({n}, 3) values (m east, north, up), "
            f"got {g.shape}"
        )
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise InputError("ground_sigma: standard deviations must be numbers of metres >= 0")
    east, north = metres_per_degree(G[:, 1], G[:, 2])
    return np.column_stack([g[:, 0] / east, g[:, 1] / north, g[:, 2]])


def refine_rpc(
    rpc: RPC,
    ground,
    image,
    *,
    model: str = "affine",
    sigma=1.0,
    ground_sigma=None,
    ids: Sequence | None = None,
    check_ground=None,
    check_image=None,
    check_ids: Sequence | None = None,
) -> Fit:
    """Bias-compensate an RPC with control points (image-space correction).

    Parameters
    ----------
    rpc : RPC
        Vendor model (an existing correction is kept and the new one composed with it).
    ground : array_like, shape (n, 3)
        Control points: lon (deg), lat (deg), h (m).
    image : array_like, shape (n, 2)
        Their measured image positions: col, row (px, first pixel centre at (0, 0)).
    model : {"shift", "shift+drift", "affine"}
        Correction model (see the module docstring).
    sigma : float or array_like
        Standard deviation of the image measurements (px): one number, one per point, or
        (n, 2).
    ground_sigma : float or array_like, optional
        Standard deviations of the control points' ground coordinates (m): one number, east,
        north, up (3,), or (n, 3). Propagated into image space (see the module docstring);
        None (default): the ground coordinates are exact.
    ids, check_ids : sequence, optional
    check_ground, check_image : array_like, optional
        Check points, not used in the estimate.

    Returns
    -------
    Fit
        ``model``: the corrected RPC; parameters ``a0, a1, a2, b0, b1, b2`` (those of the
        model); residuals (n, 2) px, computed - observed.
    """
    t0 = time.perf_counter()
    key = _ALIASES.get(model, model)
    if key not in MODELS:
        raise InputError(
            f"unknown bias-compensation model {model!r}; use one of {', '.join(MODELS)}"
        )
    what = f"RPC bias compensation ({key})"
    G = as_points(ground, 3, "ground (lon, lat, h)")
    im = as_points(image, 2, "image (col, row)")
    check_same_length(G, im, "ground", "image")
    n = G.shape[0]
    check_count(n, _MIN_POINTS[key], what, f"the {key} model has {len(MODELS[key])} parameters")
    sig = _sigmas(sigma, n)
    c, r = rpc.project(G[:, 0], G[:, 1], G[:, 2])
    if key == "shift+drift" and np.ptp(r) < 1e-6 * max(1.0, float(np.max(np.abs(r)))):
        raise DegenerateGeometryError(
            f"{what}: all control points lie on one image row; the drift (change with the row) "
            "cannot be determined. Use points at different rows or the 'shift' model"
        )
    if key == "affine" and n >= 3:
        d = np.column_stack([c - c.mean(), r - r.mean()])
        s = np.linalg.svd(d, compute_uv=False)
        if s[-1] <= 1e-9 * max(s[0], 1.0):
            raise DegenerateGeometryError(
                f"{what}: the control points lie on one line in the image; an affine correction "
                "needs at least 3 points not on a line. Add points or use 'shift+drift'"
            )
    names = MODELS[key]
    zero, one = np.zeros(n), np.ones(n)
    blocks = {
        "a0": (one, zero), "a1": (c, zero), "a2": (r, zero),
        "b0": (zero, one), "b1": (zero, c), "b2": (zero, r),
    }  # fmt: skip
    A = np.column_stack([np.concatenate(blocks[p]) for p in names])
    L = np.concatenate([im[:, 0] - c, im[:, 1] - r])
    if ground_sigma is None:
        w = 1.0 / np.concatenate([sig[:, 0], sig[:, 1]]) ** 2
        adj = solve_linear(A, L, weights=w, sigma0_prior=1.0, names=names, what=what)
    else:
        # per point a full 2 x 2 covariance: observations reordered point by point
        gs = _ground_sigmas_deg(ground_sigma, G)
        J = rpc.jacobian(G[:, 0], G[:, 1], G[:, 2])  # (n, 2, 3) px/deg, px/m
        C = np.einsum("nik,nk,njk->nij", J, gs**2, J)
        C[:, 0, 0] += sig[:, 0] ** 2
        C[:, 1, 1] += sig[:, 1] ** 2
        order = np.arange(2 * n).reshape(2, n).T.reshape(-1)  # col_0, row_0, col_1, ...
        adj = solve_linear(
            A[order], L[order], covariance=C, sigma0_prior=1.0, names=names, what=what
        )
        adj = _reordered(adj, order)
    full = dict.fromkeys(("a0", "a1", "a2", "b0", "b1", "b2"), 0.0)
    full.update(zip(names, adj.x))
    D = np.array([[full["a1"], full["a2"], full["a0"]], [full["b1"], full["b2"], full["b0"]]])
    corrected = rpc.with_correction(D)
    v = adj.residuals.reshape(2, n).T.copy()

    def per_point(a):
        return None if a is None else np.asarray(a).reshape(2, n).T.copy()

    shift_px = float(np.hypot(full["a0"], full["b0"]))
    fit = Fit(
        model=corrected,
        method=f"RPC bias compensation, image-space {key}",
        parameter_names=tuple(names),
        parameters=adj.x.copy(),
        covariance=adj.covariance,
        cofactor=adj.cofactor,
        sigma0=adj.sigma0,
        sigma0_prior=adj.sigma0_prior,
        redundancy=adj.redundancy,
        n_observations=adj.n_observations,
        residuals=v,
        ids=None if ids is None else tuple(ids),
        residual_labels=("col", "row"),
        residual_unit="px",
        parameter_units={p: _UNITS[p] for p in names},
        normalized_residuals=per_point(adj.normalized_residuals),
        redundancy_numbers=per_point(adj.redundancy_numbers),
        iterations=0,
        converged=True,
        message=adj.message,
        elapsed=time.perf_counter() - t0,
        notes=(
            "correction applied to the RPC's own projection: col' = col + a0 + a1 col + a2 row, "
            "row' = row + b0 + b1 col + b2 row (px)",
        ),
        extras={"model": key, "shift_px": shift_px},
    )
    return with_check_points(fit, corrected, check_ground, check_image, check_ids)


def _reordered(adj, order: np.ndarray):
    """``adj`` with its per-observation arrays put back into the order (cols, then rows)
    of the observations before ``order`` was applied."""
    from dataclasses import replace

    back = np.empty_like(order)
    back[order] = np.arange(order.size)

    def undo(a):
        return None if a is None else np.asarray(a)[back]

    return replace(
        adj,
        residuals=undo(adj.residuals),
        normalized_residuals=undo(adj.normalized_residuals),
        redundancy_numbers=undo(adj.redundancy_numbers),
    )
