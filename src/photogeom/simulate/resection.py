"""Random single-image resection problems with known truth (the robustness study of
:func:`photogeom.space_resection`, ``benchmarks/resection_robustness.py`` and its tests).

Each problem is a digital camera (f 800-8000 px on a 6000 x 4000 px frame, Brown distortion
K1, K2, P1, P2), a random exterior orientation of one of three kinds (``"nadir"``: tilt below
5 degrees, any heading; ``"oblique"``: tilt 20-70 degrees, any heading; ``"any"``: a
uniformly random rotation), 4-40 control points spread over the frame where the distortion
is one-to-one, at depths with random relief, and image coordinates with 0.5 px Gaussian noise.
A seed gives the same problem on every machine.
"""

from __future__ import annotations

import numpy as np

from ..camera import BrownDistortion, ExteriorOrientation, InteriorOrientation, project
from ..errors import InputError
from ..rotation import opk_matrix

__all__ = ["RESECTION_KINDS", "random_rotation", "resection_problem"]

#: The kinds of attitude of :func:`resection_problem`.
RESECTION_KINDS = ("nadir", "oblique", "any")


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix uniformly distributed over SO(3) (QR of a Gaussian matrix)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def resection_problem(seed: int, kind: str):
    """One random resection problem (see the module).

    Returns
    -------
    tuple
        ``(io, true exterior orientation, ground (n, 3), noisy image (n, 2) in px, sigma)``,
        sigma the noise's standard deviation in px (0.5).
    """
    if kind not in RESECTION_KINDS:
        raise InputError(f"kind must be one of {', '.join(RESECTION_KINDS)}, not {kind!r}")
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 41))
    w, h = 6000.0, 4000.0
    f = float(rng.uniform(800.0, 8000.0))
    dist = BrownDistortion(
        k1=float(rng.uniform(-0.25, 0.1)),
        k2=float(rng.uniform(-0.1, 0.1)),
        p1=float(rng.uniform(-1e-3, 1e-3)),
        p2=float(rng.uniform(-1e-3, 1e-3)),
    )
    io = InteriorOrientation.digital(f, w / 2 + rng.uniform(-50, 50), h / 2, distortion=dist)
    if kind == "any":
        M = random_rotation(rng)
    else:
        tilt = np.radians(rng.uniform(0, 5) if kind == "nadir" else rng.uniform(20, 70))
        az = rng.uniform(-np.pi, np.pi)
        M = opk_matrix(tilt * np.cos(az), tilt * np.sin(az), rng.uniform(-np.pi, np.pi))
    position = rng.uniform(-1000, 1000, 3)
    eo = ExteriorOrientation.from_matrix(position, M, on_gimbal_lock="omega-zero")
    # points spread over the frame (normalised undistorted coordinates) where the distortion
    # is one-to-one (the radial derivative 1 + 3 K1 r^2 + 5 K2 r^4 >= 0.5), random depths
    half = np.array([w, h]) / 2 / f * 0.95
    xn = np.empty((0, 2))
    while len(xn) < n:
        cand = rng.uniform(-half, half, (4 * n, 2))
        r2 = np.sum(cand**2, axis=1)
        cand = cand[1 + 3 * dist.k1 * r2 + 5 * dist.k2 * r2**2 >= 0.5]
        xn = np.concatenate([xn, cand])[:n]
    d0 = float(rng.uniform(20.0, 2000.0))
    relief = float(rng.uniform(0.02, 1.0))
    depth = d0 * rng.uniform(1.0, 1.0 + relief, n)
    pc = np.column_stack([xn[:, 0], -xn[:, 1], -np.ones(n)]) * depth[:, None]
    ground = eo.position + pc @ eo.matrix
    sigma = 0.5
    image = project(ground, io, eo) + rng.normal(0.0, sigma, (n, 2))
    return io, eo, ground, image, sigma
