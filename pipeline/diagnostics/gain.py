"""Held-out gain of an extension: 1 − RMSE_after/RMSE_before on the validation free-run residuals,
with a 95 % interval that holds when the residuals are smooth.

Diebold–Mariano-type interval (Diebold & Mariano 1995, JBES 13(3); the loss differential of two
forecasts on the same record, with a long-run variance): the relative gain is a smooth function of
the two mean squared errors, R = 1 − exp(−L), L = ½ ln(m_b/m_a) with m_b, m_a the means of the squared
before/after residuals (summed over outputs). By the delta method L̂ − L ≈ (1/N) Σ_t h_t,
h_t = ½((b_t² − m_b)/m_b − (a_t² − m_a)/m_a), so se(L̂) = √Ω_h / N with Ω_h the long-run variance of
h_t (sum scale) from the prewhitened equal-weighted-cosine estimator (:mod:`pipeline.hac`; Andrews &
Monahan 1992; Lazarus, Lewis, Stock & Watson 2018), whose Satterthwaite degrees of freedom ν include
the uncertainty of the prewhitening coefficient (few when the residuals are smooth). The interval
L̂ ± t_{ν, 0.975} se is mapped through R = 1 − exp(−L): R is monotone in L, so the interval brackets
the reported ``relative`` and never exceeds 1. The moving-block bootstrap it replaces (blocks of ⌈√N⌉)
covered 91 % / 89 % / 76 % at residual AR(1) φ = 0 / 0.9 / 0.98 (N = 1000, 1000 records;
this interval: 93.8 % / 94.2 % / 95.2 %).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as sps

from .. import hac

L_CLIP = math.log(100.0)
CI_MEANING = ("for this validation input: the interval is the sampling uncertainty of the noise on the "
              "validation record; a different input (other amplitudes, other frequencies) can give a "
              "different gain")


def _ratio_interval(num: np.ndarray, den: np.ndarray, level: float = 0.95) -> tuple[float, float, int]:
    """Interval of L = ½ ln(mean(den)/mean(num)) (module docstring), and the ν used."""
    mb, ma = float(np.mean(den)), float(np.mean(num))
    n = len(num)
    L = 0.5 * math.log(mb / ma)
    h = 0.5 * ((den - mb) / mb - (num - ma) / ma)
    lr = hac.long_run(h[:, None])
    se = math.sqrt(max(float(lr.omega[0, 0]), 0.0)) / n
    t = float(sps.t.ppf(0.5 + level / 2, lr.dof))
    return L - t * se, L + t * se, lr.dof


def gain_ci(before: np.ndarray, after: np.ndarray, rng: np.random.Generator | None = None,
            n_boot: int | None = None) -> dict:
    """Relative gain 1 − RMSE_after/RMSE_before of validation residuals (N×ny) with its 95 % interval
    (module docstring). ``rng`` and ``n_boot`` are accepted for the old bootstrap's call signature and
    not used: the interval is analytic and deterministic."""
    # mean over outputs: ``before``/``after`` are then the RMSE over all residuals (the summary's rmse_sim)
    b2 = np.mean(np.atleast_2d(before.T).T ** 2, axis=1)
    a2 = np.mean(np.atleast_2d(after.T).T ** 2, axis=1)
    rb, ra = math.sqrt(float(np.mean(b2))), math.sqrt(float(np.mean(a2)))
    rel = 1.0 - ra / rb if rb > 0 else 0.0
    if rb <= 0 or ra <= 0 or len(b2) < 8:
        ci = [rel, rel] if ra > 0 or rb <= 0 else [rel, 1.0]
        return {"metric": "validation_rmse_sim", "before": rb, "after": ra, "relative": rel, "ci95": ci,
                "bootstrap": {"method": "none (degenerate residuals)", "block": None, "n": len(b2)}}
    lo, hi, dof = _ratio_interval(a2, b2)
    # L is clipped to ±ln 100: a bound at an RMSE ratio of 100 (relative gain −99 or 0.99) says that this
    # record cannot bound the gain on that side (the residuals are too smooth: few degrees of freedom)
    lo, hi = max(lo, -L_CLIP), min(hi, L_CLIP)
    ci = [float(min(-math.expm1(-lo), rel)), float(max(-math.expm1(-hi), rel))]
    return {"metric": "validation_rmse_sim", "before": rb, "after": ra, "relative": rel, "ci95": ci,
            "ci95_meaning": CI_MEANING,
            "bootstrap": {"method": "delta method, prewhitened EWC long-run variance, Student t (Diebold-Mariano type)",
                          "block": None, "dof": dof, "n": len(b2)}}


def mean_interval(d: np.ndarray, base: np.ndarray | None = None, level: float = 0.95) -> list[float]:
    """95 % interval of mean(d), or with ``base`` of mean(d)/|mean(base)| (the same samples), by the
    delta method with the prewhitened EWC long-run variance and Student t_ν (Diebold & Mariano 1995;
    Lazarus et al. 2018). For the ratio r = m_d/|m_b|: r̂ − r ≈ (1/N) Σ_t ((d_t − m_d) − r (b_t − m_b))/|m_b|."""
    d = np.asarray(d, float)
    n = len(d)
    md = float(np.mean(d))
    if base is None:
        h, est, scale = d - md, md, 1.0
    else:
        mb = float(np.mean(base))
        est = md / abs(mb)
        h, scale = (d - md) - est * np.sign(mb) * (np.asarray(base, float) - mb), 1.0 / abs(mb)
    if n < 8:
        return [est, est]
    lr = hac.long_run(h[:, None])
    se = scale * math.sqrt(max(float(lr.omega[0, 0]), 0.0)) / n
    t = float(sps.t.ppf(0.5 + level / 2, lr.dof))
    return [float(est - t * se), float(est + t * se)]
