"""Nonlinear least squares: θ̂ = argmin ½ Σ r_k(θ)², by scipy's trust-region least_squares with tight
tolerances (Johansson 5.12a, (5.143)–(5.147): the listing's gradient descent stops early; the true
minimiser is K = 3.35821, τ = 0.582935, misprint 28). Any residual vector works, e.g. the relative-error
criterion of Johansson 5.12b ((5.148)–(5.151)). Covariance σ̂²(JᵀJ)⁻¹ (Gauss–Newton), σ̂² = Σr²/(N − p).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from .base import Estimate, EstimationError, as_target, gaussian_loglik


def fit_residuals(residual_fn, theta0, *, bounds=None) -> Estimate:
    """Minimise ½‖r(θ)‖² for a user residual function r(θ) -> (N,)."""
    x0 = np.asarray(theta0, dtype=float)
    b = (-np.inf, np.inf) if bounds is None else bounds
    res = optimize.least_squares(residual_fn, x0, bounds=b, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                                 max_nfev=10000, x_scale="jac")
    if not res.success and res.status <= 0:
        raise EstimationError(f"nonlinear least squares did not converge: {res.message}")
    r = np.asarray(res.fun, dtype=float)
    n, p = r.size, x0.size
    jac = res.jac
    dof = n - p
    cov = None
    if dof > 0 and np.linalg.matrix_rank(jac) == p:
        cov = float(r @ r) / dof * np.linalg.inv(jac.T @ jac)
    return Estimate(res.x, cov, r, gaussian_loglik(r), p, "nls",
                    {"cost": 0.5 * float(r @ r), "jac": jac, "nfev": res.nfev, "dof": dof if dof > 0 else None})


def fit(regressors, target, *, model, theta0, bounds=None) -> Estimate:
    """NLS for y = model(regressors, θ) + e; residuals are y − model(regressors, θ)."""
    y = as_target(target)
    x = np.asarray(regressors, dtype=float)
    return fit_residuals(lambda th: y - np.asarray(model(x, th), dtype=float), theta0, bounds=bounds)
