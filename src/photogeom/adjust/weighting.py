"""Observation weights and covariances: whitening ``W`` with ``W.T W = P``.

Three forms are accepted everywhere in the engine:

* ``weights``: the diagonal of ``P``, shape (n_obs,);
* ``covariance``: a full ``Cll`` of shape (n_obs, n_obs);
* ``covariance``: block-diagonal ``Cll`` of shape (k, b, b) with ``k * b = n_obs``
  (consecutive observations of one point, e.g. b = 3 for 3D points).

With a covariance the weight matrix is ``P = sigma0_prior^2 Cll^-1``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ..errors import InputError


class Whitener:
    """Applies ``W`` and ``W.T`` (``W.T W = P``) and knows ``diag(P)`` and ``diag(Qll)``."""

    def __init__(
        self,
        n_obs: int,
        weights: np.ndarray | None = None,
        covariance: np.ndarray | None = None,
        sigma0_prior: float = 1.0,
    ) -> None:
        if weights is not None and covariance is not None:
            raise InputError("give either weights or a covariance matrix, not both")
        if not (np.isfinite(sigma0_prior) and sigma0_prior > 0):
            raise InputError(f"sigma0_prior must be a positive number, got {sigma0_prior!r}")
        self.n = n_obs
        self.kind = "unit"
        self.sqrt_w: np.ndarray | None = None
        self.chol: np.ndarray | None = None  # lower Cholesky factor(s) of Qll
        if weights is not None:
            w = np.asarray(weights, dtype=float).reshape(-1)
            if w.shape[0] != n_obs:
                raise InputError(f"weights: {w.shape[0]} value(s) for {n_obs} observation(s)")
            if not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise InputError("weights must be finite and > 0")
            self.kind = "diagonal"
            self.sqrt_w = np.sqrt(w)
        elif covariance is not None:
            C = np.asarray(covariance, dtype=float) / sigma0_prior**2
            if not np.all(np.isfinite(C)):
                raise InputError("covariance matrix contains NaN or infinite values")
            if C.ndim == 2 and C.shape == (n_obs, n_obs):
                self.kind = "full"
            elif C.ndim == 3 and C.shape[1] == C.shape[2] and C.shape[0] * C.shape[1] == n_obs:
                self.kind = "block"
            else:
                raise InputError(
                    f"covariance: expected shape ({n_obs}, {n_obs}) or (k, b, b) with "
                    f"k*b = {n_obs}, got {C.shape}"
                )
            try:
                self.chol = np.linalg.cholesky(C)
            except np.linalg.LinAlgError as exc:
                raise InputError(
                    "covariance matrix is not symmetric positive definite; check the variances"
                ) from exc

    # ``W = G^-1`` with ``Qll = G G.T``
    def apply(self, M: np.ndarray) -> np.ndarray:
        """``W @ M`` for M of shape (n_obs,) or (n_obs, k)."""
        if self.kind == "unit":
            return M
        if self.kind == "diagonal":
            return (self.sqrt_w * M.T).T
        if self.kind == "full":
            return scipy.linalg.solve_triangular(self.chol, M, lower=True)
        k, b, _ = self.chol.shape
        Mb = M.reshape(k, b, -1)
        out = np.linalg.solve(self.chol, Mb)
        return out.reshape(M.shape)

    def apply_t(self, M: np.ndarray) -> np.ndarray:
        """``W.T @ M``."""
        if self.kind in ("unit", "diagonal"):
            return self.apply(M)
        if self.kind == "full":
            return scipy.linalg.solve_triangular(self.chol, M, lower=True, trans="T")
        k, b, _ = self.chol.shape
        Mb = M.reshape(k, b, -1)
        out = np.linalg.solve(np.swapaxes(self.chol, 1, 2), Mb)
        return out.reshape(M.shape)

    def diag_p(self) -> np.ndarray:
        """Diagonal of ``P``."""
        if self.kind == "unit":
            return np.ones(self.n)
        if self.kind == "diagonal":
            return self.sqrt_w**2
        if self.kind == "full":
            Ginv = scipy.linalg.solve_triangular(self.chol, np.eye(self.n), lower=True)
            return np.sum(Ginv * Ginv, axis=0)
        _k, _b, _ = self.chol.shape
        Ginv = np.linalg.inv(self.chol)
        return np.sum(Ginv * Ginv, axis=1).reshape(-1)

    def diag_q(self) -> np.ndarray:
        """Diagonal of ``Qll`` (cofactors of the observations)."""
        if self.kind == "unit":
            return np.ones(self.n)
        if self.kind == "diagonal":
            return 1.0 / self.sqrt_w**2
        if self.kind == "full":
            return np.sum(self.chol * self.chol, axis=1)
        return np.sum(self.chol * self.chol, axis=2).reshape(-1)

    def q_times(self, M: np.ndarray) -> np.ndarray:
        """``Qll @ M``."""
        if self.kind == "unit":
            return M
        if self.kind == "diagonal":
            return ((1.0 / self.sqrt_w**2) * M.T).T
        if self.kind == "full":
            return self.chol @ (self.chol.T @ M)
        k, b, _ = self.chol.shape
        Mb = M.reshape(k, b, -1)
        out = self.chol @ (np.swapaxes(self.chol, 1, 2) @ Mb)
        return out.reshape(M.shape)
