"""Find → extend → refit → measure, repeated while causes remain.

1. Fit the nominal model (output error). Residual tests on the estimation part.
2. Every family proposes hypotheses. Each is tested by regressing the output-error residual on the
   output sensitivity of its new coefficients, beyond the current parameters' sensitivities (the
   output-error analogue of correlating the equation error with the candidate term; HAC Wald test,
   :func:`stats.added_terms_test`). A family's p-value is its best hypothesis' p times the number of
   its hypotheses (Bonferroni); the periodic family also needs Fisher's g. Families are then
   controlled together with Holm at ``diagnose.alpha``.
3. For every family that fires, its best hypothesis is added and the model refitted. It is accepted
   only if the validation free-run RMSE falls with a 95 % block-bootstrap interval of the relative gain
   above zero **and** BIC on the estimation part falls.
4. The accepted extension with the lowest ΔBIC is the finding; the extended model becomes the model
   and the loop repeats, up to ``max_findings`` causes.
"""

from __future__ import annotations

import math
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .. import criteria
from ..fit import FitResult, Problem, fit_output_error, simulate_until, states_full
from ..model import Model, rhs_vectorized, term_on
from ..simulate import simulate_states
from . import stats
from ..config import NOISE_FAMILIES
from ..errors import InputError
from .families import REGISTRY, Hypothesis, Structure, amplitude_phase
from .noise import diagnose_noise


@dataclass
class Candidate:
    hyp: Hypothesis
    wald: stats.WaldResult | None
    p_family: float
    evidence: list[dict]
    fit: FitResult | None = None
    gain: dict | None = None
    delta_bic: float | None = None
    accepted: bool = False
    reason: str = ""
    start: dict = field(default_factory=dict)


@dataclass
class Diagnosis:
    nominal: FitResult
    final: FitResult
    findings: list[dict]
    tests: list[stats.TestResult]
    history: list[dict]          # every hypothesis tested, per iteration (for the report)
    fits: list[FitResult]        # nominal, then each accepted extension
    noise_tests: list[stats.TestResult] = field(default_factory=list)
    final_tests: list[stats.TestResult] = field(default_factory=list)   # residual tests of the final model


def _log(msg: str) -> None:
    print(f"[diagnose] {msg}", file=sys.stderr, flush=True)


def val_resid(fit: FitResult, prob: Problem) -> np.ndarray:
    sl = prob.split.val_slice()
    return prob.Y[sl] - fit.Yhat[sl]


def rmse(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(r))))


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB ``compare`` fit: 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (free-run simulation)."""
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean(axis=0))))


def bic_of(fit: FitResult) -> float:
    return criteria.bic(fit.resid_est, fit.n_params)


def residual_tests(fit: FitResult, prob: Problem, alpha: float) -> tuple[list[stats.TestResult], float]:
    e = fit.resid_est[:, 0]
    sl = prob.split.est_slice()
    tests = [stats.mean_test(e, alpha), stats.whiteness(e, 25, alpha), stats.ljung_box(e, 20, alpha)]
    if prob.U.shape[1] and np.ptp(prob.U[sl, 0]) > 0:
        tests.append(stats.input_crosscorr(e, prob.U[sl, 0], 25, alpha))
    g, f_cyc = stats.fisher_g(e, alpha)
    tests.append(g)
    return tests, f_cyc


def gain_ci(before: np.ndarray, after: np.ndarray, rng: np.random.Generator, n_boot: int) -> dict:
    """Relative gain 1 − RMSE_after/RMSE_before on validation data, with a 95 % moving-block bootstrap
    interval (Künsch 1989; block length ⌈√N⌉ keeps the residuals' autocorrelation inside blocks)."""
    b2 = np.sum(before ** 2, axis=1)
    a2 = np.sum(after ** 2, axis=1)
    n = len(b2)
    L = max(10, int(math.ceil(math.sqrt(n))))
    nb = int(math.ceil(n / L))
    # block sums from cumulative sums: a resample is nb blocks of L consecutive samples
    cb = np.concatenate([[0.0], np.cumsum(b2)])
    ca = np.concatenate([[0.0], np.cumsum(a2)])
    starts = rng.integers(0, n - L + 1, size=(n_boot, nb))
    sb = (cb[starts + L] - cb[starts]).sum(axis=1)
    sa = (ca[starts + L] - ca[starts]).sum(axis=1)
    rel = 1.0 - np.sqrt(sa / sb)
    rb, ra = rmse(before), rmse(after)
    lo, hi = np.percentile(rel, [2.5, 97.5])
    return {"metric": "validation_rmse_sim", "before": rb, "after": ra, "relative": 1.0 - ra / rb,
            "ci95": [float(lo), float(hi)], "bootstrap": {"method": "moving block", "block": L, "n": n_boot}}


class Diagnoser:
    def __init__(self, prob: Problem, *, alpha: float, families: list[str], max_findings: int, seed: int,
                 n_boot: int = 400, max_delay_s: float | None = None, dt: float = 1.0):
        self.prob, self.alpha, self.families = prob, alpha, families
        self.max_findings, self.seed, self.n_boot = max_findings, seed, n_boot
        self.dt = dt
        self.max_delay = max_delay_s if max_delay_s is not None else 20 * dt
        self.w = prob.weights

    # -- sensitivities -------------------------------------------------------------------------
    def _sim_est(self, model: Model, x0: np.ndarray) -> np.ndarray | None:
        Y = simulate_until(model, self.prob, x0, self.prob.split.est[1])
        return None if Y is None else Y[self.prob.split.est[0]:]

    def _step(self, fit: FitResult, hyp: Hypothesis, coef: str, X: np.ndarray) -> float:
        """Finite-difference step for a new coefficient: 1e-3 × the equation's derivative scale over the
        term's scale on the fitted model's simulated states X."""
        term = next((t for t in hyp.terms if t.coef == coef), None)
        if term is None:  # input delay
            return 0.5 * self.dt
        if term.is_output:
            return 1e-3 * float(np.std(self.prob.Y[:, 0]) or 1.0)
        m = self.hyp_model(fit, hyp)
        i = m.states.index(term.target)
        dscale = float(np.nanstd(np.gradient(X[:, i], self.dt))) or 1.0
        vals = term_on(m, term, X, self.prob.U, self.prob.t)
        tscale = float(np.sqrt(np.nanmean(vals ** 2))) or 1.0
        return 1e-3 * dscale / tscale

    def hyp_model(self, fit: FitResult, hyp: Hypothesis, values: dict[str, float] | None = None) -> Model:
        if hyp.family == "input_delay":
            name = hyp.coefs[0]
            d = (values or {}).get(name, 0.0)
            return fit.model.extend([], {name: d}, delay=name)
        params = {c: 0.0 for c in hyp.coefs}
        params.update(hyp.extra_params)
        params.update(values or {})
        return fit.model.extend(hyp.terms, params)

    def test(self, fit: FitResult, hyp: Hypothesis, X: np.ndarray) -> stats.WaldResult | None:
        base = self._sim_est(self.hyp_model(fit, hyp), fit.x0)
        if base is None:
            return None
        cols = []
        for c in hyp.coefs:
            h = self._step(fit, hyp, c, X)
            Yh = self._sim_est(self.hyp_model(fit, hyp, {c: h}), fit.x0)
            if Yh is None:
                return None
            cols.append((((Yh - base) * self.w).ravel()) / h)
        S = np.column_stack(cols)
        e = (fit.resid_est * self.w).ravel()
        return stats.added_terms_test(e, fit.jac, S)

    # -- refits ------------------------------------------------------------------------------------
    def refit(self, fit: FitResult, cand: Candidate) -> FitResult | None:
        hyp = cand.hyp
        try:
            if hyp.family == "input_delay":
                return self._fit_delay(fit, hyp.coefs[0])
            start = {c: float(b) for c, b in zip(hyp.coefs, cand.wald.beta)}
            return fit_output_error(self.hyp_model(fit, hyp, start), self.prob)
        except (InputError, np.linalg.LinAlgError, ArithmeticError) as exc:  # rejected, not fatal
            cand.reason = f"refit failed: {exc}"
            return None

    def _fit_delay(self, fit: FitResult, name: str) -> FitResult | None:
        """Profile search: weighted SSE over integer delays 0..max with the current parameters, a
        parabola through the best one and its neighbours for the fractional part, then one refit of
        all free parameters at that delay. None when the best delay is below a quarter sample."""
        y = self.prob.Y[self.prob.split.est_slice()]
        kmax = max(1, min(int(round(self.max_delay / self.dt)), len(y) // 4))
        sse = []
        for k in range(kmax + 1):
            m = fit.model.extend([], {name: k * self.dt}, delay=name)
            Yh = self._sim_est(m, fit.x0)
            sse.append(np.inf if Yh is None else float(np.sum(((y - Yh) * self.w) ** 2)))
        k0 = int(np.argmin(sse))
        frac = 0.0
        if 0 < k0 < kmax:
            s0, s1, s2 = sse[k0 - 1], sse[k0], sse[k0 + 1]
            den = s0 - 2 * s1 + s2
            frac = float(np.clip(0.5 * (s0 - s2) / den, -0.5, 0.5)) if den > 0 else 0.0
        d = (k0 + frac) * self.dt
        if d < 0.25 * self.dt:
            return None
        m = fit.model.extend([], {name: d}, delay=name)
        return fit_output_error(m, self.prob)

    # -- one iteration -----------------------------------------------------------------------------
    def candidates(self, fit: FitResult, f_hz: float | None, fisher: stats.TestResult) -> list[Candidate]:
        st = Structure.of(fit.model)
        X = states_full(fit.model, self.prob, fit.x0)
        out = []
        for fam in self.families:
            if fam not in REGISTRY:
                continue
            hyps = REGISTRY[fam].hypotheses(fit.model, st, outputs=self.prob.out_names, freq_hz=f_hz,
                                              X=X)
            best: Candidate | None = None
            for h in hyps:
                wr = self.test(fit, h, X)
                if wr is None:
                    continue
                ev = [{"test": f"added_term_wald[{h.key}]", "statistic": wr.statistic, "p_value": wr.p_value,
                       "dof": wr.dof}]
                if best is None or wr.statistic / wr.dof > best.wald.statistic / best.wald.dof:
                    best = Candidate(h, wr, 1.0, ev)
            if best is None:
                continue
            best.p_family = min(1.0, best.wald.p_value * len(hyps))
            if fam == "periodic_disturbance":
                best.evidence.append({"test": "fisher_g", "statistic": fisher.statistic,
                                      "p_value": fisher.p_value})
                best.p_family = max(best.p_family, fisher.p_value)
            if fam == "input_delay":
                best.evidence.append(self._xcorr_lag(fit))
            ee = self._equation_error_evidence(fit, best.hyp)
            if ee:
                best.evidence.append(ee)
            out.append(best)
        return out

    def _xcorr_lag(self, fit: FitResult) -> dict:
        """Lag (samples, parabola-refined) that maximises the cross-correlation of the measured output
        with the nominal simulation on the estimation part: > 0 when the measurement lags the
        simulation, i.e. a dead time. p-value: the residual–input cross-correlation test."""
        sl = self.prob.split.est_slice()
        y = self.prob.Y[sl, 0] - self.prob.Y[sl, 0].mean()
        yh = fit.Yhat[sl, 0] - fit.Yhat[sl, 0].mean()
        n = len(y)
        kmax = max(1, min(int(round(self.max_delay / self.dt)), n // 4))
        f = np.fft.irfft(np.fft.rfft(y, 2 * n) * np.conj(np.fft.rfft(yh, 2 * n)))
        lags = np.arange(-kmax, kmax + 1)
        c = np.array([f[k] if k >= 0 else f[2 * n + k] for k in lags])
        k = int(np.argmax(c))
        shift = 0.0
        if 0 < k < len(c) - 1:
            den = c[k - 1] - 2 * c[k] + c[k + 1]
            shift = float(np.clip(0.5 * (c[k - 1] - c[k + 1]) / den, -0.5, 0.5)) if den != 0 else 0.0
        xc = stats.input_crosscorr(fit.resid_est[:, 0], self.prob.U[sl, 0], 25, self.alpha)
        return {"test": "output_simulation_crosscorrelation_lag", "statistic": float(lags[k] + shift),
                "p_value": xc.p_value, "detail": "lag in samples (biased toward 0: the fitted nominal partly compensates a delay); "
                          "p from the residual-input cross-correlation"}

    def _equation_error_evidence(self, fit: FitResult, hyp) -> dict | None:
        """When every state is measured: regress the equation error ẋ − f(x, u; θ̂) of the hypothesis'
        equation (ẋ by a Savitzky–Golay derivative, window 7, order 2) on the candidate term evaluated
        on the measured states; HAC Wald test of the slope (intercept partialled out)."""
        m = fit.model
        prob = self.prob
        if hyp.equation is None or m.extra_states or not all(st in prob.out_names for st in m.states):
            return None
        from scipy.signal import savgol_filter
        sl = prob.split.est_slice()
        X = np.column_stack([prob.Y[sl, prob.out_names.index(st)] for st in m.states])
        if len(X) < 20:
            return None
        i = m.states.index(hyp.equation)
        dx = savgol_filter(X[:, i], 7, 2, deriv=1, delta=self.dt)
        f = rhs_vectorized(m, X, prob.U[sl], prob.t[sl])[:, i]
        eps = dx - f
        mh = self.hyp_model(fit, hyp)
        S = np.column_stack([term_on(mh, term, X, prob.U[sl], prob.t[sl]) for term in hyp.terms])
        # partial out the fitted parameters: J = ∂f_i/∂θ at θ̂ (central differences), an LM test in
        # equation-error form (the biased θ̂ of a misspecified model absorbs part of a missing term)
        J = []
        for name in m.free:
            h = 1e-6 * max(abs(m.params[name]), 1e-3)
            up = rhs_vectorized(m.with_params({name: m.params[name] + h}), X, prob.U[sl], prob.t[sl])[:, i]
            dn = rhs_vectorized(m.with_params({name: m.params[name] - h}), X, prob.U[sl], prob.t[sl])[:, i]
            J.append((up - dn) / (2 * h))
        J = np.column_stack(J) if J else np.zeros((len(eps), 0))
        keep = np.std(J, axis=0) > 0 if J.size else np.zeros(0, bool)
        J = J[:, keep] if J.size else J
        w = stats.added_terms_test(eps, J, S)
        return {"test": f"equation_error_wald[{hyp.key}]", "statistic": w.statistic, "p_value": w.p_value,
                "dof": w.dof, "coefficient": [float(b) for b in w.beta]}

    def run(self, model: Model, start: dict | None = None) -> Diagnosis:
        prob = self.prob
        _log(f"fitting the nominal model ({len(model.free)} free parameters, output error)")
        nominal = fit_output_error(model, prob, start=start)
        current = nominal
        tests0, f_cyc0 = residual_tests(nominal, prob, self.alpha)
        findings, history, fits = [], [], [nominal]
        for it in range(self.max_findings):
            tests, f_cyc = (tests0, f_cyc0) if it == 0 else residual_tests(current, prob, self.alpha)
            fisher = next(t for t in tests if t.name == "fisher_g")
            cands = self.candidates(current, f_cyc / self.dt, fisher)
            fired = stats.holm({c.hyp.family: c.p_family for c in cands}, self.alpha)
            _log(f"iteration {it + 1}: {len(cands)} families tested, fired: "
                 f"{[k for k, v in fired.items() if v] or 'none'}")
            rng = np.random.default_rng([self.seed, it])
            before = val_resid(current, prob)
            bic0 = bic_of(current)
            todo = [c for c in cands if fired[c.hyp.family]]
            for c in cands:
                if not fired[c.hyp.family]:
                    c.reason = "not significant after Holm correction"
            # refits are independent: run them in threads (the kernel releases the GIL)
            with ThreadPoolExecutor(max_workers=min(len(todo), os.cpu_count() or 1) or 1) as pool:
                for c, f in zip(todo, pool.map(lambda c: self.refit(current, c), todo)):
                    c.fit = f
            for c in todo:
                if c.fit is None:
                    c.reason = c.reason or "no extension estimated (e.g. delay below a quarter sample)"
                    continue
                c.gain = gain_ci(before, val_resid(c.fit, prob), rng, self.n_boot)
                c.delta_bic = bic_of(c.fit) - bic0
                c.accepted = c.gain["ci95"][0] > 0 and c.delta_bic < 0
                c.reason = "accepted" if c.accepted else (
                    "validation error not lower with 95 % confidence" if c.gain["ci95"][0] <= 0
                    else "BIC not lower")
                _log(f"  {c.hyp.key}: gain {c.gain['relative']:+.3f} ci {c.gain['ci95'][0]:+.3f}.."
                     f"{c.gain['ci95'][1]:+.3f}, dBIC {c.delta_bic:+.1f} -> {c.reason}")
            history.append({"iteration": it + 1, "candidates": [_cand_record(c) for c in cands]})
            acc = [c for c in cands if c.accepted]
            if not acc:
                break
            best = min(acc, key=lambda c: c.delta_bic)
            findings.append(self.finding(best))
            current = best.fit
            fits.append(current)
        noise_tests = []
        noise_fams = [f for f in self.families if f in NOISE_FAMILIES]
        if noise_fams and len(findings) < self.max_findings:
            _log("noise families on the final model: " + ", ".join(noise_fams))
            nf, noise_tests = diagnose_noise(current, prob, alpha=self.alpha, seed=self.seed, n_boot=self.n_boot)
            findings += [f for f in nf if f["family"] in noise_fams][: self.max_findings - len(findings)]
        final_tests = tests0 if current is nominal else residual_tests(current, prob, self.alpha)[0]
        return Diagnosis(nominal, current, findings, tests0, history, fits, noise_tests, final_tests)

    def finding(self, c: Candidate) -> dict:
        h, fit = c.hyp, c.fit
        val = dict(zip(fit.names, fit.theta))
        sd = dict(zip(fit.names, fit.std))
        f: dict = {"family": h.family}
        g = c.gain
        gtxt = (f"lowers the validation free-run RMSE from {g['before']:.4g} to {g['after']:.4g} "
                f"({100 * g['relative']:.1f} % better, 95 % CI {100 * g['ci95'][0]:.1f} to "
                f"{100 * g['ci95'][1]:.1f} %) and BIC by {-c.delta_bic:.1f}")
        if h.family == "input_delay":
            d = float(fit.model.params[fit.model.delay])
            f.update(delay_s=d, delay_samples=d / self.dt)
            desc = f"The input acts with a dead time of {d:.4g} s ({d / self.dt:.2f} samples); delaying it {gtxt}."
        elif h.family == "output_offset":
            c0 = h.coefs[0]
            f.update(output=h.output, value=val[c0], value_std=sd[c0], coefficient=val[c0])
            desc = f"The measured output {h.output} carries a constant offset of {val[c0]:.4g}; removing it {gtxt}."
        elif h.family == "periodic_disturbance":
            a, b = val[h.coefs[0]], val[h.coefs[1]]
            fname = next(iter(h.extra_params))
            amp, ph = amplitude_phase(a, b)
            fz = float(fit.model.params[fname])
            f.update(equation=h.equation, frequency_hz=fz, frequency_std=sd.get(fname), amplitude=amp,
                     phase_rad=ph, term=f"sin(2*pi*{fz:.6g}*t + {ph:.4g})", coefficient=amp)
            desc = (f"A periodic disturbance of {fz:.4g} Hz and amplitude {amp:.4g} acts in the equation of "
                    f"{h.equation}; adding it {gtxt}.")
        else:
            c0 = h.coefs[0]
            f.update(equation=h.equation, term=h.term, coefficient=val[c0], coefficient_std=sd[c0])
            what = {"offset": "A constant offset", "cubic_stiffness": f"A cubic stiffness term {h.term}",
                    "coulomb_friction": f"Coulomb friction {h.term}",
                    "quadratic_damping": f"Quadratic damping {h.term}"}.get(h.family, h.family)
            desc = (f"{what} is missing from the equation of {h.equation}: adding {val[c0]:.4g}*{h.term} {gtxt}.")
        f.update(description=desc, evidence=c.evidence, gain=g, delta_bic=c.delta_bic,
                 extended_equations=fit.model.describe_equations())
        return f


def _cand_record(c: Candidate) -> dict:
    return {"family": c.hyp.family, "hypothesis": c.hyp.key, "p_family": c.p_family,
            "statistic": None if c.wald is None else c.wald.statistic,
            "gain": c.gain, "delta_bic": c.delta_bic, "accepted": c.accepted, "reason": c.reason}
