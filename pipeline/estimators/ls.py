"""Ordinary least squares, identifiability and exact determination.

* LS: θ̂ = argmin ‖Y − Φθ‖², solved by QR (Johansson (5.5)–(5.10); Wrocław (2.73)–(2.81) with the
  corrected (ΣφφT)⁻¹ of misprint 10). Covariance σ̂²(ΦᵀΦ)⁻¹ with σ̂² = SSE/(N − p) (Johansson (5.36),
  and 11.3 with the corrected factor: σ̂² = εᵀε/(N − p)).
* Rank deficiency: numerical rank from the SVD (tolerance max(N, p)·eps·s_max) of the triangular factor R
  of [Φ | Y] (same singular values and right singular vectors as Φ; the SVD of Φ itself only for
  rank-deficient or borderline Φ); the null-space basis
  (the non-identifiable parameter directions) is reported; the minimum-norm solution
  θ̂ = (ΦᵀΦ)⁺ΦᵀY = Φ⁺Y (Johansson 5.2, (5.13)–(5.16)) is returned only with ``min_norm=True``.
* Identifiability of the noise-free static MIMO characteristic y = Θu: det(U_N) ≠ 0 and the exact
  solution Θ = Y_N U_N⁻¹ (Wrocław Example 2.1, (2.12)–(2.16); Example 2.2, (2.29)).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from .base import (Estimate, EstimationError, as_regressors, as_target, augmented_r, gaussian_loglik,
                   numerical_rank)

#: relative tolerance for det(U_N) = 0: |det U| <= DET_RTOL · Π‖u_i‖ (Hadamard bound of |det U|).
DET_RTOL = 1e-10


def _format_dirs(null: np.ndarray) -> str:
    cols = []
    for k in range(null.shape[1]):
        v = null[:, k]
        v = v / v[np.argmax(np.abs(v))]
        v = np.where(np.abs(v) < 1e-10, 0.0, v)
        cols.append("[" + ", ".join(f"{c:.4g}" for c in v) + "]")
    return "; ".join(cols)


#: the R-based rank decision is handed to the SVD of Φ itself when s_min(R) is within this factor of
#: the tolerance (R and Φ have the same singular values only up to rounding, ~eps·s_max).
RANK_MARGIN = 4.0


def fit(regressors, target, *, min_norm: bool = False, rtol: float | None = None) -> Estimate:
    """Least squares (Johansson (5.5)–(5.10), covariance (5.36)); minimum-norm solution (Johansson 5.2,
    θ̂ = Φ⁺Y) when ``min_norm=True`` and Φ is rank deficient.

    ``rtol`` overrides the relative SVD tolerance of the numerical rank (default max(N, p)·eps).

    Full-rank path: one Householder QR of the augmented matrix [Φ | Y] = Q [[R11, r12], [0, r22]]
    keeping only R (:func:`~pipeline.estimators.base.augmented_r`); rank, singular values and null space
    from the SVD of the p×p factor R11 (ΦᵀΦ = R11ᵀR11, so Φ and R11 have the same singular values and
    right singular vectors), θ̂ = R11⁻¹r12 (Johansson (5.10) with QᵀY = [r12; r22]), SSE = r22² = ‖Y − Φθ̂‖²
    and (ΦᵀΦ)⁻¹ = R11⁻¹R11⁻ᵀ. A rank-deficient (or borderline, s_min(R11) <= 4·tol) Φ, and N <= p,
    take the SVD of Φ itself as before (error message with the non-identifiable directions, or Φ⁺Y).
    """
    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    r = None
    if n > p:
        r = augmented_r(phi, y)
        rank, s, v, tol = numerical_rank(r[:p, :p], rtol, n_rows=n)
        if rank < p or s[-1] <= RANK_MARGIN * tol:
            r = None  # rank deficient or borderline: decide on the SVD of Φ itself
    if r is None:
        rank, s, v, tol = numerical_rank(phi, rtol)
    null = v[:, rank:]
    extra = {"rank": rank, "singular_values": s, "rank_tol": tol, "null_space": null}
    if rank < p:
        if not min_norm:
            raise EstimationError(
                f"singular regressors: numerical rank {rank} < {p} parameters (N = {n}, SVD tolerance {tol:.3g}); "
                f"non-identifiable parameter direction(s) {_format_dirs(null)}; expected full column rank, "
                "or pass min_norm=True for the minimum-norm (pseudo-inverse) solution")
        pinv = np.linalg.pinv(phi, rcond=rtol if rtol is not None else max(n, p) * np.finfo(float).eps)
        theta = pinv @ y
        gram_pinv = pinv @ pinv.T  # (ΦᵀΦ)⁺
        extra["min_norm"] = True
    else:
        if r is None:  # full rank but decided on the SVD of Φ (borderline, or N == p)
            r = augmented_r(phi, y)
        r11 = r[:p, :p]
        theta = solve_triangular(r11, r[:p, p])  # θ̂ = R11⁻¹ (QᵀY)[:p]
        rinv = solve_triangular(r11, np.eye(p))
        gram_pinv = rinv @ rinv.T  # (ΦᵀΦ)⁻¹ = R11⁻¹R11⁻ᵀ
        extra["min_norm"] = False
    resid = y - phi @ theta
    sse = float(resid @ resid)  # = r22² on the full-rank path (up to rounding)
    dof = n - rank
    extra["pinv_gram"] = gram_pinv
    extra["sse"] = sse
    if dof > 0:
        sigma2 = sse / dof
        cov = sigma2 * gram_pinv
        extra["sigma2"] = sigma2
        extra["dof"] = dof
    else:
        cov = None
        extra["sigma2"] = None
        extra["dof"] = 0
    return Estimate(theta=theta, cov=cov, residuals=resid, loglik=gaussian_loglik(resid), n_params=rank,
                    name="ls", extra=extra)


def _as_columns(u) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    return u[None, :] if u.ndim == 1 else u


def identifiability(inputs, rtol: float = DET_RTOL) -> tuple[bool, float]:
    """det(U_N) test of Wrocław Example 2.1 ((2.12)–(2.14)). ``inputs`` is the square R×N matrix whose
    columns are the (basis-transformed) input vectors of the chosen measurements. Returns
    (identifiable, det U_N); det counts as zero when |det| <= rtol·Π‖columns‖."""
    u = _as_columns(inputs)
    if u.shape[0] != u.shape[1]:
        raise EstimationError(f"U_N must be square (R inputs × N = R measurements), got shape {u.shape}")
    det = float(np.linalg.det(u))
    scale = float(np.prod(np.linalg.norm(u, axis=0))) or 1.0
    return abs(det) > rtol * scale, det


def exact_determination(inputs, outputs, rtol: float = DET_RTOL) -> np.ndarray:
    """Noise-free exact determination Θ = Y_N U_N⁻¹ (Wrocław (2.16); for a scalar output with basis
    functions, θᵀ = Y_N [f̄(U_N)]⁻¹, Wrocław (2.29)). Columns of ``inputs``/``outputs`` are measurements."""
    u = _as_columns(inputs)
    yv = _as_columns(outputs)
    ok, det = identifiability(u, rtol)
    if not ok:
        raise EstimationError(f"parameters not identifiable from these measurements: det(U_N) = {det:.3g} "
                              "(expected det(U_N) != 0; choose measurements with linearly independent inputs)")
    if yv.shape[1] != u.shape[1]:
        raise EstimationError(f"Y_N has {yv.shape[1]} measurements but U_N has {u.shape[1]}; expected equal")
    return np.linalg.solve(u.T, yv.T).T


def augmented_inverse(regressors) -> np.ndarray:
    """Inverse of the augmented LS system [[I, Φ], [Φᵀ, 0]] in closed form (Johansson (5.85)):
    [[I − P, Φ(ΦᵀΦ)⁻¹], [(ΦᵀΦ)⁻¹Φᵀ, −(ΦᵀΦ)⁻¹]] with P = Φ(ΦᵀΦ)⁻¹Φᵀ."""
    phi = as_regressors(regressors)
    n, p = phi.shape
    rank = numerical_rank(phi)[0]
    if rank < p:
        raise EstimationError(f"singular regressors: rank {rank} < {p}; the augmented system has no inverse")
    g = np.linalg.inv(phi.T @ phi)
    proj = phi @ g @ phi.T
    top = np.hstack([np.eye(n) - proj, phi @ g])
    bottom = np.hstack([g @ phi.T, -g])
    return np.vstack([top, bottom])
