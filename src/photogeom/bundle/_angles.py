"""omega, phi, kappa of rotation matrices that reproduce the matrix to rounding, also near
gimbal lock (the interchange formats store matrices or quaternions; the block stores angles).

``phi = atan2(m31, hypot(m32, m33))`` and ``omega = atan2(-m32, m33)`` as usual; ``kappa`` is
then taken from ``A = M M1(omega)^T = M3(kappa) M2(phi)`` (``A[0, 1] = sin kappa``,
``A[1, 1] = cos kappa``), so that an omega made inaccurate by a small ``cos(phi)`` is
compensated by kappa: ``M3(kappa) M2(phi) M1(omega)`` equals ``M`` to a few 1e-16 at any
attitude, where the independent formula ``kappa = atan2(-m21, m11)`` loses up to 1e-7 rad
near phi = +-90 degrees. Away from the lock the angles are the closed formulas' (01, 2).
No tolerance is applied: even a ``cos(phi)`` of 1e-15 keeps its omega (setting omega to 0
there would move the matrix by ``cos(phi)``); only at the exact lock (``m32 = m33 = 0``)
is omega 0, with kappa carrying the whole rotation about the vertical.
"""

from __future__ import annotations

import numpy as np


def opk_from_rotations(M: np.ndarray) -> np.ndarray:
    """Angles (n, 3) omega, phi, kappa in radians of rotation matrices ``M`` (n, 3, 3)."""
    M = np.asarray(M, dtype=float).reshape(-1, 3, 3)
    m31, m32, m33 = M[:, 2, 0], M[:, 2, 1], M[:, 2, 2]
    cphi = np.hypot(m32, m33)
    phi = np.arctan2(m31, cphi)
    omega = np.where(cphi == 0.0, 0.0, np.arctan2(-m32, m33))
    c, s = np.cos(omega), np.sin(omega)
    kappa = np.arctan2(M[:, 0, 1] * c + M[:, 0, 2] * s, M[:, 1, 1] * c + M[:, 1, 2] * s)
    return np.column_stack([omega, phi, kappa])
