"""Direct (closed-form) solvers of the 3D similarity ``X = s R x + t``, vectorised over problems.

Every function here works on a *batch* of independent problems (leading axis B) so that the
same code serves single solves, :func:`~photogeom.orientation.absolute_orientation_batch`
and the minimal solver inside RANSAC. Methods (see ``docs/absolute-orientation.md``):

* :func:`solve_svd` - Arun, Huang & Blostein (1987) with Umeyama's (1991) scale and reflection
  guard, weighted centroids;
* :func:`solve_quaternion` - Horn (1987), rotation from the dominant eigenvector of a 4x4
  symmetric matrix; least-squares (default) or Horn's symmetric scale;
* :func:`solve_dual_quaternion` - Walker, Shao & Volz (1991), with scale (Wang et al. 2014)
  and weights (Zeng et al. 2022): rotation and translation from one dual-quaternion cost;
* :func:`solve_gauss_helmert_direct` - the errors-in-both-systems solution (Chang 2015);
* :func:`solve_closed_form` - the normalised-vector method (Afary 2024), raw non-orthogonal R.

All but the closed form need only the weighted moments of the two point sets
(:class:`Moments`), which :func:`batch_moments` and :func:`large_moments` compute; the latter
in one pass over the data for millions of points.

Single problems take a leaner path with the same formulas (:class:`PairMoments`,
:func:`solve_single`, :func:`closed_form_single`: LAPACK called directly, scalar arithmetic for
the 3x3 algebra), and three-point problems a closed form of their SVD
(:func:`solve_three_points`, the minimal solver of RANSAC). Tests check every path against the
others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg.lapack as _lapack

from .batch_linalg import svd3

#: Points closer to their centroid than this fraction of the largest centroid distance carry
#: no direction; the closed form leaves them out of its scale ratios and unit vectors.
CENTROID_TOLERANCE = 1e-9
#: The closed form treats a point set as (nearly) coplanar, and augments its unit vectors with a
#: plane normal, when the smallest singular value of the centred coordinates is below this
#: fraction of the largest, for the source or the target set (always for n = 3). Chosen from
#: the Monte-Carlo study (benchmarks/absolute_orientation_montecarlo.py): without the
#: augmentation, N M.T amplifies the noise as the sets flatten (5-50x larger rotation error
#: at ratio 0.01-0.1); with it the error stays at the level of thick sets.
COPLANAR_THRESHOLD = 0.3
#: The rotation is undetermined (collinear or coincident points) when the second singular value
#: of the cross-covariance ``H`` is below this fraction of the first.
DEGENERATE_TOLERANCE = 1e-12
#: A best fit is declared a reflection when the mirror image leaves less than this fraction of
#: the residual sum of squares of the best proper rotation.
REFLECTION_RATIO = 0.5
#: Coplanar sets (``sigma3(H) <= 1e-10 sigma1(H)``) fit a reflection and a rotation equally
#: well; they are never declared reflections.
COPLANAR_REFLECTION = 1e-10
#: Largest ``|centroid|^2 / variance`` for which the one-pass moments of :func:`large_moments`
#: are accurate to ~1e-11; beyond it the centroids are removed exactly first.
CANCELLATION_LIMIT = 1e4
#: Points per chunk of :func:`large_moments` (the chunk stays in the CPU's last-level cache).
CHUNK_POINTS = 32768
#: Rows (of four points) per BLAS call of :func:`large_moments`: the (12 x 512) (512 x 12)
#: products, (512 x 12) sums and 6144-element dot products stay below the sizes from which
#: OpenBLAS runs on several threads. On a machine busy with other work those threads wait for
#: each other: with one product per 4096-row chunk the pass took 5.5 s instead of 0.26 s for
#: 1e7 points (median of seven runs on a loaded 2-core machine).
BLAS_ROWS = 512


@dataclass(frozen=True)
class Moments:
    """Weighted moments of B pairs of point sets about reference points.

    With ``u_i = x_i - ref_source`` and ``U_i = X_i - ref_target`` (weights ``w_i``):

    Attributes
    ----------
    weight : numpy.ndarray, shape (B,)
        ``W = sum w_i``.
    ref_source, ref_target : numpy.ndarray, shape (B, 3)
        Reference points (the centroids, or the origin for one-pass moments).
    sum_source, sum_target : numpy.ndarray, shape (B, 3)
        ``sum w_i u_i`` and ``sum w_i U_i``.
    cross : numpy.ndarray, shape (B, 3, 3)
        ``sum w_i u_i U_i.T``.
    sq_source, sq_target : numpy.ndarray, shape (B,)
        ``sum w_i |u_i|^2`` and ``sum w_i |U_i|^2``.
    scatter_source : numpy.ndarray, shape (B, 3, 3), optional
        ``sum w_i u_i u_i.T`` (when computed).
    """

    weight: np.ndarray
    ref_source: np.ndarray
    ref_target: np.ndarray
    sum_source: np.ndarray
    sum_target: np.ndarray
    cross: np.ndarray
    sq_source: np.ndarray
    sq_target: np.ndarray
    scatter_source: np.ndarray | None = None

    @property
    def source_centroid(self) -> np.ndarray:
        """Weighted centroid ``xg`` (B, 3)."""
        return self.ref_source + self.sum_source / self.weight[:, None]

    @property
    def target_centroid(self) -> np.ndarray:
        """Weighted centroid ``Xg`` (B, 3)."""
        return self.ref_target + self.sum_target / self.weight[:, None]

    @property
    def H(self) -> np.ndarray:
        """Centred cross-covariance ``H = sum w_i x'_i X'_i.T`` (B, 3, 3)."""
        return self.cross - self.sum_source[:, :, None] * self.sum_target[:, None, :] / (
            self.weight[:, None, None]
        )

    @property
    def S(self) -> np.ndarray | None:
        """Centred source scatter ``sum w_i x'_i x'_i.T`` (B, 3, 3), when computed."""
        if self.scatter_source is None:
            return None
        return self.scatter_source - self.sum_source[:, :, None] * self.sum_source[:, None, :] / (
            self.weight[:, None, None]
        )

    @property
    def a(self) -> np.ndarray:
        """``sum w_i |x'_i|^2`` (B,)."""
        return self.sq_source - np.sum(self.sum_source**2, axis=1) / self.weight

    @property
    def b(self) -> np.ndarray:
        """``sum w_i |X'_i|^2`` (B,)."""
        return self.sq_target - np.sum(self.sum_target**2, axis=1) / self.weight


@dataclass(frozen=True)
class DirectSolution:
    """Estimates of B problems.

    Attributes
    ----------
    scale : numpy.ndarray, shape (B,)
    rotation : numpy.ndarray, shape (B, 3, 3)
        Proper rotations, except the raw closed-form matrix (not exactly orthogonal).
    translation : numpy.ndarray, shape (B, 3)
    degenerate : numpy.ndarray of bool, shape (B,)
        Rotation undetermined (collinear or coincident points); estimates are meaningless.
    reflection : numpy.ndarray of bool, shape (B,)
        The best fit is a reflection; the returned rotation is the best *proper* rotation
        (or, for the closed form, a matrix with det < 0).
    augmented : numpy.ndarray of bool, shape (B,) or None
        Closed form only: the plane-normal augmentation was used.
    at_centroid : numpy.ndarray of int, shape (B,) or None
        Closed form only: points left out because they lie at the centroid.
    """

    scale: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    degenerate: np.ndarray
    reflection: np.ndarray
    augmented: np.ndarray | None = None
    at_centroid: np.ndarray | None = None


# --- moments -------------------------------------------------------------------------------


def batch_moments(x: np.ndarray, X: np.ndarray, w: np.ndarray | None = None) -> Moments:
    """Exact moments about the (weighted) centroids of B problems.

    Parameters
    ----------
    x, X : numpy.ndarray, shape (B, n, 3)
        Source and target points.
    w : numpy.ndarray, shape (B, n), optional
        Positive point weights.
    """
    B, n, _ = x.shape
    if w is None:
        W = np.full(B, float(n))
        xg = np.add.reduce(x, axis=1) / n
        Xg = np.add.reduce(X, axis=1) / n
        xr = x - xg[:, None, :]
        Xr = X - Xg[:, None, :]
        cross = np.matmul(np.swapaxes(xr, 1, 2), Xr)
        wxr = xr
    else:
        W = np.add.reduce(w, axis=1)
        xg = np.einsum("bn,bni->bi", w, x) / W[:, None]
        Xg = np.einsum("bn,bni->bi", w, X) / W[:, None]
        xr = x - xg[:, None, :]
        Xr = X - Xg[:, None, :]
        wxr = xr * w[:, :, None]
        cross = np.matmul(np.swapaxes(wxr, 1, 2), Xr)
    sq_s = np.einsum("bni,bni->b", wxr, xr)
    wXr = Xr if w is None else Xr * w[:, :, None]
    sq_t = np.einsum("bni,bni->b", wXr, Xr)
    # sums about the centroid: zero up to rounding; kept so that H, a, b are exact
    ss = np.add.reduce(wxr, axis=1)
    st = np.add.reduce(wXr, axis=1)
    return Moments(W, xg, Xg, ss, st, cross, sq_s, sq_t)


def _reference(p: np.ndarray) -> np.ndarray | None:
    """Reference point of one-pass moments: None (the origin) unless the first chunk of the
    points lies far from the origin compared with its spread (``|mean|^2 > var`` / 100 of
    :data:`CANCELLATION_LIMIT`, e.g. UTM coordinates); then the mean of that chunk."""
    head = p[:CHUNK_POINTS]
    mu = np.add.reduce(head, axis=0) / head.shape[0]
    d = head - mu
    var = float(np.einsum("ij,ij->", d, d)) / head.shape[0]
    if float(mu @ mu) <= 0.01 * CANCELLATION_LIMIT * var:
        return None
    return mu


def _raw_moments_chunked(
    x: np.ndarray,
    X: np.ndarray,
    w: np.ndarray | None,
    ref_x: np.ndarray | None,
    ref_X: np.ndarray | None,
    scatter: bool,
) -> tuple:
    """Moments about ``ref_x``/``ref_X`` (None: the origin) in one cache-friendly pass.

    Chunks of :data:`CHUNK_POINTS` points, four points per row: ``(m/4, 12) x (m/4, 12)``
    products (stacks of :data:`BLAS_ROWS`-row products) whose 3x3 diagonal blocks are the
    per-point cross products (BLAS runs far faster on 12 than on 3 columns); sums and sums of
    squares of the same rows. A reference
    costs one subtraction per chunk (the chunk is in the CPU cache). ``scatter`` also
    accumulates ``sum w u u.T`` of the source.
    """
    n = x.shape[0]
    n4 = n - n % 4
    G = np.zeros((12, 12))
    Gs = np.zeros((12, 12)) if scatter else None
    sa = np.zeros(12)
    sb = np.zeros(12)
    qa = 0.0
    qb = 0.0
    W = 0.0 if w is not None else float(n)
    rx = None if ref_x is None else np.tile(ref_x, 4)
    rX = None if ref_X is None else np.tile(ref_X, 4)
    ones = np.ones(CHUNK_POINTS // 4)
    ones_r = ones[:BLAS_ROWS]
    # reduced chunks go to buffers that stay in the CPU cache (no new array per chunk)
    buf_x = None if rx is None else np.empty((CHUNK_POINTS // 4, 12))
    buf_X = None if rX is None else np.empty((CHUNK_POINTS // 4, 12))
    for i in range(0, n4, CHUNK_POINTS):
        j = min(i + CHUNK_POINTS, n4)
        A = x[i:j].reshape(-1, 12)
        B = X[i:j].reshape(-1, 12)
        if rx is not None:
            A = np.subtract(A, rx, out=buf_x[: A.shape[0]])
        if rX is not None:
            B = np.subtract(B, rX, out=buf_X[: B.shape[0]])
        if w is None:
            Aw, Bw = A, B
        else:
            wi = w[i:j]
            W += float(np.add.reduce(wi))
            w12 = np.repeat(wi, 3).reshape(-1, 12)
            Aw, Bw = A * w12, B * w12
        k = A.shape[0]
        if k % BLAS_ROWS:  # the last, partial chunk
            G += Aw.T @ B
            if scatter:
                Gs += Aw.T @ A
            sa += ones[:k] @ Aw
            sb += ones[:k] @ Bw
            qa += float(Aw.reshape(-1) @ A.reshape(-1))
            qb += float(Bw.reshape(-1) @ B.reshape(-1))
            continue
        # stacks of BLAS_ROWS-row products: each small enough for one BLAS thread
        A3, B3 = A.reshape(-1, BLAS_ROWS, 12), B.reshape(-1, BLAS_ROWS, 12)
        Aw3T = Aw.reshape(-1, BLAS_ROWS, 12).transpose(0, 2, 1)
        G += np.matmul(Aw3T, B3).sum(axis=0)
        if scatter:
            Gs += np.matmul(Aw3T, A3).sum(axis=0)
        sa += np.matmul(ones_r, Aw.reshape(-1, BLAS_ROWS, 12)).sum(axis=0)
        sb += np.matmul(ones_r, Bw.reshape(-1, BLAS_ROWS, 12)).sum(axis=0)
        f = 12 * BLAS_ROWS
        qa += float(np.matmul(Aw.reshape(-1, 1, f), A.reshape(-1, f, 1)).sum())
        qb += float(np.matmul(Bw.reshape(-1, 1, f), B.reshape(-1, f, 1)).sum())
    cross = G[0:3, 0:3] + G[3:6, 3:6] + G[6:9, 6:9] + G[9:12, 9:12]
    S = None if Gs is None else Gs[0:3, 0:3] + Gs[3:6, 3:6] + Gs[6:9, 6:9] + Gs[9:12, 9:12]
    sx = sa.reshape(4, 3).sum(axis=0)
    sX = sb.reshape(4, 3).sum(axis=0)
    if n4 < n:  # the last n % 4 points
        a = x[n4:] if ref_x is None else x[n4:] - ref_x
        b = X[n4:] if ref_X is None else X[n4:] - ref_X
        if w is None:
            wa, wb = a, b
        else:
            wt = w[n4:]
            W += float(np.add.reduce(wt))
            wa, wb = a * wt[:, None], b * wt[:, None]
        cross = cross + wa.T @ b
        if S is not None:
            S = S + wa.T @ a
        sx = sx + np.add.reduce(wa, axis=0)
        sX = sX + np.add.reduce(wb, axis=0)
        qa += float(np.sum(wa * a))
        qb += float(np.sum(wb * b))
    return W, sx, sX, cross, qa, qb, S


def large_moments(
    x: np.ndarray, X: np.ndarray, w: np.ndarray | None = None, *, scatter: bool = False
) -> Moments:
    """Moments of one large problem (n, 3) in a single pass over the data.

    The sums are taken about the origin, or - for a point set far from the origin compared
    with its spread, e.g. UTM coordinates - about the mean of its first chunk, so that no
    digits are lost. Should the sums still show cancellation (``|centroid - reference|^2 /
    variance`` above :data:`CANCELLATION_LIMIT`: the first chunk was not representative),
    a second pass takes them about the centroids of the first. ``scatter`` also returns the
    source scatter matrix (``Moments.scatter_source``).
    """
    # No BLAS thread limit is set around the chunked products: the limit is process-wide
    # state (other threads' BLAS calls would change with it, and concurrent set/restore
    # pairs can leave the process single-threaded), and it measured no faster here.
    return _large_moments(x, X, w, scatter)


def _cancellation(W: float, s: np.ndarray, q: float) -> float:
    """``|sum / W|^2 / variance`` of one point set's one-pass sums (inf when degenerate)."""
    ss = float(s @ s) / W
    var = q - ss
    return ss / var if var > 0 else (0.0 if ss == 0 else math.inf)


def _large_moments(x: np.ndarray, X: np.ndarray, w: np.ndarray | None, scatter: bool) -> Moments:
    x = np.ascontiguousarray(x)
    X = np.ascontiguousarray(X)
    ref_x, ref_X = _reference(x), _reference(X)
    W, sx, sX, cross, qx, qX, S = _raw_moments_chunked(x, X, w, ref_x, ref_X, scatter)
    if not math.isfinite(qx + qX + float(sx.sum() + sX.sum())) or not W > 0:
        pass  # NaN / inf in the data (or overflow): the caller reports it
    elif max(_cancellation(W, sx, qx), _cancellation(W, sX, qX)) > CANCELLATION_LIMIT:
        zero = np.zeros(3)
        ref_x = (zero if ref_x is None else ref_x) + sx / W
        ref_X = (zero if ref_X is None else ref_X) + sX / W
        W, sx, sX, cross, qx, qX, S = _raw_moments_chunked(x, X, w, ref_x, ref_X, scatter)
    ref_x = np.zeros(3) if ref_x is None else ref_x
    ref_X = np.zeros(3) if ref_X is None else ref_X
    return Moments(
        np.array([W]),
        ref_x[None].copy(),
        ref_X[None].copy(),
        sx[None],
        sX[None],
        cross[None],
        np.array([qx]),
        np.array([qX]),
        None if S is None else S[None],
    )


@dataclass(slots=True)
class PairMoments:
    """Centred moments of one problem (the single-solve path).

    Attributes
    ----------
    weight : float
        ``W = sum w_i``.
    source_centroid, target_centroid : numpy.ndarray, shape (3,)
    H : numpy.ndarray, shape (3, 3)
        ``sum w_i x'_i X'_i.T``.
    a, b : float
        ``sum w_i |x'_i|^2`` and ``sum w_i |X'_i|^2``.
    S : numpy.ndarray, shape (3, 3), optional
        Source scatter ``sum w_i x'_i x'_i.T`` (when computed).
    """

    weight: float
    source_centroid: np.ndarray
    target_centroid: np.ndarray
    H: np.ndarray
    a: float
    b: float
    S: np.ndarray | None = None

    @classmethod
    def of(cls, x: np.ndarray, X: np.ndarray, w: np.ndarray | None = None) -> PairMoments:
        """Exact moments of points x, X (n, 3) with optional point weights w (n,)."""
        Z = np.concatenate((x, X), axis=1)
        W = float(x.shape[0]) if w is None else float(np.add.reduce(w))
        mu = (np.add.reduce(Z, axis=0) if w is None else w @ Z) / W
        if not math.isfinite(float(np.add.reduce(mu))):  # NaN/inf input: see finite()
            return cls(W, mu[:3], mu[3:], np.full((3, 3), np.nan), math.nan, math.nan)
        Zr = Z - mu
        C = Zr.T @ Zr if w is None else (Zr * w[:, None]).T @ Zr
        c = C.tolist()
        return cls(
            W, mu[:3], mu[3:], C[:3, 3:], c[0][0] + c[1][1] + c[2][2], c[3][3] + c[4][4] + c[5][5],
            C[:3, :3],
        )

    @classmethod
    def from_moments(cls, m: Moments, i: int = 0) -> PairMoments:
        """Problem ``i`` of a batch of :class:`Moments`."""
        S = m.S
        return cls(
            float(m.weight[i]), m.source_centroid[i], m.target_centroid[i], m.H[i],
            float(m.a[i]), float(m.b[i]), None if S is None else S[i],
        )

    def finite(self) -> bool:
        """False when NaN/inf entered the sums (bad input or overflow)."""
        return math.isfinite(self.a + self.b + float(self.H.sum()))


def _det_list(M: list) -> float:
    return (
        M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1])
        - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0])
        + M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])
    )


def _classify_one(S: list, d: float, a: float, b: float, with_scale: bool) -> tuple[bool, bool]:
    """Scalar version of :func:`classify` (same rules)."""
    degenerate = not (S[1] > DEGENERATE_TOLERANCE * S[0]) or not (a > 0) or not (b > 0)
    if d > 0 or degenerate or not (S[2] > COPLANAR_REFLECTION * S[0]):
        return degenerate, False
    tr_rot = S[0] + S[1] - S[2]
    tr_ref = S[0] + S[1] + S[2]
    if with_scale:
        e_rot = b - max(tr_rot, 0.0) ** 2 / a
        e_ref = b - tr_ref**2 / a
    else:
        e_rot = a + b - 2 * tr_rot
        e_ref = a + b - 2 * tr_ref
    e_rot = max(e_rot, 1e-14 * (a + b))
    return False, max(e_ref, 0.0) < REFLECTION_RATIO * e_rot


@dataclass(slots=True)
class SingleSolution:
    """Estimate of one problem (see :class:`DirectSolution`)."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    degenerate: bool
    reflection: bool
    singular_values: list | None = None  # of the cross-covariance H, descending


def solve_single(
    pm: PairMoments,
    method: str,
    *,
    with_scale: bool = True,
    scale_method: str = "least-squares",
    ratio: float = 1.0,
) -> SingleSolution:
    """One problem by ``"svd"``, ``"quaternion"``, ``"dual-quaternion"`` or
    ``"gauss-helmert"`` (direct), with the formulas of the batched solvers but scalar
    arithmetic for the 3x3 algebra (no per-call numpy overhead: the path for single solves)."""
    u, S_, vt, info = _lapack.dgesvd(pm.H)
    if info != 0:
        raise np.linalg.LinAlgError("SVD did not converge")
    S = S_.tolist()
    R0 = vt.T @ u.T  # V U.T; det(R0) = det(U) det(V) = +-1
    d = 1.0 if _det_list(R0.tolist()) >= 0 else -1.0
    a, b = pm.a, pm.b
    degenerate, reflection = _classify_one(S, d, a, b, with_scale)
    xg, Xg = pm.source_centroid, pm.target_centroid
    if method in ("quaternion", "dual-quaternion"):
        if method == "quaternion":
            (Sxx, Sxy, Sxz), (Syx, Syy, Syz), (Szx, Szy, Szz) = pm.H.tolist()
            N = np.array(
                [
                    [Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx],
                    [Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz],
                    [Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy],
                    [Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz],
                ]
            )
        else:
            # centred moments: sum w u = 0, so the dual part C3 r / 2W vanishes and the
            # rotation part is C1 = sum w Q(X').T W(x') (Walker et al.); t = Xg - s R xg
            N = np.tensordot(pm.H, _QW, 2)
            N = 0.5 * (N + N.T)
        vals, vecs, info = _lapack.dsyev(N)
        if info != 0:
            raise np.linalg.LinAlgError("eigen-decomposition did not converge")
        q = vecs[:, 3].tolist()
        R = _quaternion_matrix(q)
        trace = float(vals[3])
    else:
        # V diag(1, 1, d) U.T = V U.T - (1 - d) v3 u3.T
        R = R0 if d > 0 else R0 - 2.0 * np.outer(vt[2], u[:, 2])
        trace = S[0] + S[1] + d * S[2]
    if not with_scale:
        s = 1.0
    elif method == "gauss-helmert":
        aa = a * ratio * ratio
        c = trace * ratio
        dd = aa - b
        f = math.hypot(dd, 2 * c)
        if c == 0:
            s = math.nan
        else:
            s = (2 * c / (dd + f) if dd > 0 else (f - dd) / (2 * c)) * ratio
    elif scale_method == "symmetric":
        s = math.sqrt(b / a) if a > 0 else math.nan
    else:
        s = trace / a if a > 0 else math.nan
    t = Xg - s * (R @ xg)
    return SingleSolution(s, R, t, degenerate, reflection, S)


# --- small linear-algebra helpers (LAPACK directly for a single 3x3 / 4x4) ------------------


def _svd3(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched SVD ``H = U diag(S) Vt`` of (B, 3, 3); one matrix goes straight to LAPACK."""
    if H.shape[0] == 1:
        u, s, vt, info = _lapack.dgesvd(H[0])
        if info == 0:
            return u[None], s[None], vt[None]
    return svd3(H)


def _eigh4(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched symmetric eigen-decomposition of (B, 4, 4), ascending eigenvalues."""
    if N.shape[0] == 1:
        vals, vecs, info = _lapack.dsyev(N[0])
        if info == 0:
            return vals[None], vecs[None]
    return np.linalg.eigh(N)


def _det3(M: np.ndarray) -> np.ndarray:
    """Determinants of (B, 3, 3) by the rule of Sarrus (exact for orthogonal factors)."""
    return (
        M[:, 0, 0] * (M[:, 1, 1] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 1])
        - M[:, 0, 1] * (M[:, 1, 0] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 0])
        + M[:, 0, 2] * (M[:, 1, 0] * M[:, 2, 1] - M[:, 1, 1] * M[:, 2, 0])
    )


def _quaternion_matrix(q: list) -> np.ndarray:
    """Rotation matrix of one quaternion (list, scalar first; normalised here)."""
    w, x, y, z = q
    k = 1.0 / (w * w + x * x + y * y + z * z)
    return np.array(
        [
            [(w * w + x * x - y * y - z * z) * k, 2 * (x * y - w * z) * k, 2 * (x * z + w * y) * k],
            [2 * (x * y + w * z) * k, (w * w - x * x + y * y - z * z) * k, 2 * (y * z - w * x) * k],
            [2 * (x * z - w * y) * k, 2 * (y * z + w * x) * k, (w * w - x * x - y * y + z * z) * k],
        ]
    )


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (B, 3, 3) of unit quaternions (B, 4), scalar first, acting as ``R x``."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = w * w + x * x - y * y - z * z
    R[:, 0, 1] = 2 * (x * y - w * z)
    R[:, 0, 2] = 2 * (x * z + w * y)
    R[:, 1, 0] = 2 * (x * y + w * z)
    R[:, 1, 1] = w * w - x * x + y * y - z * z
    R[:, 1, 2] = 2 * (y * z - w * x)
    R[:, 2, 0] = 2 * (x * z - w * y)
    R[:, 2, 1] = 2 * (y * z + w * x)
    R[:, 2, 2] = w * w - x * x - y * y + z * z
    return R


# --- geometry classification ------------------------------------------------------------------


def classify(
    m: Moments, S: np.ndarray, det_sign: np.ndarray, with_scale: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Flag degenerate problems and best-fit reflections.

    Parameters
    ----------
    m : Moments
    S : numpy.ndarray, shape (B, 3)
        Singular values of ``H`` (descending).
    det_sign : numpy.ndarray, shape (B,)
        Sign of ``det(V U.T)`` of the SVD of ``H`` (-1: the unconstrained best orthogonal fit
        is a reflection).
    with_scale : bool

    Returns
    -------
    degenerate, reflection : numpy.ndarray of bool, shape (B,)
        ``degenerate``: collinear or coincident points (``sigma2(H) <= 1e-12 sigma1(H)``) -
        the rotation about the line is undetermined. ``reflection``: ``det < 0`` and the mirror
        image leaves less than :data:`REFLECTION_RATIO` of the residual sum of squares of the
        best proper rotation.
    """
    a, b = m.a, m.b
    degenerate = ~(S[:, 1] > DEGENERATE_TOLERANCE * S[:, 0]) | ~(a > 0) | ~(b > 0)
    neg = det_sign < 0
    reflection = np.zeros_like(neg)
    if np.any(neg):
        tr_rot = S[:, 0] + S[:, 1] - S[:, 2]
        tr_ref = S[:, 0] + S[:, 1] + S[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            if with_scale:
                e_rot = b - np.maximum(tr_rot, 0.0) ** 2 / a
                e_ref = b - tr_ref**2 / a
            else:
                e_rot = a + b - 2 * tr_rot
                e_ref = a + b - 2 * tr_ref
        floor = 1e-14 * (a + b)
        e_rot = np.maximum(e_rot, floor)
        e_ref = np.maximum(e_ref, 0.0)
        reflection = (
            neg
            & (e_ref < REFLECTION_RATIO * e_rot)
            & (S[:, 2] > COPLANAR_REFLECTION * S[:, 0])
            & ~degenerate
        )
    return degenerate, reflection


def _sv_and_sign(H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    U, S, Vt = _svd3(H)
    d = np.sign(_det3(U) * _det3(Vt))
    d = np.where(d == 0, 1.0, d)
    return U, S, Vt, d


def _translation(m: Moments, s: np.ndarray, R: np.ndarray) -> np.ndarray:
    xg, Xg = m.source_centroid, m.target_centroid
    return Xg - s[:, None] * np.einsum("bij,bj->bi", R, xg)


def _scale(m: Moments, trace: np.ndarray, with_scale: bool, scale_method: str) -> np.ndarray:
    if not with_scale:
        return np.ones_like(trace)
    a = m.a
    with np.errstate(divide="ignore", invalid="ignore"):
        if scale_method == "symmetric":
            return np.sqrt(m.b / a)
        return trace / a


# --- B: SVD ---------------------------------------------------------------------------------


def solve_svd(
    m: Moments, *, with_scale: bool = True, scale_method: str = "least-squares"
) -> DirectSolution:
    """SVD solution: ``H = U S V.T``, ``R = V diag(1, 1, det(V U.T)) U.T``,
    ``s = trace(S D) / a`` (Umeyama; ``"symmetric"``: ``sqrt(b / a)``), ``t = Xg - s R xg``."""
    U, S, Vt, d = _sv_and_sign(m.H)
    D = np.ones((d.shape[0], 3))
    D[:, 2] = d
    R = np.matmul(np.swapaxes(Vt, 1, 2) * D[:, None, :], np.swapaxes(U, 1, 2))
    s = _scale(m, np.sum(S * D, axis=1), with_scale, scale_method)
    degenerate, reflection = classify(m, S, d, with_scale)
    return DirectSolution(s, R, _translation(m, s, R), degenerate, reflection)


def _plane_frames(xr: list) -> tuple[list, list, list, np.ndarray, np.ndarray]:
    """Orthonormal in-plane axes ``p1, p2`` and normal of three centred points (SoA lists
    of (B,) arrays per coordinate), the normal length and the reference length squared."""
    d2 = [xr[i][0] ** 2 + xr[i][1] ** 2 + xr[i][2] ** 2 for i in range(3)]
    # first axis: the point farthest from the centroid (robust)
    first = d2[0] >= np.maximum(d2[1], d2[2])
    second = d2[1] >= d2[2]

    def pick(a, b, c):
        return np.where(first, a, np.where(second, b, c))

    p1 = [pick(xr[0][k], xr[1][k], xr[2][k]) for k in range(3)]
    r2 = pick(*d2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.sqrt(r2)
        p1 = [c * inv for c in p1]
        # normal from the two points with the largest cross product (x0 + x1 + x2 = 0)
        a, b = xr[0], xr[1]
        n = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        nl = np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
        inv = 1.0 / nl
        n = [c * inv for c in n]
    p2 = [n[1] * p1[2] - n[2] * p1[1], n[2] * p1[0] - n[0] * p1[2], n[0] * p1[1] - n[1] * p1[0]]
    return p1, p2, n, nl, r2


def _solve_three_chunk(x, X, with_scale, gh_ratio):
    B = x.shape[0]
    xg = (x[:, 0] + x[:, 1] + x[:, 2]) / 3.0
    Xg = (X[:, 0] + X[:, 1] + X[:, 2]) / 3.0
    xr = [[x[:, i, k] - xg[:, k] for k in range(3)] for i in range(3)]
    Xr = [[X[:, i, k] - Xg[:, k] for k in range(3)] for i in range(3)]
    p1, p2, ns, nls, r2s = _plane_frames(xr)
    q1, q2, nt, nlt, r2t = _plane_frames(Xr)

    def dot(u, v):
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    # K = sum xi eta.T in the two planes (2x2); a, b = sums of squares
    K00 = K01 = K10 = K11 = 0.0
    a = b = 0.0
    for i in range(3):
        xi0, xi1 = dot(p1, xr[i]), dot(p2, xr[i])
        et0, et1 = dot(q1, Xr[i]), dot(q2, Xr[i])
        K00 = K00 + xi0 * et0
        K01 = K01 + xi0 * et1
        K10 = K10 + xi1 * et0
        K11 = K11 + xi1 * et1
        a = a + dot(xr[i], xr[i])
        b = b + dot(Xr[i], Xr[i])
    # proper rotations mapping plane to plane: n_s -> n_t (in-plane rotation) or n_s -> -n_t
    # (in-plane reflection); the larger trace wins. trace(R H) = sigma1 + sigma2 of H.
    e_p, f_p = K00 + K11, K01 - K10
    e_m, f_m = K00 - K11, K01 + K10
    tr_p = np.hypot(e_p, f_p)
    tr_m = np.hypot(e_m, f_m)
    flip = tr_m > tr_p
    trace = np.where(flip, tr_m, tr_p)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(flip, e_m / tr_m, e_p / tr_p)
        s_ = np.where(flip, f_m / tr_m, f_p / tr_p)
    # target-plane images of p1, p2, n_s:  R p1 = c q1 + s q2 (both cases),
    # R p2 = -s q1 + c q2 (rotation) or s q1 - c q2 (flip), R n = +-n_t
    sg = np.where(flip, -1.0, 1.0)
    Rp1 = [c * q1[k] + s_ * q2[k] for k in range(3)]
    Rp2 = [sg * (-s_ * q1[k] + c * q2[k]) for k in range(3)]
    Rn = [sg * nt[k] for k in range(3)]
    R = np.empty((B, 3, 3))
    for i in range(3):
        for j in range(3):
            R[:, i, j] = Rp1[i] * p1[j] + Rp2[i] * p2[j] + Rn[i] * ns[j]
    # singular values of the 2x2 K: (tr_p + tr_m) / 2 +- |tr_p - tr_m| / 2
    sig1 = 0.5 * (tr_p + tr_m)
    sig2 = 0.5 * np.abs(tr_p - tr_m)
    degenerate = (
        ~(nls > DEGENERATE_TOLERANCE * r2s)
        | ~(nlt > DEGENERATE_TOLERANCE * r2t)
        | ~(sig2 > DEGENERATE_TOLERANCE * sig1)
        | ~(a > 0) | ~(b > 0)
    )
    if not with_scale:
        scale = np.ones(B)
    elif gh_ratio is None:
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = trace / a
    else:
        k = gh_ratio
        aa, cc = a * k * k, trace * k
        dd = aa - b
        f = np.hypot(dd, 2 * cc)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(dd > 0, 2 * cc / (dd + f), (f - dd) / (2 * cc)) * k
    t = Xg - scale[:, None] * np.einsum("bij,bj->bi", R, xg)
    return scale, R, t, degenerate


def solve_three_points(
    x: np.ndarray, X: np.ndarray, *, with_scale: bool = True, gh_ratio: float | None = None
) -> DirectSolution:
    """Least-squares solution of B three-point problems (B, 3, 3), closed form.

    Three centred points are coplanar, so ``H = P K Q.T`` with orthonormal in-plane axes
    ``P``, ``Q`` of the two triangles and the 2x2 ``K = sum xi eta.T`` of in-plane
    coordinates: the SVD of H is that of K (closed form). The optimal proper rotation maps the
    source plane onto the target plane either keeping or flipping the normal, with the in-plane
    angle of the 2x2 Procrustes problem; the larger ``trace(R H) = sigma1 + sigma2`` decides.
    Identical to :func:`solve_svd` (and, with ``gh_ratio``, to
    :func:`solve_gauss_helmert_direct`) for n = 3, without any per-problem LAPACK call.
    Three points never determine a reflection (coplanar).
    """
    from .batch_linalg import CHUNK

    parts = [
        _solve_three_chunk(x[i : i + CHUNK], X[i : i + CHUNK], with_scale, gh_ratio)
        for i in range(0, x.shape[0], CHUNK)
    ]
    s, R, t, deg = (np.concatenate(p, axis=0) for p in zip(*parts))
    return DirectSolution(s, R, t, deg, np.zeros_like(deg))


# --- C: unit quaternion (Horn) -----------------------------------------------------------------


def horn_matrix(H: np.ndarray) -> np.ndarray:
    """Horn's symmetric 4x4 matrix of ``S = H`` (B, 3, 3): its largest eigenvalue is
    ``max_R trace(R H)`` and its eigenvector the quaternion (scalar first) of that ``R``."""
    Sxx, Sxy, Sxz = H[:, 0, 0], H[:, 0, 1], H[:, 0, 2]
    Syx, Syy, Syz = H[:, 1, 0], H[:, 1, 1], H[:, 1, 2]
    Szx, Szy, Szz = H[:, 2, 0], H[:, 2, 1], H[:, 2, 2]
    N = np.empty((H.shape[0], 4, 4))
    N[:, 0, 0] = Sxx + Syy + Szz
    N[:, 1, 1] = Sxx - Syy - Szz
    N[:, 2, 2] = -Sxx + Syy - Szz
    N[:, 3, 3] = -Sxx - Syy + Szz
    N[:, 0, 1] = N[:, 1, 0] = Syz - Szy
    N[:, 0, 2] = N[:, 2, 0] = Szx - Sxz
    N[:, 0, 3] = N[:, 3, 0] = Sxy - Syx
    N[:, 1, 2] = N[:, 2, 1] = Sxy + Syx
    N[:, 1, 3] = N[:, 3, 1] = Szx + Sxz
    N[:, 2, 3] = N[:, 3, 2] = Syz + Szy
    return N


def _eigen_rotation(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    vals, vecs = _eigh4(N)
    q = vecs[:, :, 3]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return quaternion_to_matrix(q), vals[:, 3]


def _geometry_flags(m: Moments, with_scale: bool) -> tuple[np.ndarray, np.ndarray]:
    _, S, _, d = _sv_and_sign(m.H)
    return classify(m, S, d, with_scale)


def solve_quaternion(
    m: Moments, *, with_scale: bool = True, scale_method: str = "least-squares"
) -> DirectSolution:
    """Horn's unit-quaternion solution. ``scale_method="least-squares"`` (default) gives
    ``s = lambda_max / a``, identical to :func:`solve_svd`; ``"symmetric"`` Horn's
    ``s = sqrt(b / a)``."""
    R, lam = _eigen_rotation(horn_matrix(m.H))
    s = _scale(m, lam, with_scale, scale_method)
    degenerate, reflection = _geometry_flags(m, with_scale)
    return DirectSolution(s, R, _translation(m, s, R), degenerate, reflection)


# --- D: dual quaternion -------------------------------------------------------------------


def _basis_products() -> np.ndarray:
    """``E[j, k] = Q(e_k).T W(e_j)`` (3, 3, 4, 4): ``sum w Q(X).T W(x) = einsum(P, E)``."""

    def left(v):  # v (x) q = Q(v) q for a pure quaternion v
        M = np.zeros((4, 4))
        M[0, 1:] = -v
        M[1:, 0] = v
        M[1:, 1:] = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        return M

    def right(v):  # q (x) v = W(v) q
        M = left(v)
        M[1:, 1:] *= -1
        return M

    e = np.eye(3)
    return np.array([[left(e[k]).T @ right(e[j]) for k in range(3)] for j in range(3)])


_QW = _basis_products()


def _left_batch(v: np.ndarray) -> np.ndarray:
    """``Q(v)`` (B, 4, 4) of pure quaternions v (B, 3)."""
    B = v.shape[0]
    M = np.zeros((B, 4, 4))
    M[:, 0, 1:] = -v
    M[:, 1:, 0] = v
    M[:, 1, 2], M[:, 1, 3] = -v[:, 2], v[:, 1]
    M[:, 2, 1], M[:, 2, 3] = v[:, 2], -v[:, 0]
    M[:, 3, 1], M[:, 3, 2] = -v[:, 1], v[:, 0]
    return M


def _right_batch(v: np.ndarray) -> np.ndarray:
    """``W(v)`` (B, 4, 4): ``q (x) v = W(v) q``."""
    M = _left_batch(v)
    M[:, 1:, 1:] *= -1
    return M


def solve_dual_quaternion(
    m: Moments, *, with_scale: bool = True, scale_method: str = "least-squares"
) -> DirectSolution:
    """Dual-quaternion solution with scale and weights.

    With ``q = r + eps s_d`` (``s_d = t r / 2``) the weighted cost
    ``sum w |U - s R u - t|^2`` (coordinates about the reference points) is
    ``const + s^2 A + 4 W |s_d|^2 - 2 s r.T C1 r - 4 s_d.T C3(s) r`` with
    ``C1 = sum w Q(U).T W(u)``, ``C3(s) = Q(sum w U) - s W(sum w u)``. Eliminating ``s_d``
    (``s_d = C3 r / 2W``, which also satisfies ``r.T s_d = 0``) leaves
    ``-2 s r.T (C1 - Q(sum w U).T W(sum w u) / W) r``: ``r`` is the dominant eigenvector of
    that 4x4 matrix, ``s = lambda / a``, and ``t = 2 W(r).T s_d`` (plus the reference shift).
    """
    W = m.weight
    C1 = np.einsum("bjk,jkpq->bpq", m.cross, _QW)
    QX = _left_batch(m.sum_target)
    Wx = _right_batch(m.sum_source)
    K = C1 - np.matmul(np.swapaxes(QX, 1, 2), Wx) / W[:, None, None]
    K = 0.5 * (K + np.swapaxes(K, 1, 2))
    vals, vecs = _eigh4(K)
    r = vecs[:, :, 3]
    r = r / np.linalg.norm(r, axis=1, keepdims=True)
    lam = vals[:, 3]
    s = _scale(m, lam, with_scale, scale_method)
    C3 = QX - s[:, None, None] * Wx
    sd = np.einsum("bij,bj->bi", C3, r) / (2 * W[:, None])
    t_q = 2 * np.einsum("bji,bj->bi", _right_batch_full(r), sd)  # 2 W(r).T s_d
    R = quaternion_to_matrix(r)
    t = t_q[:, 1:] + m.ref_target - s[:, None] * np.einsum("bij,bj->bi", R, m.ref_source)
    degenerate, reflection = _geometry_flags(m, with_scale)
    return DirectSolution(s, R, t, degenerate, reflection)


def _right_batch_full(r: np.ndarray) -> np.ndarray:
    """``W(r)`` (B, 4, 4) of full quaternions r (B, 4): ``q (x) r = W(r) q``."""
    M = _right_batch(r[:, 1:])
    M[:, 0, 0] += r[:, 0]
    M[:, 1, 1] += r[:, 0]
    M[:, 2, 2] += r[:, 0]
    M[:, 3, 3] += r[:, 0]
    return M


# --- F: Gauss-Helmert direct solution --------------------------------------------------------


def solve_gauss_helmert_direct(
    m: Moments, *, with_scale: bool = True, ratio: float | np.ndarray = 1.0
) -> DirectSolution:
    """Direct solution of ``X - e = t + s R (x - eps)``, minimising
    ``sum |e|^2 / sigma_X^2 + |eps|^2 / sigma_x^2`` (Chang 2015).

    ``R = V diag(1, 1, det(U) det(V)) U.T`` (as SVD), ``c = trace(R H)``, ``d = a - b``,
    ``s = (-d + sqrt(d^2 + 4 c^2)) / (2 c)``, ``t = Xg - s R xg``, computed on the source
    prescaled by ``ratio = sigma_X / sigma_x`` (exact for one sigma per system), and the
    scale scaled back.
    """
    U, S, Vt, dsign = _sv_and_sign(m.H)
    D = np.ones((dsign.shape[0], 3))
    D[:, 2] = dsign
    R = np.matmul(np.swapaxes(Vt, 1, 2) * D[:, None, :], np.swapaxes(U, 1, 2))
    if with_scale:
        k = np.asarray(ratio, dtype=float)
        a = m.a * k * k
        c = np.sum(S * D, axis=1) * k
        d = a - m.b
        f = np.hypot(d, 2 * c)
        with np.errstate(divide="ignore", invalid="ignore"):
            # (-d + f) / (2 c) written without cancellation for d > 0
            s_tilde = np.where(d > 0, 2 * c / (d + f), (f - d) / (2 * c))
        s = s_tilde * k
    else:
        s = np.ones(dsign.shape[0])
    degenerate, reflection = classify(m, S, dsign, with_scale)
    return DirectSolution(s, R, _translation(m, s, R), degenerate, reflection)


# --- A: normalised-vector closed form (Afary 2024) -------------------------------------------


def published_angles(R, convention: str = "direct"):
    """Angles of the raw (non-orthogonal) closed-form matrix read as the paper reads them.

    With ``M = R`` (``"direct"``, the paper's convention ``R = M(Omega, Phi, K)``) or
    ``M = R.T`` (``"transposed"``): ``phi = asin(m31)``, ``omega = atan2(-m32, m33)``,
    ``kappa = atan2(-m21, m11)`` (radians; ``R`` of shape (..., 3, 3)). For a rotation this
    equals :func:`~photogeom.rotation.opk_from_matrix` (which reads phi as
    ``atan2(m31, hypot(m32, m33))``, robust near +-90 degrees); for the raw matrix the two
    readings differ (by 0.003 degrees in phi on the laser-scan data), and only this one
    reproduces the paper's tables. ``m31`` is clipped to [-1, 1].
    """
    R = np.asarray(R, dtype=float)
    M = R if convention == "direct" else np.swapaxes(R, -1, -2)
    m31 = np.clip(M[..., 2, 0], -1.0, 1.0)
    phi = np.arcsin(m31)
    omega = np.arctan2(-M[..., 2, 1], M[..., 2, 2])
    kappa = np.arctan2(-M[..., 1, 0], M[..., 0, 0])
    if np.ndim(phi) == 0:
        return float(omega), float(phi), float(kappa)
    return omega, phi, kappa


def _sym_eigvals(x: np.ndarray) -> np.ndarray:
    """Singular values (B, 3), descending, of centred point sets (B, n, 3)."""
    C = np.matmul(np.swapaxes(x, 1, 2), x)
    ev = np.linalg.eigvalsh(C)[:, ::-1]
    return np.sqrt(np.clip(ev, 0.0, None))


def _perpendicular_pair(
    xb: np.ndarray, Xb: np.ndarray, usable: np.ndarray, size: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Indices (l, k) per problem of the pair of points whose unit vectors are closest to
    perpendicular in both sets: smallest ``(xb_l . xb_k)^2 + (Xb_l . Xb_k)^2``.

    Exhaustive over all pairs for n <= 64; for larger n, ``l`` is the usable point with the
    largest product of its centroid distances ``size = |x'_l| |X'_l|`` and ``k`` the point
    closest to perpendicular to it (O(n) instead of O(n^2)). Both rules depend on the points,
    not on their order, and the target term separates pairs that a symmetric source layout
    (a regular grid) ties; every term is computed alike wherever its pair lies in the input.

    Parameters
    ----------
    xb, Xb : numpy.ndarray, shape (B, n, 3)
        Unit vectors from the centroids (source, target); anything where not usable.
    usable : numpy.ndarray of bool, shape (B, n)
    size : numpy.ndarray, shape (B, n)
        ``|x'_i| |X'_i|`` (squared lengths, m^2 in the units of the points; only its order
        matters).
    """
    B, n, _ = xb.shape
    if n <= 64:
        def dots(u: np.ndarray) -> np.ndarray:  # elementwise: the same rounding for any order
            c = (
                u[:, :, None, 0] * u[:, None, :, 0]
                + u[:, :, None, 1] * u[:, None, :, 1]
                + u[:, :, None, 2] * u[:, None, :, 2]
            )
            return c * c

        G = dots(xb) + dots(Xb)
        bad = ~(usable[:, :, None] & usable[:, None, :]) | np.eye(n, dtype=bool)[None]
        G = np.where(bad, np.inf, G)
        flat = np.argmin(G.reshape(B, -1), axis=1)
        return flat // n, flat % n
    rows = np.arange(B)
    first = np.argmax(np.where(usable, size, -np.inf), axis=1)
    xl, Xl = xb[rows, first], Xb[rows, first]
    cx = xb[..., 0] * xl[:, None, 0] + xb[..., 1] * xl[:, None, 1] + xb[..., 2] * xl[:, None, 2]
    cX = Xb[..., 0] * Xl[:, None, 0] + Xb[..., 1] * Xl[:, None, 1] + Xb[..., 2] * Xl[:, None, 2]
    cost = cx * cx + cX * cX
    cost = np.where(usable, cost, np.inf)
    cost[rows, first] = np.inf
    return first, np.argmin(cost, axis=1)


def solve_closed_form(
    x: np.ndarray,
    X: np.ndarray,
    *,
    nearest: bool = False,
    with_scale: bool = True,
    coplanar_threshold: float = COPLANAR_THRESHOLD,
) -> DirectSolution:
    """The normalised-vector closed form of Afary (2024), exactly as published.

    1. centroids ``xg, Xg``; 2. ``s = mean |X'_i| / |x'_i|``; 3. unit vectors as columns of
    ``N`` (source) and ``M`` (target); 4. ``R = (M M.T) inv(N M.T)``; 5. with n = 3 or a
    (nearly) coplanar set (see :data:`COPLANAR_THRESHOLD`) append the unit normals
    ``xb_l x xb_k`` and ``Xb_l x Xb_k`` of the pair closest to perpendicular; 6.
    ``t = Xg - s R xg``. ``R`` is *not* orthogonalised (its defect is reported) unless
    ``nearest=True`` (polar decomposition, then ``t`` recomputed). Points at the centroid
    (:data:`CENTROID_TOLERANCE`) are left out of steps 2-5.

    Parameters
    ----------
    x, X : numpy.ndarray, shape (B, n, 3)
    nearest : bool
        Orthogonalise R (polar decomposition).
    with_scale : bool
        False: rigid (s = 1).
    coplanar_threshold : float
    """
    B, n, _ = x.shape
    xg = np.add.reduce(x, axis=1) / n
    Xg = np.add.reduce(X, axis=1) / n
    xr = x - xg[:, None, :]
    Xr = X - Xg[:, None, :]
    dx = np.sqrt(np.einsum("bni,bni->bn", xr, xr))
    dX = np.sqrt(np.einsum("bni,bni->bn", Xr, Xr))
    usable = (dx > CENTROID_TOLERANCE * dx.max(axis=1, keepdims=True)) & (
        dX > CENTROID_TOLERANCE * dX.max(axis=1, keepdims=True)
    )
    nu = usable.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(usable, dX / dx, 0.0)
        s = ratio.sum(axis=1) / nu
        xb = np.where(usable[..., None], xr / dx[..., None], 0.0)
        Xb = np.where(usable[..., None], Xr / dX[..., None], 0.0)
    MMt = np.matmul(np.swapaxes(Xb, 1, 2), Xb)
    NMt = np.matmul(np.swapaxes(xb, 1, 2), Xb)
    sv = np.minimum(
        (lambda e: e[:, 2] / np.maximum(e[:, 0], 1e-300))(_sym_eigvals(xr)),
        (lambda e: e[:, 2] / np.maximum(e[:, 0], 1e-300))(_sym_eigvals(Xr)),
    )
    augment = (sv < coplanar_threshold) | (nu <= 3)
    if np.any(augment):
        l, k = _perpendicular_pair(xb, Xb, usable, np.where(usable, dx * dX, 0.0))
        idx = np.arange(B)
        xp = np.cross(xb[idx, l], xb[idx, k])
        Xp = np.cross(Xb[idx, l], Xb[idx, k])
        with np.errstate(divide="ignore", invalid="ignore"):
            xp = xp / np.linalg.norm(xp, axis=1, keepdims=True)
            Xp = Xp / np.linalg.norm(Xp, axis=1, keepdims=True)
        xp = np.nan_to_num(xp)
        Xp = np.nan_to_num(Xp)
        a3 = augment[:, None, None]
        MMt = np.where(a3, MMt + Xp[:, :, None] * Xp[:, None, :], MMt)
        NMt = np.where(a3, NMt + xp[:, :, None] * Xp[:, None, :], NMt)
    # R NMt = MMt  <=>  NMt.T R.T = MMt.T
    svn = np.linalg.svd(NMt, compute_uv=False)
    degenerate = ~(svn[:, 2] > DEGENERATE_TOLERANCE**0.5 * svn[:, 0]) | (nu < 2) | ~np.isfinite(s)
    safe = np.where(degenerate[:, None, None], np.eye(3), NMt)
    R = np.swapaxes(np.linalg.solve(np.swapaxes(safe, 1, 2), np.swapaxes(MMt, 1, 2)), 1, 2)
    reflection = (_det3(R) < 0) & ~degenerate
    if nearest:
        U, _, Vt = np.linalg.svd(R)
        d = np.sign(_det3(U) * _det3(Vt))
        d = np.where(d == 0, 1.0, d)
        R = np.matmul(U * np.stack([np.ones_like(d), np.ones_like(d), d], axis=1)[:, None, :], Vt)
    if not with_scale:
        s = np.ones(B)
    s = np.where(degenerate, np.nan, s)
    t = Xg - s[:, None] * np.einsum("bij,bj->bi", R, xg)
    return DirectSolution(
        s, R, t, degenerate, reflection, augmented=augment, at_centroid=n - nu
    )


def closed_form_single(
    x: np.ndarray,
    X: np.ndarray,
    *,
    nearest: bool = False,
    with_scale: bool = True,
    coplanar_threshold: float = COPLANAR_THRESHOLD,
) -> tuple[SingleSolution, bool, int]:
    """:func:`solve_closed_form` for one problem (n, 3), with LAPACK called directly.

    Returns the solution, whether the plane-normal augmentation was used, and the number of
    points left out because they lie at the centroid. From
    :data:`CLOSED_FORM_CHUNKED_N` points on, :func:`closed_form_chunked`.
    """
    n = x.shape[0]
    if n >= CLOSED_FORM_CHUNKED_N:
        return closed_form_chunked(
            x, X, nearest=nearest, with_scale=with_scale, coplanar_threshold=coplanar_threshold
        )
    xg = np.add.reduce(x, axis=0) / n
    Xg = np.add.reduce(X, axis=0) / n
    xr = x - xg
    Xr = X - Xg
    dx = np.sqrt(np.einsum("ni,ni->n", xr, xr))
    dX = np.sqrt(np.einsum("ni,ni->n", Xr, Xr))
    usable = (dx > CENTROID_TOLERANCE * dx.max()) & (dX > CENTROID_TOLERANCE * dX.max())
    nu = int(np.count_nonzero(usable))
    if nu < n:
        xr_u, Xr_u, dx_u, dX_u = xr[usable], Xr[usable], dx[usable], dX[usable]
    else:
        xr_u, Xr_u, dx_u, dX_u = xr, Xr, dx, dX
    if nu < 2:
        eye = np.eye(3)
        return SingleSolution(math.nan, eye, Xg.copy(), True, False), False, n - nu
    s = float(np.add.reduce(dX_u / dx_u)) / nu if with_scale else 1.0
    xb = xr_u / dx_u[:, None]
    Xb = Xr_u / dX_u[:, None]
    MMt = Xb.T @ Xb
    NMt = xb.T @ Xb
    ev_x = _lapack.dsyev(xr.T @ xr, compute_v=0)[0]
    ev_X = _lapack.dsyev(Xr.T @ Xr, compute_v=0)[0]
    ratio = min(
        math.sqrt(max(ev_x[0], 0.0) / ev_x[2]) if ev_x[2] > 0 else 0.0,
        math.sqrt(max(ev_X[0], 0.0) / ev_X[2]) if ev_X[2] > 0 else 0.0,
    )
    augment = ratio < coplanar_threshold or nu <= 3
    if augment:
        l_, k_ = _perpendicular_pair(
            xb[None], Xb[None], np.ones((1, nu), dtype=bool), (dx_u * dX_u)[None]
        )
        l_, k_ = int(l_[0]), int(k_[0])
        xp = np.cross(xb[l_], xb[k_])
        Xp = np.cross(Xb[l_], Xb[k_])
        nx, nX = math.sqrt(float(xp @ xp)), math.sqrt(float(Xp @ Xp))
        if nx > 0 and nX > 0:
            xp /= nx
            Xp /= nX
            MMt = MMt + np.outer(Xp, Xp)
            NMt = NMt + np.outer(xp, Xp)
    sv = _lapack.dgesvd(NMt, compute_uv=0)[1]
    if not sv[2] > DEGENERATE_TOLERANCE**0.5 * sv[0] or not math.isfinite(s):
        return SingleSolution(math.nan, np.eye(3), Xg.copy(), True, False), augment, n - nu
    # R NMt = MMt  <=>  NMt.T R.T = MMt.T
    _, _, Rt, info = _lapack.dgesv(NMt.T, MMt.T)
    if info != 0:
        return SingleSolution(math.nan, np.eye(3), Xg.copy(), True, False), augment, n - nu
    R = Rt.T
    reflection = _det_list(R.tolist()) < 0
    if nearest:
        u, _, vt, _ = _lapack.dgesvd(R)
        if _det_list(u.tolist()) * _det_list(vt.tolist()) < 0:
            u[:, 2] *= -1
        R = u @ vt
    t = Xg - s * (R @ xg)
    return SingleSolution(s, R, t, False, reflection), augment, n - nu


# --- the closed form for many points: chunked, no n-row temporaries ---------------------------

#: From this many points the closed form runs in cache-sized chunks (two passes over the data:
#: the centroids, then everything else), without n-row temporaries.
CLOSED_FORM_CHUNKED_N = 65536
#: Points per chunk of the chunked closed form.
CLOSED_FORM_CHUNK = 32768
#: Points per BLAS call of the chunked closed form (stacks of (12 x 2048) (2048 x 6) products
#: and 2048-element dot products): sizes OpenBLAS runs on one thread. On a machine busy with
#: other work its threads wait for each other, and the pass with one product per chunk ran up
#: to ten times slower.
CLOSED_FORM_PRODUCT = 2048


@dataclass
class ClosedFormSums:
    """What the closed form accumulates over the points (see :func:`closed_form_sums`).

    ``tx``, ``tX``: the centroid-distance thresholds below which a point carries no direction;
    ``MMt``, ``NMt`` include the plane-normal augmentation when ``aug`` is set:
    ``(l, k, xp, Xp, |Xb_l x Xb_k|, Xb_l, Xb_k)``.
    """

    n: int
    xg: np.ndarray
    Xg: np.ndarray
    tx: float
    tX: float
    nu: int
    ratio_sum: float
    MMt: np.ndarray
    NMt: np.ndarray
    augment: bool
    aug: tuple | None


def _chunks(n: int):
    for i in range(0, n, CLOSED_FORM_CHUNK):
        yield i, min(i + CLOSED_FORM_CHUNK, n)


def centred_chunk(p: np.ndarray, a: int, b: int, tiled: np.ndarray):
    """Rows ``a:b`` of ``p`` (n, 3) minus a centre given tiled (``np.tile(centre, chunk)``),
    and their squared norms: flat arithmetic (numpy's (n, 3) broadcasts with an inner length
    of 3 are several times slower)."""
    m = 3 * (b - a)
    r = (p[a:b].reshape(-1) - tiled[:m]).reshape(-1, 3)
    sq = r * r
    return r, sq[:, 0] + sq[:, 1] + sq[:, 2]


def centroid_about_reference(p: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
    """``(ref, c)``: the centroid of ``p`` (n, 3) is ``ref + c``, in one chunked pass (four
    points per row of a 12-column view, summed by a matrix-vector product).

    ``ref`` is None (the origin) unless the points lie far from the origin compared with their
    spread (e.g. UTM coordinates, :func:`_reference`); then it is the mean of the first chunk
    and ``c`` the mean of ``p - ref``: no digits are lost to the offset, and centring as
    ``(p - ref) - c`` keeps the digits that ``ref + c`` rounded in absolute coordinates would
    drop (~1e-16 of the offset).
    """
    n = p.shape[0]
    n4 = n - n % 4
    ref = _reference(p)
    ones = np.ones(CLOSED_FORM_CHUNK // 4)
    r12 = None if ref is None else np.tile(ref, 4)
    buf = None if ref is None else np.empty((CLOSED_FORM_CHUNK // 4, 12))
    s = np.zeros(12)
    for a in range(0, n4, CLOSED_FORM_CHUNK):
        A = p[a : min(a + CLOSED_FORM_CHUNK, n4)].reshape(-1, 12)
        if r12 is not None:
            A = np.subtract(A, r12, out=buf[: A.shape[0]])
        k = A.shape[0]
        if k % BLAS_ROWS:
            s += ones[:k] @ A
        else:  # stacked sums of BLAS_ROWS rows (one BLAS thread, see BLAS_ROWS)
            s += np.matmul(ones[:BLAS_ROWS], A.reshape(-1, BLAS_ROWS, 12)).sum(axis=0)
    total = s.reshape(4, 3).sum(axis=0)
    if n4 < n:
        total = total + (p[n4:] if ref is None else p[n4:] - ref).sum(axis=0)
    return ref, total / n


def closed_form_sums(
    x: np.ndarray, X: np.ndarray, coplanar_threshold: float = COPLANAR_THRESHOLD
) -> ClosedFormSums | None:
    """The sums of the closed form in chunks: the centroids (first pass), then the centroid
    distances, length ratios, ``M M.T``, ``N M.T``, both scatter matrices (coplanarity) and
    the point farthest from the centroids (second pass); for a (nearly) coplanar set a third
    pass finds the point closest to perpendicular to it (the plane-normal augmentation,
    :func:`_perpendicular_pair`: chosen by the points, not by their order).

    Two passes are the least: every unit vector ``(X_i - Xg) / |X_i - Xg|`` depends on the
    centroid through its norm, so no sums of powers of the raw coordinates give ``M M.T``,
    ``N M.T`` or the length ratios. The second pass takes every point off the centroid; only
    if some point then lies within :data:`CENTROID_TOLERANCE` of the largest centroid distance
    (known at the end of the pass) another pass repeats it with the exact thresholds. The same
    estimate as :func:`closed_form_single` for n > 64 (its O(n) pair search) to rounding.
    """
    centres = centroid_about_reference(x), centroid_about_reference(X)
    res = _closed_form_pass(x, X, centres, 0.0, 0.0)
    if res is None:
        return None
    _, (dx_max, dX_max, dx_min, dX_min) = res
    tx, tX = CENTROID_TOLERANCE * dx_max, CENTROID_TOLERANCE * dX_max
    if dx_min > tx and dX_min > tX:
        return _finish(res[0], tx, tX, coplanar_threshold, x, X, centres)
    exact = _closed_form_pass(x, X, centres, tx, tX)  # some point lies at the centroid
    return None if exact is None else _finish(exact[0], tx, tX, coplanar_threshold, x, X, centres)


def _centre(p: np.ndarray, ref: np.ndarray | None, c: np.ndarray) -> np.ndarray:
    """``p`` about its centroid ``ref + c`` (:func:`centroid_about_reference`)."""
    return p - c if ref is None else (p - ref) - c


def _unit_pair(x, X, centres, i: int):
    """Unit vectors (source, target) from the centroids to point ``i``."""
    xr, Xr = _centre(x[i], *centres[0]), _centre(X[i], *centres[1])
    return xr / math.sqrt(float(xr @ xr)), Xr / math.sqrt(float(Xr @ Xr))


def _perpendicular_to(x, X, centres, tx, tX, l_idx: int) -> int:
    """Index of the usable point closest to perpendicular to point ``l_idx`` in both sets,
    ``min (xb_l . x')^2 / |x'|^2 + (Xb_l . X')^2 / |X'|^2`` (the ``k`` of
    :func:`_perpendicular_pair`); one pass in chunks, -1 if there is none."""
    xb_l, Xb_l = _unit_pair(x, X, centres, l_idx)
    C = CLOSED_FORM_CHUNK
    buf = np.empty((6, C))
    d = np.empty((2, C))
    best, where = math.inf, -1
    for a, b in _chunks(x.shape[0]):
        m = b - a
        for p, (ref, c), rows in ((x, centres[0], buf[0:3, :m]), (X, centres[1], buf[3:6, :m])):
            if ref is None:
                np.subtract(p[a:b].T, c[:, None], out=rows)
            else:  # (p - ref) - c, as in _closed_form_pass
                np.subtract(p[a:b].T, ref[:, None], out=rows)
                rows -= c[:, None]
        cx, cX = xb_l @ buf[0:3, :m], Xb_l @ buf[3:6, :m]
        np.multiply(buf[:, :m], buf[:, :m], out=buf[:, :m])
        dd = np.add(buf[0::3, :m], buf[1::3, :m], out=d[:, :m])  # squared distances
        dd += buf[2::3, :m]
        # points at the centroid (as _closed_form_pass: sqrt(|x'|^2) <= tx) are left out
        off = (dd[0] > 0.0) & (dd[1] > 0.0)
        if tx > 0.0 or tX > 0.0:
            off &= (np.sqrt(dd[0]) > tx) & (np.sqrt(dd[1]) > tX)
        if not off.all():
            dd[:, ~off] = 1.0
            cx[~off] = math.inf
        np.multiply(cx, cx, out=cx)
        np.divide(cx, dd[0], out=cx)
        np.multiply(cX, cX, out=cX)
        np.divide(cX, dd[1], out=cX)
        cost = np.add(cx, cX, out=cx)
        if a <= l_idx < b:
            cost[l_idx - a] = math.inf
        j = int(np.argmin(cost))
        if cost[j] < best:
            best, where = float(cost[j]), a + j
    return where


def _closed_form_pass(x, X, centres, tx, tX):
    """One pass over the centred points in chunks. Each chunk's coordinates go to the rows of
    a (12, chunk) buffer (``x'``, ``X'``, ``X' / |X'|^2``, ``x' / (|x'| |X'|)``); one matrix
    product of the buffer with its first six rows gives both scatter matrices, ``M M.T`` and
    ``N M.T`` of the chunk; per point only the two squared distances, one square root and
    two reciprocals."""
    n = x.shape[0]
    C = CLOSED_FORM_CHUNK
    buf = np.empty((12, C))
    sq = np.empty((6, C))
    d = np.empty((4, C))
    G = np.zeros((12, 6))
    P = CLOSED_FORM_PRODUCT
    # the full chunk as C / P stacked products (one matmul call, each product single-threaded)
    stacked = None if C % P else (
        buf.reshape(12, -1, P).transpose(1, 0, 2),
        buf[:6].reshape(6, -1, P).transpose(1, 2, 0),
    )
    (rx, cx), (rX, cX) = centres
    xg, Xg = (cx if rx is None else rx + cx), (cX if rX is None else rX + cX)
    ratio_sum = 0.0
    nu = 0
    best = (-math.inf, -1)  # the point with the largest |x'| |X'| (see _perpendicular_pair)
    hi = np.zeros(2)  # largest squared distances (source, target)
    lo = np.full(2, math.inf)  # smallest squared distances of the usable points
    t2 = np.array([tx, tX])
    for a, b in _chunks(n):
        m = b - a
        for p, (ref, c), rows in ((x, centres[0], buf[0:3, :m]), (X, centres[1], buf[3:6, :m])):
            if ref is None:
                np.subtract(p[a:b].T, c[:, None], out=rows)
            else:  # (p - ref) - c: exact differences first
                np.subtract(p[a:b].T, ref[:, None], out=rows)
                rows -= c[:, None]
        s2 = np.multiply(buf[:6, :m], buf[:6, :m], out=sq[:, :m])
        dd = np.add(s2[0::3], s2[1::3], out=d[:2, :m])  # squared centroid distances
        dd += s2[2::3]
        np.maximum(hi, dd.max(axis=1), out=hi)
        # sqrt is monotone: the extreme distances are the roots of the extreme squares
        lo_c = dd.min(axis=1)
        gidx = None  # global indices of the columns when some points are left out
        if not np.all(np.sqrt(lo_c) > t2):  # points at the centroid: keep the usable ones
            keep = np.flatnonzero((np.sqrt(dd[0]) > tx) & (np.sqrt(dd[1]) > tX))
            m = keep.size
            if m == 0:
                continue
            buf[:6, :m] = buf[:6, keep]
            d[:2, :m] = d[:2, keep]
            gidx = keep + a
            lo_c = d[:2, :m].min(axis=1)
        np.minimum(lo, lo_c, out=lo)
        nu += m
        dx2, dX2, v, w = d[0, :m], d[1, :m], d[2, :m], d[3, :m]
        np.multiply(dx2, dX2, out=v)
        np.sqrt(v, out=v)
        np.divide(1.0, v, out=v)  # 1 / (|x'| |X'|)
        full = m == C and stacked is not None
        if full:  # sum of |X'| / |x'|
            ratio_sum += float(np.matmul(dX2.reshape(-1, 1, P), v.reshape(-1, P, 1)).sum())
        else:
            ratio_sum += float(np.add.reduce(dX2 * v))
        np.divide(1.0, dX2, out=w)
        np.multiply(buf[3:6, :m], w, out=buf[6:9, :m])
        np.multiply(buf[0:3, :m], v, out=buf[9:12, :m])
        if full:
            G += np.matmul(*stacked).sum(axis=0)
        else:
            for k in range(0, m, P):
                e = min(k + P, m)
                G += buf[:, k:e] @ buf[:6, k:e].T
        size = np.multiply(dx2, dX2, out=w)  # squared: the same order as |x'| |X'|
        j = int(np.argmax(size))
        if size[j] > best[0]:
            best = (float(size[j]), a + j if gidx is None else int(gidx[j]))
    dx_max, dX_max = math.sqrt(float(hi[0])), math.sqrt(float(hi[1]))
    dx_min, dX_min = math.sqrt(float(lo[0])), math.sqrt(float(lo[1]))
    if best[1] < 0:
        return None
    sums = dict(n=n, xg=xg, Xg=Xg, nu=nu, ratio_sum=ratio_sum, MMt=G[6:9, 3:6].copy(),
                NMt=G[9:12, 3:6].copy(), Sx=G[0:3, 0:3].copy(), SX=G[3:6, 3:6].copy(),
                farthest=best[1])
    return sums, (dx_max, dX_max, dx_min, dX_min)


def _finish(
    sums: dict, tx: float, tX: float, coplanar_threshold: float, x, X, centres
) -> ClosedFormSums:
    ev_x = np.linalg.eigvalsh(sums["Sx"])
    ev_X = np.linalg.eigvalsh(sums["SX"])
    ratio = min(
        math.sqrt(max(ev_x[0], 0.0) / ev_x[2]) if ev_x[2] > 0 else 0.0,
        math.sqrt(max(ev_X[0], 0.0) / ev_X[2]) if ev_X[2] > 0 else 0.0,
    )
    nu = sums["nu"]
    augment = ratio < coplanar_threshold or nu <= 3
    MMt, NMt = sums["MMt"], sums["NMt"]
    aug = None
    l_idx = sums["farthest"]
    k_idx = _perpendicular_to(x, X, centres, tx, tX, l_idx) if augment else -1
    if k_idx >= 0:  # a third pass, only for (nearly) coplanar sets
        xb_l, Xb_l = _unit_pair(x, X, centres, l_idx)
        xb_k, Xb_k = _unit_pair(x, X, centres, k_idx)
        xp = np.cross(xb_l, xb_k)
        c = np.cross(Xb_l, Xb_k)
        nx, nc = float(np.linalg.norm(xp)), float(np.linalg.norm(c))
        if nx > 0 and nc > 0:
            xp, Xp = xp / nx, c / nc
            MMt = MMt + np.outer(Xp, Xp)
            NMt = NMt + np.outer(xp, Xp)
            aug = (l_idx, k_idx, xp, Xp, nc, Xb_l, Xb_k)
    return ClosedFormSums(sums["n"], sums["xg"], sums["Xg"], tx, tX, nu, sums["ratio_sum"],
                          MMt, NMt, augment, aug)


def closed_form_chunked(
    x: np.ndarray,
    X: np.ndarray,
    *,
    nearest: bool = False,
    with_scale: bool = True,
    coplanar_threshold: float = COPLANAR_THRESHOLD,
) -> tuple[SingleSolution, bool, int]:
    """:func:`closed_form_single` for many points, from :func:`closed_form_sums` (two passes
    over the data in cache-sized chunks, no n-row temporaries)."""
    cs = closed_form_sums(x, X, coplanar_threshold)
    n = x.shape[0]
    if cs is None or cs.nu < 2:
        xg_ = np.add.reduce(X, axis=0) / n
        return SingleSolution(math.nan, np.eye(3), xg_, True, False), False, n
    s = cs.ratio_sum / cs.nu if with_scale else 1.0
    sv = _lapack.dgesvd(cs.NMt, compute_uv=0)[1]
    if not sv[2] > DEGENERATE_TOLERANCE**0.5 * sv[0] or not math.isfinite(s):
        return (SingleSolution(math.nan, np.eye(3), cs.Xg.copy(), True, False), cs.augment,
                n - cs.nu)
    _, _, Rt, info = _lapack.dgesv(cs.NMt.T, cs.MMt.T)
    if info != 0:
        return (SingleSolution(math.nan, np.eye(3), cs.Xg.copy(), True, False), cs.augment,
                n - cs.nu)
    R = Rt.T
    reflection = _det_list(R.tolist()) < 0
    if nearest:
        u, _, vt, _ = _lapack.dgesvd(R)
        if _det_list(u.tolist()) * _det_list(vt.tolist()) < 0:
            u[:, 2] *= -1
        R = u @ vt
    t = cs.Xg - s * (R @ cs.xg)
    return SingleSolution(s, R, t, False, reflection), cs.augment, n - cs.nu
