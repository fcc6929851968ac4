"""Weighted and generalised least squares, feasible GLS, and the weighted continuous criterion.

* WLS: θ̂ = (ΦᵀWΦ)⁻¹ΦᵀWY with W = diag(w) (Johansson (5.37)–(5.45)).
* Markov / GLS estimate with a full noise covariance R: θ̂ = (ΦᵀR⁻¹Φ)⁻¹ΦᵀR⁻¹Y,
  Cov θ̂ = (ΦᵀR⁻¹Φ)⁻¹ (Johansson 5.7, (5.76)–(5.77)).
* Given variance model σ²_i = v(Φ_i) → w_i = 1/σ²_i; feasible GLS: log ε_i² = Z_i γ fitted to the
  current residuals, w_i = exp(−Z_i γ), iterated.
* Weighted continuous criterion min_θ ∫_U (F(u) − θᵀg(u))² ρ(u) du (Wrocław Example 2.5,
  (2.67)–(2.72)), normal equations by scipy quad.
"""

from __future__ import annotations

import numpy as np
from scipy import integrate, linalg

from .base import Estimate, EstimationError, as_regressors, as_target, augmented_r, numerical_rank
from .ls import RANK_MARGIN


def _check_weights(w: np.ndarray, n: int) -> np.ndarray:
    w = np.asarray(w, dtype=float).ravel()
    if w.size != n:
        raise EstimationError(f"weights have {w.size} entries but the target has {n} samples; expected equal")
    if not np.all(np.isfinite(w)):
        raise EstimationError("weights contain NaN or infinite values; expected finite positive numbers")
    bad = np.flatnonzero(w <= 0)
    if bad.size:
        raise EstimationError(f"weights must be strictly positive (inverse variances); {bad.size} of {n} are "
                              f"zero or negative (first at index {bad[0]}: {w[bad[0]]:g})")
    return w


def _solve_whitened(phi: np.ndarray, y: np.ndarray, scale: np.ndarray | None = None):
    """LS on the whitened data Φ_w = diag(scale)·Φ, y_w = diag(scale)·y (scale = √w; None: Φ, y are
    already whitened): θ̂ = (Φ_wᵀΦ_w)⁻¹Φ_wᵀy_w = (ΦᵀWΦ)⁻¹ΦᵀWY (Johansson (5.40)).

    One R-only Householder QR of [Φ_w | y_w] = Q [[R11, r12], [0, r22]]
    (:func:`~pipeline.estimators.base.augmented_r`): the rank test uses the SVD of the p×p factor R11
    (same singular values as Φ_w, tolerance max(N, p)·eps·s_max), θ̂ = R11⁻¹r12, the weighted residual
    energy εᵀWε = r22² and (ΦᵀWΦ)⁻¹ = R11⁻¹R11⁻ᵀ. Returns (θ̂, (ΦᵀWΦ)⁻¹)."""
    n, p = phi.shape
    rank = None
    if n > p:
        r = augmented_r(phi, y, scale)
        rank, s, _, tol = numerical_rank(r[:p, :p], n_rows=n)
        if rank < p or s[-1] <= RANK_MARGIN * tol:
            rank = None  # rank deficient or borderline: decide on the SVD of Φ_w itself (as before)
    if rank is None:
        phi_w = phi if scale is None else phi * scale[:, None]
        rank = numerical_rank(phi_w)[0]
        if rank < p:
            raise EstimationError(f"singular weighted regressors: numerical rank {rank} < {p} parameters; "
                                  "expected full column rank")
        r = augmented_r(phi, y, scale)
    r11 = r[:p, :p]
    theta = linalg.solve_triangular(r11, r[:p, p])
    rinv = linalg.solve_triangular(r11, np.eye(p))
    return theta, rinv @ rinv.T


def fit(regressors, target, *, weights=None, noise_cov=None, variance_model=None, fgls: bool = False,
        variance_regressors=None, n_iter: int = 5, scale_cov: bool | None = None) -> Estimate:
    """Weighted LS (Johansson (5.37)–(5.45)) / Markov estimate (Johansson 5.7, (5.76)).

    Exactly one of: ``weights`` (N,) positive inverse variances; ``noise_cov`` (N, N) positive definite R;
    ``variance_model`` callable(Φ) -> (N,) variances; ``fgls=True`` with ``variance_regressors`` Z (N, q)
    (default Z = [1, log|Φθ̂|]) for feasible GLS iterated ``n_iter`` times.
    ``scale_cov``: multiply (ΦᵀWΦ)⁻¹ by the weighted residual variance σ̂² = εᵀWε/(N − p); defaults to
    True for relative weights and feasible GLS, False for a given noise_cov / variance_model.
    """
    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    given = sum(x is not None for x in (weights, noise_cov, variance_model)) + bool(fgls)
    if given != 1:
        raise EstimationError("wls: give exactly one of weights, noise_cov, variance_model or fgls=True")
    extra: dict = {}
    if noise_cov is not None:
        r = np.asarray(noise_cov, dtype=float)
        if r.shape != (n, n):
            raise EstimationError(f"noise_cov must be ({n}, {n}), got {r.shape}")
        try:
            chol = np.linalg.cholesky(r)
        except np.linalg.LinAlgError:
            raise EstimationError("noise_cov is not positive definite; expected a symmetric positive-definite "
                                  "noise covariance matrix R") from None
        phi_w = linalg.solve_triangular(chol, phi, lower=True)
        y_w = linalg.solve_triangular(chol, y, lower=True)
        scale_cov = False if scale_cov is None else scale_cov
    else:
        if variance_model is not None:
            var = np.asarray(variance_model(phi), dtype=float).ravel()
            if var.size != n or np.any(~np.isfinite(var)) or np.any(var <= 0):
                raise EstimationError("variance_model must return N strictly positive finite variances")
            w = 1.0 / var
            scale_cov = False if scale_cov is None else scale_cov
        elif fgls:
            w, gamma, hist = _fgls_weights(phi, y, variance_regressors, n_iter)
            extra["variance_params"] = gamma
            extra["fgls_history"] = hist
            scale_cov = True if scale_cov is None else scale_cov
        else:
            w = _check_weights(weights, n)
            scale_cov = True if scale_cov is None else scale_cov
        sw = np.sqrt(w)
        extra["weights"] = w
    if noise_cov is not None:
        theta, g = _solve_whitened(phi_w, y_w)
        resid = y - phi @ theta
        e_w = y_w - phi_w @ theta
    else:  # whitening inside the QR copy: Φ·√w is never stored separately
        theta, g = _solve_whitened(phi, y, sw)
        resid = y - phi @ theta
        e_w = resid * sw  # ε_w = √w·(Y − Φθ̂)
    wsse = float(e_w @ e_w)
    dof = n - p
    sigma2 = wsse / dof if dof > 0 else None
    cov = g * sigma2 if scale_cov else g
    if scale_cov and sigma2 is None:
        cov = None
    extra.update({"weighted_sse": wsse, "sigma2": sigma2, "dof": dof if dof > 0 else None})
    # Gaussian log-likelihood of the whitened model (the weights carry relative/absolute variances)
    if noise_cov is not None:
        logdet = 2.0 * float(np.sum(np.log(np.diag(chol))))
        loglik = -0.5 * (n * np.log(2 * np.pi) + logdet + wsse)
    else:
        s2 = 1.0 if not scale_cov else (wsse / n if wsse > 0 else None)
        loglik = None if s2 is None else float(-0.5 * (n * np.log(2 * np.pi * s2) - np.sum(np.log(w)) + wsse / s2))
    return Estimate(theta=theta, cov=cov, residuals=resid, loglik=loglik, n_params=p, name="wls", extra=extra)


def _fgls_weights(phi, y, z, n_iter):
    from .ls import fit as ls_fit

    est = ls_fit(phi, y)
    hist = [est.theta]
    gamma = None
    w = np.ones(y.size)
    for _ in range(max(1, int(n_iter))):
        e2 = np.maximum(est.residuals ** 2, 1e-300)
        if z is None:
            fitted = np.abs(phi @ est.theta)
            zz = np.column_stack([np.ones(y.size), np.log(np.maximum(fitted, 1e-12))])
        else:
            zz = as_regressors(z, y.size)
        gamma = np.linalg.lstsq(zz, np.log(e2), rcond=None)[0]
        w = np.exp(-(zz @ gamma))
        sw = np.sqrt(w)
        theta, _ = _solve_whitened(phi, y, sw)
        est = type(est)(theta=theta, cov=None, residuals=y - phi @ theta, loglik=None, n_params=phi.shape[1],
                        name="wls")
        hist.append(theta)
    return w, gamma, np.array(hist)


def continuous_fit(func, basis, weight, domain, *, epsabs: float = 1e-13, epsrel: float = 1e-12) -> Estimate:
    """Weighted continuous approximation θ* = argmin ∫_a^b (F(u) − θᵀg(u))² ρ(u) du (Wrocław Example 2.5,
    (2.67)–(2.72)). Normal equations G θ = c with G_ij = ∫ g_i g_j ρ, c_i = ∫ g_i F ρ (scipy quad).
    ``basis`` is a list of callables g_i(u); ``weight`` a callable ρ(u) >= 0 (None = 1)."""
    a, b = map(float, domain)
    if not b > a:
        raise EstimationError(f"domain must be an interval [a, b] with b > a, got {domain}")
    rho = weight if weight is not None else (lambda u: 1.0)
    k = len(basis)
    gram = np.empty((k, k))
    rhs = np.empty(k)
    for i in range(k):
        rhs[i] = integrate.quad(lambda u: basis[i](u) * func(u) * rho(u), a, b, epsabs=epsabs, epsrel=epsrel)[0]
        for j in range(i, k):
            gram[i, j] = gram[j, i] = integrate.quad(lambda u: basis[i](u) * basis[j](u) * rho(u), a, b,
                                                     epsabs=epsabs, epsrel=epsrel)[0]
    if np.linalg.matrix_rank(gram) < k:
        raise EstimationError("basis functions are linearly dependent under the weight; singular Gram matrix")
    theta = np.linalg.solve(gram, rhs)
    crit = integrate.quad(lambda u: (func(u) - sum(t * g(u) for t, g in zip(theta, basis))) ** 2 * rho(u), a, b,
                          epsabs=epsabs, epsrel=epsrel)[0]
    return Estimate(theta=theta, cov=None, residuals=np.array([crit]), loglik=None, n_params=k, name="wls",
                    extra={"gram": gram, "rhs": rhs, "criterion": crit})
