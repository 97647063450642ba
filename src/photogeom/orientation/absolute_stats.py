"""Statistics of the 3D similarity from the linearised Gauss-Markov model, in closed form.

The observation equations ``X_i + v_i = t + s R(omega, phi, kappa) x_i`` (per-point isotropic
weights ``w_i``) linearised at a solution give, with ``x'_i`` the source coordinates reduced to
their weighted centroid ``xg`` and the shift re-parametrised about it
(``t = Xg + t' - s R xg``), a *block-diagonal* normal matrix:

* shift ``t'``: ``W I`` with ``W = sum w_i``;
* scale: ``a = sum w_i |x'_i|^2`` (no coupling: ``sum w_i x'_i = 0``; ``x.T R.T dR x = 0``);
* rotation, as a right perturbation ``R (I + [delta]x)``: ``s^2 (a I - S)`` with the
  weighted scatter ``S = sum w_i x'_i x'_i.T``.

So the 7x7 cofactor matrix needs only ``W``, ``S`` and the solution: no (3n x 7) design
matrix. The rotation block is mapped to omega, phi, kappa (``delta = G d(angles)``) and the
shift back to ``t`` with the Jacobian of ``t = Xg + t' - s R xg``. Redundancy numbers and
Baarda's normalised residuals follow per point from the same blocks (O(n)).

Angles follow the *transposed* convention ``R = M(omega, phi, kappa).T`` (radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..rotation import GIMBAL_TOLERANCE, NEAR_GIMBAL_LOCK, opk_matrix_and_derivatives


def opk_transposed(R: np.ndarray) -> tuple[float, float, float, bool]:
    """``(omega, phi, kappa, gimbal)`` of ``R = M(omega, phi, kappa).T`` in radians.

    The same formulas as :func:`photogeom.rotation.opk_from_matrix` (applied to ``R.T``),
    in scalar arithmetic for speed; at gimbal lock (``cos phi < 1e-9``) omega is set to 0
    and ``gimbal`` is True; near it (``cos phi < 1e-2``) kappa is read from entries of order
    one, as there. Works on a non-orthogonal ``R`` (reads the same elements).
    """
    r = R.tolist()
    m31, m32, m33, m21, m11 = r[0][2], r[1][2], r[2][2], r[0][1], r[0][0]
    cos_phi = math.hypot(m32, m33)
    phi = math.atan2(m31, cos_phi)
    if cos_phi < GIMBAL_TOLERANCE:
        return 0.0, phi, math.atan2(r[1][0], r[1][1]), True
    omega = math.atan2(-m32, m33)
    if cos_phi < NEAR_GIMBAL_LOCK:
        # as opk_from_matrix: kappa from entries of order one, so that the angles give R back
        # to rounding (atan2(-m21, m11) divides R's rounding errors by cos(phi))
        cw, sw = math.cos(omega), math.sin(omega)
        m12, m13 = r[1][0], r[2][0]
        kappa = math.atan2(m12 * cw + m13 * sw, m11 * cos_phi + (m12 * sw - m13 * cw) * m31)
        return omega, phi, kappa, False
    return omega, phi, math.atan2(-m21, m11), False


def rotation_derivatives(omega: float, phi: float, kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """``R = M(omega, phi, kappa).T`` and ``dR / d(omega, phi, kappa)`` (3, 3, 3), radians.

    ``M = M3(kappa) M2(phi) M1(omega)`` (see :func:`photogeom.rotation.opk_matrix`); the
    derivatives replace one factor by its derivative. Scalar arithmetic (called once per
    iteration or solve).
    """
    M, dM = opk_matrix_and_derivatives(omega, phi, kappa)
    R = M.T
    dR = np.stack([d.T for d in dM])
    return R, dR


def angle_to_perturbation(R: np.ndarray, dR: np.ndarray) -> np.ndarray:
    """``G`` (3, 3) with ``delta = G d(angles)`` for ``R(angles + d) = R (I + [delta]x)``:
    column a is ``vee(R.T dR_a)``."""
    K = R.T @ dR  # (3, 3, 3): R.T dR_a, skew-symmetric
    return np.array(
        [[K[0, 2, 1], K[1, 2, 1], K[2, 2, 1]],
         [K[0, 0, 2], K[1, 0, 2], K[2, 0, 2]],
         [K[0, 1, 0], K[1, 1, 0], K[2, 1, 0]]]
    )


def transpose_angles(omega: float, phi: float, kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """Angles of ``R.T`` and their Jacobian with respect to the angles of ``R`` (radians).

    ``R = M(omega, phi, kappa).T``; the returned angles ``b`` satisfy ``M(b).T = R.T``, i.e.
    they are the angles of the inverse rotation in the same convention (the coordinate-frame
    Helmert rotations from the position-vector ones, or the ``"direct"`` angles ``R = M(b)``
    from the ``"transposed"`` ones). With right perturbations ``R(a + d) = R (I + [G_a d]x)``
    (:func:`angle_to_perturbation`), ``R(b + e) = R(a + d).T`` gives exactly, to first order,
    ``G_b e = -R(a) G_a d``, so ``J = -G_b^-1 R(a) G_a`` (3, 3); covariances propagate as
    ``J C J.T``. NaN at gimbal lock of either set of angles.
    """
    R, dR = rotation_derivatives(omega, phi, kappa)
    wb, pb, kb, gimbal = opk_transposed(R.T)
    Rb, dRb = rotation_derivatives(wb, pb, kb)
    Ga = angle_to_perturbation(R, dR)
    Gb = angle_to_perturbation(Rb, dRb)
    b = np.array([wb, pb, kb])
    if gimbal or math.cos(phi) < 1e-9:
        return b, np.full((3, 3), np.nan)
    return b, -np.linalg.solve(Gb, R @ Ga)


@dataclass(frozen=True)
class LinearisedStatistics:
    """Statistics of the linearised model at a solution.

    Attributes
    ----------
    cofactor : numpy.ndarray, shape (u, u)
        ``Qxx`` of ``(tx, ty, tz[, scale], omega, phi, kappa)`` (u = 7, or 6 without scale);
        NaN rows/columns for angles at gimbal lock.
    vtpv : float
    redundancy_numbers, normalized_residuals : numpy.ndarray, shape (n, 3)
        Per component; the normalised residual is NaN where the redundancy number is ~0.
    point_blocks : numpy.ndarray, shape (n, 3, 3)
        ``A Qxx A.T`` blocks per point (for Gauss-Helmert corrections of the source).
    """

    cofactor: np.ndarray
    vtpv: float
    redundancy_numbers: np.ndarray
    normalized_residuals: np.ndarray
    point_blocks: np.ndarray


#: Points per chunk of the per-point statistics (the temporaries stay in the CPU cache, and
#: the chunk's BLAS calls, (6144 x 3) (3 x 12) products, stay below the sizes from which
#: OpenBLAS runs on several threads, whose waiting for each other on a machine busy with other
#: work made the statistics of 1e7 points ten times slower; sums of squares by numpy, not BLAS).
CHUNK_POINTS = 6144


def _psd_factor(Q: np.ndarray) -> np.ndarray:
    """``L`` with ``Q = L L.T`` for a symmetric positive (semi-)definite 3x3 matrix."""
    try:
        return np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        e, V = np.linalg.eigh(0.5 * (Q + Q.T))
        return V * np.sqrt(np.clip(e, 0.0, None))


@dataclass(frozen=True)
class _Model:
    """Everything the per-point pass needs. ``(A Qxx A.T)_i`` of point i is
    ``Y_i Y_i.T + I / W`` with ``Y_i`` (3 x 4) the rows j = 1..3 of ``M x'_i``: three
    components ``s L.T [R_j]x x'_i`` (``Qd = L L.T``, the rotation cofactor) and, with scale,
    ``(R x'_i)_j / sqrt(a)``. So its diagonal is ``(M x')**2`` summed per j (``B``)."""

    MT: np.ndarray  # (3, 12): Y = x' @ MT, columns 4 j + c
    B: np.ndarray  # (12, 3): sums the squares of the four columns of each j
    inv_W: float


def _cofactor(
    S: np.ndarray,
    W: float,
    *,
    scale: float,
    angles: tuple[float, float, float],
    source_centroid: np.ndarray,
    with_scale: bool,
) -> tuple[np.ndarray, _Model]:
    """``Qxx`` of ``(t, [s,] omega, phi, kappa)`` and the per-point model, from the scatter."""
    a = float(S[0, 0] + S[1, 1] + S[2, 2])
    s = scale
    R, _, Ginv = _rotation_and_perturbation(*angles)
    Qd = np.linalg.inv(s * s * (a * _EYE3 - S))
    u = 7 if with_scale else 6
    # cofactor of the reduced unknowns (t', [s,] delta): block diagonal
    Qr = np.zeros((u, u))
    Qr[0, 0] = Qr[1, 1] = Qr[2, 2] = 1.0 / W
    if with_scale:
        Qr[3, 3] = 1.0 / a
    Qr[u - 3 :, u - 3 :] = Qd
    # back from the reduced shift t' to t = Xg + t' - s R xg: dt/ds = -R xg,
    # dt/d(delta) = s R [xg]x
    J = np.eye(u)
    xg = np.asarray(source_centroid, dtype=float)
    if with_scale:
        J[:3, 3] = -(R @ xg)
    J[:3, u - 3 :] = s * (R @ _skew(xg))
    Q1 = J @ Qr @ J.T
    # rotation perturbation -> omega, phi, kappa (undefined at gimbal lock: NaN rows)
    K = np.eye(u)
    if Ginv is not None:
        K[u - 3 :, u - 3 :] = Ginv
        Q = K @ Q1 @ K.T
    else:
        Q = Q1.copy()
        Q[u - 3 :, :] = np.nan
        Q[:, u - 3 :] = np.nan
    # per point, the rotation rows of A (as delta) are -s (R_j x x'_i) = -s [R_j]x x'_i, so
    # (A Qxx A.T)_jk = s^2 x'.T [R_j]x.T Qd [R_k]x x' + ... (parametrisation-invariant)
    Lt = _psd_factor(Qd).T
    M = np.zeros((3, 4, 3))
    M[:, :3] = s * (Lt[None] @ np.stack([_skew(R[0]), _skew(R[1]), _skew(R[2])]))
    if with_scale:
        M[:, 3] = R / math.sqrt(a)
    return Q, _Model(np.ascontiguousarray(M.reshape(12, 3).T), _SUM4, 1.0 / W)


def _rotation_and_perturbation(omega: float, phi: float, kappa: float):
    """``R = M(omega, phi, kappa).T``, ``G`` with ``delta = G d(angles)`` (the right
    perturbation ``R (I + [delta]x)``, as :func:`angle_to_perturbation` of
    :func:`rotation_derivatives`) and ``G^-1`` (None at gimbal lock, ``cos phi <= 1e-9``), in
    closed form: the columns of ``G`` are ``M3 M2 e_x``, ``M3 e_y`` and ``e_z``, so
    ``det G = cos phi``."""
    sw, cw = math.sin(omega), math.cos(omega)
    sp, cp = math.sin(phi), math.cos(phi)
    sk, ck = math.sin(kappa), math.cos(kappa)
    R = np.array(
        [
            [ck * cp, -sk * cp, sp],
            [ck * sp * sw + sk * cw, -sk * sp * sw + ck * cw, -cp * sw],
            [-ck * sp * cw + sk * sw, sk * sp * cw + ck * sw, cp * cw],
        ]
    )
    G = np.array([[ck * cp, sk, 0.0], [-sk * cp, ck, 0.0], [sp, 0.0, 1.0]])
    if abs(cp) <= 1e-9:
        return R, G, None
    Ginv = np.array(
        [
            [ck / cp, -sk / cp, 0.0],
            [sk, ck, 0.0],
            [-sp * ck / cp, sp * sk / cp, 1.0],
        ]
    )
    return R, G, Ginv


def _skew(v) -> np.ndarray:
    """``[v]x`` of one vector (3,)."""
    x, y, z = v.tolist() if isinstance(v, np.ndarray) else v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


#: (12, 3): sums four consecutive columns.
_SUM4 = np.kron(np.eye(3), np.ones((4, 1)))


def _point_pass(
    pm: _Model,
    Y: np.ndarray,
    v: np.ndarray,
    w: np.ndarray | None,
    sigma0_prior: float,
    red: np.ndarray,
    wn: np.ndarray,
    C: np.ndarray | None,
) -> None:
    """Redundancy numbers, normalised residuals (and blocks) of points with ``Y = x' @ MT``
    (m, 12; overwritten) and residuals ``v`` into the output rows ``red``, ``wn`` (``C``)."""
    if C is not None:
        Yb = Y.reshape(-1, 3, 4)
        np.matmul(Yb, np.swapaxes(Yb, 1, 2), out=C)
        C += _EYE3 * pm.inv_W
    np.multiply(Y, Y, out=Y)
    hd = Y @ pm.B
    hd += pm.inv_W
    if w is None:
        num = v
    else:
        hd *= w[:, None]
        num = v * np.sqrt(w)[:, None]
    np.subtract(1.0, hd, out=red)
    wn.fill(np.nan)
    np.sqrt(np.abs(red), out=hd)
    if sigma0_prior != 1.0:
        hd *= sigma0_prior
    np.divide(num, hd, out=wn, where=red > 1e-12)


def linearised_statistics(
    xr: np.ndarray,
    v: np.ndarray,
    *,
    scale: float,
    angles: tuple[float, float, float],
    source_centroid: np.ndarray,
    weights: np.ndarray | None = None,
    sigma0_prior: float = 1.0,
    with_scale: bool = True,
    blocks: bool = False,
    scatter: np.ndarray | None = None,
) -> LinearisedStatistics:
    """Closed-form Gauss-Markov statistics of ``X_i + v_i = t + s R x_i`` at a solution.

    Parameters
    ----------
    xr : numpy.ndarray, shape (n, 3)
        Source points reduced to their (weighted) centroid.
    v : numpy.ndarray, shape (n, 3)
        Residuals (computed minus observed) at the solution, target units.
    scale : float
    angles : (omega, phi, kappa)
        Radians, transposed convention: the linearisation uses ``R(angles)`` (orthogonal).
    source_centroid : numpy.ndarray, shape (3,)
        ``xg`` (to map the reduced shift back to ``t``).
    weights : numpy.ndarray, shape (n,), optional
        Point weights (``P_i = w_i I``); 1 when omitted.
    sigma0_prior : float
    with_scale : bool
        False: rigid model (6 parameters).
    blocks : bool
        Also return the per-point 3x3 blocks of ``A Qxx A.T`` (else ``point_blocks`` is None).
    scatter : numpy.ndarray, shape (3, 3), optional
        ``sum w_i x'_i x'_i.T`` when already known.
    """
    w = weights
    if w is None:
        Wsum = float(xr.shape[0])
        S = xr.T @ xr if scatter is None else scatter
        vtpv = float(v.reshape(-1) @ v.reshape(-1))
    else:
        Wsum = float(np.add.reduce(w))
        S = (xr * w[:, None]).T @ xr if scatter is None else scatter
        vtpv = float(np.add.reduce(np.add.reduce(v * v, axis=1) * w))
    Q, pm = _cofactor(S, Wsum, scale=scale, angles=angles, source_centroid=source_centroid,
                      with_scale=with_scale)
    n = xr.shape[0]
    red = np.empty((n, 3))
    wn = np.empty((n, 3))
    C = np.empty((n, 3, 3)) if blocks else None
    for i in range(0, n, CHUNK_POINTS):
        j = min(i + CHUNK_POINTS, n)
        _point_pass(pm, xr[i:j] @ pm.MT, v[i:j], None if w is None else w[i:j], sigma0_prior,
                    red[i:j], wn[i:j], None if C is None else C[i:j])
    return LinearisedStatistics(Q, vtpv, red, wn, C)


def residual_statistics(
    x: np.ndarray,
    X: np.ndarray,
    *,
    scale: float,
    rotation: np.ndarray,
    translation: np.ndarray,
    angles: tuple[float, float, float],
    source_centroid: np.ndarray,
    scatter: np.ndarray,
    weight_sum: float,
    weights: np.ndarray | None = None,
    sigma0_prior: float = 1.0,
    with_scale: bool = True,
) -> tuple[LinearisedStatistics, np.ndarray]:
    """Residuals ``v = s R x + t - X`` (computed minus observed) and the statistics of
    :func:`linearised_statistics`, in one chunked pass over the points.

    ``rotation`` is the R of the reported model (the raw closed form's may be slightly
    non-orthogonal); the linearisation uses ``R(angles)``. ``scatter`` is the weighted
    centred source scatter and ``weight_sum`` the sum of the weights (the moments).
    """
    Q, pm = _cofactor(scatter, weight_sum, scale=scale, angles=angles,
                      source_centroid=source_centroid, with_scale=with_scale)
    xg = np.asarray(source_centroid, dtype=float)
    sR = scale * np.asarray(rotation, dtype=float)
    k = sR @ xg + translation  # v = sR x' + k - X
    n = x.shape[0]
    v = np.empty((n, 3))
    red = np.empty((n, 3))
    wn = np.empty((n, 3))
    vtpv = 0.0
    if n <= 2048:  # few points: one chunk, plain broadcasting
        xr = x - xg
        np.matmul(xr, sR.T, out=v)
        v += k
        v -= X
        vtpv = float(np.vdot(v, v)) if weights is None else float(
            np.einsum("ij,ij,i->", v, v, weights))
        _point_pass(pm, xr @ pm.MT, v, weights, sigma0_prior, red, wn, None)
        return LinearisedStatistics(Q, vtpv, red, wn, None), v
    # row-wise broadcasting over 3 columns is slow in numpy: centre and shift the chunks as
    # flat arrays against tiled vectors
    m0 = min(CHUNK_POINTS, n)
    xg_t = np.tile(xg, m0)
    k_t = np.tile(k, m0)
    x_flat = x.reshape(-1)
    for i in range(0, n, CHUNK_POINTS):
        j = min(i + CHUNK_POINTS, n)
        m3 = 3 * (j - i)
        xr = (x_flat[3 * i:3 * j] - xg_t[:m3]).reshape(-1, 3)
        vc = v[i:j]
        np.matmul(xr, sR.T, out=vc)
        vflat = vc.reshape(-1)
        vflat += k_t[:m3]
        vc -= X[i:j]
        Y = xr @ pm.MT
        wc = None if weights is None else weights[i:j]
        if wc is None:
            vtpv += float(np.einsum("ij,ij->", vc, vc))
        else:
            vtpv += float(np.einsum("ij,ij,i->", vc, vc, wc))
        _point_pass(pm, Y, vc, wc, sigma0_prior, red[i:j], wn[i:j], None)
    return LinearisedStatistics(Q, vtpv, red, wn, None), v


def gauss_helmert_statistics(
    x: np.ndarray,
    X: np.ndarray,
    *,
    scale: float,
    rotation: np.ndarray,
    translation: np.ndarray,
    angles: tuple[float, float, float],
    source_centroid: np.ndarray,
    target_centroid: np.ndarray,
    sigma_source: float,
    sigma_target: float,
    sigma0_prior: float = 1.0,
    with_scale: bool = True,
) -> tuple[LinearisedStatistics, np.ndarray, dict]:
    """Statistics of the direct Gauss-Helmert solution (one sigma per system), in chunks.

    Misclosures ``g = s R x + t - X``; corrections ``e_x = -sx^2 s R.T g / mm`` and
    ``e_X = sX^2 g / mm`` (``mm = s^2 sx^2 + sX^2``); the cofactor from the linearised model
    at the corrected source points (weights ``sigma0_prior^2 / mm``); redundancy numbers and
    normalised residuals of both systems' corrections from the per-point blocks
    ``(A Qxx A.T)_i`` in units of the misclosure cofactor ``mm / sigma0_prior^2``.

    Two passes over the points in chunks of :data:`CHUNK_POINTS` (the corrections and the
    scatter of the corrected source, then the per-point statistics), writing straight into
    the returned arrays: no (n, 3, 3) blocks and no full-size temporaries. Returns the
    statistics (``redundancy_numbers`` of the target), the target corrections and the extras
    ``corrected_source``, ``corrected_target``, ``source_residuals``,
    ``source_redundancy_numbers``, ``source_normalized_residuals`` and ``misclosures``.
    """
    s = float(scale)
    R = np.asarray(rotation, dtype=float)
    xg = np.asarray(source_centroid, dtype=float)
    Xg = np.asarray(target_centroid, dtype=float)
    sx, sX = float(sigma_source), float(sigma_target)
    n = x.shape[0]
    mm = s * s * sx * sx + sX * sX
    s02 = sigma0_prior**2
    wgt = s02 / mm  # weight of every misclosure component
    cx = -(sx * sx * s / mm)
    cX = sX * sX / mm
    c = s * (R @ xg) + translation - Xg
    g = np.empty((n, 3))
    vx = np.empty((n, 3))
    vX = np.empty((n, 3))
    corr_s = np.empty((n, 3))
    corr_t = np.empty((n, 3))
    S = np.zeros((3, 3))
    vtpv = 0.0
    xr = np.empty((min(CHUNK_POINTS, n), 3))
    for i in range(0, n, CHUNK_POINTS):
        j = min(i + CHUNK_POINTS, n)
        xc = np.subtract(x[i:j], xg, out=xr[: j - i])
        gc = g[i:j]
        np.matmul(xc, R.T, out=gc)
        gc *= s
        gc -= X[i:j] - Xg
        gc += c
        np.multiply(gc @ R, cx, out=vx[i:j])
        np.multiply(gc, cX, out=vX[i:j])
        np.add(x[i:j], vx[i:j], out=corr_s[i:j])
        np.add(X[i:j], vX[i:j], out=corr_t[i:j])
        xc += vx[i:j]  # the corrected source about the centroid (its centroid is unchanged)
        S += (xc * wgt).T @ xc
        vtpv += float(np.einsum("ij,ij->", gc, gc)) * wgt
    Q, pm = _cofactor(S, n * wgt, scale=s, angles=angles, source_centroid=xg,
                      with_scale=with_scale)
    qg = mm / s02
    ft = sX * sX / (mm * qg)
    fs = s * s * sx * sx / (mm * qg)
    red_t = np.empty((n, 3))
    wn_t = np.empty((n, 3))
    red_s = np.empty((n, 3))
    wn_s = np.full((n, 3), np.nan)
    # diag (A Qxx A.T)_i = sum_c Y_jc^2 + 1/W with Y = x' @ MT (see _Model), and the diagonal
    # of R.T (A Qxx A.T)_i R alike from the rows of R.T Y (R is orthogonal: R.T I R / W = I / W)
    MT = pm.MT
    K = np.kron(R, np.eye(4))  # (12, 12): column 4 i + c of Y @ K is (R.T Y)_ic
    MTK = MT @ K
    sqrt_w = math.sqrt(wgt)
    for i in range(0, n, CHUNK_POINTS):
        j = min(i + CHUNK_POINTS, n)
        xc = np.subtract(x[i:j], xg, out=xr[: j - i])
        xc += vx[i:j]
        Y = xc @ MT
        Z = xc @ MTK
        np.multiply(Y, Y, out=Y)
        dC = Y @ pm.B
        dC += pm.inv_W  # diag (A Qxx A.T)_i, in units of the misclosure cofactor
        np.multiply(Z, Z, out=Z)
        qs = Z @ pm.B
        qs += pm.inv_W
        np.subtract(qg, qs, out=qs)  # diag of the source corrections' cofactor
        gc = g[i:j]
        # the misclosures' normalised residuals (Gauss-Markov at weight wgt)
        hd = dC * wgt
        red = np.subtract(1.0, hd, out=hd)
        wt = wn_t[i:j]
        wt.fill(np.nan)
        den = np.sqrt(np.abs(red))
        if sigma0_prior != 1.0:
            den *= sigma0_prior
        np.divide(gc * sqrt_w, den, out=wt, where=red > 1e-12)
        np.subtract(qg, dC, out=red_t[i:j])
        red_t[i:j] *= ft
        np.multiply(qs, fs, out=red_s[i:j])
        np.divide(-(gc @ R), np.sqrt(np.abs(qs)) * sigma0_prior, out=wn_s[i:j],
                  where=qs > 1e-12 * qg)
    st = LinearisedStatistics(Q, vtpv, red_t, wn_t, None)
    extras = {
        "corrected_source": corr_s,
        "corrected_target": corr_t,
        "source_residuals": vx,
        "source_redundancy_numbers": red_s,
        "source_normalized_residuals": wn_s,
        "misclosures": g,
    }
    return st, vX, extras


_EYE3 = np.eye(3)
#: Points per chunk of :func:`closed_form_statistics` (its per-chunk arrays are (u, chunk, 3)).
COFACTOR_CHUNK = 8192


# --- the closed form: propagation through the estimator itself -------------------------------


def _closed_form_outputs(z: np.ndarray, xg: np.ndarray, nearest: bool, with_scale: bool):
    """``(t - Xg0, [s,] omega, phi, kappa)`` of the closed form from ``z = (vec R_raw, s,
    Xg - Xg0)``, ``Xg0`` the target centroid of the estimate: the translation about it, so
    that central differences of ``t`` do not lose the digits of far-away targets (UTM, ECEF;
    the derivatives are those of ``t``)."""
    from .absolute_direct import published_angles

    R = z[:9].reshape(3, 3)
    s = z[9]
    Xg = z[10:13]
    if nearest:
        U, _, Vt = np.linalg.svd(R)
        if np.linalg.det(U) * np.linalg.det(Vt) < 0:
            U[:, 2] *= -1
        R = U @ Vt
        w, p, k, _ = opk_transposed(R)
    else:
        w, p, k = published_angles(R, "transposed")
    t = Xg - s * (R @ xg)
    return np.array([*t, s, w, p, k] if with_scale else [*t, w, p, k])


@dataclass
class _ClosedFormSetup:
    """What the closed form's propagation needs: ``z = (vec R_raw, s, Xg)``, the Jacobian
    ``Jz`` of the reported parameters with respect to ``z``, the pieces of ``R_raw``'s
    derivative and a generator of the usable points in chunks."""

    n: int
    nu: int
    xg: np.ndarray
    s: float
    R_raw: np.ndarray
    Binv: np.ndarray
    Jz: np.ndarray
    aug: tuple | None
    chunks: object  # callable: () -> iterator of (gidx, xb, Xb, dx, dX)


def _closed_form_setup(
    x: np.ndarray,
    X: np.ndarray,
    nearest: bool,
    with_scale: bool,
    coplanar_threshold: float | None,
) -> _ClosedFormSetup:
    """Sums, ``R_raw``, ``s`` and ``Jz`` of the closed form (see :func:`closed_form_statistics`)."""
    from .absolute_direct import (
        CENTROID_TOLERANCE,
        CLOSED_FORM_CHUNKED_N,
        COPLANAR_THRESHOLD,
        _perpendicular_pair,
        closed_form_sums,
    )

    thr = COPLANAR_THRESHOLD if coplanar_threshold is None else coplanar_threshold
    n = x.shape[0]
    if n >= CLOSED_FORM_CHUNKED_N:  # the sums in chunks; per-point terms recomputed per chunk
        cs = closed_form_sums(x, X, thr)
        xg, Xg, nu, MMt, NMt = cs.xg, cs.Xg, cs.nu, cs.MMt, cs.NMt
        aug = cs.aug
        tx, tX = cs.tx, cs.tX

        def chunks():
            for a in range(0, n, COFACTOR_CHUNK):
                b = min(a + COFACTOR_CHUNK, n)
                xr, Xr = x[a:b] - xg, X[a:b] - Xg
                dx = np.sqrt(np.einsum("ni,ni->n", xr, xr))
                dX = np.sqrt(np.einsum("ni,ni->n", Xr, Xr))
                use = (dx > tx) & (dX > tX)
                gidx = np.flatnonzero(use) + a
                xr, Xr, dx, dX = xr[use], Xr[use], dx[use], dX[use]
                yield gidx, xr / dx[:, None], Xr / dX[:, None], dx, dX

    else:
        xg = np.add.reduce(x, axis=0) / n
        Xg = np.add.reduce(X, axis=0) / n
        xr = x - xg
        Xr = X - Xg
        dx = np.sqrt(np.einsum("ni,ni->n", xr, xr))
        dX = np.sqrt(np.einsum("ni,ni->n", Xr, Xr))
        usable = (dx > CENTROID_TOLERANCE * dx.max()) & (dX > CENTROID_TOLERANCE * dX.max())
        idx = np.flatnonzero(usable)
        nu = idx.size
        xb = xr[idx] / dx[idx, None]
        Xb = Xr[idx] / dX[idx, None]
        MMt = Xb.T @ Xb
        NMt = xb.T @ Xb
        ev_x = np.linalg.eigvalsh(xr.T @ xr)
        ev_X = np.linalg.eigvalsh(Xr.T @ Xr)
        ratio = min(
            math.sqrt(max(ev_x[0], 0.0) / ev_x[2]) if ev_x[2] > 0 else 0.0,
            math.sqrt(max(ev_X[0], 0.0) / ev_X[2]) if ev_X[2] > 0 else 0.0,
        )
        aug = None
        if ratio < thr or nu <= 3:
            lq, kq = _perpendicular_pair(
                xb[None], Xb[None], np.ones((1, nu), dtype=bool), (dx[idx] * dX[idx])[None]
            )
            lq, kq = int(lq[0]), int(kq[0])
            xp = np.cross(xb[lq], xb[kq])
            c = np.cross(Xb[lq], Xb[kq])
            nx, nc = float(np.linalg.norm(xp)), float(np.linalg.norm(c))
            if nx > 0 and nc > 0:
                xp, Xp = xp / nx, c / nc
                MMt = MMt + np.outer(Xp, Xp)
                NMt = NMt + np.outer(xp, Xp)
                aug = (int(idx[lq]), int(idx[kq]), xp, Xp, nc, Xb[lq], Xb[kq])

        def chunks():
            for a in range(0, nu, CHUNK_POINTS):
                b = min(a + CHUNK_POINTS, nu)
                yield idx[a:b], xb[a:b], Xb[a:b], dx[idx[a:b]], dX[idx[a:b]]

    Binv = np.linalg.inv(NMt)
    R_raw = MMt @ Binv
    if with_scale:
        s = sum(float(np.add.reduce(dXc / dxc)) for _, _, _, dxc, dXc in chunks()) / nu
    else:
        s = 1.0
    # outputs as a function of z = (vec R_raw, s, Xg): Jacobian by central differences
    # z[10:13] is the shift of the target centroid from Xg (see _closed_form_outputs): with
    # Xg itself, t ~ 5e6 m of a UTM target took ~1e-9 m of rounding into differences of
    # ~1e-7 |xg| (std errors of t 1e-5 off, relative)
    z = np.concatenate([R_raw.ravel(), [s], np.zeros(3)])
    steps = np.concatenate(
        [np.full(9, 1e-7), [1e-7 * max(abs(s), 1.0)], 1e-7 * np.maximum(np.abs(Xg), 1.0)]
    )
    cols = []
    for j in range(13):
        e = np.zeros(13)
        e[j] = steps[j]
        cols.append(
            (
                _closed_form_outputs(z + e, xg, nearest, with_scale)
                - _closed_form_outputs(z - e, xg, nearest, with_scale)
            )
            / (2 * steps[j])
        )
    Jz = np.column_stack(cols)  # (u, 13)
    if not with_scale:
        Jz[:, 9] = 0.0
    return _ClosedFormSetup(n, nu, xg, s, R_raw, Binv, Jz, aug, chunks)


def _closed_form_gradients(cf: _ClosedFormSetup, Jo: np.ndarray):
    """Per chunk of usable points, ``(gidx, a)`` with ``a`` (u, c, 3) the gradients of the
    outputs ``o(z)`` (``Jo = d o / d z``, (u, 13)) with respect to the reduced target points
    ``X'_i = X_i - Xg`` (through the unit vectors, the scale and the augmentation)."""
    u = Jo.shape[0]
    G = Jo[:, :9].reshape(u, 3, 3)  # d output / d R_raw
    H = G @ cf.Binv.T  # (u, 3, 3)
    K = np.swapaxes(cf.R_raw.T @ H, 1, 2)  # K_k.T with K_k = R_raw.T H_k
    Hs = H + np.swapaxes(H, 1, 2)
    # gradient with respect to the augmentation normal, mapped to the two unit vectors
    extra = {}
    if cf.aug is not None:
        lq, kq, xp, Xp, nc, Xb_l, Xb_k = cf.aug
        qp = Hs @ Xp - K @ xp  # (u, 3)
        gc = (qp - np.outer(qp @ Xp, Xp)) / nc
        extra[lq] = np.cross(Xb_k, gc)
        extra[kq] = np.cross(gc, Xb_l)
    HsT = np.swapaxes(Hs, 1, 2)
    KT = np.swapaxes(K, 1, 2)
    for gidx, xb_c, Xb_c, dx_c, dX_c in cf.chunks():
        # per output k and point i (layout (u, c, 3), BLAS products)
        qb = np.matmul(Xb_c[None], HsT) - np.matmul(xb_c[None], KT)
        for i, g in extra.items():
            qb[:, gidx == i, :] += g[:, None, :]
        # through the unit vector: P_i q / rho_i, P_i = I - Xb_i Xb_i.T (in place: the
        # (u, c, 3) arrays are the cost of this pass)
        dots = np.einsum("ucj,cj->uc", qb, Xb_c)
        qb -= dots[:, :, None] * Xb_c[None]
        qb /= dX_c[None, :, None]
        if Jo[:, 9].any():  # s = mean |X'_i| / |x'_i|: d s / d X'_i = Xb_i / (nu |x'_i|)
            qb += Jo[:, 9, None, None] * (Xb_c / (cf.nu * dx_c[:, None]))[None]
        yield gidx, qb


def _closed_form_sums(cf: _ClosedFormSetup, Jo: np.ndarray):
    """``Q = sum_j g_j g_j.T`` of the outputs ``o(z)`` (``Jo = d o / d z``) over the target
    points, ``g_j = a_j + b`` their gradients (the centroid: ``d X'_i / d X_j = (delta_ij -
    1/n) I``, so ``b = (d o / d Xg - sum_i a_i) / n``, ``a_j = 0`` for unusable points);
    returns ``(Q, b)``."""
    u = Jo.shape[0]
    S1 = np.zeros((u, 3))
    S2 = np.zeros((u, u))
    for _, ai in _closed_form_gradients(cf, Jo):
        flat = ai.reshape(u, -1)
        S2 += flat @ flat.T
        S1 += np.add.reduce(ai, axis=1)
    n = cf.n
    bvec = (Jo[:, 10:13] - S1) / n
    return S2 + S1 @ bvec.T + bvec @ S1.T + n * bvec @ bvec.T, bvec


def _used_rotation(R_raw: np.ndarray, nearest: bool) -> np.ndarray:
    """The R the closed form reports: ``R_raw`` or its nearest rotation."""
    if not nearest:
        return R_raw
    U, _, Vt = np.linalg.svd(R_raw)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        U[:, 2] *= -1
    return U @ Vt


def nearest_identity(G: np.ndarray) -> bool:
    """True when ``G`` is the identity (the raw R: no polar factor to differentiate)."""
    return G.shape[0] == G.shape[1] and bool(np.array_equal(G, np.eye(G.shape[0])))


def _fitted_jacobians(xr: np.ndarray, s: float, R: np.ndarray, Gp: np.ndarray,
                      with_scale: bool) -> np.ndarray:
    """``D_i = d F_i / d z`` (c, 3, 13) of the fitted points ``F_i = s R x'_i + Xg``,
    ``z = (vec R_raw, s, Xg)``, ``Gp = d vec R / d vec R_raw`` (9, 9)."""
    c = xr.shape[0]
    E = np.zeros((c, 3, 9))
    for a in range(3):  # d F_a / d R[a, b] = s x'_b (R row-major)
        E[:, a, 3 * a : 3 * a + 3] = xr
    D = np.zeros((c, 3, 13))
    D[:, :, :9] = s * E if nearest_identity(Gp) else s * (E @ Gp)
    if with_scale:
        D[:, :, 9] = xr @ R.T
    D[:, :, 10:13] = np.eye(3)
    return D


def closed_form_statistics(
    x: np.ndarray,
    X: np.ndarray,
    v: np.ndarray,
    *,
    nearest: bool = False,
    with_scale: bool = True,
    weights: np.ndarray | None = None,
    coplanar_threshold: float | None = None,
    sigma0_prior: float = 1.0,
    out: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """Cofactor, expected ``v'Pv`` and residual tests of the closed-form estimate, all
    propagated through the estimator itself.

    The cofactor is ``Q = sum_i J_i J_i.T / w_i`` with ``J_i`` the Jacobian of the
    parameters ``(tx, ty, tz[, scale], omega, phi, kappa)`` with respect to the target point
    ``X_i`` (isotropic target errors, weight ``w_i``; source coordinates error-free, as in the
    Gauss-Markov model). The closed form (Afary 2024) is not a least-squares estimator, so
    the linearised least-squares cofactor is not its covariance (it is too small by up to a
    factor 1.6 in the standard deviations). The Jacobian follows the estimator step by step:
    centroid, scale (the mean length ratio), unit vectors, ``R = (M M.T) inv(N M.T)`` with
    the plane-normal augmentation where used, then the angles as read (published reading of
    the raw R, or of its nearest rotation) and ``t = Xg - s R xg``; the last 3x3 map is
    differentiated numerically (central differences on 13 inputs), the per-point part
    analytically. O(n), in chunks.

    The residuals ``v_i = F_i(z) - X_i`` (``F_i = s R x'_i + Xg`` with the reported R) are a
    function of the target points through ``z = (vec R_raw, s, Xg)``: to first order
    ``v = (H - I) e`` with ``H = D Z`` (``D_i = d F_i / d z``, ``Z_j = d z / d X_j``), so the
    residual cofactor is ``Qvv = (H - I)(H - I).T / w`` (uniform point weight ``w``). Its trace
    times ``w``, ``3n - 2 tr H + tr(H.T H)``, is the expectation of ``v'Pv / sigma0^2``: the
    redundancy to divide by (the least-squares ``3n - u`` holds for a projection ``H`` only;
    the raw closed form's residuals are smaller, those of its nearest rotation larger).
    Redundancy numbers are the diagonal of ``Qvv P``, normalised residuals
    ``v_i sqrt(w) / (sigma0_prior sqrt(r_i))``.

    Parameters
    ----------
    x, X : numpy.ndarray, shape (n, 3)
        Source and target points.
    v : numpy.ndarray, shape (n, 3)
        Residuals (computed minus observed) of the closed-form estimate, target units.
    nearest, with_scale, coplanar_threshold
        As for the estimate.
    weights : numpy.ndarray, shape (n,), optional
        Uniform point weights (the closed form takes no others).
    sigma0_prior : float
        A-priori standard deviation of unit weight.
    out : (numpy.ndarray, numpy.ndarray), optional
        Arrays (n, 3) to write the redundancy numbers and normalised residuals into (e.g.
        those of the linearised statistics, no longer needed): no further n-row arrays.

    Returns
    -------
    cofactor : numpy.ndarray, shape (u, u)
        Of ``(tx, ty, tz[, scale], omega, phi, kappa)`` (see above).
    redundancy : float
        Expected ``v'Pv / sigma0^2`` (not an integer).
    redundancy_numbers, normalized_residuals : numpy.ndarray, shape (n, 3)
        NaN normalised residual where the redundancy number is ~0.
    """
    cf = _closed_form_setup(x, X, nearest, with_scale, coplanar_threshold)
    # gradients of z itself; those of Xg are I / n for every point (a_i = 0), uncorrelated
    # with the rest (sum_j of the others' gradients is 0): the passes carry vec R_raw and s
    Iz = np.eye(13)[:10]
    if not with_scale:
        Iz[9, 9] = 0.0
    Q10, b10 = _closed_form_sums(cf, Iz)
    Qz = np.zeros((13, 13))
    Qz[:10, :10] = Q10
    Qz[10:, 10:] = np.eye(3) / cf.n
    bz = np.vstack([b10, np.eye(3) / cf.n])
    Q = cf.Jz @ Qz @ cf.Jz.T
    R = _used_rotation(cf.R_raw, nearest)
    if nearest:  # d vec R / d vec R_raw of the polar factor, central differences
        Gp = np.empty((9, 9))
        for j in range(9):
            e = np.zeros(9)
            e[j] = 1e-7
            Gp[:, j] = (
                _used_rotation(cf.R_raw + e.reshape(3, 3), True)
                - _used_rotation(cf.R_raw - e.reshape(3, 3), True)
            ).ravel() / 2e-7
    else:
        Gp = np.eye(9)
    n = cf.n
    red, wn = (np.empty((n, 3)), np.empty((n, 3))) if out is None else out
    w = None if weights is None else float(np.mean(np.asarray(weights, dtype=float)))
    root_w = 1.0 if w is None else math.sqrt(w)
    total = 0.0

    def rows(idx, a=None) -> float:
        """Redundancy numbers diag(D_i Qz D_i.T) - 2 diag(D_i g_i) + 1 (g_i = a_i + b the
        gradient of z) and normalised residuals of the points ``idx``; returns their sum."""
        D = _fitted_jacobians(x[idx] - cf.xg, cf.s, R, Gp, with_scale)
        DQ = D @ Qz
        DQ -= 2.0 * bz.T
        if a is not None:
            DQ[:, :, :10] -= 2.0 * np.transpose(a, (1, 2, 0))
        r_i = np.einsum("ckm,ckm->ck", DQ, D)  # (c, 3): BLAS products, no n x 13 x 13 loop
        r_i += 1.0
        np.clip(r_i, 0.0, None, out=r_i)
        red[idx] = r_i
        ok = r_i > 1e-12
        wi = np.full(r_i.shape, np.nan)
        np.divide(v[idx] * root_w, sigma0_prior * np.sqrt(r_i), out=wi, where=ok)
        wn[idx] = wi
        return float(np.add.reduce(r_i.reshape(-1)))

    seen = np.zeros(n, dtype=bool)
    for gidx, ai in _closed_form_gradients(cf, Iz):  # usable points
        total += rows(gidx, ai)
        seen[gidx] = True
    rest = np.flatnonzero(~seen)  # points at the centroid (no unit vector): g_i = b
    for a0 in range(0, rest.size, COFACTOR_CHUNK):
        total += rows(rest[a0 : a0 + COFACTOR_CHUNK])
    if w is not None:
        Q = Q / w
    return Q, total, red, wn
