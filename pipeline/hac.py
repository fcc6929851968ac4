"""Long-run (HAC) covariance of a vector series that stays honest when the series is smooth.

Output-error residuals of a slightly wrong model have lag-1 autocorrelation 0.9–0.98, and so do the
score rows g_t = x_t e_t built from them. A Newey–West/Bartlett estimate with a bandwidth of a few dozen
lags then misses most of the long-run variance and tests over-reject. Two published remedies are
combined here:

* **Prewhitening** (Andrews & Monahan 1992, Econometrica 60(4), 953–966): fit a VAR(1)
  g_t = A g_{t−1} + v_t by least squares, estimate the long-run covariance Ω_v of the whitened rows
  v_t, recolour Ω = (I − A)⁻¹ Ω_v (I − A)⁻ᵀ. Andrews & Monahan shrink A by its singular values so
  (I − A) stays invertible; the cap here is :data:`A_CAP`. The least-squares A is biased towards 0 by
  about −(1 + 3ρ)/T for an AR(1) (Kendall 1954; Marriott & Pope 1954); that first-order bias is added
  back to each singular value before the cap, because at ρ ≈ 0.95 and T = 1000 it alone shrinks
  (1 − ρ)⁻² by a fifth.
* **Fixed-b / equal-weighted cosine (EWC) estimator** on the whitened rows (Lazarus, Lewis, Stock &
  Watson 2018, "HAR inference: recommendations for practice", JBES 36(4) 541–559, eq. (8) and §4):
  Ω_v = (1/B) Σ_{j=1}^{B} Λ_j Λ_jᵀ, Λ_j = √(2/T) Σ_t v_t cos(π j (t − ½)/T), with B = ν =
  ⌈0.4 T^{2/3}⌉ degrees of freedom. With this estimator the Wald statistic W over q restrictions is
  referred to F(q, B − q + 1) after scaling W·(B − q + 1)/(B q) (their eq. (11)), a t statistic to
  Student's t_B; the χ² limit would ignore the estimator's own variance.

All covariances are returned on the *sum* scale (≈ gᵀg for white rows, T × the long-run covariance),
like :func:`pipeline.diagnostics.stats.long_run_variance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

A_CAP = 0.99   # largest singular value allowed for the prewhitening VAR(1) matrix


@dataclass
class LongRun:
    """A long-run covariance estimate with the degrees of freedom of its fixed-b reference law."""

    omega: np.ndarray      # (q, q), sum scale
    dof: int               # B of the EWC estimator (Student t_B / F(q, B − q + 1) critical values)
    a: np.ndarray          # the (bias-corrected, capped) prewhitening VAR(1) matrix


def ewc_dof(n: int, rho: float | None = None) -> int:
    """Degrees of freedom ν (= number of cosines B) of the EWC estimator.

    Without ``rho``: ν = ⌈0.4 T^{2/3}⌉ (Lazarus et al. 2018, rule (9)). That rule is the size–power
    optimum ν* ∝ (T/|ω⁽²⁾|)^{2/3} evaluated at their design persistence, an AR(1) with ρ = 0.7, where
    ω⁽²⁾ = 2ρ/(1 − ρ)² is the AR(1) spectral curvature (their eq. (5)). With ``rho`` (a plug-in AR(1)
    coefficient of the rows) the same optimum is rescaled to that persistence,
    ν = 0.4 T^{2/3} (ω⁽²⁾(0.7)/ω⁽²⁾(ρ))^{2/3}, never above the default and never below 4: smooth rows get
    few cosines (the long-run variance is only flat over the lowest frequencies) and the Student/F
    reference with ν degrees of freedom pays for it. Measured on AR(1) residuals up to φ = 0.98 (tests/
    diagnosis/test_mc_calibration.py)."""
    base = max(2, min(n // 2, math.ceil(0.4 * n ** (2.0 / 3.0))))
    if rho is None or rho <= 0.7:
        return int(base)
    rho = min(rho, 0.999)
    curv = lambda r: 2.0 * r / (1.0 - r) ** 2
    nu = round(base * (curv(0.7) / curv(rho)) ** (2.0 / 3.0))
    return int(max(min(4, base), min(base, nu)))


def ar1_pooled(g: np.ndarray) -> float:
    """Pooled lag-1 autocorrelation Σ_a Σ_t g_{t,a} g_{t−1,a} / Σ_a Σ_t g_{t−1,a}², plus the AR(1)
    first-order bias (1 + 3ρ)/N (Kendall 1954); a plug-in for :func:`ewc_dof`."""
    x0, x1 = g[:-1], g[1:]
    den = float(np.sum(x0 * x0))
    if den <= 0 or g.shape[0] < 3:
        return 0.0
    r = float(np.sum(x1 * x0)) / den
    return float(min(r + (1.0 + 3.0 * r) / g.shape[0], 0.999))


def var1(g: np.ndarray, cap: float = A_CAP) -> np.ndarray:
    """Least-squares VAR(1) matrix of the rows of g (N×q, centred by the caller), each singular value
    raised by the AR(1) first-order bias (1 + 3σ)/N (Kendall 1954) and capped at ``cap``
    (Andrews & Monahan 1992, §3: singular-value truncation keeps I − A invertible)."""
    x0, x1 = g[:-1], g[1:]
    n = g.shape[0]
    xx = x0.T @ x0
    if not np.all(np.isfinite(xx)) or np.linalg.matrix_rank(xx) < g.shape[1]:
        return np.zeros((g.shape[1], g.shape[1]))
    a = np.linalg.solve(xx, x0.T @ x1).T          # g_t ≈ a g_{t−1}
    u, s, vt = np.linalg.svd(a)
    s = np.minimum(s + (1.0 + 3.0 * s) / n, cap)
    return (u * s) @ vt


def ewc(v: np.ndarray, dof: int) -> np.ndarray:
    """EWC long-run covariance of the rows of v (N×q) with B = ``dof`` cosines, sum scale
    (Lazarus et al. 2018, eq. (8)): N·(1/B) Σ_j Λ_j Λ_jᵀ."""
    n = v.shape[0]
    t = (np.arange(n) + 0.5) / n
    basis = np.cos(np.pi * np.outer(np.arange(1, dof + 1), t)) * math.sqrt(2.0 / n)   # (B, N)
    lam = basis @ v                                                                  # (B, q)
    return n * (lam.T @ lam) / dof


def long_run(g: np.ndarray, prewhiten: bool = True, dof: int | None = None) -> LongRun:
    """Prewhitened EWC long-run covariance of the rows g_t (N×q) (module docstring). The rows are
    used as given (scores have mean zero at the estimate; they are not centred again). ``dof``: the
    number of cosines; by default :func:`ewc_dof` at the rows' own pooled AR(1) coefficient (tests);
    pass ``ewc_dof(N)`` for a point estimate of a covariance (a standard error)."""
    g = np.atleast_2d(np.asarray(g, float).T).T
    n, q = g.shape
    if dof is None:
        dof = ewc_dof(n, ar1_pooled(g))
    if n < 8:
        return LongRun(g.T @ g, max(1, n - 1), np.zeros((q, q)))
    a = var1(g) if prewhiten else np.zeros((q, q))
    v = g[1:] - g[:-1] @ a.T
    om_v = ewc(v, dof) * n / (n - 1)
    b = np.linalg.inv(np.eye(q) - a)
    return LongRun(b @ om_v @ b.T, dof, a)
