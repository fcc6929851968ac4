"""Find → extend → refit → measure, repeated while causes remain.

1. Fit the nominal model (output error). Residual tests on the estimation part.
2. Every family proposes hypotheses. Each is tested by regressing the output-error residual on the
   output sensitivity of its new coefficients, beyond the current parameters' sensitivities (the
   output-error analogue of correlating the equation error with the candidate term; HAC Wald test,
   :func:`stats.added_terms_test`). A family's p-value is its best hypothesis' p times the number of
   its hypotheses (Bonferroni); the periodic family also needs Fisher's g. Families are then
   controlled together with Holm at ``diagnose.alpha``. Two shortcuts keep long records fast and
   leave the tests valid: a hypothesis that equals the current model before a time (a jump) is
   simulated from there only (:meth:`Diagnoser._sim_est_from`, the same numbers), and of a screen
   group (a jump's grid of times) only the time explaining most by OLS is tested in full
   (:meth:`Diagnoser.screened_out`, conservative under Bonferroni).
3. For every family that fires, its best hypothesis is added and the model refitted (with a runner-up
   acting elsewhere that explains at least 0.8 of its share, :meth:`Diagnoser._near_tie`). It is accepted
   only if the validation free-run RMSE falls with a 95 % interval of the relative gain above zero
   (:mod:`.gain`) **and** a likelihood-ratio test with the effective sample size N(1 − ρ̂)/(1 + ρ̂)
   (ρ̂ of the refitted residual) on the estimation part rejects the current model at ``alpha``
   (:func:`stats.lr_test`); ΔBIC is
   kept as information.
4. The accepted extension with the lowest ΔBIC + 2 ln(places of its family) is the finding (a uniform
   prior over causes and, within one, over its places: :func:`choose`), ΔBIC counted with the residual's
   effective sample size (:func:`effective_bic`); when another accepted extension is within 6 of it
   (``naming.SEPARATE_CRITERION``) and clearly better on the validation part, that one (:func:`.naming.separate`). The extended model
   becomes the model and the loop repeats, up to ``max_findings`` causes.

Beside this loop: the intersample pre-stage of each round (:mod:`.intersample_stage`), the choice among
accepted extensions and a finding's words (:mod:`.naming`), the refit criteria (:mod:`.refit_criteria`),
the held-out gain (:mod:`.gain`) and the backward step over the chosen chain (:mod:`.revisit`).
"""

from __future__ import annotations

import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from .. import criteria
from ..fit import (FitResult, Problem, estimated_x0, excited_inputs, fit_output_error, simulate_until, stable_quotient,
                   states_full, undefined_from)
from ..model import Model, rhs_vectorized, switches, term_on
from ..simulate import outputs, simulate_states
from . import stats
from ..errors import InputError, SimulationError
from .families import NOISE_FAMILY_IDS, REGISTRY, Context, Hypothesis, Structure
from .families.base import Family
from .families.periodic_disturbance import (family_p_value as periodic_p_value, line_test_p as periodic_line_p,
                                            n_lines as periodic_n_lines)
from .cusum import cusum_squares_test, cusum_test
from .adequacy import MATERIAL_R2, adequacy_tests, feedback_tests, material, structurally_adequate, where_it_fails
from .form import Accepted, form_test
from .hausman import NAME as HAUSMAN
from .noise import diagnose_noise
from .console import log as _log
from .gain import gain_ci, gain_resid, pooled, unbounded_note
from .intersample_stage import IntersampleStage
from .refit_criteria import bic_of, lr_against
from . import naming
from .naming import RUNNER_UP_DBIC, SEPARATION_MIN_GAIN, p_text, separates
from .state_probe import NAME as PROBE_NAME, probe_hypotheses, what as probe_what, where as probe_where
from .pairs import Member, hidden_pairs
from .revisit import Link, revisit, revisited_findings
from .why import LOOKED_AHEAD


@dataclass
class Candidate:
    hyp: Hypothesis
    wald: stats.WaldResult | None
    p_family: float
    evidence: list[dict]
    fit: FitResult | None = None
    gain: dict | None = None
    delta_bic: float | None = None
    delta_bic_eff: float | None = None   # ΔBIC with the residual's effective sample size (effective_bic)
    separation: str = ""         # why it was chosen over a near-equal by the validation part (Diagnoser.separate)
    accepted: bool = False
    reason: str = ""
    start: dict = field(default_factory=dict)
    runner_up: bool = False      # a family's near-tie second hypothesis (Diagnoser._near_tie)
    places: int = 1              # distinct places the family's hypotheses act on (Diagnoser._where)
    lr: stats.TestResult | None = None   # the likelihood-ratio test of the refit against the current model
    # the family's other significant hypotheses, refitted beside it for a family of forms or when its
    # refit fails from every start (Diagnoser._fallbacks); (Hypothesis, WaldResult), largest share first
    alternates: list = field(default_factory=list)
    # accepted by the look-ahead (Diagnoser._lookahead): the extension it was accepted with, and its
    # validation gain and likelihood-ratio test given that extension
    given: dict | None = None

    @property
    def prior_penalty(self) -> float:
        """−2 ln of the model prior's within-family share, 2 ln(places) (:func:`choose`)."""
        return 2.0 * math.log(max(1, self.places))

    @property
    def criterion(self) -> float:
        """ΔBIC (with the effective sample size when :func:`effective_bic` has set it) plus the prior
        penalty: the number :func:`choose` minimises."""
        d = self.delta_bic if self.delta_bic_eff is None else self.delta_bic_eff
        return d + self.prior_penalty


@dataclass
class Round:
    """One round of the loop (:meth:`Diagnoser._propose`): its weighed candidates, the families it
    skipped, the intersample stage's finding (a fit and a finding, or None) and history rows (None when
    it did not run), and the families' p-values and residual shares on the round's model."""
    cands: list[Candidate]
    skipped: list
    inter: tuple | None
    inter_history: dict | None
    last_p: dict[str, float]
    last_r2: dict[str, float]
    n_eff: float | None = None     # the effective sample size the round's ΔBIC_eff use (:func:`effective_bic`)

    def record(self, it: int) -> dict:
        """The round's row of ``Diagnosis.history`` (iteration ``it`` counted from 0)."""
        return {"iteration": it + 1, "candidates": [_cand_record(c) for c in self.cands]
                + (self.inter_history["candidates"] if self.inter_history is not None else []),
                "skipped": [{"family": f, "reason": r} for f, r in dict.fromkeys(self.skipped)]}


def effective_bic(weighed: list[Candidate], current: FitResult) -> float | None:
    """Sets each weighed candidate's ``delta_bic_eff`` (a refit with its ΔBIC), its ΔBIC against
    ``current`` with the residual's effective sample size, and returns that N_eff (None when there is
    none). N_eff is taken from the accepted candidates when there are any (the choice is among them),
    else from all of them; rejected ones get the same N_eff, so that a runner-up that was not accepted
    is listed on the finding's scale (:func:`.naming.finding`).

    ΔBIC = N ln(det Σ̂₁/det Σ̂₀) + Δk ln N counts every residual as an independent sample. An output-error
    residual with lag-1 autocorrelation ρ carries the information of N_eff = N(1 − ρ)/(1 + ρ) independent
    samples (the engine's likelihood-ratio test, :func:`stats.lr_test`), and BIC with an effective sample
    size is ΔBIC_eff = (N_eff/N)·N ln(det Σ̂₁/det Σ̂₀) + Δk ln N_eff (Jones 2011, Statist. Med. 30(25),
    "Bayesian information criterion for longitudinal and clustered data": the log-likelihood of correlated
    samples, the penalty in ln N_eff). One N_eff serves every candidate of the choice, from the residual
    of the one that fits the estimation part best (the closest to the noise), so that the ranking compares
    like with like; ρ is clipped to [0, 0.999] as in the LR test, N_eff to at least 2 samples.

    Why: on coloured residuals raw ΔBIC differences are inflated by about (1 + ρ)/(1 − ρ), and the model
    prior's 2 ln(places) (:func:`choose`) was swamped by noise-fitting. On independent-bench records of
    quadratic damping in a DC motor (AR(1) noise φ = 0.9, 2 % noise; tuning seed 0, test seed 1000) a
    library term tanh(w/0.535) fitted the estimation part 14.4 BIC units better than w·|w| and was named
    over a 4-place prior; with the effective size the lead is 0.9 units and the prior (2 ln 4 = 2.8)
    names the quadratic damping, whose validation gain is the same (28.7 % vs 28.6 %)."""
    weighed = [c for c in weighed if c.fit is not None and c.delta_bic is not None]
    if not weighed:
        return None
    n = current.resid_est.shape[0]
    best = min([c for c in weighed if c.accepted] or weighed, key=lambda c: c.fit.sse_w)
    n_eff = max(stats.effective_n(n, stats.lag1(best.fit.resid_est))[1], 2.0)
    for c in weighed:
        dk = c.fit.n_params + len(c.hyp.searched) - current.n_params
        c.delta_bic_eff = criteria.bic_effective_delta(c.delta_bic, dk, n, n_eff)
    return n_eff


def choose(accepted: list[Candidate]) -> Candidate | None:
    """The finding among the accepted extensions: the one with the highest approximate posterior
    probability, i.e. the lowest ΔBIC − 2 ln p(M) (Kass & Raftery 1995, JASA 90(430), §4.1: BIC
    approximates −2 ln p(y | M), so the posterior adds −2 ln p(M)). The prior is uniform over causes
    (families) and, within a cause, uniform over the places it can act on (an equation, a term of the
    library, a parameter, an input, a state or an output; a grid of times or delays is a search and is
    already counted in BIC as a parameter): p(M) = 1/F · 1/K_f, and F cancels. This is the multiplicity
    correction of Scott & Berger (2010, Ann. Statist. 38(5)) for a model space searched by families: a
    term picked from a 6–22-term library pays 2 ln K = 3.6–6.2 against a one-place family. Without
    it, on the independent bench, quadratic damping lost to a static term 1.3 BIC units better and a
    cubic stiffness to a library term (both records within 2 BIC units, 'not worth more than a bare
    mention' on Kass & Raftery's scale)."""
    return min(accepted, key=lambda c: c.criterion) if accepted else None




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
    adequacy: list[stats.TestResult] = field(default_factory=list)      # structural adequacy, final model
    adequacy_nominal: list[stats.TestResult] = field(default_factory=list)
    verdict: str = "no_significant_discrepancy"
    where: dict | None = None                                            # where an unexplained misfit is
    revisit: list[dict] = field(default_factory=list)   # moves of the backward step (:mod:`.revisit`)
    rounding: str | None = None     # why nothing was tested: the nominal model fits to rounding error
    # an unexplained verdict's best refits of the final model that were not accepted (:func:`unaccepted_fits`)
    unaccepted: list[tuple[str, FitResult]] = field(default_factory=list)


REFIT_SHARE = 0.2     # see Diagnoser._screen
REFIT_BUDGET_ITERATIONS = 4   # a refit still above the current error after ~4 iterations is abandoned
COLOUR_TESTS = ("autocorrelation", "ljung_box", "fisher_g")   # residual tests of colour, not of structure
# BIC units (with the round's effective sample size: Diagnoser.inter_wins) by which a physical cause must
# beat the intersample choice (which adds no parameter) to be preferred: 10 is where Kass & Raftery
# (1995, JASA 90, §3.2) put "very strong" evidence on the 2 ln B scale that a BIC difference approximates
INTERSAMPLE_TIE_BIC = 10.0
MAX_REFITS = 4
# the state probe is refitted (Diagnoser.probe_refit) only when its linearised test explains at least this
# share of the residual: half the adequacy threshold. Null records (AR(0.9) noise) stayed at 0.1-0.8 %,
# out-of-library springs that ended ``colored_noise`` at 1.0-2.5 %; a refit costs ~0.1-0.3 s
PROBE_REFIT_MIN_SHARE = 0.5 * MATERIAL_R2


def validation_undefined(prob: Problem, stop: int, which: str) -> stats.TestResult:
    """The failed adequacy row of a model whose free-run simulation stops on the validation part (a NaN
    or a divergence from sample ``stop``; :func:`pipeline.fit.simulate_full` with ``partial``): what the
    simulation gets wrong includes that it cannot follow the record there at all, so the model is not
    adequate however its estimation residual looks (material: its share is 1). Its validation figures
    and every gain against it are computed on the rows before ``stop``."""
    sl = prob.split.val_slice()
    share = (sl.stop - stop) / (sl.stop - sl.start)
    t = prob.t[stop]
    row = stats.TestResult(
        "validation_simulation", float(share), 0.0, None, False,
        f"the {which} model's free-run simulation stops at sample {stop} (t = {t:.6g} s) of the validation part "
        f"(NaN or divergence: an expression undefined there, e.g. the root of a negative state, or a state "
        f"growing without bound); {100 * share:.3g} % of the validation part has no simulated value, and its "
        "validation numbers and gains are computed on the samples before", r2=1.0)
    row.on = f"{which} model, validation data"
    return row


UNACCEPTED_SHOWN = 2   # refitted-but-not-accepted extensions drawn beside an unexplained verdict's final model


def unaccepted_fits(base: FitResult, cands: list) -> list[tuple[str, FitResult]]:
    """An unexplained verdict's picture of what was tried: the refits of the final model ``base`` (the
    last round's candidates) that lowered the validation error (point gain > 0) without being accepted,
    the largest gain of each family first, at most ``UNACCEPTED_SHOWN`` families. Each is labelled with
    its hypothesis and its validation gain; the report draws them beside the final model (the reasons
    they were not accepted are the history's). On the cascaded tanks: an offset (+47.2 %) and a
    square-root outflow (+46.5 %) that the record cannot tell apart nor bound."""
    rows = [c for c in cands if c.fit is not None and c.gain and not c.accepted and c.gain["relative"] > 0]
    rows.sort(key=lambda c: -c.gain["relative"])
    out, seen = [], set()
    for c in rows:
        if c.hyp.family in seen:
            continue
        seen.add(c.hyp.family)
        out.append((f"{c.hyp.key} (not accepted; {100 * c.gain['relative']:+.1f} %)", c.fit))
        if len(out) == UNACCEPTED_SHOWN:
            break
    return out


def rmse(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(r))))


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB ``compare`` fit: 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (free-run simulation)."""
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean(axis=0))))


def residual_tests(fit: FitResult, prob: Problem, alpha: float) -> tuple[list[stats.TestResult], float]:
    """The residual battery on every output (and every output × excited input for the
    cross-correlation and the Billings–Voon higher-order correlations). The first output (and its first excited input) keeps the plain names the
    contract's ``tests`` rows have always had (``ljung_box``, ``input_crosscorrelation``…); the other
    outputs and pairs add rows named ``…[y]`` / ``…[u->y]``. With more than one output or excited input
    every row also carries the output (``output``) and, for a pair, the input (``input``) it is on, so
    the plainly named first rows say which they are. Returns the tests and the
    frequency (cycles/sample) of the most significant Fisher-g peak over the outputs."""
    sl = prob.split.est_slice()
    ny = fit.resid_est.shape[1]
    excited = excited_inputs(prob)
    several = ny > 1 or len(excited) > 1
    tests, best = [], None
    for i in range(ny):
        e = fit.resid_est[:, i]
        tag = f"[{prob.out_names[i]}]" if i > 0 else ""
        rows = [stats.mean_test(e, alpha), stats.whiteness(e, 25, alpha), stats.ljung_box(e, 20, alpha),
                cusum_test(e, Ji := fit.jac[i::ny] if fit.jac is not None else np.zeros((len(e), 0)), prob.t[sl], alpha),
                cusum_squares_test(e, Ji, prob.t[sl], alpha)]
        for j in excited:
            pair = [stats.input_crosscorr(e, prob.U[sl, j], 25, alpha), stats.billings_voon(e, prob.U[sl, j], 25, alpha)]
            for xc in (r for r in pair if r is not None):
                if i > 0 or j != excited[0]:
                    xc.name += f"[{fit.model.inputs[j]}->{prob.out_names[i]}]"
                if several:
                    xc.input = fit.model.inputs[j]
                rows.append(xc)
        g, f_cyc = stats.fisher_g(e, alpha)
        rows.append(g)
        for r in rows:
            if tag and not r.name.endswith("]"):
                r.name += tag
            if several:
                r.output = prob.out_names[i]
        tests += rows
        if best is None or g.p_value < best[0].p_value:
            best = (g, f_cyc)
    return tests, best[1]


def strongest_fisher(tests: list[stats.TestResult]) -> stats.TestResult:
    """The Fisher-g row with the smallest p-value (one per output)."""
    return min((t for t in tests if t.name.startswith("fisher_g")), key=lambda t: t.p_value)


def _share(w: stats.WaldResult) -> float:
    """The share of the residual's sum of squares an added-term test's columns remove by least squares
    on the *unfiltered* residual: the linearised refit's SSE drop (a Gauss–Newton step). Not the GLS
    test's ``r2``: its AR prewhitening filter nearly differences a smooth residual, and an offset's
    near-constant sensitivity then looked like 2 % of the residual when its refit removed 74 %."""
    return w.r2 if w.share is None else w.share


class Diagnoser:
    def __init__(self, prob: Problem, *, alpha: float, families: list[str], max_findings: int, seed: int,
                 n_boot: int = 400, max_delay_s: float | None = None, dt: float = 1.0, couplings: bool = False):
        self.couplings = couplings
        self.prob, self.alpha, self.families = prob, alpha, families
        self.max_findings, self.seed, self.n_boot = max_findings, seed, n_boot
        self.dt = dt
        self.max_delay = max_delay_s if max_delay_s is not None else 20 * dt
        self.w = prob.weights
        self.inter = IntersampleStage(prob, alpha=alpha, n_boot=n_boot, dt=dt)
        self._probe_best: dict[int, tuple] = {}   # id(fit) -> (fit, probe hypothesis, its test): state_probe
        self._basis_cache: dict[int, tuple] = {}   # id(fit) -> (fit, its Jacobian's column basis): _basis
        self._basis_lock = threading.Lock()
        # (id(fit), id(hypothesis), id(its test)) -> (fit, hypothesis, test, refit, its reason): likelihood-
        # ratio screen refits that were not taken, for :meth:`estimate` (the objects are held so their ids
        # stay unique)
        self._screen_refits: dict[tuple, tuple] = {}
        # the last candidates() round's (fit, context, families, test results), for second_chance; None
        # once its lazy screen has run
        self._round: tuple | None = None
        # the last candidates() round's (fit, context, [(representative, sensitivities, multiplicity)]),
        # for the test of one hypothesis given another, for causes that hide each other (_pair_first)
        self._members: tuple | None = None

    # -- sensitivities -------------------------------------------------------------------------
    def _sim_est(self, model: Model, x0: np.ndarray) -> np.ndarray | None:
        Y = simulate_until(model, self.prob, x0, self.prob.split.est[1])
        return None if Y is None else Y[self.prob.split.est[0]:]

    def sim_est(self, model: Model, x0: np.ndarray) -> np.ndarray | None:
        return self._sim_est(model, x0)

    RESUME_BACK = 2   # samples before t_j a resumed simulation restarts (see _sim_est_from)

    def _current_states(self, fit: FitResult) -> tuple[int, np.ndarray] | None:
        """(s0, X): the states of the fitted simulation of ``fit`` on rows [s0, est_end) of its (warm-up)
        segment, when that one segment holds the whole estimation part; computed once per fit."""
        cached = getattr(self, "_states_cache", None)
        if cached is not None and cached[0] is fit:
            return cached[1]
        prob = self.prob
        s0, s1 = prob.fit_segment()
        e1 = prob.split.est[1]
        out = None
        if s1 >= e1 and fit.model.delay is None:
            res = simulate_states(fit.model, prob.t[s0:e1], prob.inputs(fit.model)[s0:e1], fit.x0,
                                  bound=prob.bound, prefiltered=True)
            if res.diverged_at is None:
                out = (s0, res.X)
        self._states_cache = (fit, out)
        return out

    def _sim_est_from(self, model: Model, fit: FitResult, t_from: float,
                      after: Model | None = None) -> np.ndarray | None:
        """The estimation-part outputs of ``model``, which equals ``fit.model`` before ``t_from``:
        the fit's own simulated rows up to there, and from ``RESUME_BACK`` samples before the last
        sample at or before ``t_from`` a simulation resumed from the fit's simulated state. The kernel
        is a one-step recursion in the stored state, so this equals the full simulation (up to the
        rounding of ``step(t − t_j)`` being 0 before t_j); it costs the part after t_j only (a jump's
        test, half a simulation on average). Falls back to the full simulation when the estimation
        part spans several segments or the model has an input delay (whose shifted input looks back).

        ``after`` (:meth:`Family.settled`): a model equal to ``model`` at every time after ``t_from``
        without its programs; ``model`` is then simulated only up to the end of the sample interval
        holding ``t_from`` and ``after`` (the current model's kernel, compiled on long records: about
        a third of the interpreting kernel's time) from there, its states given to ``model``'s outputs."""
        prob = self.prob
        e0, e1 = prob.split.est
        st = self._current_states(fit)
        if st is None or model.delay is not None or len(model.states) != st[1].shape[1]:
            return self._sim_est(model, self._x0_for(fit, model))
        s0, X = st
        # the record's time restarts in each experiment: search the fit segment's rows only
        k = s0 + int(np.searchsorted(prob.t[s0:e1], t_from, side="right")) - 1 - self.RESUME_BACK
        if k <= e0:
            return self._sim_est(model, self._x0_for(fit, model))
        k = min(k, e1 - 1)
        # every stage time of the intervals from sample j on is at or after t[j] > t_from
        j = k + self.RESUME_BACK + 1
        split = after is not None and j < e1 - 1
        stop = j + 1 if split else e1
        res = simulate_states(model, prob.t[k:stop], prob.inputs(model)[k:stop], X[k - s0], bound=prob.bound,
                              prefiltered=True)
        if res.diverged_at is not None:
            return None
        if split:
            rest = simulate_states(after, prob.t[j:e1], prob.inputs(after)[j:e1], res.X[-1], bound=prob.bound,
                                   prefiltered=True)
            if rest.diverged_at is not None:
                return None
            res = replace(res, X=np.concatenate([res.X[:-1], rest.X]))
        Y = np.array(fit.Yhat[e0:e1], dtype=float, copy=True)
        Y[k - e0:] = outputs(model, prob.t[k:e1], prob.U[k:e1], res.X, prob.out_names)
        return Y

    def _step(self, fit: FitResult, hyp: Hypothesis, coef: str, X: np.ndarray) -> float:
        """Finite-difference step for a tested parameter: the family's absolute ``info['step']`` or
        1e-3 × its ``info['scale']``; for an additive term, 1e-3 × the equation's derivative scale over
        the term's RMS on the fitted model's simulated states X."""
        if "step" in hyp.info:
            return float(hyp.info["step"])
        if "scale" in hyp.info:
            return 1e-3 * float(hyp.info["scale"])
        term = next((t for t in hyp.terms if t.coef == coef), None)
        if term is None:
            return 1e-3
        if term.is_output:
            return 1e-3 * float(np.std(self.prob.Y[:, 0]) or 1.0)
        m = self.hyp_model(fit, hyp)
        i = m.states.index(term.target)
        dscale = float(np.nanstd(np.gradient(X[:, i], self.dt))) or 1.0
        Xm = X if X.shape[1] == len(m.states) else states_full(m, self.prob, self._x0_for(fit, m))
        with np.errstate(invalid="ignore"):   # a term undefined off the estimation part (√u of a validation
            vals = term_on(m, term, Xm, self.prob.U, self.prob.t)   # input below 0) is NaN: nanmean skips it
        tscale = float(np.sqrt(np.nanmean(vals ** 2))) or 1.0
        return 1e-3 * dscale / tscale

    @staticmethod
    def _x0_for(fit: FitResult, model: Model) -> np.ndarray:
        """The fit's initial state extended by the initial values of a hypothesis' extra states."""
        extra = [float(model.initial[s]) for s in model.states[len(fit.x0):]]
        return np.concatenate([fit.x0, extra]) if extra else fit.x0

    def hyp_model(self, fit: FitResult, hyp: Hypothesis, values: dict[str, float] | None = None) -> Model:
        return REGISTRY[hyp.family].extend(fit.model, hyp, values)

    @staticmethod
    def _null_is_current(hyp: Hypothesis) -> bool:
        """The hypothesis at its null is the current model itself: additive terms whose coefficients
        are 0 there, added by the generic extension (no rewrite, limit or new state). Its simulation
        at the null is then the fit's own, and the test needs one simulation per coefficient."""
        fam = REGISTRY[hyp.family]
        if getattr(fam, "null_is_current", False):     # the family says so (a rewrite that is the identity at 0)
            return all(float(hyp.null.get(c, 0.0)) == 0.0 for c in hyp.coefs)
        coefs = {t.coef for t in hyp.terms}
        return (type(fam).extend is Family.extend and not hyp.input_rewrites and not hyp.param_rewrites
                and not hyp.limits and not hyp.extra_states and all(c in coefs for c in hyp.coefs)
                and all(float(hyp.null.get(c, 0.0)) == 0.0 for c in hyp.coefs))

    def test(self, fit: FitResult, hyp: Hypothesis, X: np.ndarray) -> stats.WaldResult | None:
        """The added-term test of ``hyp`` on the current fit (module docstring, step 2)."""
        S = self.sensitivity(fit, hyp, X)
        return None if S is None else self.statistic(fit, S)

    def statistic(self, fit: FitResult, S: np.ndarray) -> stats.WaldResult:
        e = (fit.resid_est * self.w).ravel()
        return stats.added_terms_test(e, fit.jac, S, basis=self._basis(fit))

    def _basis(self, fit: FitResult) -> np.ndarray:
        """:func:`stats.column_basis` of the fit's Jacobian, computed once per fit (every hypothesis'
        test projects on it); call it before threads share it. Kept for the last few fits: the nominal
        model's adequacy rows run in a side thread while the loop tests the current fit (:meth:`_run`),
        and one slot would make the two recompute each other's basis in turn."""
        with self._basis_lock:
            hit = self._basis_cache.get(id(fit))
        if hit is None or hit[0] is not fit:
            hit = (fit, None if fit.jac is None else stats.column_basis(fit.jac))
            with self._basis_lock:
                while len(self._basis_cache) >= 4:
                    self._basis_cache.pop(next(iter(self._basis_cache)))
                self._basis_cache[id(fit)] = hit
        return hit[1]

    ROUGH_TIMES = 2        # a rough simulation's test step is widened at most this many times (fit.stable_quotient)

    def sensitivity(self, fit: FitResult, hyp: Hypothesis, X: np.ndarray) -> np.ndarray | None:
        """(n_est·ny, q) finite-difference output sensitivities (weighted) of the hypothesis'
        coefficients at their null; None when it cannot be simulated or has no effect.

        A model with sign() of a state (Coulomb friction) is a rough simulation: fixed-step RK4 across
        the switch of sign(v) gives a step whose result jumps when an intermediate stage's v changes sign,
        so the simulated output is a discontinuous function of the parameters (jumps of about 1e-4 on the
        mass–spring–damper, 3 % of the residual's RMS). A forward difference then carries that jump over
        h: with h = 1e-5 the column of a 1.3 Hz disturbance force had an RMS of 17 and explained 0.2 % of a
        residual whose 1.3 Hz line holds 7 %; with h = 0.05 its RMS was 0.017 and it explained 7 %. For
        such a current model each column is the stable quotient of :func:`pipeline.fit.stable_quotient`
        (the step widened 10× while that changes it by more than 10 %, at most ``ROUGH_TIMES`` times;
        Moré & Wild 2011, "Estimating derivatives of noisy simulations"). Not for a hypothesis that
        adds sign(v) to a smooth model: widened there, the friction column of the ball-and-beam record
        became a secant over a large step, and its p-value rose from 5e-5 to 2e-3."""
        m0 = self.hyp_model(fit, hyp)
        x0 = self._x0_for(fit, m0)
        if self._null_is_current(hyp):
            base = fit.Yhat[self.prob.split.est[0]:self.prob.split.est[1]]
        else:
            base = self._sim_est(m0, x0)
        if base is None:
            return None
        resume = hyp.acts_from is not None and self._null_is_current(hyp)
        # the current model's sign(state) with a coefficient makes the simulation rough; a hypothesis adding
        # one at its null does not (at c = h the switches move by O(h): the quotient is a derivative)
        rough = switches(fit.model)

        def column(c: str, h: float) -> np.ndarray | None:
            null = float(hyp.null.get(c, 0.0))
            mh = self.hyp_model(fit, hyp, {c: null + h})
            if resume:
                after = REGISTRY[hyp.family].settled(fit.model, hyp, {c: null + h})
                Yh = self._sim_est_from(mh, fit, hyp.acts_from, after)
            else:
                Yh = self._sim_est(mh, x0)
            return None if Yh is None else (((Yh - base) * self.w).ravel()) / h

        cols = []
        for c in hyp.coefs:
            col = stable_quotient(lambda h: column(c, h), self._step(fit, hyp, c, X),
                                  times=self.ROUGH_TIMES if rough else 0)
            if col is None:
                return None
            cols.append(col)
        S = np.column_stack(cols)
        if not np.all(np.isfinite(S)) or not np.any(S):
            return None
        return S

    def screened_out(self, fit: FitResult, hyps: list[Hypothesis], sens: list) -> set[int]:
        """Hypotheses that share ``info['screen_group']`` (a jump's grid of times for one parameter) get
        the full added-term test only for the one whose sensitivities explain the largest share of the
        residual by ordinary least squares beyond the current parameters' (R² of e on S⊥, S⊥ = (I − J J⁺) S),
        or the ``info['screen_keep']`` largest (a periodic disturbance's scanned frequencies);
        the others are not tested (ids returned). The family's p-value stays Bonferroni over *all* its
        hypotheses: the tested one's p is at least the smallest p of the group, so min p × m still
        bounds the family's size by α (Bonferroni 1936), and the share explained is what picks the
        refitted representative anyway. On Silverbox this is 16 tests instead of 192 (each ~0.1 s on
        90 000 rows)."""
        groups: dict = {}
        for h, S in zip(hyps, sens):
            g = h.info.get("screen_group")
            if g is not None and S is not None:
                groups.setdefault((h.family, g), []).append((h, S))
        if not groups:
            return set()
        e = (fit.resid_est * self.w).ravel()
        J = fit.jac if fit.jac is not None and fit.jac.size else None
        Q = np.linalg.qr(J)[0] if J is not None else None
        ee = float(e @ e) or 1.0
        out: set[int] = set()
        for items in groups.values():
            if len(items) < 2:
                continue
            share = []
            for h, S in items:
                Sp = S - Q @ (Q.T @ S) if Q is not None else S
                b = np.linalg.lstsq(Sp, e, rcond=None)[0]
                share.append(float(np.sum((Sp @ b) ** 2)) / ee)
            n_keep = max(1, int(items[0][0].info.get("screen_keep", 1)))
            keep = set(np.argsort(-np.asarray(share), kind="stable")[:n_keep])
            out |= {id(h) for i, (h, _) in enumerate(items) if i not in keep}
        return out

    # -- refits ------------------------------------------------------------------------------------
    def refit(self, fit: FitResult, cand: Candidate) -> FitResult | None:
        """The family's model refitted from the Wald estimate; retried from 1/2, 1/4 and 0 of that
        step when the refit diverges; None (with the reasons in ``cand.reason``) when every start fails."""
        hyp = cand.hyp
        fam = REGISTRY[hyp.family]
        beta = cand.wald.beta if cand.wald is not None else np.zeros(len(hyp.coefs))
        why, best, tried = [], None, set()
        for scale in (1.0, 0.5, 0.25, 0.0):
            start = {c: float(hyp.null.get(c, 0.0)) + scale * float(b) for c, b in zip(hyp.coefs, beta)}
            try:
                m = fam.refit_model(fit.model, hyp, start)
                key = tuple(sorted(m.params.items()))
                if key in tried:          # the family's refit model does not depend on this start
                    continue
                tried.add(key)
                if m.extra_states:
                    m = replace(m, initial=dict(m.initial))
                f = self.budgeted_fit(fit, m)
            except (InputError, np.linalg.LinAlgError, ArithmeticError) as exc:
                why.append(f"from {scale:g} x the test's estimate: {exc}")
                continue
            if best is None or f.sse_w < best.sse_w:
                best = f
            # a refit that ends above the current model's error stopped in a worse local minimum than
            # the null it nests: start again closer to the null
            if f.sse_w <= fit.sse_w * (1 + 1e-9):
                return f
            why.append(f"from {scale:g} x the test's estimate: ended above the current model's error")
        if best is None:
            cand.reason = "refit failed " + "; ".join(why)[:600]
        return best

    def budgeted_fit(self, fit: FitResult, m: Model) -> FitResult:
        """An extension ``m`` of ``fit`` refitted from ``fit``'s initial state, abandoned
        (:class:`RefitAbandoned`, an :class:`InputError`) if still above ``fit``'s error after about
        ``REFIT_BUDGET_ITERATIONS`` iterations; compiled on a long record (:meth:`_compiled_if_long`)."""
        m = self._compiled_if_long(m)
        return fit_output_error(m, self.prob, start=estimated_x0(fit), abandon_above=fit.sse_w * (1 + 1e-9),
                                abandon_after=REFIT_BUDGET_ITERATIONS * (len(m.free) + 2))

    def estimate(self, fit: FitResult, cand: Candidate) -> FitResult | None:
        """The candidate's extension refitted on ``fit``: the family's own ``estimate`` or :meth:`refit`.
        Both read only the hypothesis and its added-term test and write only ``cand.reason``, so a
        likelihood-ratio screen's refit of the same hypothesis from the same test on the same fit, not
        taken by :meth:`_lr_screen`, is this result: it is returned (with its reason) instead of being
        computed again (on Silverbox a delay profile and its refit in each of two rounds, about 120
        simulations)."""
        hit = self._screen_refits.pop((id(fit), id(cand.hyp), id(cand.wald)), None)
        if hit is not None:
            f, why = hit[-2:]
            if why:
                cand.reason = why
            return f
        fam = REGISTRY[cand.hyp.family]
        try:
            if hasattr(fam, "estimate"):
                return fam.estimate(self, fit, cand)
            return self.refit(fit, cand)
        except (InputError, np.linalg.LinAlgError, ArithmeticError) as exc:  # rejected, not fatal
            cand.reason = f"refit failed: {exc}"
            return None

    # -- one iteration -----------------------------------------------------------------------------
    def context(self, fit: FitResult, f_hz: float | None, first_round: bool = False) -> Context:
        prob = self.prob
        return Context(fit.model, Structure.of(fit.model), prob.t, prob.U, prob.Y, prob.out_names,
                       states_full(fit.model, prob, fit.x0), prob.split.est, self.dt, f_hz, self.couplings,
                       long_record=self._long(fit.model), first_round=first_round,
                       resid=fit.resid_est * self.w)

    def candidates(self, fit: FitResult, f_hz: float | None, fisher: stats.TestResult,
                   first_round: bool = False) -> tuple[list[Candidate], list]:
        self._screen_refits.clear()       # a round's screen refits serve that round's candidates only
        ctx = self.context(fit, f_hz, first_round)
        out = []
        fams = [(fam, REGISTRY[fam].hypotheses(ctx)) for fam in self.families
                if fam in REGISTRY and REGISTRY[fam].stage == "structural"]
        # the tests are independent simulations: run them in threads (the kernel releases the GIL);
        # results are collected in the hypotheses' order, so the outcome does not depend on scheduling
        flat = [h for _, hyps in fams for h in hyps]
        if any(h.acts_from is not None for h in flat):
            self._current_states(fit)     # once, before the threads share it
        grouped = {id(h) for h in flat if h.info.get("screen_group") is not None}
        self._basis(fit)                  # once, before the threads share it

        def sens_and_test(h):
            """A hypothesis' sensitivities, and its test at once unless a screen group must rank it first."""
            S = self.sensitivity(fit, h, ctx.X)
            return S, (None if S is None or id(h) in grouped else self.statistic(fit, S))

        # a likelihood-ratio screen's hypothesis (_lr_screen) gets its test and its refit in one job, the
        # round's longest: submitted first, it runs beside the other tests instead of after them on one core
        # a lazy one (``info['lr_lazy']``: a date search per parameter, as costly as the rest of the round)
        # is tested as the others are, and refitted for its LR test only when no family is significant
        # (:meth:`_lazy_lr`): the LR screen looks harder where the linearised tests found nothing
        lr_hyps = [h for h in flat if h.info.get("lr_screen") and not h.info.get("lr_lazy")]
        rest = [h for h in flat if not h.info.get("lr_screen") or h.info.get("lr_lazy")]
        with ThreadPoolExecutor(max_workers=max(1, min(len(flat), os.cpu_count() or 1))) as pool:
            lr_jobs = [pool.submit(self._lr_refit, fit, h, ctx.X) for h in lr_hyps]
            both = list(pool.map(sens_and_test, rest))
            sens = [S for S, _ in both]
            skip = self.screened_out(fit, rest, sens)
            wait = [(h, S) for h, S in zip(rest, sens) if id(h) in grouped and id(h) not in skip and S is not None]
            late = dict(zip([id(h) for h, _ in wait], pool.map(lambda hs: self.statistic(fit, hs[1]), wait)))
            results = {id(h): (late.get(id(h)) if id(h) in grouped else wr) for h, (_, wr) in zip(rest, both)}
            lr_done = {}
            for h, j in zip(lr_hyps, lr_jobs):
                results[id(h)], lr_done[id(h)] = j.result()
        sens_of = {id(h): S for h, S in zip(rest, sens)}
        members = []                      # (representative, its sensitivities or None, multiplicity)
        for fam, hyps in fams:
            tested = [(h, results[id(h)]) for h in hyps if results[id(h)] is not None]
            if not tested:
                continue
            # the family's test: the smallest p over its hypotheses, Bonferroni over their number. Its
            # representative (the one refitted): among the hypotheses significant at that level, the
            # one explaining the largest share of the residual (the linearised R² approximates the
            # refit's SSE drop; the largest statistic can belong to a smaller but sharper effect, e.g.
            # h*u over sqrt(h) on a Torricelli tank); otherwise the largest statistic per dof
            p_min = min(wr.p_value for _, wr in tested)
            sig = [(h, wr) for h, wr in tested if wr.p_value * len(hyps) < self.alpha]
            h, wr = (max(sig, key=lambda x: x[1].r2) if sig
                     else max(tested, key=lambda x: x[1].statistic / max(x[1].dof, 1)))
            best = Candidate(h, wr, 1.0, [_wald_evidence(h, wr)])
            best.p_family = min(1.0, p_min * len(hyps))
            best = self._lr_screen(fit, fam, hyps, results, best, lr_done)
            if fam == "periodic_disturbance":
                n_est = self.prob.split.est[1] - self.prob.split.est[0]
                n_freq = periodic_n_lines(n_est, any("scan_hz" in x.info for x in hyps))
                # Bonferroni over the equations here: the frequencies searched are counted by the line
                # test's factor n_freq (families.periodic_disturbance)
                best.p_family = min(1.0, p_min * len({x.equation for x in hyps}))
                best.evidence.append({"test": "fisher_g", "statistic": fisher.statistic,
                                      "p_value": fisher.p_value})
                # the line test beside Fisher's g (families.periodic_disturbance): the family's p is the
                # smaller of the two, doubled; both rows are shown so the evidence says which decided
                h_min, w_min = min(tested, key=lambda x: x[1].p_value)
                f_min = float(next(iter(h_min.extra_params.values())))
                best.evidence.append({"test": "periodic_line_test", "statistic": w_min.statistic,
                                      "p_value": periodic_line_p(best.p_family, n_freq),
                                      "detail": f"smallest added-term Wald p of {len(tested)} proposed frequencies "
                                                f"(at {f_min:.5g} Hz, equation {h_min.equation}) x {n_freq} "
                                                "frequencies searched (Bonferroni)"})
                best.p_family = periodic_p_value(best.p_family, fisher.p_value, n_freq)
            if fam == "input_delay":
                best.evidence += [self._xcorr_lag(fit, best.hyp.input, i) for i in range(len(self.prob.out_names))]
            ee = self._equation_error_evidence(fit, best.hyp)
            if ee:
                best.evidence.append(ee)
            best.places = len({self._where(x) for x in hyps})
            out.append(best)
            members.append((best, sens_of.get(id(best.hyp)),
                            n_freq * len({x.equation for x in hyps}) if fam == "periodic_disturbance" else len(hyps)))
            if sig and best.hyp is h:
                tie = [replace(c, places=best.places) for c in self._near_tie(fit, h, wr, sig, best.p_family)]
                out += tie
                best.alternates = self._alternates(h, wr, sig, [c.hyp for c in tie])
        self._round = (fit, ctx, fams, results)
        self._members = (fit, ctx, members)
        return self._lazy_lr(fit, ctx, fams, results, out), ctx.skipped

    def _held_out(self, base: FitResult, before: np.ndarray, fit: FitResult, searched: int,
                  rng) -> tuple[dict, stats.TestResult, bool]:
        """``fit``'s held-out gain over ``base`` (whose validation residuals are ``before``), pooled over
        outputs, its likelihood-ratio test against ``base`` with the effective sample size, and the rule
        that accepts an extension: the gain's 95 % lower bound above 0 and LR p below α."""
        g = pooled(gain_ci(before, gain_resid(fit, self.prob), rng, self.n_boot), before.shape[1])
        lr = lr_against(base, fit, self.alpha, searched)
        return g, lr, g["ci95"][0] > 0 and lr.p_value < self.alpha

    def _weigh(self, c: Candidate, current: FitResult, before: np.ndarray, bic0: float, rng) -> None:
        """A refitted candidate's held-out gain, ΔBIC and likelihood-ratio test against ``current``, and
        its acceptance: the gain's 95 % lower bound above 0 and LR p below α."""
        if c.fit is None:
            c.reason = c.reason or "no extension estimated"
            return
        c.gain, lr, c.accepted = self._held_out(current, before, c.fit, len(c.hyp.searched), rng)
        c.lr = lr
        c.delta_bic = bic_of(c.fit, len(c.hyp.searched)) - bic0
        c.reason = "accepted" if c.accepted else (
            "validation error not lower with 95 % confidence" + unbounded_note(c.gain) if c.gain["ci95"][0] <= 0
            else f"estimation fit not better by the likelihood-ratio test with the effective sample size "
                 f"(p = {lr.p_value:.3g}; {lr.detail})")
        _log(f"  {c.hyp.key}: gain {c.gain['relative']:+.3f} ci {c.gain['ci95'][0]:+.3f}.."
             f"{c.gain['ci95'][1]:+.3f}, dBIC {c.delta_bic:+.1f} -> {c.reason}")

    def second_chance(self, fit: FitResult, out: list[Candidate]) -> list[Candidate]:
        """The round's lazy likelihood-ratio screen (:meth:`_lazy_lr`) after all, when some family was
        significant (so it did not run) but no candidate was accepted: the candidates of the families it
        changed (a new p-value and refit), to be weighed as the round's were. Empty when it ran already,
        or has nothing to add. On a thermal record whose loss coefficient jumps 0.5 -> 0.9 at 80 s, a
        drift of a was significant and rejected (LR p 0.13, N_eff 2.5), the jump's Wald test was not, and
        the run ended unexplained with the jump never refitted."""
        r = self._round
        if r is None or r[0] is not fit:
            return []
        _, ctx, fams, results = r
        self._round = None
        new = self._lazy_lr(fit, ctx, fams, results, list(out), force=True)
        return [c for c, o in zip(new, out) if c is not o]

    def _lazy_lr(self, fit: FitResult, ctx: Context, fams: list, results: dict, out: list[Candidate],
                 force: bool = False) -> list[Candidate]:
        """When no family is significant after Holm correction (or ``force``, :meth:`second_chance`), the
        families' lazy likelihood-ratio hypotheses (``info['lr_lazy']``) are refitted (in threads) and
        their families' candidates pass :meth:`_lr_screen` again with them."""
        lazy = [h for _, hyps in fams for h in hyps if h.info.get("lr_lazy")]
        firsts = [c for c in out if not c.runner_up]
        if not lazy:
            return out
        if not force and any(stats.holm({c.hyp.family: c.p_family for c in firsts}, self.alpha).values()):
            return out
        self._round = None          # ran: no second chance
        with ThreadPoolExecutor(max_workers=max(1, min(len(lazy), os.cpu_count() or 1))) as pool:
            done = dict(zip([id(h) for h in lazy], pool.map(lambda h: self._lr_refit(fit, h, ctx.X), lazy)))
        res = dict(results)
        res.update({k: wr for k, (wr, _) in done.items()})
        refits = {k: fr for k, (_, fr) in done.items()}
        for fam, hyps in fams:
            if not any(h.info.get("lr_lazy") for h in hyps):
                continue
            i = next((j for j, c in enumerate(out) if c.hyp.family == fam and not c.runner_up), None)
            if i is not None:
                new = self._lr_screen(fit, fam, hyps, res, out[i], refits)
                new.places = out[i].places
                out[i] = new
        return out

    FALLBACK_SHARE = 0.5   # after a failed refit: the family's hypotheses explaining this share of its
    MAX_FALLBACKS = 3      # representative's, at most this many, are refitted instead
    MAX_ALTERNATES = 3     # a family of alternative forms: this many more refits, largest share first

    def _alternates(self, h: Hypothesis, wr, sig: list, taken: list[Hypothesis]) -> list:
        """The family's other significant hypotheses, largest linearised share first, one per column
        (h*abs(h) is h**2 on a positive level) and one per place (a lag or a limit at another grid value
        is the same place: the refit frees the value), without the representative and its near tie
        (``taken``): what :meth:`_fallbacks` may refit."""
        seen = [wr] + [w for h2, w in sig if any(h2 is t for t in taken)]
        places = {self._where(h)}      # not the same place at another grid value: its refit frees that value
        out = []
        for h2, w2 in sorted(sig, key=lambda x: -x[1].r2):
            if h2 is h or any(h2 is t for t in taken) or any(_same_column(w2, w) for w in seen) \
                    or self._where(h2) in places:
                continue
            places.add(self._where(h2))
            seen.append(w2)
            out.append((h2, w2))
        return out

    def _fallbacks(self, todo: list[Candidate]) -> list[Candidate]:
        """More of a family's significant hypotheses to refit (from :meth:`_alternates`), as candidates
        with the family's p-value:

        * the ``MAX_ALTERNATES`` largest, beside a refitted representative, for a family of alternative
          forms (``Family.refit_alternates``, the static-term library): the linearised share ranks forms
          only near the current fit. On a tank with square-root outflow fitted as linear, sqrt(h)
          explains under half of h**2's share there, yet its refit is the cause (coefficient within
          2 %). Not on a long record (:meth:`_long`; Silverbox: 4 s more for the same findings), where
          the representative and its near tie stand for the family as before;
        * after a representative's refit failed from every start (it diverged, or ended above the
          current model's error) or its family rejected the refitted form ("refit rejected": a coupled
          state faster than the samples), the next ones explaining at least ``FALLBACK_SHARE`` of its
          share, at most ``MAX_FALLBACKS``: the first-ranked hypothesis can be one that cannot be
          simulated (c·h² with c > 0 runs away on that tank)."""
        out = []
        for c in todo:
            forms = REGISTRY[c.hyp.family].refit_alternates
            failed = c.fit is None and c.reason.startswith(("refit failed", "refit rejected"))
            if failed and not forms:
                alts = [(h2, w2) for h2, w2 in c.alternates
                        if w2.r2 >= self.FALLBACK_SHARE * c.wald.r2][:self.MAX_FALLBACKS]
                if alts:
                    c.reason += ("; the family's next significant hypotheses refitted instead: "
                                 + ", ".join(h2.key for h2, _ in alts))
            elif forms and (failed or (c.fit is not None and not self._long(c.fit.model))):
                alts = c.alternates[:self.MAX_ALTERNATES]
            else:
                continue
            out += [Candidate(h2, w2, c.p_family, [_wald_evidence(h2, w2)], runner_up=True, places=c.places)
                    for h2, w2 in alts]
        return out

    WITHIN_TIE = 0.8   # a family's runner-up explaining this share of its best hypothesis' is refitted too

    @staticmethod
    def _where(h: Hypothesis) -> tuple:
        return (h.equation, h.term, h.input, h.parameter, h.state, h.output)

    def _near_tie(self, fit: FitResult, h: Hypothesis, wr, sig: list, p_family: float) -> list[Candidate]:
        """The family's significant hypothesis acting elsewhere (another term, parameter, input, state or
        output; not the same one at another grid value, whose refit frees that value anyway) that
        explains at least ``WITHIN_TIE`` of the representative's linearised share, as a second
        candidate with the family's p-value. The linearised R² only approximates the refit's SSE
        drop, and a near tie can reverse in the refit: on a Torricelli tank sqrt(h) explained 0.58
        against h**2's 0.69 and only the refit tells them apart; a tank's jump in b against one in a."""
        rest = [(h2, w2) for h2, w2 in sig if self._where(h2) != self._where(h) and not _same_column(w2, wr)
                and w2.r2 >= self.WITHIN_TIE * wr.r2]
        if not rest:
            return []
        h2, w2 = max(rest, key=lambda x: x[1].r2)
        c = Candidate(h2, w2, p_family, [_wald_evidence(h2, w2)], runner_up=True)
        ee = self._equation_error_evidence(fit, h2)
        if ee:
            c.evidence.append(ee)
        return [c]

    def state_probe(self, fit: FitResult) -> list[stats.TestResult]:
        """The ``state_nonlinearity`` adequacy row (:mod:`.state_probe`): the most significant of the
        (equation, state) probes, its p Bonferroni over them, its share of the residual as ``r2``; no row
        when no probe can be simulated."""
        if "static_nonlinearity" not in REGISTRY:
            return []
        ctx = self.context(fit, None)
        res = []
        for h in probe_hypotheses(ctx):
            # one bump per simulation: the other bumps' terms at their null add exactly 0, so the columns are
            # those of the joint hypothesis, at a fifth of the interpreted terms per simulation
            cols = [self.sensitivity(fit, replace(h, key=f"{h.key}:{i}", terms=[t], coefs=[c]), ctx.X)
                    for i, (t, c) in enumerate(zip(h.terms, h.coefs))]
            if all(S is not None for S in cols):
                S = stats.determined(np.column_stack(cols), self._basis(fit))
                if S.shape[1]:
                    res.append((h, self.statistic(fit, S)))
        if not res:
            return []
        h, w = min(res, key=lambda x: x[1].p_value)
        self._probe_best[id(fit)] = (fit, h, w)      # for probe_refit (the nominal's runs in another thread)
        p = float(min(1.0, w.p_value * len(res)))
        lo, hi = h.info["range"]
        return [stats.TestResult(
            PROBE_NAME, w.statistic, p, None, p >= self.alpha,
            f"{probe_what(h)} (centres {lo:.4g} to {hi:.4g}) added to {probe_where(h)}, "
            f"HAC Wald test of {w.dof} directions beyond the current parameters, Bonferroni over {len(res)} places (equation-state "
            f"pairs and measured states); they explain {100 * w.r2:.2g} % of the residual", r2=w.r2)]

    def probe_refit(self, fit: FitResult) -> stats.TestResult | None:
        """The ``state_nonlinearity`` probe refitted: before the noise families may explain a coloured
        residual, the most significant probe's Gaussian bumps (:meth:`state_probe`) are refitted by
        output error from their added-term estimate and judged on the validation part, as an extension's
        gain is (:func:`gain_ci`): the row fails when the 95 % interval of the gain lies above 0 and the
        validation mean square falls by at least ``MATERIAL_R2``. The colour is then a misfit of the
        structure that no family names, not the noise's, and the verdict is unexplained. The
        likelihood-ratio test with the effective sample size is shown, not required: where the bumps
        do not fully explain the misfit, their residual stays smooth and N_eff falls to a few samples
        (lag-1 autocorrelation 0.995, N_eff = 3.7 on one x·exp(−x²) record), and the decision rests on
        the held-out gain. Only when the linearised probe explains at least
        ``PROBE_REFIT_MIN_SHARE`` of the residual (a cost gate; the decision is the held-out test's).

        Why: on a very smooth residual (lag-1 autocorrelation 0.997) the linearised probe has few
        effective degrees of freedom; an x·exp(−(x/0.28)²) spring term (an independent-bench record,
        2 % white noise) left it at p = 0.04 and the run named ``colored_noise``, while the refitted
        bumps lower the validation RMSE from 0.281 to 0.0075. None when there is no probe on this fit,
        it explains too little, or its refit fails."""
        best = self._probe_best.get(id(fit))
        if best is None or best[0] is not fit:
            return None
        _, h, w = best
        if w.r2 < PROBE_REFIT_MIN_SHARE:
            return None
        cand = Candidate(h, w, 1.0, [])
        try:
            f = self.refit(fit, cand)
        except (InputError, np.linalg.LinAlgError, ArithmeticError):   # SimulationError is an InputError
            return None
        if f is None:
            return None
        before = gain_resid(fit, self.prob)
        g = gain_ci(before, gain_resid(f, self.prob), one_sided=True)
        lr = lr_against(fit, f, self.alpha)
        share = 1.0 - (g["after"] / g["before"]) ** 2 if g["before"] > 0 else 0.0
        fails = g["ci95"][0] > 0 and share >= MATERIAL_R2
        lo, hi = h.info["range"]
        return stats.TestResult(
            PROBE_NAME + "_refit", float(g["relative"]), float(g.get("p_not_lower", 1.0)), None, not fails,
            ("a static function of " + h.state + " that no family's term holds acts in " + probe_where(h)
             + ": " if fails else "") +
            f"{probe_what(h)} (centres {lo:.4g} to {hi:.4g}) in {probe_where(h)}, "
            f"refitted: validation RMSE (free run) {g['before']:.4g} -> {g['after']:.4g} "
            f"({100 * g['relative']:+.1f} %, 95 % interval {100 * g['ci95'][0]:+.1f} to {100 * g['ci95'][1]:+.1f} %; "
            f"the mean square {100 * share:+.1f} %); likelihood-ratio p = {lr.p_value:.3g} on the estimation part "
            f"({lr.detail})", r2=max(share, 0.0))

    def _lr_refit(self, fit: FitResult, h: Hypothesis, X: np.ndarray) -> tuple:
        """(Wald result, (refit, reason)) of an ``lr_screen`` hypothesis: its added-term test, and the
        family's refit started from that test's estimate, with the reason the refit gave when it set one
        (a failed refit's)."""
        S = self.sensitivity(fit, h, X)
        wr = None if S is None else self.statistic(fit, S)
        c = Candidate(h, wr, 1.0, [])
        return wr, (self.estimate(fit, c), c.reason)

    def _lr_screen(self, fit: FitResult, fam: str, hyps: list, results: dict, best: Candidate,
                   done: dict | None = None) -> Candidate:
        """A family may mark hypotheses ``info['lr_screen']``: a large, strongly nonlinear effect (a hard
        end stop), a delay of many samples, a parameter's jump at a searched date, whose linearised
        added-term test has little power. Each is refitted now and tested by the likelihood-ratio test
        with the effective sample size (:func:`lr_against`; ``info['lr_extra_dof']`` more χ² degrees of
        freedom, or ``info['lr_law'] == 'break'``: the supremum over a break date,
        :func:`stats.sup_lr_break_p` with ``info['trim']``). The family's p-value is Bonferroni over its
        Wald test and these k tests, (k + 1)·min(p), and the candidate is the one whose test is smallest
        (its refit kept) if its refit explains at least ``MATERIAL_R2`` of the residual. ``done``: the refits
        :meth:`_lr_refit` computed beside the other tests."""
        lr_hs = [h for h in hyps if h.info.get("lr_screen") and (not h.info.get("lr_lazy") or (done and id(h) in done))]
        if not lr_hs:
            return best
        k = len(lr_hs) + 1
        best.p_family = min(1.0, k * best.p_family)
        out = best
        for lr_h in lr_hs:
            wr = results.get(id(lr_h))
            cand = Candidate(lr_h, wr, 1.0, [])
            f, why = done[id(lr_h)] if done and id(lr_h) in done else (self.estimate(fit, cand), cand.reason)
            # the LR route is for a large effect whose linearised test lacks power: a refit explaining
            # less than the adequacy threshold of the residual is not one, and there the effective sample
            # size from the lag-1 autocorrelation can overstate the evidence of a residual coloured at
            # longer lags (a jump fitted to 0.24 % of a Coulomb model's residual: LR p = 6e-5)
            if f is None or f.sse_w > (1.0 - MATERIAL_R2) * fit.sse_w:
                self._screen_refits[(id(fit), id(lr_h), id(wr))] = (fit, lr_h, wr, f, why)
                continue
            if lr_h.info.get("lr_law") == "break":
                lr = lr_against(fit, f, self.alpha, break_trim=float(lr_h.info["trim"]))
            else:
                lr = lr_against(fit, f, self.alpha, len(lr_h.searched) + int(lr_h.info.get("lr_extra_dof", 0)))
            p = min(1.0, k * lr.p_value)
            if p >= out.p_family:
                self._screen_refits[(id(fit), id(lr_h), id(wr))] = (fit, lr_h, wr, f, why)
                continue
            cand.fit, cand.p_family = f, p
            if wr is not None:
                cand.evidence.append(_wald_evidence(lr_h, wr))
            else:
                cand.wald = best.wald
            cand.evidence.append({"test": f"likelihood_ratio_neff[{lr_h.key}]", "statistic": lr.statistic,
                                  "p_value": lr.p_value, "detail": lr.detail})
            out = cand
        return out

    def _xcorr_lag(self, fit: FitResult, input_name: str | None = None, i: int = 0) -> dict:
        """Lag (samples, parabola-refined) that maximises the cross-correlation of measured output ``i``
        with its nominal simulation on the estimation part: > 0 when the measurement lags the
        simulation, i.e. a dead time. p-value: the residual–input cross-correlation test of that output,
        with the delayed input (the first when every input is). The first output's row has the plain
        name, the others' are tagged ``[y]``."""
        sl = self.prob.split.est_slice()
        y = self.prob.Y[sl, i] - self.prob.Y[sl, i].mean()
        yh = fit.Yhat[sl, i] - fit.Yhat[sl, i].mean()
        n = len(y)
        kmax = max(1, min(int(round(self.max_delay / self.dt)), n // 4))
        # zero-padded to a fast FFT length ≥ 2N (any length ≥ 2N − 1 gives the linear correlation; 2N
        # itself can have a large prime factor: Silverbox's 180 844 = 4·29·1559)
        m = stats._fast_len(2 * n)
        f = np.fft.irfft(np.fft.rfft(y, m) * np.conj(np.fft.rfft(yh, m)), m)
        lags = np.arange(-kmax, kmax + 1)
        c = np.array([f[k] if k >= 0 else f[m + k] for k in lags])
        k = int(np.argmax(c))
        shift = 0.0
        if 0 < k < len(c) - 1:
            den = c[k - 1] - 2 * c[k] + c[k + 1]
            shift = float(np.clip(0.5 * (c[k - 1] - c[k + 1]) / den, -0.5, 0.5)) if den != 0 else 0.0
        j = fit.model.inputs.index(input_name) if input_name else 0
        xc = stats.input_crosscorr(fit.resid_est[:, i], self.prob.U[sl, j], 25, self.alpha)
        tag = f"[{self.prob.out_names[i]}]" if i else ""
        return {"test": f"output_simulation_crosscorrelation_lag{tag}", "statistic": float(lags[k] + shift),
                "p_value": xc.p_value, "detail": "lag in samples (biased toward 0: the fitted nominal partly compensates a delay); "
                          "p from the residual-input cross-correlation"}

    def _equation_error_evidence(self, fit: FitResult, hyp) -> dict | None:
        """When every state is measured: regress the equation error ẋ − f(x, u; θ̂) of the hypothesis'
        equation (ẋ by a Savitzky–Golay derivative, window 7, order 2) on the candidate term evaluated
        on the measured states; HAC Wald test of the slope (intercept partialled out). Not for a term of a
        new (unmeasured) state."""
        m = fit.model
        prob = self.prob
        if hyp.equation is None or m.extra_states or hyp.extra_states \
                or not all(st in prob.out_names for st in m.states):
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

    @staticmethod
    def _screen(todo: list[Candidate]) -> list[Candidate]:
        """The fired candidates worth a full refit: those whose added-term test explains at least
        ``REFIT_SHARE`` of the residual share the best one explains (the linearised R² of the test
        approximates the refit's SSE drop, ΔBIC ≈ N ln(1 − R²)), at most ``MAX_REFITS`` of them. A
        candidate explaining a fifth of the best one's share cannot have the lowest ΔBIC unless its
        linearisation is far off; each one left out says so in the history. The cap counts families:
        a family's near-tie runner-up is refitted with its representative and takes no other family's
        place."""
        if len(todo) <= 1:
            return todo
        # refitted by their screen already (no cost), or of a family whose linearised R² understates
        # its refit (Family.screened False, e.g. a delay of several samples): always kept
        always = [c for c in todo if not c.runner_up and (c.fit is not None or not REGISTRY[c.hyp.family].screened)]
        seconds = [c for c in todo if c.runner_up]
        todo = [c for c in todo if not c.runner_up and c.fit is None and REGISTRY[c.hyp.family].screened]
        best = max([_share(c.wald) for c in todo] or [0.0])
        ranked = sorted(todo, key=lambda c: -_share(c.wald))
        keep = [c for c in ranked if _share(c.wald) >= REFIT_SHARE * best][:MAX_REFITS]
        kept = {id(c) for c in keep}      # by identity: Candidate's dataclass equality compares arrays
        for c in todo:
            if id(c) not in kept:
                c.reason = (f"not refitted: its added terms explain {100 * _share(c.wald):.2g} % of the residual, "
                            + (f"under {REFIT_SHARE:g} x the {100 * best:.2g} % of the strongest candidate"
                               if _share(c.wald) < REFIT_SHARE * best else
                               f"and {MAX_REFITS} candidates explain more"))
        fams = {c.hyp.family for c in always + keep}
        for c in seconds:
            if c.hyp.family not in fams:
                c.reason = "not refitted: its family's representative was not refitted"
        return always + [c for c in todo if id(c) in kept] + [c for c in seconds if c.hyp.family in fams]

    def run(self, model: Model, start: dict | None = None) -> Diagnosis:
        """The diagnosis loop (module docstring). The hypotheses' tests and refits run in threads (the
        kernel releases the GIL), so BLAS runs one thread per call meanwhile: with OpenBLAS's own
        threads on top, the two pools oversubscribed the cores and Silverbox took 58 s instead of 38 s.
        One BLAS thread also makes the linear algebra's rounding independent of the machine's cores."""
        with threadpool_limits(limits=1, user_api="blas"):
            return self._run(model, start)

    NOMINAL_MARGIN = 1e-6   # relative SSE by which the config-start fit must beat the equation-error one

    # simulated steps (samples x substeps) from which an accepted model gets its own compiled kernel
    COMPILE_MIN_STEPS = 200_000

    def _long(self, m: Model) -> bool:
        """A record long enough that each simulation of ``m`` costs milliseconds (compiled kernels pay
        off there): extra refits of alternative forms are skipped on it (:meth:`_fallbacks`)."""
        return len(self.prob.t) * m.substeps >= self.COMPILE_MIN_STEPS

    def _compiled_if_long(self, m: Model) -> Model:
        """A refit's model with its additive terms compiled (as :meth:`_accepted` does, and from the same
        length): a refit runs 20–150 simulations of one structure, so on a long record it pays the
        compile as an accepted model does. Bit-identical to the interpreted model
        (tests/test_simulate.py), so no number changes."""
        return m.compiled() if self._long(m) else m

    def _accepted(self, fit: FitResult) -> FitResult:
        """The accepted fit, whose model every later hypothesis extends: on a long record its extension
        terms are compiled into its own kernel (:meth:`Model.compiled`; the same arithmetic in the same
        order, so the simulation is unchanged to the last bit). Each interpreted term costs about a
        nominal right-hand side (Silverbox with three accepted terms: 45 ms per simulation interpreted,
        9 ms compiled); a compile costs a few seconds once per structure and machine (cached on disk),
        which pays off from about this many simulated steps per simulation."""
        m = self._compiled_if_long(fit.model)
        return fit if m is fit.model else replace(fit, model=m)

    def _fit_nominal(self, model: Model, start: dict | None) -> FitResult:
        """The nominal output-error fit from the equation-error ``start`` and, when there is one, also
        from the config's own parameter values; the lower weighted SSE wins (the equation-error start
        unless the other is lower by ``NOMINAL_MARGIN``). An equation-error estimate is biased by
        whatever the model misses (a 3.6-sample dead time on a two-tank record made it unstable, the
        output-error fit stayed in that basin and the run stopped with "the fitted model fails on this
        record" although the config's values fit). A start whose fit cannot be simulated is dropped;
        when both fail the first error is raised. The two fits are independent and run side by side
        (the kernel releases the GIL): about 0.3 s of Silverbox's nominal stage."""
        if not start:
            return fit_output_error(model, self.prob, partial=True)

        def one(s):
            try:
                return fit_output_error(model, self.prob, start=s, partial=True), None
            except SimulationError as exc:
                return None, exc

        with ThreadPoolExecutor(max_workers=2) as pool:
            done = list(pool.map(one, (start, None)))
        fits = [f for f, _ in done if f is not None]
        errors = [e for _, e in done if e is not None]
        if not fits:
            raise errors[0]
        if len(fits) == 2 and fits[1].sse_w < fits[0].sse_w * (1 - self.NOMINAL_MARGIN):
            _log("  the fit from the config's parameter values is better than from the equation-error start")
            return fits[1]
        return fits[0]

    def _propose(self, current: FitResult, it: int, tests_of, switched: bool) -> Round:
        """One round of the loop on ``current``: every family's added-term tests, Holm across families,
        the screen, the refits (and, until the intersample choice is made, the intersample stage beside
        them), each refit weighed (:meth:`_weigh`), the lazy likelihood-ratio screen when nothing was
        accepted, and the effective ΔBIC."""
        prob = self.prob
        tests, f_cyc = tests_of(current)
        fisher = strongest_fisher(tests)
        cands, skipped = self.candidates(current, f_cyc / self.dt, fisher, first_round=it == 0)
        fired = stats.holm({c.hyp.family: c.p_family for c in cands}, self.alpha)
        last_p = {c.hyp.family: c.p_family for c in cands}
        last_r2 = _family_r2(cands)
        _log(f"iteration {it + 1}: {len(cands)} families tested, fired: "
             f"{[k for k, v in fired.items() if v] or 'none'}")
        rng = np.random.default_rng([self.seed, it])
        before = gain_resid(current, prob)
        bic0 = bic_of(current)
        todo = [c for c in cands if fired[c.hyp.family]]
        for c in cands:
            if not fired[c.hyp.family]:
                c.reason = "not significant after Holm correction"
        todo = self._screen(todo)
        # refits are independent: run them in threads (the kernel releases the GIL), and the
        # intersample stage's refits beside them (it reads only the current fit). A refit that adds a
        # state is submitted first: it is the round's longest (Silverbox's second round: a lag node in
        # the velocity equation 1.8 s, the other refits 0.25-0.45 s each), and started last it ran alone
        # on one core for a second. Each result is the candidate's own, so the order changes no number.
        inter_job = None
        with ThreadPoolExecutor(max_workers=min(len(todo) + (not switched), os.cpu_count() or 1) or 1) as pool:
            def submit(c: Candidate):
                return pool.submit(lambda: c.fit or self.estimate(current, c))
            jobs = {id(c): submit(c) for c in todo if c.hyp.extra_states}
            if not switched:
                _log("  intersample: the current model with the other input interpolation and a finer step")
                inter_job = pool.submit(self.inter.run, current,
                                        np.random.default_rng([self.seed, 1000 + it]))
            jobs.update({id(c): submit(c) for c in todo if id(c) not in jobs})
            for c in todo:
                c.fit = jobs[id(c)].result()
            extra = self._fallbacks(todo)
            for c, f in zip(extra, pool.map(lambda c: self.estimate(current, c), extra)):
                c.fit = f
        cands += extra
        todo += extra
        for c in todo:
            self._weigh(c, current, before, bic0, rng)
        inter = None
        if inter_job is not None:
            f_is, finding_is, hist = inter_job.result()
            if finding_is is not None:
                inter = (f_is, finding_is)
        if inter is None and not any(c.accepted for c in cands):
            more = self.second_chance(current, cands)
            if more:
                _log(f"  nothing accepted: likelihood-ratio screen of {[c.hyp.family for c in more]}")
                swap = {c.hyp.family: c for c in more}
                cands = [swap.pop(c.hyp.family) if not c.runner_up and c.hyp.family in swap else c
                         for c in cands]
                last_p = {c.hyp.family: c.p_family for c in cands if not c.runner_up}
                fired = stats.holm(last_p, self.alpha)
                for c in more:
                    if not fired[c.hyp.family]:
                        c.reason = "not significant after Holm correction (likelihood-ratio screen)"
                        continue
                    if c.fit is None:
                        c.fit = self.estimate(current, c)
                    self._weigh(c, current, before, bic0, rng)
        n_eff = effective_bic(cands, current)
        return Round(cands, skipped, inter, hist if inter_job is not None else None, last_p, last_r2, n_eff)

    def _lookahead(self, current: FitResult, cands: list[Candidate], it: int, tests_of):
        """Two causes at once, when no single extension is accepted: each alone leaves the other's smooth
        misfit in the validation residual, so the interval of its gain (:mod:`.gain`, which counts the
        after-model's residual as noise) is unbounded, although its point gain is large (a dead zone and
        a force offset on an independent record: the offset alone 49 %, 95 % interval −115 % to +88 %;
        with the dead zone the validation RMSE falls 18-fold). Then the best *pending* extension A (by
        :func:`choose`; refitted, positive point gain, likelihood-ratio p below α) is taken as the current
        model for one more round. A is accepted only when that round accepts some B on top of it (the
        usual test: B's gain bounded above 0 given A, LR p below α) *and* A earns its place given B: the
        gain of A+B over B alone (B refitted on the model without A) has its 95 % lower bound above 0
        and A+B beats B by the likelihood-ratio test. Both are then named, each with its gain given the
        other; otherwise nothing is (the loop stops as before). Returns (A, A's accepted fit, B, B's
        round) or None."""
        pending = [c for c in cands if not c.accepted and c.fit is not None and c.gain is not None
                   and c.lr is not None and c.delta_bic is not None and c.delta_bic < 0
                   and c.gain["relative"] > 0 and c.lr.p_value < self.alpha]
        first = choose(pending)
        if first is not None:
            _log(f"  nothing accepted: looking ahead from {first.hyp.key} (validation gain "
                 f"{100 * first.gain['relative']:+.1f} %, its interval not above 0)")
            return self._ahead_from(first, current, cands, it, tests_of)
        for first in self._pair_first(current, cands):
            _log(f"  looking ahead from {first.hyp.key}")
            if first.fit is None:
                first.fit = self.estimate(current, first)
                if first.fit is None:
                    continue
                self._weigh(first, current, gain_resid(current, self.prob), bic_of(current),
                            np.random.default_rng([self.seed, it, 2]))
            ahead = self._ahead_from(first, current, cands, it, tests_of)
            if ahead is not None:
                return ahead
        return None

    def _ahead_from(self, first: Candidate, current: FitResult, cands: list[Candidate], it: int, tests_of):
        """The look-ahead (:meth:`_lookahead`) from the refitted candidate ``first``."""
        first_fit = self._accepted(first.fit)
        rnd = self._propose(first_fit, it + 1, tests_of, switched=True)
        acc = [c for c in rnd.cands if c.accepted]
        second = self.separate(choose(acc), acc)
        if second is None:
            first.reason += f"; {LOOKED_AHEAD}with {first.hyp.key} in the model no further extension was accepted"
            return None
        alone = next((c.fit for c in cands if c.hyp.key == second.hyp.key and c.fit is not None), None)
        if alone is None:
            alone = self.estimate(current, Candidate(second.hyp, second.wald, second.p_family, [],
                                                     start=dict(second.start)))
        if alone is None:
            first.reason += f"; {LOOKED_AHEAD}{second.hyp.key} could not be refitted without it"
            return None
        g, lr, ok = self._held_out(alone, gain_resid(alone, self.prob), second.fit, len(first.hyp.searched),
                                   np.random.default_rng([self.seed, it, 1]))
        worth = (f"given {second.hyp.key}, its validation gain is {100 * g['relative']:+.1f} % "
                 f"(95 % interval {100 * g['ci95'][0]:+.1f} to {100 * g['ci95'][1]:+.1f} %; likelihood-ratio "
                 f"p {p_text(lr.p_value)})")
        _log(f"  look-ahead: {second.hyp.key} accepted on top; {first.hyp.key} {worth}")
        if not ok:
            first.reason += f"; {LOOKED_AHEAD}{worth}, not significantly better"
            return None
        first.accepted = True
        first.reason = f"accepted with {second.hyp.key} (look-ahead): {worth}"
        first.given = {"with": second.hyp.key, "gain": g, "lr_p_value": lr.p_value, "lr_statistic": lr.statistic,
                       "fit": second.fit}
        return first, first_fit, second, rnd

    def _pair_first(self, current: FitResult, cands: list[Candidate]) -> list[Candidate]:
        """The look-ahead's starts when no extension is pending: a family's hypothesis a with which another
        family's b explains at least twice its share alone, and b's added-term test given a significant
        (:mod:`.pairs`, weighted Bonferroni over every ordered hypothesis pair of the round): the two
        hide each other (quadratic damping and Coulomb friction under a refitted linear damping). Each
        such a, smallest p first, with the pair's test added to its evidence; empty when there is none."""
        r = self._members
        if r is None or r[0] is not current or current.jac is None:
            return []
        _, ctx, rows = r
        reps = {c.hyp.family: c for c in cands if not c.runner_up and c.wald is not None}
        chosen, members = [], []
        for old, S, m in rows:
            c = reps.get(old.hyp.family)
            if c is None:
                continue
            if S is None or c.hyp is not old.hyp:       # a likelihood-ratio screen's hypothesis
                S = self.sensitivity(current, c.hyp, ctx.X)
            if S is None:
                continue
            chosen.append(c)
            members.append(Member(c.hyp.key, c.hyp.family, S, m))
        starts: list[Candidate] = []
        for pair in hidden_pairs((current.resid_est * self.w).ravel(), current.jac, self._basis(current),
                                 members, self.alpha):
            a, b = chosen[pair.a], chosen[pair.b]
            if any(c is a for c in starts):
                continue
            _log(f"  nothing accepted, but {b.hyp.key} given {a.hyp.key} is significant (p {p_text(pair.p_value)})")
            a.evidence = a.evidence + [{
                "test": f"pair_wald[{b.hyp.key}|{a.hyp.key}]", "statistic": pair.wald.statistic,
                "p_value": pair.p_value, "dof": pair.wald.dof, "detail": pair.detail(members)}]
            starts.append(a)
        return starts

    def _run(self, model: Model, start: dict | None = None) -> Diagnosis:
        prob = self.prob
        _log(f"fitting the nominal model ({len(model.free)} free parameters, output error)")
        nominal = self._fit_nominal(model, start)
        current = nominal
        memo: dict[int, tuple] = {}

        def tests_of(fit: FitResult):
            """The residual battery of a fit, computed once (the fit is kept, so its id stays unique)."""
            if id(fit) not in memo:
                memo[id(fit)] = (fit, residual_tests(fit, prob, self.alpha))
            return memo[id(fit)][1]

        exact = self._rounding_level(nominal)
        if exact is not None:
            return self._exact_fit(nominal, exact, tests_of)
        # the nominal model's adequacy rows (reported beside the final model's) depend on the nominal fit
        # only: computed in a side thread from here on, they fill the cores where the loop runs one thread
        # (the residual battery, the backward step, a round's last refit). shutdown(wait=False): the job
        # runs to its end, the pool takes nothing more
        side = ThreadPoolExecutor(max_workers=1)
        nominal_job = side.submit(lambda: adequacy_tests(nominal, prob, self.alpha) + self.state_probe(nominal))
        side.shutdown(wait=False)
        tests0, f_cyc0 = tests_of(nominal)
        findings, history = [], []
        last_round: tuple = (None, [])
        links: list[Link] = []          # the forward pass: its fits, the form test's steps, the backward step
        switched = "intersample" not in self.families   # the intersample choice is made at most once
        last_p: dict[str, float] | None = None             # family p-values on the final model
        last_r2: dict[str, float] = {}
        done_until = 0                  # a look-ahead accepts two extensions and uses two iterations
        for it in range(self.max_findings):
            if it < done_until:
                continue
            rnd = self._propose(current, it, tests_of, switched)
            cands, inter, last_p, last_r2 = rnd.cands, rnd.inter, rnd.last_p, rnd.last_r2
            last_round = (current, cands)   # the fit the round extended and its candidates (their refits)
            history.append(rnd.record(it))
            acc = [c for c in cands if c.accepted]
            best = self.separate(choose(acc), acc)
            # the intersample choice competes with the physical causes on ΔBIC: on a misspecified model,
            # foh vs zoh can look better by accident; the true cause explains more. It adds no parameter,
            # so a physical cause must beat it by INTERSAMPLE_TIE_BIC to be preferred (a wrong foh on a
            # held input is a lag of about half a sample, which a fitted delay mimics within 1–2 BIC units).
            # Both sides with the round's effective sample size, as choose() ranks the causes:
            # raw differences grow as (1 + ρ)/(1 − ρ) on coloured residuals (inter_wins)
            if inter is not None and self.inter_wins(inter, best, rnd.n_eff, current):
                findings.append(inter[1])
                history[-1] = self._not_taken(rnd, it, f"intersample {inter[1].get('chosen')}")
                links.append(Link("intersample", current, self._accepted(inter[0])))
                current = links[-1].after
                switched = True
                last_p = None
                continue
            if best is None:
                ahead = self._lookahead(current, cands, it, tests_of) if it + 2 <= self.max_findings else None
                history[-1] = rnd.record(it)             # the look-ahead's outcome is in the first one's reason
                if ahead is None:
                    break
                first, first_fit, best, rnd2 = ahead
                history.append(rnd2.record(it + 1))
                last_round = (first_fit, rnd2.cands)
                findings.append(naming.finding(self.prob, self.dt, first, [c for c in cands if c is not first and c.gain is not None
                                                     and c.delta_bic_eff is not None]))
                links.append(Link("look-ahead", current, first_fit, first, self._alternatives(first, cands)))
                current = first_fit
                cands = rnd2.cands
                done_until = it + 2
            findings.append(naming.finding(self.prob, self.dt, best, [c for c in cands if c is not best and c.gain is not None
                                                and c.delta_bic_eff is not None]))
            if done_until != it + 2:
                history[-1] = self._not_taken(rnd, it, best.hyp.key)
            links.append(Link("look-ahead" if done_until == it + 2 else "extension", current,
                              self._accepted(best.fit), best, self._alternatives(best, cands)))
            current = links[-1].after
            last_p = None
        old = list(links)
        links, moves = revisit(self, links)
        if moves:
            findings = revisited_findings(self, links, old, findings, moves)
            current = links[-1].after
            last_p = None
        fits = [nominal] + [l.after for l in links]
        # the accepted extensions (look-ahead or not; not the intersample switch), for the form test
        steps = [Accepted(l.cand.hyp.family, f.get("equation"), f.get("term"), l.cand.lr.p_value,
                          l.cand.lr.statistic, l.before.sse_w, l.after.sse_w)
                 for l, f in zip(links, findings) if l.cand is not None]
        # the final model's adequacy rows and its state probe in two threads, beside the last round of
        # tests when the loop stopped at max_findings (all of them read the final fit only): that round's
        # pool leaves a core idle between its stages
        with ThreadPoolExecutor(max_workers=2) as pool:
            probe = pool.submit(self.state_probe, current)
            rows = pool.submit(adequacy_tests, current, prob, self.alpha)
            if last_p is None and self.max_findings > 0:   # the loop stopped at max_findings: test once more
                tests_f, f_cyc_f = tests_of(current)
                cands, _ = self.candidates(current, f_cyc_f / self.dt, strongest_fisher(tests_f))
                last_p = {c.hyp.family: c.p_family for c in cands}
                last_r2 = _family_r2(cands)
            adequacy = rows.result() + probe.result()
        nominal_adequacy = nominal_job.result()
        for fit, rows_of, which in ((current, adequacy, "final"), (nominal, nominal_adequacy, "nominal")):
            stop = undefined_from(fit.Yhat, prob)
            if stop is not None:
                rows_of.append(validation_undefined(prob, stop, which))
        if last_p:
            # a family whose added-term test is significant on the final model, yet whose extension was
            # not accepted: a direction the model misses that no family's extension explains
            holm = stats.holm(last_p, self.alpha)
            sig = sorted(k for k, v in holm.items() if v)
            pmin = min(last_p.values())
            r2 = max([last_r2.get(k, 0.0) for k in sig] or [0.0])
            adequacy.append(stats.TestResult(
                "structural_wald", float(len(sig)), float(min(1.0, pmin * len(last_p))), None, not sig,
                ("significant added-term tests, no accepted extension: " + ", ".join(
                    f"{k} ({100 * last_r2.get(k, 0.0):.2g} % of the residual)" for k in sig)) if sig else
                "no family's added-term test is significant after Holm correction", r2=r2))
        form = form_test(steps)
        if form is not None:
            adequacy.append(form)
        structural_ok = structurally_adequate(adequacy)
        noise_tests = []
        noise_fams = [f for f in self.families if f in NOISE_FAMILY_IDS]
        # the noise families need more than an adequate structure: no structural test may be
        # significant at all (issue 9: "input cross-correlation passes, no structural Wald test
        # significant"). A misfit too small to fail adequacy (MATERIAL_R2) still colours the residual,
        # and an AR noise model would take that colour for the noise's.
        significant = [t.name for t in adequacy if not t.passed]
        final_tests = tests_of(current)[0]
        # the residual battery as one family of tests (Holm at α): five tests at α each would call
        # about 5 % of correct models "unexplained"
        ps = {f"{i}:{t.name}": t.p_value for i, t in enumerate(final_tests) if t.p_value == t.p_value}
        rejected = [k.split(":", 1)[1] for k, v in stats.holm(ps, self.alpha).items() if v]
        colour_only = bool(rejected) and all(n.startswith(COLOUR_TESTS) for n in rejected)
        # nor may the residual be unstable: the CUSUM of recursive residuals, scaled by a HAC variance,
        # keeps its size under stationary AR noise (tests/diagnosis/test_cusum.py, φ up to 0.95), so its
        # rejection contradicts the coloured-noise explanation itself. (Not the CUSUM of squares: a noise
        # level that changes over time is the heteroscedastic_noise family's own evidence.)
        unstable = [n for n in rejected if n == "cusum" or n.startswith("cusum[")]
        gated = False      # the noise families were kept out by a significant (immaterial) structural test
        if noise_fams and len(findings) < self.max_findings and rejected and structural_ok and not significant \
                and not unstable:
            # a coloured residual the noise families would explain: is it the structure's after all?
            row = self.probe_refit(current)
            if row is not None:
                adequacy.append(row)
                if not row.passed:
                    significant.append(row.name)
                    structural_ok = structurally_adequate(adequacy)
        if noise_fams and len(findings) < self.max_findings:
            if structural_ok and not significant and not unstable:
                _log("noise families on the final model: " + ", ".join(noise_fams))
                nf, noise_tests = diagnose_noise(current, prob, alpha=self.alpha, seed=self.seed,
                                                 n_boot=self.n_boot)
                findings += [f for f in nf if f["family"] in noise_fams][: self.max_findings - len(findings)]
                spec = [t for t in noise_tests if t.name == HAUSMAN and material(t)]
                if spec:   # the coloured residual is a structural misfit (pipeline.diagnostics.hausman)
                    adequacy += spec
                    structural_ok = False
            else:
                why = ("the final model fails its adequacy tests" if not structural_ok else
                       "significant structural tests on the final model (" + ", ".join(significant) +
                       "), each explaining less than the adequacy threshold" if significant else
                       "the CUSUM of the final model's recursive residuals leaves its bounds (" +
                       ", ".join(unstable) + "): a slow systematic departure, which stationary coloured "
                       "noise does not produce")
                _log(f"noise families not tested: {why}")
                gated = structural_ok
                noise_tests = [stats.TestResult(f, float("nan"), float("nan"), None, False,
                                                f"not tested: structure inadequate ({why})")
                               for f in noise_fams]
        if not structural_ok:
            verdict = "unexplained_discrepancy"
        elif findings:
            # a coloured residual that the noise families were not allowed to explain (a structural test
            # is still significant) is unexplained, whatever the findings explained before it
            verdict = "unexplained_discrepancy" if gated and rejected else "discrepancy"
        else:
            # a coloured residual of an adequate structure is a noise property: the noise families name
            # it (a finding); where they could not run (too few samples) colour alone is not an
            # unexplained *model* discrepancy
            noise_skipped = any(t.name == "noise_families" for t in noise_tests)
            verdict = ("unexplained_discrepancy" if rejected and not (colour_only and noise_skipped)
                       else "no_significant_discrepancy")
        where = where_it_fails(current, prob, adequacy + final_tests) if verdict == "unexplained_discrepancy" else None
        tests0 = list(tests0) + feedback_tests(nominal, prob, self.alpha)
        return Diagnosis(nominal, current, findings, tests0, history, fits, noise_tests, final_tests,
                         adequacy=adequacy, adequacy_nominal=nominal_adequacy,
                         verdict=verdict, where=where, revisit=moves,
                         unaccepted=unaccepted_fits(*last_round) if verdict == "unexplained_discrepancy"
                         and last_round[0] is current else [])

    # a residual RMS below this share of the output's RMS, on the estimation and the validation part, is
    # floating-point rounding, not measurement noise: a 24-bit converter's quantisation is about 2e-8 of
    # its full scale, double precision 1e-16
    ROUNDING_LEVEL = 1e-9

    def _rounding_level(self, fit: FitResult) -> str | None:
        """The words for a nominal model that reproduces the record to rounding error (each output's free-run
        RMSE on both parts below ``ROUNDING_LEVEL`` of its RMS), else None. On such a residual every test
        reads floating-point rounding as a signal: an independent probe (x' = b u on its exact zoh
        solution, RMSE 3e-14) got "b jumps from 1 to 1 at t = 29.11 s", coloured and heavy-tailed noise."""
        prob = self.prob
        parts = (("estimation", prob.split.est_slice()), ("validation", prob.split.val_slice()))
        rel = {}
        for name, sl in parts:
            y, r = prob.Y[sl], prob.Y[sl] - fit.Yhat[sl]
            scale = np.sqrt(np.mean(np.square(y), axis=0))
            if not np.all(np.isfinite(r)) or np.any(scale <= 0):
                return None
            q = np.sqrt(np.mean(np.square(r), axis=0)) / scale
            if np.any(q >= self.ROUNDING_LEVEL):
                return None
            rel[name] = float(np.max(q))
        return (f"the nominal model reproduces the record to rounding error (free-run RMSE "
                f"{rel['estimation']:.2g} of the output's RMS on the estimation part, {rel['validation']:.2g} on "
                f"the validation part, below {self.ROUNDING_LEVEL:g}): the residual is floating-point rounding, "
                "on which no statistical test means anything")

    def _exact_fit(self, nominal: FitResult, why: str, tests_of) -> Diagnosis:
        """The diagnosis of a nominal model that reproduces the record to rounding error
        (:meth:`_rounding_level`): no discrepancy, no family tested, every row "not tested" with the reason."""
        _log(f"{why}: nothing to diagnose")
        nan = float("nan")
        rows = [stats.TestResult(t.name, nan, nan, None, False, f"not tested: {why}") for t in tests_of(nominal)[0]]
        return Diagnosis(nominal, nominal, [], rows, [], [nominal], final_tests=list(rows),
                         verdict="no_significant_discrepancy", rounding=why)

    @staticmethod
    def _not_taken(rnd: Round, it: int, taken: str) -> dict:
        """The round's history row once its extension is chosen: a candidate (or an intersample
        alternative) that met the acceptance rule but was not the one taken says so, where its reason
        read "accepted" as if it were a finding (Silverbox's first round listed three)."""
        why = f"met the acceptance rule, not taken: iteration {it + 1} took {taken}"
        for c in rnd.cands:
            if c.accepted and c.hyp.key != taken:
                c.reason = why
        for row in (rnd.inter_history or {}).get("candidates", []):
            if row.get("accepted") and f"intersample {row.get('hypothesis')}" != taken:
                row["reason"] = why
        return rnd.record(it)

    def separate(self, best: Candidate | None, accepted: list[Candidate]) -> Candidate | None:
        """:func:`.naming.separate` on this record; a replacement is logged."""
        c = naming.separate(self.prob, best, accepted)
        if c is not best:
            _log(f"  {c.hyp.key} {c.separation}")
        return c

    def inter_wins(self, inter: tuple, best: Candidate | None, n_eff: float | None, current: FitResult) -> bool:
        """Is the intersample switch (``inter``: its fit and finding) chosen over the round's best physical
        cause? Yes unless the cause's ΔBIC is lower by ``INTERSAMPLE_TIE_BIC``; and also when it is so
        only by the raw ΔBIC, not with the round's effective sample size N_eff (:func:`effective_bic`,
        the scale :func:`choose` ranks causes on; the switch adds no parameter, so its ΔBIC_eff is the raw
        one scaled by N_eff/N, Jones 2011), unless the validation part clearly prefers the cause (the
        rule of :meth:`separate`: its validation error lower with the 95 % interval above 0 and by at
        least ``SEPARATION_MIN_GAIN``). Sets the finding's ``delta_bic_eff``.

        Why: raw differences grow as (1 + ρ)/(1 − ρ) on coloured residuals. On an independent-bench record
        of a held input configured as foh (tank, 2 % AR(0.9) noise, test seed 1000) a first-order lag of
        0.7 samples was 34 raw BIC units ahead of the switch to zoh, 1.7 effective units, and was named,
        although the switch's validation gain was the larger (27.5 % against 26.1 %). Why the validation
        check: with the effective scale alone, a 3.6-sample dead time (tank, smooth input, 10 % AR(0.9),
        test seed 1001) was 3.2 effective units ahead of a switch to zoh that explains half a sample of it,
        and the switch was named, although the delay's validation gain was 22 % against 5.7 %."""
        f_is, finding = inter
        d = finding["delta_bic"]
        n = current.resid_est.shape[0]
        d_eff = d if n_eff is None else criteria.bic_effective_delta(d, 0, n, n_eff)
        finding["delta_bic_eff"] = d_eff
        if best is None or d < best.delta_bic + INTERSAMPLE_TIE_BIC:
            return True
        best_eff = best.delta_bic if best.delta_bic_eff is None else best.delta_bic_eff
        if d_eff >= best_eff + INTERSAMPLE_TIE_BIC or best.fit is None:
            return False
        g = gain_ci(gain_resid(f_is, self.prob), gain_resid(best.fit, self.prob))   # 1 − RMSE_cause/RMSE_switch
        return not separates(g, SEPARATION_MIN_GAIN)

    def _alternatives(self, c: Candidate, cands: list[Candidate]) -> list[Candidate]:
        """The refitted candidates of ``c``'s round from other families within ``RUNNER_UP_DBIC`` of it: what
        the backward step (:mod:`.revisit`) may put in its place."""
        return [o for o in cands if o is not c and o.fit is not None and o.gain is not None
                and o.delta_bic_eff is not None and c.delta_bic_eff is not None and o.hyp.family != c.hyp.family
                and o.criterion - c.criterion <= RUNNER_UP_DBIC]


def _wald_evidence(h: Hypothesis, w: stats.WaldResult) -> dict:
    """A candidate's evidence row for its added-term test."""
    return {"test": f"added_term_wald[{h.key}]", "statistic": w.statistic, "p_value": w.p_value, "dof": w.dof}


def _same_column(a: stats.WaldResult, b: stats.WaldResult) -> bool:
    """Two hypotheses whose tests agree to 1e-9: the same column under another name (h*abs(h) is h**2
    on a level that stays positive)."""
    return abs(a.r2 - b.r2) <= 1e-9 * b.r2 and abs(a.statistic - b.statistic) <= 1e-9 * abs(b.statistic)


def _family_r2(cands: list[Candidate]) -> dict[str, float]:
    """Each family's largest linearised share (a family can have a near-tie runner-up candidate)."""
    out: dict[str, float] = {}
    for c in cands:
        out[c.hyp.family] = max(out.get(c.hyp.family, 0.0), c.wald.r2)
    return out


def _cand_record(c: Candidate) -> dict:
    return {"family": c.hyp.family, "hypothesis": c.hyp.key, "p_family": c.p_family,
            "statistic": None if c.wald is None else c.wald.statistic,
            "gain": c.gain, "delta_bic": c.delta_bic, "delta_bic_eff": c.delta_bic_eff,
            "prior_penalty": c.prior_penalty, "accepted": c.accepted,
            "reason": c.reason}
