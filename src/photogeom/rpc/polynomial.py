"""The 20-term cubic polynomial of RPC00B and its derivatives, evaluated in blocks.

Term order (RPC00B, also used by GDAL, NITF and the vendors' files), with ``L`` the
normalised longitude, ``P`` the normalised latitude and ``H`` the normalised height::

    1, L, P, H, LP, LH, PH, L^2, P^2, H^2, PLH, L^3, LP^2, LH^2, L^2P, P^3, PH^2, L^2H, P^2H, H^3

The same order is used for the image-to-ground ("direct") polynomials of DIMAP files, with
the normalised column in the place of ``L`` and the normalised row in the place of ``P``.

Evaluation builds the term matrix of a block of points once, as a ``(20, m)`` array written
row by row (contiguous), and multiplies it with all the coefficient vectors at once, so every
term is computed once however many polynomials share it (four for a projection).
"""

from __future__ import annotations

import numpy as np

#: Number of terms of the RPC00B cubic polynomial.
N_TERMS = 20

#: Human-readable names of the 20 terms, in RPC00B order.
TERM_NAMES = (
    "1", "L", "P", "H", "LP", "LH", "PH", "L2", "P2", "H2",
    "PLH", "L3", "LP2", "LH2", "L2P", "P3", "PH2", "L2H", "P2H", "H3",
)  # fmt: skip

#: Number of terms of a polynomial of total degree 1, 2, 3 (the first terms of the order).
TERMS_OF_ORDER = {1: 4, 2: 10, 3: 20}

#: Points per block: the term matrix of a block stays in cache.
BLOCK = 8192


def fill_terms(T: np.ndarray, L: np.ndarray, P: np.ndarray, H: np.ndarray) -> None:
    """Write the 20 terms of the points ``(L, P, H)`` into ``T`` of shape ``(20, m)``."""
    T[0] = 1.0
    T[1] = L
    T[2] = P
    T[3] = H
    np.multiply(L, P, out=T[4])
    np.multiply(L, H, out=T[5])
    np.multiply(P, H, out=T[6])
    np.multiply(L, L, out=T[7])
    np.multiply(P, P, out=T[8])
    np.multiply(H, H, out=T[9])
    np.multiply(T[4], H, out=T[10])
    np.multiply(T[7], L, out=T[11])
    np.multiply(T[8], L, out=T[12])
    np.multiply(T[9], L, out=T[13])
    np.multiply(T[7], P, out=T[14])
    np.multiply(T[8], P, out=T[15])
    np.multiply(T[9], P, out=T[16])
    np.multiply(T[7], H, out=T[17])
    np.multiply(T[8], H, out=T[18])
    np.multiply(T[9], H, out=T[19])


def fill_derivative_terms(
    T: np.ndarray,
    dL: np.ndarray | None,
    dP: np.ndarray | None,
    dH: np.ndarray | None,
    L: np.ndarray,
    P: np.ndarray,
    H: np.ndarray,
) -> None:
    """Write the partial derivatives of the terms (``(20, m)`` each) given the terms ``T``.

    ``dL``, ``dP``, ``dH`` receive d(term)/dL, d(term)/dP, d(term)/dH; pass ``None`` to skip one.
    ``T`` must already hold the terms of the same points (see :func:`fill_terms`).
    """
    if dL is not None:
        dL[0] = 0.0
        dL[1] = 1.0
        dL[2] = 0.0
        dL[3] = 0.0
        dL[4] = P
        dL[5] = H
        dL[6] = 0.0
        np.multiply(L, 2.0, out=dL[7])
        dL[8] = 0.0
        dL[9] = 0.0
        dL[10] = T[6]
        np.multiply(T[7], 3.0, out=dL[11])
        dL[12] = T[8]
        dL[13] = T[9]
        np.multiply(T[4], 2.0, out=dL[14])
        dL[15] = 0.0
        dL[16] = 0.0
        np.multiply(T[5], 2.0, out=dL[17])
        dL[18] = 0.0
        dL[19] = 0.0
    if dP is not None:
        dP[0] = 0.0
        dP[1] = 0.0
        dP[2] = 1.0
        dP[3] = 0.0
        dP[4] = L
        dP[5] = 0.0
        dP[6] = H
        dP[7] = 0.0
        np.multiply(P, 2.0, out=dP[8])
        dP[9] = 0.0
        dP[10] = T[5]
        dP[11] = 0.0
        np.multiply(T[4], 2.0, out=dP[12])
        dP[13] = 0.0
        dP[14] = T[7]
        np.multiply(T[8], 3.0, out=dP[15])
        dP[16] = T[9]
        dP[17] = 0.0
        np.multiply(T[6], 2.0, out=dP[18])
        dP[19] = 0.0
    if dH is not None:
        dH[0] = 0.0
        dH[1] = 0.0
        dH[2] = 0.0
        dH[3] = 1.0
        dH[4] = 0.0
        dH[5] = L
        dH[6] = P
        dH[7] = 0.0
        dH[8] = 0.0
        np.multiply(H, 2.0, out=dH[9])
        dH[10] = T[4]
        dH[11] = 0.0
        dH[12] = 0.0
        np.multiply(T[5], 2.0, out=dH[13])
        dH[14] = 0.0
        dH[15] = 0.0
        np.multiply(T[6], 2.0, out=dH[16])
        dH[17] = T[7]
        dH[18] = T[8]
        np.multiply(T[9], 3.0, out=dH[19])


def terms(L, P, H) -> np.ndarray:
    """The term matrix of the points, shape ``(n, 20)`` (for design matrices of fits)."""
    L, P, H = (np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (L, P, H))
    T = np.empty((N_TERMS, L.size))
    fill_terms(T, L, P, H)
    return T.T


def evaluate(coefficients: np.ndarray, L, P, H) -> np.ndarray:
    """Evaluate ``k`` polynomials at ``n`` points.

    Parameters
    ----------
    coefficients : numpy.ndarray, shape (k, 20)
        One row of 20 coefficients (RPC00B order) per polynomial.
    L, P, H : numpy.ndarray, shape (n,)
        Normalised coordinates (see the module docstring).

    Returns
    -------
    numpy.ndarray, shape (k, n)
    """
    C = np.ascontiguousarray(coefficients, dtype=np.float64)
    L, P, H = (np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (L, P, H))
    n = L.size
    out = np.empty((C.shape[0], n))
    T = np.empty((N_TERMS, min(n, BLOCK)))
    for start in range(0, n, BLOCK):  # blocks of points, not single points
        stop = min(start + BLOCK, n)
        Tb = T[:, : stop - start]
        fill_terms(Tb, L[start:stop], P[start:stop], H[start:stop])
        np.matmul(C, Tb, out=out[:, start:stop])
    return out


def evaluate_with_derivatives(
    coefficients: np.ndarray, L, P, H, wrt: str = "LP"
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Values and partial derivatives of ``k`` polynomials at ``n`` points.

    Parameters
    ----------
    coefficients : numpy.ndarray, shape (k, 20)
    L, P, H : numpy.ndarray, shape (n,)
    wrt : str
        Which derivatives: any of the letters ``"L"``, ``"P"``, ``"H"``.

    Returns
    -------
    values : numpy.ndarray, shape (k, n)
    derivatives : dict
        Letter -> array of shape ``(k, n)``.
    """
    C = np.ascontiguousarray(coefficients, dtype=np.float64)
    L, P, H = (np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (L, P, H))
    n, k = L.size, C.shape[0]
    m = min(n, BLOCK)
    values = np.empty((k, n))
    derivs = {c: np.empty((k, n)) for c in wrt}
    T = np.empty((N_TERMS, m))
    buf = {c: np.empty((N_TERMS, m)) for c in wrt}
    for start in range(0, n, BLOCK):
        stop = min(start + BLOCK, n)
        w = stop - start
        Tb = T[:, :w]
        Ls, Ps, Hs = L[start:stop], P[start:stop], H[start:stop]
        fill_terms(Tb, Ls, Ps, Hs)
        views = {c: buf[c][:, :w] for c in wrt}
        fill_derivative_terms(Tb, views.get("L"), views.get("P"), views.get("H"), Ls, Ps, Hs)
        np.matmul(C, Tb, out=values[:, start:stop])
        for c in wrt:
            np.matmul(C, views[c], out=derivs[c][:, start:stop])
    return values, derivs
