"""Recursive least squares with exponential forgetting and covariance resetting; normalised gradient.

RLS (Johansson 11.2, (11.3)–(11.18)):
    ε_k = y_k − φ_kᵀθ_{k−1}
    P_k = (P_{k−1} − P_{k−1}φ_kφ_kᵀP_{k−1}/(λ + φ_kᵀP_{k−1}φ_k))/λ
    θ_k = θ_{k−1} + P_kφ_kε_k
With P_0 = p0·I this minimises Σ λ^{N−k}ε_k² + λ^N (θ − θ_0)ᵀP_0⁻¹(θ − θ_0); λ = 1 reproduces batch LS up
to the P_0 regularisation; the total weight Σ_{k=1}^N λ^{N−k} = (1 − λ^N)/(1 − λ) (misprint 40 corrected).
Covariance resetting: P ← p0·I every ``reset_every`` samples (tracking of parameter jumps).

Normalised gradient (Johansson 11.4, modified form (11.22)–(11.37)):
    θ_k = θ_{k−1} + Qφ_kε_k/r_k,  r_k = r_{k−1} + φ_kᵀQφ_k.
"""

from __future__ import annotations

import numpy as np

from .base import Estimate, EstimationError, as_regressors, as_target


def rls(phi, y, lam: float = 1.0, p0: float = 1e4, theta0=None, reset_every: int | None = None) -> Estimate:
    """RLS with forgetting factor ``lam`` (Johansson 11.2, (11.3)–(11.18)).

    ``phi`` (N, p) regressors, ``y`` (N,) outputs, P_0 = p0·I, θ_0 = theta0 (zeros by default).
    ``extra['theta_trajectory']`` is (N, p) (row k = θ after sample k), ``extra['P']`` the final P,
    ``extra['prior_errors']`` the a-priori errors ε_k. ``cov`` = σ̂²P with σ̂² from the a-posteriori
    residuals of the final θ (meaningful for λ = 1)."""
    yv = as_target(y)
    ph = as_regressors(phi, yv.size)
    n, p = ph.shape
    if not (0.0 < lam <= 1.0):
        raise EstimationError(f"forgetting factor lam must be in (0, 1], got {lam}")
    if not (np.isfinite(p0) and p0 > 0):
        raise EstimationError(f"p0 must be a positive finite number (P0 = p0·I), got {p0}")
    if reset_every is not None and int(reset_every) < 1:
        raise EstimationError(f"reset_every must be a positive integer, got {reset_every}")
    theta = np.zeros(p) if theta0 is None else np.asarray(theta0, dtype=float).copy()
    if theta.shape != (p,):
        raise EstimationError(f"theta0 must have shape ({p},), got {theta.shape}")
    pm = p0 * np.eye(p)
    traj = np.empty((n, p))
    eps = np.empty(n)
    for k in range(n):
        if reset_every is not None and k > 0 and k % int(reset_every) == 0:
            pm = p0 * np.eye(p)
        f = ph[k]
        e = yv[k] - f @ theta
        pf = pm @ f
        pm = (pm - np.outer(pf, pf) / (lam + f @ pf)) / lam
        pm = 0.5 * (pm + pm.T)
        theta = theta + pm @ f * e
        traj[k] = theta
        eps[k] = e
    resid = yv - ph @ theta
    dof = n - p
    sigma2 = float(resid @ resid) / dof if dof > 0 else None
    cov = sigma2 * pm if sigma2 is not None else None
    return Estimate(theta, cov, resid, None, p, "rls",
                    {"theta_trajectory": traj, "P": pm, "prior_errors": eps, "lam": lam, "p0": p0,
                     "reset_every": reset_every, "sigma2": sigma2})


def fit(regressors, target, **options) -> Estimate:
    """Registry adapter: ``fit(Φ, Y, lam=..., p0=..., theta0=..., reset_every=...)`` -> :func:`rls`."""
    return rls(regressors, target, **options)


def normalized_gradient(phi, y, Q=None, r0: float = 1.0, theta0=None) -> Estimate:
    """Normalised gradient estimator, modified form r_k = r_{k−1} + φ_kᵀQφ_k (Johansson 11.4).
    In the noise-free case the Q⁻¹-weighted parameter-error norm is non-increasing."""
    yv = as_target(y)
    ph = as_regressors(phi, yv.size)
    n, p = ph.shape
    q = np.eye(p) if Q is None else np.asarray(Q, dtype=float)
    try:
        np.linalg.cholesky(q)
    except np.linalg.LinAlgError:
        raise EstimationError("Q must be symmetric positive definite") from None
    if not r0 > 0:
        raise EstimationError(f"r0 must be positive, got {r0}")
    theta = np.zeros(p) if theta0 is None else np.asarray(theta0, dtype=float).copy()
    r = float(r0)
    traj = np.empty((n, p))
    rs = np.empty(n)
    for k in range(n):
        f = ph[k]
        e = yv[k] - f @ theta
        r = r + f @ q @ f
        theta = theta + q @ f * e / r
        traj[k] = theta
        rs[k] = r
    return Estimate(theta, None, yv - ph @ theta, None, p, "normalized_gradient",
                    {"theta_trajectory": traj, "r": rs})
