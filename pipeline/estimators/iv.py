"""Instrumental variables and Yule–Walker.

* IV: θ̂ = (ZᵀΦ)⁻¹ZᵀY (Johansson 6.6–6.8, (6.54)–(6.58)); with more instruments than parameters the
  generalised (two-stage) form θ̂ = (ΦᵀZ(ZᵀZ)⁻¹ZᵀΦ)⁻¹ΦᵀZ(ZᵀZ)⁻¹ZᵀY.
  Covariance Cov θ̂ = P Σ Pᵀ with P = (ZᵀΦ)⁻¹Zᵀ (Johansson (6.66)); Σ = σ̂²I for white equation error,
  or a banded Toeplitz Σ from the residual autocovariances up to ``ma_lags`` (MA noise as in 5.11/6.1);
  evaluated from q×q cross-moments of Z only (see :func:`fit`), never with the p×N matrix P.
* Instruments from delayed inputs z_k = [u_{k−d1}, u_{k−d2}, ...]: uncorrelated with the equation error
  when u is open-loop, which removes the coloured-noise bias of LS (Johansson 5.11, 6.1, (6.36)).
* Yule–Walker for the closed-loop ARMA(1,1) y_{k+1} = −α y_k + w_{k+1} + c w_k (α = a + bK):
  α = −C(2)/C(1), cσ² = C(1) + α C(0) (Johansson 8.8, (8.26)–(8.33), misprint 38 corrected);
  equivalently IV with the delayed output y_{k−1} as instrument.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

from .base import Estimate, EstimationError, as_regressors, as_target, numerical_rank


def delayed(signal, delays, n_rows: int | None = None) -> np.ndarray:
    """Matrix Z with Z[k, j] = signal[k − delays[j]] (NaN where k − d < 0)."""
    s = np.asarray(signal, dtype=float).ravel()
    n = s.size if n_rows is None else n_rows
    z = np.full((n, len(delays)), np.nan)
    for j, d in enumerate(delays):
        d = int(d)
        if d < 0:
            raise EstimationError(f"instrument delays must be >= 0, got {d}")
        z[d:, j] = s[: n - d]
    return z


def fit(regressors, target, *, instruments=None, inputs=None, delays=None, ma_lags: int = 0) -> Estimate:
    """IV estimate θ̂ = (ZᵀΦ)⁻¹ZᵀY (Johansson (6.54)–(6.58)) with covariance P Σ Pᵀ (Johansson (6.66)).

    Either ``instruments`` Z (N, q >= p), or ``inputs`` u aligned with the target rows and ``delays``
    (instrument z_k = [u_{k−d} for d in delays]; rows without enough history are dropped).

    Only the cross-moments ZᵀZ, ZᵀΦ, ZᵀY (and, for ``ma_lags`` L > 0, the lagged Z[:N−l]ᵀZ[l:]) are
    formed; the p×N matrix P = B Zᵀ is never built. With B = (ZᵀΦ)⁻¹ (q = p) or B = A⁻¹ΦᵀZ(ZᵀZ)⁻¹,
    A = ΦᵀZ(ZᵀZ)⁻¹ZᵀΦ (q > p, two-stage form): θ̂ = B ZᵀY and (6.66) with the banded Toeplitz
    Σ = Σ_l γ_l S_l (S_l: ones on the ±l-th diagonals) reads

        Cov θ̂ = P Σ Pᵀ = B [γ_0 ZᵀZ + Σ_{l=1..L} γ_l (G_l + G_lᵀ)] Bᵀ,  G_l = Z[:N−l]ᵀ Z[l:].

    Special case L = 0 (white equation error, Σ = σ̂²I): Cov θ̂ = σ̂² P Pᵀ = σ̂² B ZᵀZ Bᵀ, i.e.
    σ̂²(ZᵀΦ)⁻¹ZᵀZ(ΦᵀZ)⁻¹ for q = p and σ̂² A⁻¹ for q > p (B ZᵀZ Bᵀ = A⁻¹ΦᵀZ(ZᵀZ)⁻¹ZᵀZ(ZᵀZ)⁻¹ZᵀΦA⁻¹ = A⁻¹).
    """
    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    if instruments is None:
        if inputs is None or delays is None:
            raise EstimationError("iv: give either instruments Z or inputs u with delays")
        z = delayed(inputs, delays, n)
    else:
        z = np.asarray(instruments, dtype=float)
        if z.ndim == 1:
            z = z[:, None]
        if z.shape[0] != n:
            raise EstimationError(f"instruments have {z.shape[0]} rows but the target has {n}; expected equal")
    finite = np.isfinite(z)
    if finite.all():  # no row dropped: no copies of Φ, Y, Z
        keep = np.ones(n, dtype=bool)
    else:
        keep = finite.all(axis=1)
        phi, y, z = phi[keep], y[keep], z[keep]
    del finite
    n = y.size
    q = z.shape[1]
    if q < p:
        raise EstimationError(f"need at least as many instruments as parameters: {q} instruments < {p}")
    zp = z.T @ phi  # ZᵀΦ (q×p)
    if numerical_rank(zp)[0] < p:
        raise EstimationError("singular instrument cross-moment ZᵀΦ (instruments uncorrelated with the regressors "
                              "or linearly dependent); expected full rank ZᵀΦ")
    zz = z.T @ z  # ZᵀZ (q×q, BLAS syrk)
    zy = z.T @ y
    if q == p:
        b = np.linalg.inv(zp)  # B = (ZᵀΦ)⁻¹, P = B Zᵀ
        theta = np.linalg.solve(zp, zy)
        a_inv = None
    else:
        try:
            cf = linalg.cho_factor(zz)
        except np.linalg.LinAlgError:
            raise EstimationError("singular instrument moment ZᵀZ (linearly dependent instruments); expected "
                                  "linearly independent instruments") from None
        m = linalg.cho_solve(cf, zp).T  # M = ΦᵀZ(ZᵀZ)⁻¹ (p×q)
        a = m @ zp  # A = ΦᵀZ(ZᵀZ)⁻¹ZᵀΦ (p×p, symmetric)
        theta = np.linalg.solve(a, m @ zy)
        a_inv = np.linalg.inv(a)
        a_inv = 0.5 * (a_inv + a_inv.T)
        b = a_inv @ m  # B = A⁻¹M, P = B Zᵀ
    resid = y - phi @ theta
    dof = n - p
    lags = int(ma_lags)
    gam = np.array([resid[: n - l] @ resid[l:] / dof for l in range(lags + 1)])
    if lags == 0 and a_inv is not None:
        cov = gam[0] * a_inv  # σ̂²A⁻¹
    else:
        mid = gam[0] * zz
        for l in range(1, lags + 1):
            g = z[: n - l].T @ z[l:]  # G_l = Z[:N−l]ᵀZ[l:]
            mid += gam[l] * (g + g.T)
        cov = b @ mid @ b.T
        cov = 0.5 * (cov + cov.T)
    extra = {"sigma2": float(gam[0]), "noise_autocov": gam, "n_used": n, "dof": dof, "rows_kept": keep}
    return Estimate(theta=theta, cov=cov, residuals=resid, loglik=None, n_params=p, name="iv", extra=extra)


def autocov(y, max_lag: int) -> np.ndarray:
    """Sample autocovariances C(τ) = (1/N) Σ y_{k+τ} y_k, τ = 0..max_lag (zero-mean signal)."""
    y = np.asarray(y, dtype=float).ravel()
    n = y.size
    return np.array([y[tau:] @ y[: n - tau] / n for tau in range(max_lag + 1)])


def yule_walker_arma11(y) -> dict:
    """Closed-loop Yule–Walker (Johansson 8.8, (8.26)–(8.33)): α = a + bK = −C(2)/C(1),
    cσ² = C(1) + α C(0) (misprint 38: right-hand side C(1), not C(0))."""
    c = autocov(y, 2)
    if abs(c[1]) < 1e-12 * max(c[0], 1e-300):
        raise EstimationError("Yule–Walker: C(1) is zero, so a + bK is not identifiable from C(1), C(2)")
    alpha = -c[2] / c[1]
    return {"alpha": float(alpha), "c_sigma2": float(c[1] + alpha * c[0]), "C": c}
