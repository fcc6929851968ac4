"""CUSUM and CUSUM of squares of recursive residuals (Brown, Durbin & Evans 1975), for jumps and drifts.

The output-error residual e of a fitted model is, to first order, ``e ≈ J δ + v`` with J the
Jacobian of the simulated output with respect to the fitted parameters. A parameter that changes
during the record makes δ time-varying; the recursive residuals of e on J,

    w_r = (e_r − x_rᵀ b_{r−1}) / √(1 + x_rᵀ (X_{r−1}ᵀ X_{r−1})⁻¹ x_r),      r = k+1 … T        (BDE eq. 2)

(b_{r−1} the LS coefficients on the first r−1 rows, x_r the r-th row of J) are then not centred
and their cumulative sum

    W_r = Σ_{j=k+1}^{r} w_j / σ̂                                                                 (BDE eq. 7)

leaves the bounds ±a (√(T−k) + 2 (r−k)/√(T−k)); the probability that a Brownian motion crosses
them is 2 [1 − Φ(3a) + exp(−4a²) Φ(a)] (BDE eq. 13: a = 0.948 at 5 %, 1.143 at 1 %). The p-value
is that probability at the smallest a the path touches.

σ̂: BDE use the standard deviation of w. Output-error residuals are autocorrelated even for a
correct structure (coloured noise), which makes the CUSUM wander; σ̂² here is the HAC long-run
variance of w (:func:`stats.long_run_variance`), the usual correction for serial correlation
(Ploberger & Krämer 1992 for the OLS-residual CUSUM; Andrews 1991 for the bandwidth).
The CUSUM sees a change along the mean regressor (an offset that appears or drifts); a change of a
coefficient whose sensitivity oscillates (a stiffness that jumps) cancels in it (Krämer, Ploberger &
Alt 1988). BDE's second statistic, the CUSUM of squares s_r = Σ_{k+1}^{r} w_j² / Σ_{k+1}^{T} w_j²,
sees it: after the change the recursive fit is wrong and the squared residuals grow. With the HAC
long-run variance ω² of w² (Sansó, Aragó & Carrion 2004, κ₂; Inclán & Tiao 1994 for the Gaussian
case ω² = 2σ⁴) the statistic max_r |Σ_{k+1}^{r} (w_j² − mean w²)| / √((T−k) ω²) has the Kolmogorov
distribution (sup of a Brownian bridge) under a constant structure.

The recursion uses the Sherman–Morrison update of (XᵀX)⁻¹ on an orthonormal basis of the Jacobian's
columns and starts after k = max(2p, 1 % of T) rows, solved directly with a nearly diffuse prior.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.stats import norm

from . import stats


@njit(cache=True, nogil=True)
def _recursive(e: np.ndarray, X: np.ndarray, k: int, P: np.ndarray, b: np.ndarray) -> np.ndarray:
    n, p = X.shape
    w = np.empty(n - k)
    Px = np.empty(p)
    for r in range(k, n):
        x = X[r]
        f = 1.0
        pred = 0.0
        for i in range(p):
            s = 0.0
            for j in range(p):
                s += P[i, j] * x[j]
            Px[i] = s
            f += x[i] * s
            pred += x[i] * b[i]
        v = e[r] - pred
        w[r - k] = v / math.sqrt(f)
        for i in range(p):
            b[i] += Px[i] * v / f
        for i in range(p):
            for j in range(p):
                P[i, j] -= Px[i] * Px[j] / f
    return w


def recursive_residuals(e: np.ndarray, X: np.ndarray, k: int | None = None) -> tuple[np.ndarray, int]:
    """Recursive residuals (BDE eq. 2) of e on the columns of X, from row k (default max(2p, 1 % of
    n)); the first k rows are solved by least squares. Columns are scaled to unit norm first (the
    residuals do not depend on the scaling)."""
    e = np.ascontiguousarray(e, float)
    X = np.asarray(X, float).reshape(len(e), -1)
    n = len(e)
    # an orthonormal basis of the column space (the residuals are invariant to an invertible change
    # of the columns; collinear sensitivities are dropped)
    if X.shape[1]:
        Uq, sv, _ = np.linalg.svd(X, full_matrices=False)
        X = np.ascontiguousarray(Uq[:, sv > 1e-10 * sv[0]]) if sv[0] > 0 else np.zeros((n, 0))
    p = X.shape[1]
    if k is None:
        k = max(2 * p, n // 100, 1)
    if p == 0:
        return e[k:].copy(), k
    A = X[:k]
    # a nearly diffuse prior (ridge 1e-9 of the whole record's XᵀX = I) keeps (XᵀX)⁻¹ defined when a
    # sensitivity is still zero at the start (a parameter that acts only later, a limit not yet reached)
    P = np.linalg.inv(A.T @ A + 1e-9 * np.eye(p))
    b = P @ (A.T @ e[:k])
    return _recursive(e, X, k, np.ascontiguousarray(P), b), k


def crossing_probability(a: float) -> float:
    """P(a Brownian motion on [0, 1] crosses a(1 + 2s)), BDE (1975) eq. 13."""
    a = max(float(a), 0.0)
    return float(min(1.0, 2.0 * (norm.sf(3 * a) + math.exp(-4 * a * a) * norm.cdf(a))))


def cusum_test(e: np.ndarray, X: np.ndarray, t: np.ndarray | None = None, alpha: float = 0.01) -> stats.TestResult:
    """BDE CUSUM test of the residual e on the regressors X (the fit's Jacobian). The detail names
    where the cumulative sum is furthest outside (or closest to) its bound."""
    w, k = recursive_residuals(e, X)
    m = len(w)
    if m < 20 or not np.all(np.isfinite(w)):
        return stats.TestResult("cusum", float("nan"), float("nan"), None, True,
                                "not computed: too few samples or a non-finite recursion")
    sd = math.sqrt(max(float(stats.long_run_variance(w[:, None])[0, 0]) / m, 0.0)) or 1.0   # Ω is a sum over rows
    W = np.cumsum(w - 0.0) / sd
    r = np.arange(1, m + 1)
    bound = math.sqrt(m) + 2.0 * r / math.sqrt(m)
    ratio = np.abs(W) / bound
    j = int(np.argmax(ratio))
    a = float(ratio[j])
    p = crossing_probability(a)
    a_crit = _critical(alpha)
    when = f" (sample {k + j}" + (f", t = {float(t[k + j]):.6g} s)" if t is not None else ")")
    return stats.TestResult("cusum", a, p, a_crit, p >= alpha,
                            f"CUSUM of recursive residuals (Brown-Durbin-Evans, HAC scale): furthest "
                            f"{a / a_crit:.2g}x its {100 * alpha:g} % bound{when}")


def _critical(alpha: float) -> float:
    """The a of BDE eq. 13 with crossing probability alpha (bisection)."""
    lo, hi = 0.0, 5.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if crossing_probability(mid) > alpha:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def cusum_squares_test(e: np.ndarray, X: np.ndarray, t: np.ndarray | None = None,
                       alpha: float = 0.01) -> stats.TestResult:
    """CUSUM of squares of the recursive residuals with the HAC scale of the module docstring
    (Sansó, Aragó & Carrion 2004, κ₂); p from the Kolmogorov distribution (scipy ``kstwobign``)."""
    from scipy.stats import kstwobign
    w, k = recursive_residuals(e, X)
    m = len(w)
    if m < 20 or not np.all(np.isfinite(w)):
        return stats.TestResult("cusum_squares", float("nan"), float("nan"), None, True,
                                "not computed: too few samples or a non-finite recursion")
    z = w ** 2
    d = z - z.mean()
    om = float(stats.long_run_variance(d[:, None])[0, 0]) / m
    if om <= 0:
        return stats.TestResult("cusum_squares", 0.0, 1.0, None, True, "constant squared residuals")
    c = np.cumsum(d)
    j = int(np.argmax(np.abs(c)))
    stat = float(abs(c[j]) / math.sqrt(m * om))
    p = float(kstwobign.sf(stat))
    when = f"sample {k + j}" + (f", t = {float(t[k + j]):.6g} s" if t is not None else "")
    grow = "grows" if c[j] < 0 else "falls"
    return stats.TestResult("cusum_squares", stat, p, float(kstwobign.isf(alpha)), p >= alpha,
                            f"CUSUM of squared recursive residuals (HAC scale): the residual variance "
                            f"{grow} after {when}")
