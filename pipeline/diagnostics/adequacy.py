"""Is the (final) model structurally adequate, and where does it fail?

Adequacy tests on the estimation residual of every output against every input (each returns a
:class:`TestResult`; ``passed`` is p ≥ α with a Bonferroni level over the input–output pairs):

* ``input_crosscorrelation``: MATLAB ``resid``'s test for a coloured input (see :mod:`.stats`);
* ``model_error_model``: the residual regressed on ``FIR_ORDER`` lagged inputs (the model-error model of
  Ljung 1999 §16.6, MATLAB ``resid(...,'fr')``), a HAC Wald test that all FIR coefficients are zero
  (Newey–West with Andrews' bandwidth, :func:`stats.added_terms_test`): an output-error residual of a
  correct structure holds no input dynamics, whatever its colour;
* ``input_direction``: the residual regressed on the model's own response to an input perturbation
  proportional to the direction of the input's last change, d_t = sign(u_t − u_s) at the last s < t
  with u_s ≠ u_t (:func:`input_direction_test`). A play (backlash) of width w in the actuator makes the
  applied input u − (w/2)·d_t once the play is taken up (Tao & Kokotović 1996, *Adaptive Control of
  Systems with Actuator and Sensor Nonlinearities*, Wiley, §2.2, eq. 2.7), and rate-independent
  hysteresis on the input adds a term of the same sign pattern; neither is a linear function of the
  input, so the model-error model above cannot see it, and the residual it leaves is smooth and
  easily taken for coloured noise;
* ``input_rate``: the same for an input term following the signed square of the input's increments,
  r_t = Δu_t·|Δu_t| (:func:`rate_signal`). A rate (slew) limit R in the actuator turns a held step of
  size Δu into a ramp of length |Δu|/R, so the input the plant misses is a pulse of area
  Δu·|Δu|/(2R) after each change: quadratic in the step, which a delay or a lag (linear in the input)
  cannot follow. Fitted with a delay, a lag or nothing, such a record's residual was taken for
  coloured noise or left a delay named as the cause (an independent-bench generator with a slew
  limit, 2 % white noise: 9 of 54 records named a delay or a lag as the whole explanation, 4 more
  coloured noise). Not for
  an input whose changes all have one size (a two-level PRBS): r_t is then a multiple of Δu_t, and
  a rate limit is exactly a fixed input shaping, which the families ``input_delay`` and
  ``unmodeled_dynamics`` test;
* ``input_coherence``: the magnitude-squared coherence of residual and input at every frequency the
  input excites, against its exact null Beta(1, K − 1) (:mod:`.coherence`): a missing lightly damped
  mode leaves input dynamics at lags far beyond the first two tests' 25 and 15;
* ``parameter_stability`` (one per output, :mod:`.stability`): the residual regressed on each free
  parameter's sensitivity times sin and cos of k cycles per estimation record (Becker, Enders & Hurn
  2004), k = 1…5: a parameter that varies during the record (a stiffness breathing with a ripple),
  which leaves a smooth residual no input term and no noise model explains.

The engine adds ``state_nonlinearity`` (:mod:`.state_probe`: Gaussian bumps of each state, tested
with the hypotheses' sensitivity machinery), ``state_nonlinearity_refit`` (those bumps refitted and
judged on the validation part, before the noise families may explain a coloured residual:
``engine.Diagnoser.probe_refit``), ``structural_wald`` (the families' added-term tests on
the final model) and, when the loop needed two static forms of one state in one equation,
``nonlinearity_form`` (:mod:`.form`) to these rows. A model that fails them has a structural error; when no family's extension removes it the verdict is
``unexplained_discrepancy`` (contract §3), never "no discrepancy", and the noise families are not tested
(an AR noise model beats white noise on any misfit). :func:`where_it_fails` says where: the lags and
frequencies of the residual–input dependence, the amplitude range and the time window with the
largest error.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.stats import chi2, norm

from ..fit import excited_inputs, simulate_until
from . import stats
from .coherence import input_coherence
from .stability import parameter_stability_test

FIR_ORDER = 15
# per input-output pair: cross-correlation, model-error model, input direction, input rate, coherence
N_TESTS = 5
# a significant test fails adequacy only when the dependence it finds is material: it explains at least
# this share of the residual's sum of squares (with N in the thousands, a 0.1 % misfit is significant)
MATERIAL_R2 = 0.02


def material(t: stats.TestResult) -> bool:
    """Does this failed adequacy row describe a dependence worth a verdict (see MATERIAL_R2)?"""
    return (not t.passed) and getattr(t, "r2", 1.0) >= MATERIAL_R2


def structurally_adequate(tests: list[stats.TestResult]) -> bool:
    return not any(material(t) for t in tests)


def model_error_model(e: np.ndarray, u: np.ndarray, alpha: float, order: int = FIR_ORDER) -> stats.TestResult:
    n = len(e)
    order = max(2, min(order, n // 20))
    uc = u - u.mean()
    Phi = np.column_stack([uc[order - 1 - j:n - j] for j in range(order)])
    # a smooth input makes its lags nearly collinear: test on the well-determined directions only
    Uo, sv, Vt = np.linalg.svd(Phi, full_matrices=False)
    keep = sv > 1e-6 * sv[0]
    Z = Uo[:, keep]
    ee = e[order - 1:] - e[order - 1:].mean()
    w = stats.added_terms_test(ee, np.zeros((len(ee), 0)), Z)
    b = Vt[keep].T @ (w.beta / sv[keep])
    f = np.fft.rfftfreq(256)
    G = np.abs(np.exp(-2j * np.pi * f[:, None] * np.arange(order)[None, :]) @ b)
    peak = float(f[int(np.argmax(G))])
    q = int(keep.sum())
    t = stats.TestResult("model_error_model", w.statistic, w.p_value, float(chi2.isf(alpha, q)),
                         w.p_value >= alpha,
                         f"HAC Wald test of an FIR({order}) from the input to the residual ({q} well-determined "
                         f"directions; it explains {100 * w.r2:.2g} % of the residual); its gain peaks at "
                         f"{peak:.3g} cycles/sample")
    t.r2 = w.r2
    return t


def direction_signal(u: np.ndarray) -> np.ndarray:
    """d_t = sign of the input's last change before or at t (+1 rising, −1 falling; 0 before its first
    change, where the direction is unknown); changes smaller than 1e-9 of its range are no change."""
    du = np.diff(u, prepend=u[0])
    tol = 1e-9 * (float(np.ptp(u)) or 1.0)
    s = np.where(du > tol, 1.0, np.where(du < -tol, -1.0, 0.0))
    idx = np.where(s != 0, np.arange(len(s)), 0)
    np.maximum.accumulate(idx, out=idx)
    return s[idx]


DIRECTION_MIN_SWITCHES = 4


def rate_signal(u: np.ndarray) -> np.ndarray:
    """r_t = Δu_t·|Δu_t|, Δu_t = u_t − u_{t−1} (0 at the first sample): the signed square of the input's
    increments, the pulse area a rate limit removes after each change, up to the factor 1/(2R)."""
    du = np.diff(u, prepend=u[0])
    return du * np.abs(du)


def input_direction_sensitivity(fit, prob, j: int, base: np.ndarray | None = None) -> np.ndarray | None:
    """(n_est, ny) response of the fitted simulation to the perturbation u_j → u_j + ε·d̃_t (d̃ the
    direction signal, centred and scaled on the estimation part), by a forward difference; None when
    the direction carries nothing beyond the input itself (a two-level input: d_t = sign(u_t − ū)), the
    input changes direction fewer than ``DIRECTION_MIN_SWITCHES`` times, or the model cannot be simulated."""
    sl = prob.split.est_slice()
    u = prob.U[:, j]
    d = direction_signal(u)
    de = d[sl]
    if np.count_nonzero(np.diff(de)) < DIRECTION_MIN_SWITCHES:
        return None
    known = de != 0
    if stats.affine_in(de[known], u[sl][known], 1e-3):
        return None
    return _input_term_sensitivity(fit, prob, j, d, base)


def input_rate_sensitivity(fit, prob, j: int, base: np.ndarray | None = None) -> np.ndarray | None:
    """(n_est, ny) response of the fitted simulation to u_j → u_j + ε·r̃_t (r̃ = :func:`rate_signal`,
    centred and scaled on the estimation part); None when the input changes fewer than
    ``DIRECTION_MIN_SWITCHES`` times, when r is a multiple of Δu (all changes of one size, up to
    1e-3 of r's spread), or when the model cannot be simulated."""
    sl = prob.split.est_slice()
    u = prob.U[:, j]
    r = rate_signal(u)
    du = np.diff(u, prepend=u[0])[sl]
    moved = du != 0
    if np.count_nonzero(moved) < DIRECTION_MIN_SWITCHES or stats.affine_in(r[sl][moved], du[moved], 1e-3):
        return None
    return _input_term_sensitivity(fit, prob, j, r, base)


def _input_term_sensitivity(fit, prob, j: int, d: np.ndarray, base: np.ndarray | None) -> np.ndarray | None:
    """The forward-difference response of the fitted simulation to u_j → u_j + ε·(d − d̄)/sd(d), the
    mean and spread taken on the estimation part, over the estimation rows. ``base``: the fit's own
    simulation up to the end of the estimation part (:func:`_base`), when several terms share it."""
    sl = prob.split.est_slice()
    u = prob.U[:, j]
    de = d[sl]
    v = (d - de.mean()) / np.std(de)
    eps = 1e-4 * (float(np.std(u[sl])) or 1.0)
    stop = prob.split.est[1]
    if base is None:
        base = _base(fit, prob)
    U1 = prob.U.copy()
    U1[:, j] = u + eps * v
    pert = simulate_until(fit.model, dataclasses.replace(prob, U=U1), fit.x0, stop)
    if base is None or pert is None:
        return None
    S = (pert - base)[prob.split.est[0]:] / eps
    return S if np.all(np.isfinite(S)) and np.any(S) else None


def _base(fit, prob) -> np.ndarray | None:
    """The fit's simulation up to the end of the estimation part (the input terms' common baseline)."""
    return simulate_until(fit.model, prob, fit.x0, prob.split.est[1])


def input_direction_test(fit, prob, i: int, j: int, S: np.ndarray, alpha: float) -> stats.TestResult:
    """HAC Wald test (:func:`stats.added_terms_test`: feasible GLS, fixed-b) of the direction
    sensitivity S[:, i] in the residual of output i, beyond the fitted parameters' sensitivities."""
    return _input_term_test(fit, i, S, alpha, "input_direction",
                            "an input term following the direction of the input's last change (backlash, play "
                            "or hysteresis in the actuator)")


def input_rate_test(fit, prob, i: int, j: int, S: np.ndarray, alpha: float) -> stats.TestResult:
    """HAC Wald test of the rate sensitivity S[:, i] (:func:`input_rate_sensitivity`) in the residual of
    output i, beyond the fitted parameters' sensitivities."""
    return _input_term_test(fit, i, S, alpha, "input_rate",
                            "an input term following the signed square of the input's increments (a rate or "
                            "slew limit in the actuator: a step becomes a ramp that lasts longer for a larger step)")


def _input_term_test(fit, i: int, S: np.ndarray, alpha: float, name: str, what: str) -> stats.TestResult:
    ny = fit.resid_est.shape[1]
    e = fit.resid_est[:, i]
    J = fit.jac[i::ny] if fit.jac is not None and fit.jac.size else np.zeros((len(e), 0))
    w = stats.added_terms_test(e, J, S[:, i:i + 1])
    t = stats.TestResult(name, w.statistic, w.p_value, None, w.p_value >= alpha,
                         f"HAC Wald test of the model's response to {what}; it explains {100 * w.r2:.2g} % of "
                         f"the residual")
    t.r2 = w.r2
    return t


def adequacy_tests(fit, prob, alpha: float) -> list[stats.TestResult]:
    """Every output × every input, and the parameter-stability row of every output; the level of each
    is α / (number of pairs × ``N_TESTS`` + number of outputs) (Bonferroni over the rows)."""
    sl = prob.split.est_slice()
    ny = fit.resid_est.shape[1]
    pairs = [(i, j) for i in range(ny) for j in excited_inputs(prob)]
    if not pairs:
        return []
    a = alpha / (N_TESTS * len(pairs) + ny)
    inputs = sorted({j for _, j in pairs})
    base = _base(fit, prob)
    sens = {j: input_direction_sensitivity(fit, prob, j, base) for j in inputs}
    rate = {j: input_rate_sensitivity(fit, prob, j, base) for j in inputs}
    ts = prob.t[sl]
    dt = float(np.median(np.diff(ts))) if len(ts) > 1 else 1.0    # the coherence row's frequency unit
    out = []
    for i, j in pairs:
        e, u = fit.resid_est[:, i], prob.U[sl, j]
        tag = f"[{fit.model.inputs[j]}->{prob.out_names[i]}]" if len(pairs) > 1 else ""
        xc = stats.input_crosscorr(e, u, 25, a)
        xc.r2 = xc.statistic ** 2          # the share of the residual one lag of the input explains
        tests = [xc, model_error_model(e, u, a)]
        if sens[j] is not None:
            tests.append(input_direction_test(fit, prob, i, j, sens[j], a))
        if rate[j] is not None:
            tests.append(input_rate_test(fit, prob, i, j, rate[j], a))
        coh = input_coherence(e, u, a, dt)
        if coh is not None:
            tests.append(coh)
        for t in tests:
            t.name += tag
            out.append(t)
    weights = prob.weights
    for i in range(ny):
        st = parameter_stability_test(fit, i, float(weights[i]), a)
        if st is not None:
            st.name += f"[{prob.out_names[i]}]" if ny > 1 else ""
            out.append(st)
    return out


def feedback_tests(fit, prob, alpha: float) -> list[stats.TestResult]:
    """Input–residual correlation at negative lags (the residual leads the input): a sign that the
    input was computed from the output, i.e. closed-loop data (MATLAB ``advice`` reports it). Then the
    residual is not independent of the input and output-error estimates of a wrong model are biased
    toward what the controller makes likely; informational, not part of the adequacy decision.

    One row per output × excited input (a loop may close on one input only, or through one output); the
    first output with the first excited input keeps the plain name ``feedback_crosscorrelation``, the
    others are tagged ``[u->y]`` as the residual battery's pair rows are (:func:`residual_tests`). Each
    row's p-value is Bonferroni over its negative lags, with the normal approximation of the lag
    correlations (Ljung 1999, §16.6); like the battery's pair rows, each is a test at α of its pair."""
    sl = prob.split.est_slice()
    excited = excited_inputs(prob)
    several = fit.resid_est.shape[1] > 1 or len(excited) > 1
    out = []
    for i in range(fit.resid_est.shape[1]):
        for j in excited:
            t = _feedback_row(fit.resid_est[:, i], prob.U[sl, j], alpha)
            if i > 0 or j != excited[0]:
                t.name += f"[{fit.model.inputs[j]}->{prob.out_names[i]}]"
            if several:     # the pair it is on, for the plainly named first row too (residual_tests)
                t.output, t.input = prob.out_names[i], fit.model.inputs[j]
            out.append(t)
    return out


PREDICTABLE = 1e-6   # AR residual variance / input variance below which the feedback row is not tested
FEEDBACK = "feedback_crosscorrelation"


def is_informational(name: str) -> bool:
    """A test row that says something about the data, not about the model's adequacy (the closed-loop
    sign of :func:`feedback_tests`): shown, never part of the verdict, and marked so in the summary
    (``informational``) and the report, so that a failed one cannot read as a failed adequacy test
    beside a "no discrepancy" verdict."""
    return name.startswith(FEEDBACK)


def _feedback_row(e: np.ndarray, u: np.ndarray, alpha: float) -> stats.TestResult:
    """The negative-lag test of one pair on the prewhitened input and the residual filtered alike
    (Box & Jenkins 1976, §11.2.1: an AR(p ≤ 20) fitted to the input by Yule–Walker, p by AIC,
    :func:`stats.prewhiten_ar`). In open loop the residual of a misfit model is a causal filter of
    the input plus noise; with a coloured input its correlation with the input's future is the
    filter's response through the input's own autocorrelation, which grows significant with N (a
    first-order model of a two-lag plant, AR(1) 0.98 input, N = 20 000: p from 5e-32 to 6e-31 with
    the raw input on the three seeds of tests/diagnosis/test_feedback.py). With the input white the
    open-loop correlations at negative lags vanish, and a loop that feeds the output back into the
    input still shows. An input the AR cannot whiten (its residual fails :func:`stats.whiteness`: a
    line spectrum, e.g. Silverbox's multisine, whose future is a function of its past) leaves that
    confounding in place, and a failing row says so. An input the AR predicts almost exactly (less than
    ``PREDICTABLE`` of its variance left: one or two sinusoids) is not tested: its prewhitened
    residual is rounding noise, whose correlation bound collapsed to 0 and called a pure sine's record
    closed loop at p = 0."""
    uw, a = stats.prewhiten_ar(u)
    left = float(np.var(uw)) / (float(np.var(u)) or 1.0)
    if len(a) and left < PREDICTABLE:
        return stats.TestResult("feedback_crosscorrelation", float("nan"), float("nan"), None, False,
                                f"not tested: the input is predictable from its past (an AR({len(a)}) leaves "
                                f"{left:.1g} of its variance: a sum of a few sinusoids), so correlations at "
                                "negative lags cannot tell a closed loop from an open one")
    if len(a):
        e = stats._ar_filter(np.asarray(e, float) - float(np.mean(e)), a)
        u = uw
    white = stats.whiteness(u, 25, alpha).passed
    lags, c, band = stats.crosscorr(e, u, 25, 1 - alpha)
    neg = lags < 0
    sd = band / norm.ppf(1 - alpha / 2)
    worst = float(np.max(np.abs(c[neg])))
    p = float(min(1.0, int(neg.sum()) * 2 * norm.sf(worst / sd)))
    lag = int(lags[neg][int(np.argmax(np.abs(c[neg])))])
    return stats.TestResult("feedback_crosscorrelation", worst, p, None, p >= alpha,
                            f"largest input-residual correlation at negative lag {lag}"
                            + (f" (input prewhitened by AR({len(a)}), the residual filtered alike)" if len(a) else "")
                            + ("" if p >= alpha else
                               ": the input responds to the output (closed loop; estimates of a misspecified "
                               "model are then biased)" if white else
                               ": either the input responds to the output (closed loop; estimates of a "
                               "misspecified model are then biased) or, as the input is not white after "
                               "prewhitening (a line spectrum, such as a multisine, is predictable from its "
                               "past), the misfit its past drives reaches negative lags through the input's "
                               "own correlation"))


def where_it_fails(fit, prob, tests: list[stats.TestResult]) -> dict:
    """Plain facts about the misfit on the estimation part, for the output the model fits worst
    (largest residual RMS relative to the output's standard deviation)."""
    sl = prob.split.est_slice()
    Y = prob.Y[sl]
    sd = np.where(np.std(Y, axis=0) > 0, np.std(Y, axis=0), 1.0)
    worst = int(np.argmax(np.sqrt(np.mean(fit.resid_est ** 2, axis=0)) / sd))
    e = fit.resid_est[:, worst]
    y = Y[:, worst]
    n = len(e)
    k = 10
    edges = np.linspace(0, n, k + 1).astype(int)
    rms = [float(np.sqrt(np.mean(e[a:b] ** 2))) for a, b in zip(edges[:-1], edges[1:])]
    w = int(np.argmax(rms))
    t = prob.t[sl]
    q = np.quantile(y, np.linspace(0, 1, 6))
    bins = np.clip(np.searchsorted(q, y, side="right") - 1, 0, 4)
    by = [float(np.sqrt(np.mean(e[bins == b] ** 2))) if np.any(bins == b) else 0.0 for b in range(5)]
    b = int(np.argmax(by))
    total = float(np.sqrt(np.mean(e ** 2))) or 1.0
    return {
        "failed_tests": [f"{t_.name}: {t_.detail}" for t_ in tests if not t_.passed],
        "time_window_s": [float(t[edges[w]]), float(t[min(edges[w + 1], n - 1)])],
        "time_window_rms_ratio": rms[w] / total,
        "amplitude_range": [float(q[b]), float(q[b + 1])],
        "amplitude_range_rms_ratio": by[b] / total,
        "output": prob.out_names[worst],
        "note": "estimation part, output " + prob.out_names[worst] + "; ratios are the local residual RMS over the "
                "whole estimation RMS",
    }

