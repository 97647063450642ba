"""Start values of a relative orientation: the essential matrix (five-point solver in RANSAC).

OpenCV's ``findEssentialMat`` (Nister's five-point solver inside RANSAC, and inside
MAGSAC++ where OpenCV has it) and ``recoverPose`` (the cheirality test that picks one of the
four decompositions) give the relative rotation and the base direction, the candidate with
the most points in front of both images winning; the Gauss-Helmert adjustment of the coplanarity
condition (:mod:`photogeom.orientation.relative`) then decides on the final values.

Conventions. OpenCV's camera axes are x right, y down, z forward; the photogrammetric camera
frame of 01-conventions.md is x right, y up, z backward. With ``F = diag(1, -1, -1)`` and
OpenCV's ``x_2 = R x_1 + t``, the photogrammetric relative rotation (camera 1 -> camera 2)
is ``F R F`` and the base ``O2 - O1`` in the camera-1 frame is ``-F R.T t``. OpenCV's
normalised image coordinates are ``(xn, yn)`` of
:meth:`~photogeom.camera.InteriorOrientation.normalized_from_image`.

Before any solver runs, the configurations that do not determine a relative orientation are
refused by name: points (nearly) on a line, and images taken from one position (a pure
rotation: the rotation alone explains every match).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DegenerateGeometryError

#: ``diag(1, -1, -1)``: OpenCV camera axes <-> photogrammetric camera axes.
FLIP = np.diag([1.0, -1.0, -1.0])

#: Largest difference (rotation-matrix entries, unit-base components) between two start
#: candidates taken for one solution (estimates from different samples differ by noise; the
#: distinct solutions of five points differ grossly).
SAME = 0.05

#: Smallest / largest singular value of the centred image points below which they are
#: taken to lie on a line.
COLLINEAR_RATIO = 1e-3


#: OpenCV's default distance (in base lengths) beyond which recoverPose ignores a point.
OPENCV_FAR = 50.0


class PointsBehindError(DegenerateGeometryError):
    """A start or adjusted relative orientation that puts matches behind the images (for a
    plane, the signature of the twin of its essential matrix)."""


@dataclass(frozen=True)
class EssentialStart:
    """Relative orientation from the essential matrix.

    Attributes
    ----------
    rotation : (3, 3) photogrammetric relative rotation ``M2 M1.T`` (camera 1 -> camera 2).
    base : (3,) unit base ``O2 - O1`` in the camera-1 frame.
    inliers : (n,) bool, matches consistent with the essential matrix (and in front of both
        cameras).
    candidates : int, number of essential matrices the solvers returned.
    alternatives : tuple of (rotation, base, inliers), other solutions with as many points in
        front of both images (five points admit several; noisy near-planar scenes may give
        two that only the adjustment tells apart).
    """

    rotation: np.ndarray
    base: np.ndarray
    inliers: np.ndarray
    candidates: int
    alternatives: tuple = ()


def check_not_collinear(xn1: np.ndarray, xn2: np.ndarray, what: str) -> None:
    """Refuse image points that lie (nearly) on a line in either image."""
    for k, xn in ((1, xn1), (2, xn2)):
        c = xn - xn.mean(axis=0)
        sv = np.linalg.svd(c, compute_uv=False)
        if sv[0] == 0 or sv[-1] < COLLINEAR_RATIO * sv[0]:
            raise DegenerateGeometryError(
                f"{what}: the points lie on a line in image {k} (spread across the line "
                f"{sv[-1] / max(sv[0], 1e-300):.2g} of the spread along it); a relative "
                "orientation needs >= 5 points spread over the overlap of both images, not "
                "on a line"
            )


def rotation_only_residuals(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Angles (rad) between ``u2`` and ``R u1`` for the best rotation ``R`` (unit rays)."""
    H = u1.T @ u2
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    c = np.clip(np.sum((u1 @ R.T) * u2, axis=1), -1.0, 1.0)
    return np.arccos(c)


def check_base(d1: np.ndarray, d2: np.ndarray, threshold: float, what: str) -> None:
    """Refuse a pair taken from one position: one rotation maps the rays of image 1 onto
    those of image 2 to within ``threshold`` (radians) for most of the given matches."""
    u1 = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    u2 = d2 / np.linalg.norm(d2, axis=1, keepdims=True)
    e = rotation_only_residuals(u1, u2)
    if np.median(e) <= threshold:
        raise DegenerateGeometryError(
            f"{what}: the images show no base: one rotation maps the rays of image 1 onto "
            f"those of image 2 (median misfit {np.median(e):.2g} rad, threshold "
            f"{threshold:.2g} rad), as for two images taken from the same position or points "
            "far away compared with the base; a relative orientation needs a base"
        )


def essential_start(
    xn1: np.ndarray,
    xn2: np.ndarray,
    threshold: float,
    *,
    confidence: float = 0.999,
    max_iter: int = 2000,
    seed: int | None = 0,
    what: str = "relative orientation",
    homography: bool = False,
) -> EssentialStart:
    """Start values from the essential matrix of normalised coordinates (n >= 5).

    Parameters
    ----------
    xn1, xn2 : (n, 2) normalised image coordinates ``(xn, yn)`` (OpenCV's, y down).
    threshold : float
        RANSAC inlier threshold on the distance to the epipolar line, normalised units.
    confidence, max_iter : RANSAC controls.
    seed : int or None
        Seed of OpenCV's random generator (``cv2.setRNGSeed``) for reproducible runs.
    homography : bool
        Candidates from the decompositions of the homography of the dominant plane
        (``cv2.findHomography``, ``cv2.decomposeHomographyMat``) instead of the five-point
        solver: a plane (flat terrain, a facade) is fitted equally well by the true essential
        matrix and its twin (base and plane normal exchanged), RANSAC may return the twin
        alone, and the decompositions hold both. Each is counted by the matches within
        ``threshold`` of its essential matrix (Sampson distance) in front of both images.

    Raises
    ------
    DegenerateGeometryError
        No essential matrix found, or none with five points in front of both images.
    """
    import cv2

    if seed is not None:
        cv2.setRNGSeed(int(seed))
    p1 = np.ascontiguousarray(xn1, dtype=np.float64)
    p2 = np.ascontiguousarray(xn2, dtype=np.float64)
    K = np.eye(3)
    far = max(OPENCV_FAR, 1.0 / threshold)  # distance / base beyond which a point is at infinity
    best = []
    n_candidates = 0
    # RANSAC, and MAGSAC++ where OpenCV has it: near-planar scenes with a misfit above the
    # threshold can make RANSAC prefer a spurious solution (base along the viewing axis) that
    # puts many of its inliers behind the cameras; the decision below is by the number of
    # points in front of both images
    methods = [cv2.RANSAC] + ([cv2.USAC_MAGSAC] if hasattr(cv2, "USAC_MAGSAC") else [])
    if homography:
        methods = []
        for Ek in _homography_essentials(p1, p2, threshold):
            n_candidates += 1
            m = _epipolar_inliers(Ek, p1, p2, threshold).astype(np.uint8)
            count, R, t, m2 = cv2.recoverPose(Ek, p1, p2, K, mask=m)
            best.append((int(count), R, t.reshape(3), m2.reshape(-1).astype(bool)))
    for method in methods:
        if seed is not None:
            cv2.setRNGSeed(int(seed))
        E, mask = cv2.findEssentialMat(
            p1, p2, K, method=method, prob=confidence, threshold=threshold, maxIters=max_iter
        )
        if E is None or E.size == 0 or not np.all(np.isfinite(E)):
            continue
        Es = E.reshape(-1, 3, 3)
        n_candidates += len(Es)
        mask0 = None if mask is None else mask.reshape(-1).astype(np.uint8)
        for Ek in Es:
            m = None if mask0 is None else mask0.copy()
            # OpenCV's default drops points farther than 50 bases as 'at infinity': a pair of
            # base / distance below 1/50 (long range, video frames) then had no point in
            # front. Here only points whose parallax is below the threshold are too far
            count, R, t, m2, _ = cv2.recoverPose(Ek, p1, p2, K, distanceThresh=far, mask=m)
            best.append((int(count), R, t.reshape(3), m2.reshape(-1).astype(bool)))
    if not best:
        solver = "the plane's homography gave" if homography else "the five-point solver found"
        raise DegenerateGeometryError(
            f"{what}: {solver} no essential matrix (too few consistent "
            "matches, or the points do not determine the orientation)"
        )
    top = max(b[0] for b in best)
    if top < 5:
        raise PointsBehindError(
            f"{what}: no essential matrix has five or more points in front of both cameras; "
            "check the matches (and that the images overlap)"
        )
    winners = [b for b in best if b[0] == top]
    distinct: list[tuple] = []
    for b in winners:
        Rp = FLIP @ b[1] @ FLIP
        base = -FLIP @ b[1].T @ b[2]
        base = base / np.linalg.norm(base)
        if not any(
            np.max(np.abs(Rp - d[0])) < SAME and np.max(np.abs(base - d[1])) < SAME
            for d in distinct
        ):
            distinct.append((Rp, base, b[3]))
    Rp, base, inl = distinct[0]
    return EssentialStart(
        rotation=Rp,
        base=base,
        inliers=inl,
        candidates=n_candidates,
        alternatives=tuple(distinct[1:]),
    )


def _epipolar_inliers(E: np.ndarray, p1: np.ndarray, p2: np.ndarray, threshold: float):
    """Matches within ``threshold`` (normalised units) of ``E`` by the Sampson distance (the
    error OpenCV's five-point RANSAC tests)."""
    x1 = np.column_stack([p1, np.ones(len(p1))])
    x2 = np.column_stack([p2, np.ones(len(p2))])
    Ex1 = x1 @ E.T
    Etx2 = x2 @ E
    e = np.einsum("ij,ij->i", x2, Ex1)
    den = Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return e**2 <= threshold**2 * den


def plane_inliers(xn1: np.ndarray, xn2: np.ndarray, threshold: float) -> int:
    """Number of matches that one homography (RANSAC, ``threshold`` in normalised units)
    maps from image 1 to image 2: all of the right ones in a planar scene."""
    import cv2

    if len(xn1) < 4:
        return 0
    p1 = np.ascontiguousarray(xn1, dtype=np.float64)
    p2 = np.ascontiguousarray(xn2, dtype=np.float64)
    # a plane worth the question holds most matches: 100 samples of four find it (an
    # inlier ratio of 0.6 misses it with probability 1e-6), where RANSAC's default of 2000
    # on a scene without one took 28 ms, as long as the whole relative orientation
    H, mask = cv2.findHomography(p1, p2, cv2.RANSAC, threshold, maxIters=100)
    if H is None or mask is None:
        return 0
    return int(mask.sum())


def _homography_essentials(p1: np.ndarray, p2: np.ndarray, threshold: float) -> list:
    """Essential matrices ``[t]x R`` of the decompositions of the homography of the
    dominant plane (RANSAC, ``threshold`` in normalised units); none when no homography is
    found (fewer than four matches, no plane)."""
    import cv2

    if len(p1) < 4:
        return []
    H, _ = cv2.findHomography(p1, p2, cv2.RANSAC, threshold)
    if H is None or H.shape != (3, 3) or not np.all(np.isfinite(H)):
        return []
    _, Rs, ts, _ = cv2.decomposeHomographyMat(H, np.eye(3))
    out = []
    for R, t in zip(Rs, ts):
        t = np.asarray(t, dtype=float).reshape(3)
        norm = np.linalg.norm(t)
        if not norm > 1e-12:  # a rotation only: no base, no essential matrix
            continue
        t = t / norm
        tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
        out.append(tx @ np.asarray(R, dtype=float))
    return out
