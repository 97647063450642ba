"""The smallest error with which any method can recover a simulated block's local field.

The simulator draws each image's local field from a known distribution
(:class:`~photogeom.simulate.fields.LocalDistortionField`: random Fourier coefficients of
standard deviation ``s / |k|``, an AR(1) process along the flight plus an optional static
share). With that distribution as the prior and the block's observations, orientations,
calibration and points as the rest of the model, the posterior covariance of the field's
coefficients is the error covariance of the best estimator there is: the posterior mean
minimises the expected squared error over all estimators (for this linear-Gaussian model;
the projection is linearised at the truth, exact to the second order of the pixel
displacement). Its trace over the image, relative to the field's expected mean square, is
the floor of :func:`field_recovery`'s ratio that no grid, spacing, weighting or adjustment
strategy can beat on that block, in expectation.

Unknowns: exterior orientations, free calibration parameters and points as in
:func:`photogeom.bundle_adjust` (with the block's GNSS, IMU and control observations), and
the field coefficients of every image with the simulator's prior. The points are eliminated
(3 x 3 blocks); the rest, dense, holds ``4 K`` coefficients per image (``K`` wave vectors):
tens of images with ``local_field_modes`` up to 6.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..adjust.schur import invert_point_blocks
from ..bundle.adjustment import NCAL, Problem
from ..bundle.options import BundleOptions
from ..errors import DegenerateGeometryError, InputError
from .in_adjustment import _point_blocks

__all__ = ["field_bound"]

#: Largest dense system (orientations, calibration and field coefficients) handled.
DENSE_MAX = 20000
#: Evaluation pixels across and down the image (a regular grid of pixel centres).
SAMPLES = (60, 40)


def field_bound(sim, options: BundleOptions | None = None) -> dict:
    """Expected and realised error of the best estimator of the simulated local field.

    Parameters
    ----------
    sim : SimulatedBlock
        A block of :func:`photogeom.simulate.uav_block` with a local field.
    options : BundleOptions, optional
        The adjustment's settings (free calibration parameters, ``fix_exterior``); default
        those of :func:`photogeom.bundle_adjust`.

    Returns
    -------
    dict
        ``expected_ratio``: the RMS of the best estimator's error over the field's RMS,
        in expectation over fields and noise drawn like the simulator's (the floor of
        :func:`field_recovery`'s ratio); ``ratio``: the same for this block's own field and
        noise (the posterior mean from its observations, blunders left out);
        ``field_rms`` (px, expected RMS length of the field), ``error_rms`` and
        ``realised_field_rms`` (px: this block's), ``coefficients`` (field unknowns),
        ``images``. Errors and field are taken over a regular grid of 60 x 40
        pixels per image.

    Raises
    ------
    InputError
        No local field, or more unknowns than the dense posterior handles.
    """
    F = sim.field
    K = int(F.waves.shape[0])
    if K == 0 or F.total_rms <= 0:
        raise InputError("field_bound: the simulated block has no local field (local_field=0)")
    block = sim.truth.with_observations(uv=sim.ideal + sim.local)
    bp = Problem(block, options or BundleOptions())
    m, b, p = bp.m, bp.b, bp.p
    nb = 2 * K  # cos and sin coefficients of one coordinate of one image
    nl, nc, nf = m * b, bp.ng * NCAL, m * 2 * nb
    off_f, off_p = nl + nc, nl + nc + nf
    free = np.ones(off_p + 3 * p, dtype=bool)
    free[:nl] = bp.local_free.ravel()
    free[nl:off_f] = bp.global_free
    n_dense = int(np.sum(free[:off_p]))
    if n_dense > DENSE_MAX:
        raise InputError(
            f"field_bound: {n_dense} unknowns besides the points exceed the dense limit of "
            f"{DENSE_MAX}; simulate fewer images or fewer local_field_modes"
        )
    frow = F.image_rows(block.image_ids)
    lin = bp.linearize(bp.initial_state(), np.ones(bp.obs_i.size))
    sw = 1.0 / bp.sigma_obs()
    basis = F.basis(sim.ideal[bp.obs_rows]) * sw[:, None]
    J = _jacobian(bp, lin, basis, nb, off_f, off_p)
    prior = _prior_precision(F, frow)
    N = J.T @ J + sp.block_diag(
        [
            sp.block_diag(list(lin.local_info), format="csr"),
            sp.csr_matrix((nc, nc)),
            prior,
            sp.block_diag(list(lin.point_info), format="csr"),
        ],
        format="csr",
    )
    fi = np.flatnonzero(free)
    N = N[fi][:, fi].tocsr()
    # eliminate the points (3 x 3 blocks)
    Naa, Nap, Npp = N[:n_dense, :n_dense], N[:n_dense, n_dense:], N[n_dense:, n_dense:]
    # S = Naa - Nap V^-1 Npa = Naa - M'M with M = U Npa, U'U = V^-1 (3 x 3 blocks): a dense
    # product on the BLAS instead of a sparse one with a dense result
    U = np.transpose(np.linalg.cholesky(invert_point_blocks(_point_blocks(Npp, p))), (0, 2, 1))
    U = sp.block_diag(list(U), format="csr")
    M = (U @ Nap.T).toarray()
    S = Naa.toarray() - M.T @ M
    try:
        cf = sla.cho_factor(S, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise DegenerateGeometryError(
            "field_bound: the normal equations are singular (a datum defect of the block)"
        ) from None
    nfree_l = int(np.sum(free[:off_f]))
    # the field block of the inverse (LAPACK potri on the factor: its lower triangle)
    inv, info = sla.lapack.dpotri(cf[0], lower=1)
    if info != 0:
        raise DegenerateGeometryError("field_bound: the normal equations are singular")
    cov = np.tril(inv[nfree_l:, nfree_l:])
    cov = cov + np.tril(cov, -1).T  # (nf, nf), symmetric
    # the posterior mean of this block's field from its observations (noise, no blunders)
    r = -(sim.local + sim.noise)[bp.obs_rows] * sw[:, None]
    g = J.T @ r.ravel()
    g = g[fi]
    ga = g[:n_dense] - M.T @ (U @ g[n_dense:])
    c_hat = -sla.cho_solve(cf, ga, check_finite=False)[nfree_l:].reshape(m, 2, nb)
    # compare over a pixel grid: G = E'E / n with E the basis at the evaluation pixels
    nu, nv = SAMPLES
    gu, gv = np.meshgrid(np.linspace(0.0, F.width - 1, nu), np.linspace(0.0, F.height - 1, nv))
    E = F.basis(np.column_stack([gu.ravel(), gv.ravel()]))
    G = E.T @ E / E.shape[0]
    std = F.coefficient_std()
    cov = cov.reshape(m, 2, nb, m, 2, nb)
    idx = np.arange(m)
    diag = cov[idx, :, :, idx, :, :]  # (m, 2, nb, 2, nb): each image with itself
    post = float(np.einsum("idqdr,rq->", diag, G))
    expected = float(m * 2 * np.sum(np.diag(G) * std**2))
    c_true = np.transpose(F.coef[frow], (0, 3, 2, 1)).reshape(m, 2, nb)
    err = c_hat - c_true
    e2 = float(np.einsum("idq,qr,idr->", err, G, err))
    f2 = float(np.einsum("idq,qr,idr->", c_true, G, c_true))
    return {
        "expected_ratio": float(np.sqrt(post / expected)),
        "ratio": float(np.sqrt(e2 / f2)) if f2 > 0 else float("nan"),
        "field_rms": float(np.sqrt(expected / m)),
        "error_rms": float(np.sqrt(e2 / m)),
        "realised_field_rms": float(np.sqrt(f2 / m)),
        "coefficients": nf,
        "images": m,
    }


def _prior_precision(F, frow: np.ndarray) -> sp.csr_matrix:
    """Precision of the coefficients, unknowns ordered (image, coordinate, coefficient):
    across images :meth:`~LocalDistortionField.image_covariance`, within an image independent
    with :meth:`~LocalDistortionField.coefficient_std`."""
    Ci = np.linalg.inv(F.image_covariance(frow))
    Ci[np.abs(Ci) < 1e-12 * np.abs(Ci).max()] = 0.0
    per = sp.diags(np.tile(1.0 / F.coefficient_std() ** 2, 2))
    return sp.kron(sp.csr_matrix(Ci), per, format="csr")


def _jacobian(bp, lin, basis, nb, off_f, off_p) -> sp.csr_matrix:
    """Whitened Jacobian of all unknowns: orientations, calibration, field, points."""
    n, i = bp.obs_i.size, bp.obs_i
    c = bp.jacobian_columns(off_p)
    rows, cols, vals = [], [], []
    for d in range(2):  # the two image coordinates
        r = 2 * np.arange(n) + d
        v = np.concatenate([lin.A[:, d, :], lin.G[:, d, :], lin.P[:, d, :]], axis=1)
        cf = off_f + (2 * i + d)[:, None] * nb + np.arange(nb)
        rows += [np.repeat(r, c.shape[1]), np.repeat(r, nb)]
        cols += [c.ravel(), cf.ravel()]
        vals += [v.ravel(), basis.ravel()]
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(2 * n, off_p + 3 * bp.p),
    )
