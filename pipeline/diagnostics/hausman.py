"""Specification test of the structure behind a "coloured noise" verdict: output error vs prediction error.

Under a correct structure with coloured (AR) output noise, the output-error estimate θ̂_OE and the
prediction-error estimate θ̂_PEM with the AR noise filter (the ``colored_noise`` refit) are both
consistent, and θ̂_PEM is efficient. Under a structural error they converge to different values: the
AR prefilter A(q) weights the misfit by frequency differently from the plain output error (Ljung 1999
§8.5: the limit of a misspecified prediction-error estimate depends on the noise model). Hausman's
(1978, Econometrica 46(6), 1251–1271) test compares them:

    H = Δᵀ Var(Δ)⁺ Δ ~ χ²_r,   Δ = θ̂_PEM − θ̂_OE (the model's free parameters),

r the rank of Var(Δ) (Moore–Penrose inverse on its positive eigenvalues; Hausman & Taylor 1981).
Var(Δ) is computed under the null, i.e. with the fitted AR(p) noise model e_t = H(q) ε_t, H = 1/A,
var ε = σ², exactly for the two linearised estimators (:func:`covariance_of_difference`). It equals
V_OE − V_PEM asymptotically (Hausman 1978, Lemma 2.1), with V_OE = σ²(JᵀJ)⁻¹(HᵀJ)ᵀ(HᵀJ)(JᵀJ)⁻¹ and
V_PEM = σ²(J̃ᵀJ̃)⁻¹, J̃ = A(q)J (Ljung 1999 eq. 9.18), but unlike that difference of two estimates it is
positive semi-definite in every sample.

A model-based rather than a HAC variance is used on purpose: the residual of a wrong structure is
smooth and a long-run variance estimate then has so few degrees of freedom (ν < 1 on a hysteresis
record) that no test could reject. Under the null the AR model is right and the variance is accurate;
under the alternative only the test's power depends on it.

The row also carries how much the disagreement matters: ``r2`` = 1 − SSE(θ̂_OE)/SSE(θ̂_PEM), the share
of the output-error simulation's error that the PEM parameters add back (≈ 1e-6 on null records,
several % on out-of-vocabulary ones), so the materiality rule of the adequacy tests applies to it.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps
from scipy.signal import lfilter

from .stats import TestResult, _ar_filter

NAME = "oe_pem_hausman"


def _anticausal(J: np.ndarray, a: np.ndarray) -> np.ndarray:
    return lfilter([1.0], np.r_[1.0, -np.asarray(a, float)], J[::-1], axis=0)[::-1]


def covariance_of_difference(J: np.ndarray, a: np.ndarray, s2: float) -> np.ndarray:
    """Var(θ̂_PEM − θ̂_OE) under the null, exactly for the linearised estimators.

    With e = Hε (AR(p) noise started at rest), θ̂_OE − θ = (JᵀJ)⁻¹Jᵀe and θ̂_PEM − θ = (J̃ᵀJ̃)⁻¹J̃ᵀ F e,
    F the prediction-error filter A(q) without its first p rows and J̃ = F J (the refit's whitened
    sensitivities). F H = [0 | I] (A(q)/A(q) = 1 from rest), so Δ = (G₁ − G₂) ε with
    G₁ = [0 | (J̃ᵀJ̃)⁻¹J̃ᵀ] and G₂ = (JᵀJ)⁻¹(HᵀJ)ᵀ, and Var Δ = σ²(G₁ − G₂)(G₁ − G₂)ᵀ: positive
    semi-definite by construction. Asymptotically it is V_OE − V_PEM (Hausman 1978, Lemma 2.1); in
    finite samples that difference of two estimates can be nearly singular and made the test
    over-reject (11.7 % at nominal 5 % on the Monte Carlo records of tests/diagnosis/test_hausman.py)."""
    return covariance_of_difference_multi([J], [np.asarray(a, float)], [s2], [1.0], [1.0])


def covariance_of_difference_multi(Js: list[np.ndarray], As: list[np.ndarray], s2s: list[float],
                                   w_oe: list[float], w_pem: list[float]) -> np.ndarray:
    """Var(θ̂_PEM − θ̂_OE) under the null on several outputs with independent AR noise e_j = H_j ε_j.

    θ̂_OE minimises Σ_j w_j²‖r_j‖², so θ̂_OE − θ = M⁻¹ Σ_j w_j² J_jᵀ e_j, M = Σ_j w_j² J_jᵀJ_j;
    θ̂_PEM minimises Σ_j c_j²‖F_j r_j‖², so θ̂_PEM − θ = M̃⁻¹ Σ_j c_j² J̃_jᵀ [0 | I] ε_j,
    M̃ = Σ_j c_j² J̃_jᵀJ̃_j. With G_j = [0 | M̃⁻¹c_j²J̃_jᵀ] − M⁻¹w_j²(H_jᵀJ_j)ᵀ, Δ = Σ_j G_j ε_j and
    Var Δ = Σ_j σ_j² G_j G_jᵀ (the outputs' innovations independent). One output: exactly
    :func:`covariance_of_difference` (the weights cancel)."""
    Jt = [_ar_filter(J, a) for J, a in zip(Js, As)]
    Mi = np.linalg.pinv(sum(w ** 2 * J.T @ J for J, w in zip(Js, w_oe)))
    Mti = np.linalg.pinv(sum(c ** 2 * J.T @ J for J, c in zip(Jt, w_pem)))
    k = Js[0].shape[1]
    V = np.zeros((k, k))
    for J, a, s2, w, c, jt in zip(Js, As, s2s, w_oe, w_pem, Jt):
        g = -w ** 2 * Mi @ _anticausal(J, a).T
        g[:, len(a):] += c ** 2 * Mti @ jt.T
        V += s2 * g @ g.T
    return V


def oe_pem_hausman(theta_oe: np.ndarray, J, theta_pem: np.ndarray, a, s2, n_free: int, sse_oe: float,
                   sse_pem_sim: float, alpha: float, w_oe: list[float] | None = None,
                   w_pem: list[float] | None = None) -> TestResult:
    """Hausman test of θ̂_OE against θ̂_PEM over the first ``n_free`` quantities (the model's free
    parameters; estimated initial states are left out). ``J``: unweighted output sensitivities of the
    output-error fit (N×k, all k quantities); ``a``, ``s2``: the refit's AR coefficients and
    innovation variance; ``sse_pem_sim``: the estimation-part SSE of the free-run simulation with θ̂_PEM
    (weighted as ``sse_oe`` is). On several outputs ``J``, ``a`` and ``s2`` are lists (one per output,
    ``a`` empty where the output is white) and ``w_oe``/``w_pem`` the outputs' weights in the two fits
    (:func:`covariance_of_difference_multi`)."""
    if not isinstance(J, list):         # one output: the weights cancel
        J, a, s2, w_oe, w_pem = [J], [a], [s2], [1.0], [1.0]
    vd = covariance_of_difference_multi(J, [np.asarray(x, float) for x in a], list(s2), w_oe, w_pem)
    vd = vd[:n_free, :n_free]
    d = np.asarray(theta_pem, float)[:n_free] - np.asarray(theta_oe, float)[:n_free]
    ok = np.isfinite(d) & np.all(np.isfinite(vd), axis=0)
    d, dv = d[ok], vd[np.ix_(ok, ok)]
    share = float(1.0 - sse_oe / sse_pem_sim) if sse_pem_sim > 0 else 0.0
    share = max(share, 0.0)
    if d.size == 0:
        t = TestResult(NAME, 0.0, 1.0, None, True, "no free parameter to compare")
        t.r2 = 0.0
        return t
    lam, Q = np.linalg.eigh(0.5 * (dv + dv.T))
    keep = lam > 1e-8 * max(float(lam.max()), 1e-300)
    r = int(keep.sum())
    stat = float(np.sum((Q[:, keep].T @ d) ** 2 / lam[keep])) if r else 0.0
    p = float(sps.chi2.sf(stat, r)) if r else 1.0
    t = TestResult(NAME, stat, p, float(sps.chi2.isf(alpha, max(r, 1))), p >= alpha,
                   f"Hausman test, output-error vs prediction-error (AR noise) estimates of the free "
                   f"parameters, chi2({r}); the PEM parameters raise the output-error SSE by "
                   f"{100 * share:.2g} %"
                   + ("" if p >= alpha else ": the two estimators disagree, so the residual is not noise "
                      "of a correct structure"))
    t.r2 = share
    return t
