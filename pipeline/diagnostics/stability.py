"""Do the fitted parameters stay constant over the record? A trigonometric test of time dependence.

A parameter that varies smoothly during the record, θ_j(t) = θ̂_j + δ_j(t), leaves to first order the
output-error residual

    e_t ≈ J_t δ + Σ_j J_{t,j} δ_j(t) + v_t,       J = ∂e/∂θ at θ̂,

so δ_j(t) shows as the residual following the parameter's own sensitivity multiplied by a function of
time. Becker, Enders & Hurn (2004, *A general test for time dependence in parameters*, J. Applied
Econometrics 19(7), 899–906) approximate δ_j(t) by one Fourier frequency,
δ_j(t) ≈ a_j sin(2πks) + b_j cos(2πks) with s = t/T, and test a_j = b_j = 0 for all j by the added
regressors J_{t,j}·sin(2πks), J_{t,j}·cos(2πks); a single low frequency already has power against
breaks, drifts and smooth cycles, and the statistic is taken over k = 1 … K. Here each k is the HAC
Wald test of those 2p columns beyond J (:func:`stats.added_terms_test`: feasible GLS and fixed-b, so
its size holds under the autocorrelated residual of an output-error fit) and the p-value over k is
Bonferroni's, K·min_k p_k (Becker et al. take the supremum with simulated critical values; the
Bonferroni bound is conservative and needs no table).

Why a row of its own: a stiffness that breathes with a supply or temperature ripple, −k(1 + a sin ωt)x,
is neither a step (``parameter_jump``) nor a straight line (``parameter_drift``) nor a forcing
independent of the state (``periodic_disturbance``), and its residual is smooth: on 36 records of the
independent bench (solve_ivp, 2 % white noise) half were taken for coloured noise. Such a residual
contradicts the coloured-noise explanation, in which the model's parameters are constant.

Only the model's free parameters are tested (not the initial states, whose sensitivities decay).
The row names the parameter whose pair of columns has the largest Wald statistic at the best k, and
its amplitude ‖(a_j, b_j)‖ from the coefficients (the swing of the best single-frequency fit: a
variation that is not a whole number of cycles leaks to the other frequencies and reads smaller; on
the independent bench's stiffness ripples, 2.1 cycles in the estimation part, 0.4–1.1 of the true
swing, and the parameter named right on all 7 records checked): with e the unweighted residual and J the Jacobian of
the residual weighted by w = 1/std(y) (:meth:`pipeline.fit.Problem.weights`), e ≈ −(J/w)·δ, so
δ_j's amplitude is w·‖β_j‖.

Cost: each frequency is an added-terms test with 2p columns, whose fixed-b degrees of freedom take
one cosine transform of the record per column and regressor (:func:`pipeline.hac.design_terms`). On
Silverbox (90 000 estimation samples) that was over a second per frequency. Longer than
``ROWS_MAX`` samples, the regression e_t = S_t β + v_t is therefore run on every m-th row,
m = ⌈n / ROWS_MAX⌉: it holds on any subset of rows, so the test stays valid and only loses the
information of the rows left out, and a variation of at most five cycles per record is slow beside
any such stride.
"""

from __future__ import annotations

import numpy as np

from . import stats

K_MAX = 5          # frequencies 1 … 5 cycles per estimation record (Becker et al. 2004 use k ≤ 5)
ROWS_MAX = 5_000   # longer estimation parts are tested on every m-th sample (module docstring)


def free_columns(names: list[str]) -> list[int]:
    """The Jacobian columns of the fit's free parameters (not ``x0.<state>``)."""
    return [k for k, nm in enumerate(names) if not nm.startswith("x0.")]


def parameter_stability_test(fit, i: int, weight: float, alpha: float, k_max: int = K_MAX) -> stats.TestResult | None:
    """The trigonometric time-dependence test (module docstring) on the residual of output i of
    ``fit`` (estimation part); ``weight``: that output's residual weight in the fit. None when the
    fit has no free parameter or too few samples for 2p columns at each frequency."""
    ny = fit.resid_est.shape[1]
    e = fit.resid_est[:, i]
    if fit.jac is None or not fit.jac.size:
        return None
    J = fit.jac[i::ny]
    free = free_columns(list(fit.names))
    n = len(e)
    if not free or n < 20 * (2 * len(free) + J.shape[1]):
        return None
    s = (np.arange(n) + 0.5) / n
    if n > ROWS_MAX:
        rows = np.arange(0, n, -(-n // ROWS_MAX))
        e, J, s = e[rows], J[rows], s[rows]
    best = None
    for k in range(1, k_max + 1):
        sn, cs = np.sin(2 * np.pi * k * s), np.cos(2 * np.pi * k * s)
        S = np.column_stack([J[:, j] * w for j in free for w in (sn, cs)])
        r = stats.added_terms_test(e, J, S)
        if best is None or r.p_value < best[1].p_value:
            best = (k, r)
    k, r = best
    p = float(min(1.0, k_max * r.p_value))
    # which parameter: the largest Wald statistic of its own pair of columns at the best frequency
    wald = []
    for m in range(len(free)):
        b = r.beta[2 * m:2 * m + 2]
        V = r.cov[2 * m:2 * m + 2, 2 * m:2 * m + 2]
        try:
            wald.append(float(b @ np.linalg.solve(V, b)))
        except np.linalg.LinAlgError:
            wald.append(0.0)
    m = int(np.argmax(wald))
    name = fit.names[free[m]]
    amp = weight * float(np.hypot(*r.beta[2 * m:2 * m + 2]))
    theta = float(fit.theta[free[m]])
    rel = f" (±{100 * amp / abs(theta):.2g} % of {theta:.4g})" if theta != 0 else ""
    t = stats.TestResult(
        "parameter_stability", r.statistic, p, None, p >= alpha,
        f"trigonometric test of time-varying parameters (Becker, Enders & Hurn 2004: each parameter's "
        f"sensitivity times sin and cos of k cycles per estimation record, k = 1..{k_max}, HAC Wald, "
        f"Bonferroni over k); strongest at {k} cycle{'s' if k > 1 else ''}, where the terms explain "
        f"{100 * r.r2:.2g} % of the residual; most of it in {name}, whose best single-frequency "
        f"variation swings by ±{amp:.3g}{rel}")
    t.r2 = r.r2
    return t
