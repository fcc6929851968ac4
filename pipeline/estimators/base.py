"""Shared interface of every estimator: ``fit(regressors, target, **options) -> Estimate``.

An :class:`Estimate` is immutable; estimator-specific results (null-space basis, trajectories,
posterior samples, warnings...) go into ``extra``. Input checks raise
:class:`pipeline.errors.EstimationError` with a message naming what is wrong and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats
from scipy.linalg import lapack

from pipeline.errors import EstimationError

__all__ = [
    "Estimate",
    "EstimationError",
    "as_regressors",
    "as_target",
    "numerical_rank",
    "augmented_r",
    "numerical_hessian",
    "gaussian_loglik",
]


@dataclass(frozen=True)
class Estimate:
    """Result of one estimator run.

    theta: (p,) parameter estimate; cov: (p, p) covariance or None when undefined;
    residuals: target − prediction (shape of the target); loglik: log-likelihood at the estimate
    (None when undefined, e.g. an exact fit); n_params: number of estimated parameters that count
    for information criteria; name: registry key ("ls", "wls", ...); extra: estimator-specific items.
    """

    theta: np.ndarray
    cov: np.ndarray | None
    residuals: np.ndarray
    loglik: float | None
    n_params: int
    name: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def stderr(self) -> np.ndarray | None:
        if self.cov is None:
            return None
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def conf_int(self, level: float = 0.95) -> np.ndarray:
        """(p, 2) two-sided intervals theta ± q·se; q from Student t with ``extra['dof']`` if present,
        else from the normal distribution."""
        if self.cov is None:
            raise EstimationError(f"estimator '{self.name}' has no covariance, so no confidence interval")
        if not 0.0 < level < 1.0:
            raise EstimationError(f"confidence level must be in (0, 1), got {level}")
        dof = self.extra.get("dof")
        a = 0.5 + level / 2.0
        q = stats.t.ppf(a, dof) if dof else stats.norm.ppf(a)
        se = self.stderr
        return np.column_stack([self.theta - q * se, self.theta + q * se])


def as_regressors(regressors, n: int | None = None) -> np.ndarray:
    """(N, p) float array; a 1-D input is one regressor column."""
    phi = np.asarray(regressors, dtype=float)
    if phi.ndim == 1:
        phi = phi[:, None]
    if phi.ndim != 2:
        raise EstimationError(f"regressors must be a 1-D or 2-D array (N, p), got shape {phi.shape}")
    if n is not None and phi.shape[0] != n:
        raise EstimationError(f"regressors have {phi.shape[0]} rows but the target has {n} samples; expected equal")
    if not np.all(np.isfinite(phi)):
        raise EstimationError("regressors contain NaN or infinite values; expected finite numbers")
    return phi


def as_target(target) -> np.ndarray:
    y = np.asarray(target, dtype=float)
    if y.ndim == 2 and y.shape[1] == 1:
        y = y[:, 0]
    if y.ndim != 1:
        raise EstimationError(f"target must be a 1-D array (N,), got shape {y.shape}; fit each output separately")
    if not np.all(np.isfinite(y)):
        raise EstimationError("target contains NaN or infinite values; expected finite numbers")
    return y


def numerical_rank(phi: np.ndarray, rtol: float | None = None, *,
                   n_rows: int | None = None) -> tuple[int, np.ndarray, np.ndarray, float]:
    """Numerical rank via the SVD. Singular values s_i <= tol are treated as zero, with
    tol = rtol · s_max and by default rtol = max(N, p) · machine epsilon (the LAPACK/NumPy convention).
    Returns (rank, singular values, V (p×p, rows of Vᵀ as columns), tol).

    ``phi`` may be the p×p triangular factor R of a QR decomposition Φ = QR of the N×p regressor
    matrix, with ``n_rows=N``: Q has orthonormal columns, so ΦᵀΦ = RᵀR and Φ, R share their singular
    values and right singular vectors (Golub & Van Loan, Matrix Computations, 4th ed., §5.4.1,
    R-SVD); the SVD then costs O(p³) instead of O(Np²), and the default tolerance is still
    max(N, p)·eps·s_max of Φ."""
    # full V is needed for the null space when N < p; otherwise the thin SVD (never an N×N U)
    _, s, vt = np.linalg.svd(phi, full_matrices=phi.shape[0] < phi.shape[1])
    if rtol is None:
        rows = phi.shape[0] if n_rows is None else int(n_rows)
        rtol = max(rows, phi.shape[1]) * np.finfo(float).eps
    tol = float(rtol * (s[0] if s.size else 0.0))
    rank = int(np.sum(s > tol))
    return rank, s, vt.T, tol


def augmented_r(phi: np.ndarray, y: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Upper-triangular factor R of the Householder QR [Φ | y] = Q R, without forming Q.

    Rows are multiplied by ``scale`` first when given (whitening Φ·√w, y·√w for weighted LS).
    Returns R of shape (min(N, p+1), p+1). Partitioned as R = [[R11, r12], [0, r22]] with R11 p×p:
    Qᵀy = [r12; r22], so the LS solution of min ‖y − Φθ‖² is θ̂ = R11⁻¹r12, the residual energy is
    SSE = r22² and ΦᵀΦ = R11ᵀR11 (Johansson (5.5)–(5.10); Golub & Van Loan, Matrix Computations,
    4th ed., §5.3.3). One LAPACK dgeqrf on a Fortran-ordered copy of [Φ | y] that is overwritten in
    place: no N×p matrix Q (orgqr) and no N×p matrix U of an SVD is ever built.
    """
    n, p = phi.shape
    a = np.empty((n, p + 1), order="F")
    if scale is None:
        # a ufunc copy: its iterator blocks the C→Fortran transposition, ~3× faster than `a[:, :p] = phi`
        np.positive(phi, out=a[:, :p])
        a[:, p] = y
    else:
        np.multiply(phi, scale[:, None], out=a[:, :p])
        np.multiply(y, scale, out=a[:, p])
    lwork = int(lapack.dgeqrf(a, lwork=-1, overwrite_a=1)[2][0])  # workspace query, a untouched
    qr, _, _, info = lapack.dgeqrf(a, lwork=max(lwork, 1), overwrite_a=1)
    if info != 0:
        raise EstimationError(f"QR factorisation failed (LAPACK dgeqrf info = {info})")
    return np.triu(qr[: min(n, p + 1)])


def numerical_hessian(fun, x: np.ndarray, rel_step: float = 1e-4) -> np.ndarray:
    """Central-difference Hessian of a scalar function (used for the observed information)."""
    x = np.asarray(x, dtype=float)
    p = x.size
    h = rel_step * np.maximum(np.abs(x), 1.0)
    hess = np.empty((p, p))
    f0 = fun(x)
    for i in range(p):
        ei = np.zeros(p)
        ei[i] = h[i]
        hess[i, i] = (fun(x + ei) - 2.0 * f0 + fun(x - ei)) / h[i] ** 2
        for j in range(i + 1, p):
            ej = np.zeros(p)
            ej[j] = h[j]
            val = (fun(x + ei + ej) - fun(x + ei - ej) - fun(x - ei + ej) + fun(x - ei - ej)) / (4 * h[i] * h[j])
            hess[i, j] = hess[j, i] = val
    return hess


def gaussian_loglik(residuals: np.ndarray, sigma2: float | None = None) -> float | None:
    """Gaussian log-likelihood; with sigma2=None the ML variance SSE/N is plugged in.
    None when undefined (zero residuals and unknown variance)."""
    e = np.asarray(residuals, dtype=float).ravel()
    n = e.size
    sse = float(e @ e)
    if sigma2 is None:
        if sse <= 0.0:
            return None
        s2 = sse / n
        return -0.5 * n * (math.log(2 * math.pi * s2) + 1.0)
    return -0.5 * n * math.log(2 * math.pi * sigma2) - 0.5 * sse / sigma2
