"""Conversions between photogeom blocks and the peers' bundle adjusters (GTSAM, pycolmap),
for the tests that compare minima and covariances with them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from photogeom.rotation import opk_from_matrix

#: photogeom's image axes (x right, y up, z backwards) -> camera axes (z forward, y down).
D = np.diag([1.0, -1.0, -1.0])
#: The camera model pycolmap's OPENCV holds (photogeom names): fx = f + b1, fy = f.
OPENCV_SET = ("f", "cx", "cy", "k1", "k2", "p1", "p2", "b1")
#: GTSAM's Cal3DS2 adds the skew, photogeom's b2.
CAL3DS2_SET = (*OPENCV_SET, "b2")


def cal3ds2(c):
    """GTSAM ``Cal3DS2(fx, fy, s, u0, v0, k1, k2, p1, p2)`` of a Metashape calibration (pixel
    origin: the first pixel's centre, photogeom's)."""
    import gtsam

    return gtsam.Cal3DS2(
        c.f + c.b1,
        c.f,
        c.b2,
        c.width / 2 - 0.5 + c.cx,
        c.height / 2 - 0.5 + c.cy,
        c.k1,
        c.k2,
        c.p2,
        c.p1,
    )


def from_cal3ds2(k, c):
    """The Metashape calibration of a GTSAM ``Cal3DS2`` (``c`` gives the image size)."""
    fx, fy, s, u0, v0, k1, k2, p1, p2 = k.vector()
    return replace(
        c,
        f=fy,
        b1=fx - fy,
        b2=s,
        cx=u0 - c.width / 2 + 0.5,
        cy=v0 - c.height / 2 + 0.5,
        k1=k1,
        k2=k2,
        p1=p2,
        p2=p1,
    )


#: d(fx, fy, s, u0, v0, k1, k2, p1, p2) / d(f, cx, cy, k1, k2, p1, p2, b1, b2)
CAL3DS2_JACOBIAN = np.zeros((9, 9))
for _row, _cols in enumerate(((0, 7), (0,), (8,), (1,), (2,), (3,), (4,), (6,), (5,))):
    CAL3DS2_JACOBIAN[_row, list(_cols)] = 1.0


def pose(C, M):
    """GTSAM ``Pose3`` (camera to world, camera z forward) of a centre and ``M``."""
    import gtsam

    return gtsam.Pose3(gtsam.Rot3(M.T @ D), np.asarray(C, dtype=float))


def exterior_of(p) -> np.ndarray:
    """X0, Y0, Z0, omega, phi, kappa of a GTSAM ``Pose3``."""
    return np.concatenate([p.translation(), opk_from_matrix((p.rotation().matrix() @ D).T)])


def graph(block, *, gnss: bool = False, control: bool = False):
    """Factor graph and initial values of a one-camera block: a ``GeneralSFMFactor2Cal3DS2``
    per image observation with its sigma, ``GPSFactor`` for GNSS positions, a
    ``PriorFactorPoint3`` per control point (keys X_i images, L_j points, K0 the camera)."""
    import gtsam
    from gtsam.symbol_shorthand import K, L, X

    g = gtsam.NonlinearFactorGraph()
    v = gtsam.Values()
    Ms = block.rotations()
    for i in range(block.n_images):
        v.insert(X(i), pose(block.exterior[i, :3], Ms[i]))
        if gnss and np.all(np.isfinite(block.gnss[i])):
            nm = gtsam.noiseModel.Diagonal.Sigmas(block.gnss_sigma[i])
            g.add(gtsam.GPSFactor(X(i), block.gnss[i], nm))
    for j in np.flatnonzero(block.role != "check").tolist():
        v.insert(L(j), block.xyz[j])
        if control and block.role[j] == "control":
            nm = gtsam.noiseModel.Diagonal.Sigmas(block.point_sigma[j])
            g.add(gtsam.PriorFactorPoint3(L(j), block.xyz[j], nm))
    v.insert(K(0), cal3ds2(block.calibrations[0]))
    o = block.observations
    for r in np.flatnonzero(block.role[block.obs_point] != "check").tolist():
        nm = gtsam.noiseModel.Isotropic.Sigma(2, float(o.sigma[r]))
        i, j = int(block.obs_image[r]), int(block.obs_point[r])
        g.add(gtsam.GeneralSFMFactor2Cal3DS2(o.uv[r], nm, X(i), L(j), K(0)))
    return g, v


def values_of(block):
    """GTSAM values of a block's exterior orientations, points and calibration."""
    return graph(block)[1]


def block_of(block, values):
    """The block with the poses, points and calibration of GTSAM ``values``."""
    from gtsam.symbol_shorthand import K, L, X

    ext = np.array([exterior_of(values.atPose3(X(i))) for i in range(block.n_images)])
    xyz = block.xyz.copy()
    for j in np.flatnonzero(block.role != "check").tolist():
        xyz[j] = values.atPoint3(L(j))
    cal = from_cal3ds2(values.atCal3DS2(K(0)), block.calibrations[0])
    return block.replace(exterior=ext, xyz=xyz, calibrations=(cal,))


def free_gauge(g, block, sigma: float = 1e-3) -> None:
    """Priors that remove exactly the seven gauge freedoms of a free network: the first pose
    and the distance from the first to the farthest centre, at their values in ``block``."""
    import gtsam
    from gtsam.symbol_shorthand import X

    C = block.exterior[:, :3]
    far = int(np.argmax(np.linalg.norm(C - C[0], axis=1)))
    nm6 = gtsam.noiseModel.Isotropic.Sigma(6, sigma)
    g.add(gtsam.PriorFactorPose3(X(0), pose(C[0], block.rotations()[0]), nm6))
    dist = float(np.linalg.norm(C[far] - C[0]))
    g.add(gtsam.RangeFactorPose3(X(0), X(far), dist, gtsam.noiseModel.Isotropic.Sigma(1, sigma)))


def optimize(g, v, rtol: float = 1e-12):
    import gtsam

    p = gtsam.LevenbergMarquardtParams()
    p.setRelativeErrorTol(rtol)
    p.setAbsoluteErrorTol(0.0)
    p.setMaxIterations(200)
    return gtsam.LevenbergMarquardtOptimizer(g, v, p).optimize()


def tangent_to_exterior(p, h: float = 1e-6) -> np.ndarray:
    """d(X0, Y0, Z0, omega, phi, kappa) / d(GTSAM's Pose3 tangent) at ``p``, by central
    differences of ``p.retract`` (whatever chart GTSAM was built with)."""
    e0 = exterior_of(p)
    J = np.zeros((6, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        a, b = exterior_of(p.retract(d)), exterior_of(p.retract(-d))
        diff = a - b
        diff[3:] = (diff[3:] + np.pi) % (2 * np.pi) - np.pi
        J[:, k] = diff / (2 * h)
    assert np.all(np.isfinite(e0))
    return J
