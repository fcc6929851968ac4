"""Fitting the free parameters of a grey-box model.

* Output error (always): minimise Σ_k ‖W (y_k − ŷ_k(θ))‖² over the estimation samples, ŷ the free-run
  simulation (scipy ``least_squares``, trust-region reflective, Jacobian by finite differences). W scales
  each output by 1/std so outputs of different units weigh alike.
* Equation error (a fast start when every state is measured): least squares on
  ẋ_k − f(x_k, u_k; θ) with ẋ from central differences.
* Covariance: the sandwich (JᵀJ)⁻¹ Ω̂ (JᵀJ)⁻¹ with Ω̂ a HAC (prewhitened EWC) long-run covariance of
  the score rows J_t e_t (White 1982; Ljung 1999 §9.3), because output-error residuals are rarely
  white; for white residuals it reduces to σ̂² (JᵀJ)⁻¹, σ̂² = SSE/(N − p) (Ljung 1999, eq. 9.18). Both
  are computed from the column-scaled Jacobian J D (D = diag 1/‖J_j‖, so a coefficient of 5e7 next to one of
  0.3 does not make JᵀJ numerically singular) through its SVD with an explicit rank decision: singular
  values below ``RANK_RTOL`` × the largest are directions the data cannot determine (a finite-difference
  Jacobian is accurate to about √ε ≈ 1.5e-8). Parameters with weight in such a direction get no standard
  error (NaN) and the direction is reported (:class:`Identifiability`). With a robust loss, J is the
  Jacobian of the plain weighted residual at θ̂, not scipy's loss-modified one.

**Segments.** The record is simulated in segments, each from its own initial state: separate experiments
(``Record.segments``: an estimation and a validation record), and, with ``split.warmup``, the
estimation part is simulated from ``warmup`` samples before it, from the configured initial state. That
one simulation is the one minimised, tested (residuals, Jacobian, BIC, Wald tests, noise stage) and
reported for the estimation part; samples before the warm-up start are simulated from sample 0 as their
own segment (Silverbox's "arrow"). The estimated initial state ``x0`` belongs to the segment holding the
start of the estimation part; another segment starts from the measured sample for measured states and
from the same values as the estimation segment for unmeasured ones.
"""

from __future__ import annotations

import inspect
import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from functools import cached_property
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .data import Record, Split
from .errors import ConfigError, RefitAbandoned, SimulationError
from .model import Model, rhs_vectorized, switches
from .simulate import outputs, simulate_states, undefined_equation

RANK_RTOL = 1e-7
# threads for the columns of a finite-difference Jacobian (scipy >= 1.16 takes a map as ``workers``),
# from this many simulated steps (samples x substeps) per simulation: below it a simulation takes a few
# milliseconds, a thread hand-off is a large share of that, and the callers already run fits in parallel
# (the diagnosis bench's 2 000-sample records stay serial)
JACOBIAN_THREADS = max(1, min(4, os.cpu_count() or 1))
JACOBIAN_THREADS_MIN_STEPS = 50_000
_LSQ_WORKERS = "workers" in inspect.signature(least_squares).parameters


@dataclass
class Problem:
    """What a fit needs from the record: time, input, measured outputs, the split and the segments."""

    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray                 # (N, ny) measured, model names in ``out_names``
    out_names: list[str]
    split: Split
    bound: float
    restarts: tuple[int, ...] = ()   # sample indices where the simulation restarts (segment starts > 0)
    warmup_start: int | None = None  # the estimation part's simulation starts here (split.warmup)

    @classmethod
    def from_record(cls, rec: Record, model: Model, split: Split, warmup: int | None = None) -> "Problem":
        names = list(rec.outputs)
        Y = np.column_stack([rec.outputs[k] for k in names])
        scale = max(1.0, float(np.max(np.abs(Y))))
        restarts = {sg.start for sg in getattr(rec, "segments", []) if sg.start > 0}
        ws = None
        if warmup is not None:
            seg0 = max([0] + [r for r in restarts if r <= split.est[0]])
            ws = max(max(0, split.est[0] - warmup), seg0)
            if ws == seg0:
                ws = None   # the estimation part's own segment already starts there
        return cls(rec.t, rec.u_matrix(list(model.inputs)), Y, names, split, bound=1e6 * scale,
                   restarts=tuple(sorted(restarts)), warmup_start=ws)

    @property
    def weights(self) -> np.ndarray:
        sl = self.split.est_slice()
        s = np.std(self.Y[sl], axis=0)
        return 1.0 / np.where(s > 0, s, 1.0)

    def inputs(self, model: Model) -> np.ndarray:
        """The input samples a simulation of ``model`` gets: ``U`` itself, or for
        ``intersample: bandlimited`` U prefiltered experiment by experiment (:mod:`pipeline.bandlimited`),
        computed once; pass ``prefiltered=True`` to :func:`simulate_states` with it."""
        return self._u_bandlimited if model.intersample == "bandlimited" else self.U

    @cached_property
    def _u_bandlimited(self) -> np.ndarray:
        from .bandlimited import prefilter
        return prefilter(self.U, tuple(self.restarts))

    def segments(self, warm: bool = False) -> list[tuple[int, int]]:
        """[start, stop) of each simulated segment, in order, covering the record: the records'
        experiments, and with ``warm`` also the warm-up start of the estimation part."""
        extra = [self.warmup_start] if warm and self.warmup_start else []
        cuts = sorted({0, len(self.t), *[r for r in list(self.restarts) + extra if 0 < r < len(self.t)]})
        return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]

    def fit_segment(self) -> tuple[int, int]:
        """The (warm-up) segment that holds the first estimation sample (its x0 is the fitted one)."""
        e0 = self.split.est[0]
        return next(sg for sg in self.segments(warm=True) if sg[0] <= e0 < sg[1])


@dataclass
class Identifiability:
    """Rank decision on the column-scaled Jacobian (see the module docstring)."""

    rank: int
    n_params: int
    condition: float                       # of the scaled Jacobian, largest/smallest singular value
    directions: list[dict[str, float]] = field(default_factory=list)   # unit null directions (scaled)
    unidentifiable: list[str] = field(default_factory=list)             # parameters without a std
    cov_dof: float | None = None          # ν of the sandwich covariance (regions); None: classic
    param_dof: dict[str, float] | None = None   # each parameter's own ν (its t_ν interval)

    def record(self) -> dict:
        return {"rank": self.rank, "n_params": self.n_params, "condition_scaled": self.condition,
                "unidentifiable": list(self.unidentifiable), "directions": self.directions,
                "covariance": "sandwich (J'J)^-1 Omega (J'J)^-1, Omega a prewhitened EWC long-run covariance of the "
                              "score rows" if self.cov_dof is not None else "sigma^2 (J'J)^-1",
                "covariance_dof": self.cov_dof,
                "covariance_dof_by_param": self.param_dof,
                "note": "directions in column-scaled coordinates (each parameter's change times the norm of "
                        "its Jacobian column): moving along one leaves the fitted simulation unchanged"}


@dataclass
class FitResult:
    model: Model                 # with fitted parameter values
    x0: np.ndarray               # initial state at the start of the fit segment
    names: list[str]             # estimated quantities: free params then "x0.<state>"
    theta: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    Yhat: np.ndarray             # (N, ny) free-run simulated outputs, segment by segment
    resid_est: np.ndarray        # (n_est, ny) y − ŷ on the estimation part (the fitted simulation)
    jac: np.ndarray              # (n_est*ny, p) Jacobian of the weighted residual −∂ŷw/∂θ... (sign: of r)
    sse_w: float
    success: bool
    message: str
    nfev: int
    identifiability: Identifiability | None = None

    @property
    def n_params(self) -> int:
        return len(self.theta)

    def as_estimate(self):
        """The shared estimator result (pipeline.estimators.Estimate) for this output-error fit;
        log-likelihood under white Gaussian output noise with σ̂² = SSE/N (weighted units)."""
        from .estimators import Estimate
        r = (self.resid_est * 1.0).ravel()
        n = r.size
        s2 = self.sse_w / n
        loglik = -0.5 * n * (np.log(2 * np.pi * s2) + 1.0)
        return Estimate(self.theta, self.cov, r, float(loglik), self.n_params, "output_error_ls",
                        {"names": list(self.names), "converged": self.success})


def excited_inputs(prob: Problem) -> list[int]:
    """Indices of the input columns that move on the estimation part: the inputs every input–output
    test, evidence row and figure is computed for (a constant column excites nothing)."""
    sl = prob.split.est_slice()
    return [j for j in range(prob.U.shape[1]) if np.ptp(prob.U[sl, j]) > 0]


def initial_state(model: Model, prob: Problem, values: dict[str, float] | None = None, at: int = 0) -> np.ndarray:
    """Resolve the initial state at sample ``at``: numbers, "data" (the measured sample there) or
    estimates (``values`` ``x0.<state>``; the measured sample as a start)."""
    x0 = np.zeros(len(model.states))
    for i, s in enumerate(model.states):
        spec = model.initial[s]
        if values and f"x0.{s}" in values:
            x0[i] = values[f"x0.{s}"]
        elif spec == "data" or spec == "estimate":
            if s in prob.out_names:
                x0[i] = prob.Y[at, prob.out_names.index(s)]
            elif spec == "data":
                raise ConfigError(f"initial state 'data' needs state {s!r} to be measured",
                                  key=f"model.initial.{s}")
        else:
            x0[i] = float(spec)
    return x0


def segment_x0(model: Model, prob: Problem, start: int, x0_fit: np.ndarray) -> np.ndarray:
    """Initial state of the segment starting at ``start`` (see the module docstring)."""
    if start == prob.fit_segment()[0]:
        return np.asarray(x0_fit, float)
    x0 = initial_state(model, prob, at=start)
    for i, s in enumerate(model.states):
        if model.initial[s] == "estimate" and s not in prob.out_names:
            x0[i] = x0_fit[i]
    return x0


def simulate_rows(model: Model, prob: Problem, x0_fit: np.ndarray, a: int, b: int, *,
                  warm: bool = True, partial: bool = False) -> np.ndarray | None:
    """Free-run outputs on rows [0, b), simulating every segment that overlaps [a, b) (rows of other
    segments are NaN); None if the model diverges in one of them. ``warm``: with the warm-up restart.
    ``partial``: a segment that diverges keeps its rows up to the divergence, NaN from there on."""
    out = np.full((b, prob.Y.shape[1]), np.nan)
    for s0, s1 in prob.segments(warm):
        if s1 <= a or s0 >= b:
            continue
        stop = min(s1, b)
        res = simulate_states(model, prob.t[s0:stop], prob.inputs(model)[s0:stop],
                              segment_x0(model, prob, s0, x0_fit), bound=prob.bound, prefiltered=True)
        if res.diverged_at is None:
            out[s0:stop] = outputs(model, prob.t[s0:stop], prob.U[s0:stop], res.X, prob.out_names)
        elif not partial:
            return None
        else:
            k = s0 + res.diverged_at
            with np.errstate(all="ignore"):
                out[s0:k] = outputs(model, prob.t[s0:k], prob.U[s0:k], res.X[:k - s0], prob.out_names)
    return out


def simulate_until(model: Model, prob: Problem, x0: np.ndarray, stop: int) -> np.ndarray | None:
    """Free-run outputs for rows [0, stop) of the segments that hold the estimation part (the simulation
    that is fitted); None if the model diverges."""
    return simulate_rows(model, prob, x0, prob.split.est[0], stop)


def _raise_if_undefined(model: Model, t: np.ndarray, U: np.ndarray, x0: np.ndarray, res, what: str,
                        tail: str) -> None:
    """SimulationError keyed ``model.equations.<state>`` when the simulation's NaN comes from an equation
    undefined at the state before it (:func:`pipeline.simulate.undefined_equation`); otherwise nothing,
    and the caller names the model."""
    bad = undefined_equation(model, t, U, x0, res)
    if bad is not None:
        raise SimulationError(f"{what}: the simulation produced NaN at sample {res.diverged_at}: {bad[1]} {tail}",
                              key=f"model.equations.{bad[0]}")


def undefined_from(Yhat: np.ndarray, prob: Problem) -> int | None:
    """The first validation row whose free-run output is not finite (the simulation stopped there:
    :func:`simulate_full` with ``partial``), or None when the whole validation part is defined."""
    sl = prob.split.val_slice()
    bad = ~np.all(np.isfinite(Yhat[sl]), axis=1)
    return int(sl.start + np.argmax(bad)) if bad.any() else None


def defined_validation_rows(Yhat: np.ndarray, prob: Problem) -> slice | np.ndarray:
    """The validation rows validation numbers are computed on: the part's slice when every free-run
    output is finite, else the indices of the rows that are (the simulation stopped:
    :func:`undefined_from`)."""
    sl = prob.split.val_slice()
    ok = np.all(np.isfinite(Yhat[sl]), axis=1)
    return sl if ok.all() else np.arange(sl.start, sl.stop)[ok]


def simulate_full(model: Model, prob: Problem, x0: np.ndarray, partial: bool = False) -> np.ndarray:
    """Free-run outputs over the whole record (the reported numbers): the estimation rows from the
    fitted (warm-up) simulation, every other row from the records' own segments (so validation samples
    never sit in a warm-up transient). SimulationError if the model diverges; with ``partial``, only if
    it diverges on the estimation rows: elsewhere the rows from where a segment's simulation stops are
    NaN (a nominal model whose fit is undefined on part of the validation record is reported as such,
    :func:`undefined_from`, and diagnosed)."""
    Yh = simulate_rows(model, prob, x0, 0, len(prob.t), warm=False, partial=partial)
    e0, e1 = prob.split.est
    if Yh is not None and prob.warmup_start:
        Yw = simulate_until(model, prob, x0, e1)
        if Yw is None:
            Yh = None
        else:
            Yh[e0:e1] = Yw[e0:e1]
    if Yh is not None and partial and not np.all(np.isfinite(Yh[e0:e1])):
        Yh = None         # the fitted simulation itself stops: the error below names where
    if Yh is None:
        for s0, s1 in prob.segments(True):
            res = simulate_states(model, prob.t[s0:s1], prob.inputs(model)[s0:s1], segment_x0(model, prob, s0, x0),
                                  bound=prob.bound, prefiltered=True)
            if res.diverged_at is not None:
                hint = (f"(parameters {model.params}); a parameter's physical range can be given in model.bounds "
                        "(e.g. {a: [0, null]})")
                _raise_if_undefined(model, prob.t[s0:s1], prob.inputs(model)[s0:s1], segment_x0(model, prob, s0, x0),
                                    res, "the fitted model fails on this record", hint)
                raise SimulationError(f"the fitted model fails on this record: {res.reason(prob.t[s0:s1])} {hint}")
    return Yh


def states_full(model: Model, prob: Problem, x0: np.ndarray) -> np.ndarray:
    """(N, nx) simulated states over the whole record, segment by segment (NaN after a divergence)."""
    X = np.full((len(prob.t), len(model.states)), np.nan)
    for s0, s1 in prob.segments(warm=False):
        X[s0:s1] = simulate_states(model, prob.t[s0:s1], prob.inputs(model)[s0:s1],
                                   segment_x0(model, prob, s0, x0), bound=prob.bound, prefiltered=True).X
    return X


def scaled_covariance(J: np.ndarray, s2: float, names: list[str], scores: np.ndarray | None = None,
                      ny: int = 1, output_var: np.ndarray | None = None) -> tuple[np.ndarray, Identifiability]:
    """Parameter covariance from the column-scaled Jacobian's SVD with the rank decision of the module
    docstring. J D = U S Vᵀ ⇒ (JᵀJ)⁺ = D V S⁻² Vᵀ D over the kept singular values.

    Without ``scores``: σ̂² (JᵀJ)⁺ (Ljung 1999 eq. 9.18, white output noise). With ``scores`` (N×p, the
    rows g_t = Σ_outputs J_t e_t at θ̂): the sandwich (JᵀJ)⁺ Ω̂ (JᵀJ)⁺ (White 1982; Ljung 1999 §9.3,
    eq. 9.55 for correlated residuals) with Ω̂ the prewhitened equal-weighted-cosine long-run covariance
    of the score rows (:func:`pipeline.hac.long_run`, B = 0.4 N^{2/3} cosines). The residual is a
    least-squares residual on J's columns, which removes the low frequencies the estimate lives on: the
    variance of each parameter is divided by the bias factor κ_a (:func:`pipeline.hac.design_terms`,
    Bell & McCaffrey 2002; ≈ 1 − p/N for a rough Jacobian, the classic N/(N − p)) of the scores along
    its influence direction z_a = J (JᵀJ)⁺ e_a, the linear combination of score columns whose long-run
    variance *is* that parameter's (covariances by √(κ_a κ_b)). With several outputs (rows
    sample-major, ``ny``) κ_a and ν_a are those of the scores summed over each sample's outputs, the
    outputs' white errors with variances ``output_var`` (the weighted residual's mean square per output).

    Why the influence direction and not each score column: on two coupled thermal nodes with a
    near-collinear triple (a1·T1 beside c·tanh(T1/s), correlated at 0.99+), the columns' κ are 0.78–0.91
    but the weak direction the triple's variances live on has κ ≈ 0.67–0.68, so their standard deviations
    were 1.08–1.11 times too small (400 solve_ivp noise draws, one output or both); along the influence
    directions 0.97–0.98, the other two parameters 1.01–1.05 (``tests/test_trust_numbers.py``). Until the
    thirty-third session several outputs also used the classic factor and ν = B (a1, c, s covered 90.5,
    92, 92.5 %). It is formed in the same scaled coordinates, on the kept directions only:
    cov = D (V_k S_k⁻²V_kᵀ)(D Ω̂ D)(V_k S_k⁻² V_kᵀ) D / √(κκᵀ). For white residuals Ω̂ ≈ σ̂² JᵀJ and the two
    agree; for smooth residuals the sandwich is the one that covers. The estimate's degrees of freedom
    (Satterthwaite, with each parameter's own design ν_a) are returned per parameter in
    ``Identifiability.param_dof`` (θ̂_a ± t_{ν_a,0.975}·std_a is its 95 % interval, :func:`param_intervals`)
    and the smallest in ``Identifiability.cov_dof`` (regions of several parameters)."""
    p = J.shape[1]
    norms = np.linalg.norm(J, axis=0)
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 0.0)
    Js = J * d
    _, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    keep = sv > RANK_RTOL * (sv[0] if len(sv) else 0.0)
    keep &= sv > 0
    cond = float(sv[0] / sv[-1]) if len(sv) and sv[-1] > 0 else float("inf")
    V = Vt.T
    Vk = V[:, keep] / sv[keep]
    bread = Vk @ Vk.T                                   # (JᵀJ)⁺ in scaled coordinates
    cov_dof = param_dof = None
    if scores is None:
        cov = s2 * (d[:, None] * bread * d[None, :])
    else:
        from .hac import design_terms, dof_with_base, ewc_dof, long_run
        gs = np.asarray(scores, float) * d
        n_r, n = J.shape[0], gs.shape[0]
        b = ewc_dof(n)
        if n > p + 8 and np.all(norms > 0):
            z = Js @ bread                              # each parameter's influence direction
            kap, nus = design_terms(Js, z, b) if ny == 1 else \
                design_terms(Js, z, b, ny=ny, var=np.ones(ny) if output_var is None else output_var)
            kap = np.maximum(kap, 0.05)
        else:
            kap, nus = np.full(p, max(n_r - p, 1) / n_r), np.full(p, float(b))
        lr = long_run(gs, dof=b, base_dof=float(np.min(nus)))
        cov_dof = lr.dof
        param_dof = dict(zip(names, (float(v) for v in dof_with_base(lr.dof, float(np.min(nus)), nus))))
        cov = d[:, None] * ((bread @ lr.omega @ bread) / np.sqrt(np.outer(kap, kap))) * d[None, :]
        cov = 0.5 * (cov + cov.T)
    null = V[:, ~keep]
    bad = set(np.flatnonzero(norms == 0))
    dirs = []
    for j in range(null.shape[1]):
        v = null[:, j]
        big = np.flatnonzero(np.abs(v) > 0.05)
        bad |= set(big.tolist())
        dirs.append({names[i]: float(round(v[i], 6)) for i in big})
    for i in sorted(bad):
        cov[i, :] = np.nan
        cov[:, i] = np.nan
    unident = [names[i] for i in sorted(bad)]
    if param_dof is not None:
        param_dof = {k: v for k, v in param_dof.items() if k not in unident}
    return cov, Identifiability(int(keep.sum()), p, cond, dirs, unident, cov_dof, param_dof)


def region_critical(idf: Identifiability | None, q: int, level: float = 0.95) -> float:
    """Critical value c of a level-``level`` confidence region (θ − θ̂)ᵀP⁻¹(θ − θ̂) ≤ c for q of the
    parameters, P their block of the fit's covariance. For the sandwich covariance (its Satterthwaite
    degrees of freedom ν in ``idf.cov_dof``) the reference law is the one the added-term tests use,
    Hotelling's T², c = qν/(ν − q + 1)·F_{q, ν−q+1}(level) with ν floored at q
    (:func:`pipeline.hac.hotelling_critical`); for q = 1, √c is the t_ν quantile. For the classic
    σ̂²(JᵀJ)⁻¹ (white residuals assumed), χ²_q(level).

    Why not χ²: the sandwich of a smooth residual has few degrees of freedom (the heating system's 0.85,
    the cascaded tanks' 0.85). Monte Carlo, a regression on two smooth regressors (AR(1) 0.9) with AR(1)
    errors φ, 1 000 records each: χ²₂ ellipses cover 67–91 % at nominal 95 % (N = 100 and 500,
    φ = 0–0.97), Hotelling's 96–99.8 %; one-at-a-time intervals θ̂ ± 1.96σ cover 83–93 %, θ̂ ± t_νσ
    95–97 % (tests/diagnosis/test_mc_calibration.py)."""
    from scipy.stats import chi2
    nu = None if idf is None else idf.cov_dof
    if nu is None or not math.isfinite(nu):
        return float(chi2.isf(1.0 - level, q))
    from .hac import hotelling_critical
    return hotelling_critical(float(nu), q, 1.0 - level)


def param_intervals(fit: "FitResult", level: float = 0.95) -> list[tuple[float, float] | None]:
    """Per parameter the interval θ̂ ± t·σ, t = √:func:`region_critical` (q = 1: Student's t with the
    covariance's degrees of freedom; with the sandwich, each parameter's own ν from
    ``Identifiability.param_dof``); None where σ is not finite (an unidentifiable parameter).

    Why each its own ν: the smallest ν is that of the parameter whose estimate rests on the fewest
    independent stretches of the record. An estimated initial state acts through a transient at the
    start (two tanks, both initial levels estimated: ν ≈ 3 for the second level's against 7–12 for the
    rate constants); with that ν for every parameter, the rate constants' intervals were 1.6 times wider than
    their spread needed and covered 99.3–100 % (300 solve_ivp draws); with their own, 96.7–97 %, about
    1.2 times (``tests/test_trust_numbers.py``). Regions of several parameters keep the smallest ν."""
    from .hac import hotelling_critical
    idf = fit.identifiability
    own = getattr(idf, "param_dof", None) or {}
    t0 = math.sqrt(region_critical(idf, 1, level))
    out = []
    for name, v, sd in zip(getattr(fit, "names", None) or [None] * len(fit.theta), fit.theta,
                           np.asarray(fit.std, float)):
        if not math.isfinite(sd):
            out.append(None)
            continue
        t = t0 if name not in own else math.sqrt(hotelling_critical(own[name], 1, 1.0 - level))
        out.append((float(v - t * sd), float(v + t * sd)))
    return out


def score_rows(J: np.ndarray, r: np.ndarray, ny: int) -> np.ndarray:
    """Per-sample score rows g_t = Σ_o J_{(t,o)} r_{(t,o)} (N×p) of a residual raveled sample-major
    (row t·ny + o), the quantity whose long-run covariance the sandwich needs (Ljung 1999 §9.3)."""
    g = J * r[:, None]
    return g.reshape(-1, ny, J.shape[1]).sum(axis=1)


def estimated_x0(fit: FitResult) -> dict[str, float]:
    """The fit's estimated initial states {"x0.<state>": value}: the start of a refit of an extension of
    its model (``fit_output_error(start=...)``), so the refit begins where the current fit ended."""
    return {n: float(v) for n, v in zip(fit.names, fit.theta) if n.startswith("x0.")}


def equation_error_start(model: Model, prob: Problem) -> dict[str, float] | None:
    """LS on ẋ − f(x, u; θ) when every state is measured (fast start for the output-error fit)."""
    if model.extra_states or not all(s in prob.out_names for s in model.states) or not model.free:
        return None
    sl = prob.split.est_slice()
    X = np.column_stack([prob.Y[sl, prob.out_names.index(s)] for s in model.states])
    dX = np.gradient(X, prob.t[sl], axis=0)
    U, t = prob.U[sl], prob.t[sl]
    free = list(model.free)

    def resid(th):
        f = rhs_vectorized(model.with_params(dict(zip(free, th))), X, U, t)
        return (dX - f).T.ravel() / (np.std(dX) + 1e-300)

    th0 = np.array([model.params[k] for k in free])
    try:
        sol = least_squares(resid, th0, x_scale="jac", max_nfev=200)
    except Exception:
        return None
    return dict(zip(free, sol.x)) if np.all(np.isfinite(sol.x)) else None


def _declared_output_check(model: Model, t: np.ndarray, U: np.ndarray, X: np.ndarray, names: list[str]) -> None:
    """The states simulate but the fit's residual is not finite: name the declared output
    (``model.outputs``) whose expression is not finite, and where, instead of blaming the parameters."""
    with np.errstate(all="ignore"):
        Y = outputs(model, t, U, X, names)
    for j, name in enumerate(names):
        bad = ~np.isfinite(Y[:, j])
        if name not in model.states and bad.any():
            k = int(np.argmax(bad))
            raise SimulationError(f"{name!r} = {model.output_exprs[name].text!s} is {Y[k, j]} at t = {t[k]:.6g} s "
                                  "with the initial parameter values (a division by zero, or a root or logarithm "
                                  "of a negative number?)", key=f"model.outputs.{name}")


def param_bounds(model: Model, n_x0: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of ``model.free`` (config ``model.bounds``; ±inf where none), then of
    ``n_x0`` estimated initial states (unbounded)."""
    lo = [model.bounds.get(k, (-math.inf, math.inf))[0] for k in model.free] + [-math.inf] * n_x0
    hi = [model.bounds.get(k, (-math.inf, math.inf))[1] for k in model.free] + [math.inf] * n_x0
    return np.array(lo, float), np.array(hi, float)


def bound_side(model: Model, name: str, value: float) -> str | None:
    """"lower" or "upper" when ``value`` of parameter ``name`` sits on that bound of ``model.bounds``
    (within 1e-9 relative), else None."""
    lo, hi = model.bounds.get(name, (-math.inf, math.inf))
    tol = 1e-9 * max(1.0, abs(value))
    if np.isfinite(lo) and value - lo <= tol:
        return "lower"
    return "upper" if np.isfinite(hi) and hi - value <= tol else None


def at_bounds(fit: "FitResult") -> list[str]:
    """The free parameters a fit ended on one of their bounds (:func:`bound_side`): their standard
    errors are those of an interior optimum and do not describe a constrained estimate."""
    return [k for k, v in zip(fit.model.free, fit.theta) if bound_side(fit.model, k, float(v))]


STABLE_REL_STEP = 1e-4   # stable_jacobian's first relative step
TINY_PARAM = 1e-6        # fit_output_error optimises a parameter whose start is below this in units of its start
STABLE_WIDEN = 10.0       # a rough quotient's step is widened by this factor
STABLE_TIMES = 3          # at most this many times (stable_jacobian: to 0.1 of the parameter's size)
STABLE_TOL = 0.1          # until the column changes by less than this (relative norm)


def stable_quotient(column, h: float, times: int = STABLE_TIMES):
    """A difference-quotient column of a rough simulation (:func:`model.switches`): ``column(h)`` (None
    when it cannot be simulated) is recomputed with the step widened ``STABLE_WIDEN`` times while that
    changes it by more than ``STABLE_TOL`` of its norm, at most ``times`` times, and the narrower of the
    last two (the more accurate where both agree) is kept: the step is taken where the quotient is
    stable, the rule for derivatives of noisy simulations (Moré & Wild 2011, SIAM J. Sci. Comput. 33(3)).
    Shared by the fit's Jacobian (:func:`stable_jacobian`) and the added-term tests' sensitivities
    (``engine.Diagnoser.sensitivity``)."""
    c = column(h)
    if c is None:
        return None
    for _ in range(times):
        h *= STABLE_WIDEN
        wider = column(h)
        if wider is None or np.linalg.norm(c - wider) <= STABLE_TOL * np.linalg.norm(wider):
            break            # stable: the narrower quotient is the more accurate one
        c = wider
    return c


def stable_jacobian(resid, th: np.ndarray, deferred=None, ub: np.ndarray | None = None) -> np.ndarray:
    """Forward-difference Jacobian of ``resid`` at ``th`` for a rough simulation: each column by
    :func:`stable_quotient` from the step ``STABLE_REL_STEP``·max(|θ_i|, 0.01). The step is taken
    backwards where the forward one would cross the upper bound ``ub``. ``deferred``: the fit's
    thread-local flag that keeps these simulations out of a refit's budget."""
    if deferred is not None:
        deferred.on = True
    try:
        r0 = np.asarray(resid(th), float)
        cols = []
        for i in range(len(th)):
            def col(h):
                t = np.array(th, float)
                if ub is not None and t[i] + h > ub[i]:
                    h = -h
                t[i] += h
                return (np.asarray(resid(t), float) - r0) / h
            cols.append(stable_quotient(col, STABLE_REL_STEP * max(abs(float(th[i])), 0.01)))
        return np.column_stack(cols) if cols else np.zeros((len(r0), 0))
    finally:
        if deferred is not None:
            deferred.on = False


def fit_output_error(model: Model, prob: Problem, *, start: dict[str, float] | None = None,
                     max_nfev: int = 200, loss="linear", f_scale: float = 1.0,
                     sample_weights: np.ndarray | None = None, abandon_above: float | None = None,
                     abandon_after: int = 0, ftol: float = 1e-8, partial: bool = False) -> FitResult:
    """Output-error fit of ``model.free`` (and initial states marked "estimate").

    ``abandon_above``: raise :class:`RefitAbandoned` once ``abandon_after`` simulations (Jacobian
    columns included) have been run without any reaching a weighted SSE at or below this value. A refit
    of an extension starts at its linearised test estimate, whose error is below the current model's
    when the effect is real; the trust-region iterates only ever lower the cost, so a refit still above
    after a few iterations is in a poor basin (on Silverbox such refits ran 17–58 evaluations, 10–24 s,
    and ended at 3–27 times the current error).

    ``loss``/``f_scale`` are passed to ``least_squares`` (a robust ρ, e.g. a Student-t negative
    log-likelihood as a callable of z = r²); ``sample_weights`` (n_est,) multiply each estimation
    sample's residual (weighted LS, e.g. 1/σ_k for a variance model); (n_est, ny) weight each output's
    sample separately. ``ftol``: least_squares' relative cost tolerance (its default 1e-8; a looser one
    where the fit only ranks alternatives, e.g. the jump family's grid of break dates). ``partial``: a
    fitted model whose simulation stops (NaN, divergence) outside the estimation rows is returned with
    NaN there instead of raising (:func:`simulate_full`; the nominal fit of the diagnosis)."""
    est = prob.split.est
    stop = est[1]
    w = prob.weights
    yobs = prob.Y[est[0]:stop]
    sw = np.ones((yobs.shape[0], 1)) if sample_weights is None else np.asarray(sample_weights, float)
    if sw.ndim == 1:
        sw = sw[:, None]
    x0_names = [f"x0.{s}" for s in model.states if model.initial[s] == "estimate"]
    names = list(model.free) + x0_names
    # an estimated initial state starts from ``start``'s "x0.<state>" when given (a refit from the current
    # fit: at its null the refit's first simulation is then the current fit's own), else from the data
    x0_start = {k: v for k, v in (start or {}).items() if k in x0_names}
    x0_base = initial_state(model, prob, values=x0_start or None, at=prob.fit_segment()[0])
    th0 = np.array([(start or {}).get(k, model.params[k]) for k in model.free]
                   + [x0_base[model.states.index(n[3:])] for n in x0_names], dtype=float)
    nfree = len(model.free)
    lb, ub = param_bounds(model, len(x0_names))
    bounded = bool(np.any(np.isfinite(lb)) or np.any(np.isfinite(ub)))
    if bounded:      # a start outside the bounds (an equation-error estimate, a test's linearised value)
        th0 = np.clip(th0, lb, ub)
    penalty = np.full(yobs.size, 1e3)
    # the optimiser works on θ/s: s = |θ₀| for a start below TINY_PARAM in magnitude (not 0), else 1.
    # scipy's finite-difference step is √ε·max(1, |θ|), absolute below 1: a cubic coefficient of 3e-12
    # (the demo's spring with x and u in micro-units) got a step 5 000 times its size, and its refit
    # kept a quarter of the gain. With s = 1 (every other start) φ = θ exactly: nothing changes, bit for bit.
    s = np.where((np.abs(th0) < TINY_PARAM) & (th0 != 0), np.abs(th0), 1.0)

    def unpack(th):
        m = model.with_params(dict(zip(model.free, th[:nfree])))
        x0 = x0_base.copy()
        for n, v in zip(x0_names, th[nfree:]):
            x0[model.states.index(n[3:])] = v
        return m, x0

    calls = [0, math.inf]          # simulations run, lowest SSE seen
    deferred = threading.local()   # set in the Jacobian's worker threads: counted afterwards, in order

    def count(r):
        calls[0] += 1
        calls[1] = min(calls[1], float(r @ r))
        if calls[0] >= abandon_after and calls[1] > abandon_above:
            raise RefitAbandoned(f"abandoned after {calls[0]} simulations: its error stayed at "
                                 f"{calls[1] / abandon_above:.3g} x the current model's or more")

    start_r = [None]   # the start's residual: scipy evaluates the start again, the simulation is reused

    def resid(th):
        if start_r[0] is not None and np.array_equal(th, th0):
            r = start_r[0].copy()
        else:
            m, x0 = unpack(th)
            Yh = simulate_until(m, prob, x0, stop)
            if Yh is None or not np.all(np.isfinite(Yh[est[0]:stop])):
                r = penalty
            else:
                r = ((yobs - Yh[est[0]:stop]) * w * sw).ravel()
        if abandon_above is not None and not getattr(deferred, "on", False):
            count(r)
        return r

    def jacobian_map(fun, xs):
        """scipy's finite-difference Jacobian columns (one simulation each) evaluated in threads (the
        kernel releases the GIL). scipy forms J from the returned values exactly as from its serial map,
        and the abandon rule is applied afterwards to the results in column order, so the fit, its
        Jacobian and the point where a refit is abandoned are the same as when run serially."""
        xs = list(xs)

        def one(x):
            deferred.on = True
            try:
                return fun(x)
            finally:
                deferred.on = False

        with ThreadPoolExecutor(max_workers=min(len(xs), JACOBIAN_THREADS) or 1) as pool:
            rs = list(pool.map(one, xs))
        if abandon_above is not None:
            for r in rs:
                count(np.asarray(r, float))
        return rs

    def resid_s(ph):
        """``resid`` of θ = s·φ (the optimiser's variables; :data:`TINY_PARAM`)."""
        return resid(ph * s)

    if len(th0):
        r0 = resid(th0)
        start_r[0] = None if r0 is penalty else r0
        if r0 is penalty:
            m0, x00 = unpack(th0)
            a, b = prob.fit_segment()
            why = simulate_states(m0, prob.t[a:stop], prob.inputs(m0)[a:stop], x00, bound=prob.bound,
                                  prefiltered=True)
            if why.diverged_at is None:
                _declared_output_check(m0, prob.t[a:stop], prob.U[a:stop], why.X, prob.out_names)
            detail = why.reason(prob.t[a:stop]) if why.diverged_at is not None else "the model diverges"
            _raise_if_undefined(m0, prob.t[a:stop], prob.inputs(m0)[a:stop], x00, why,
                                "the model diverges with its initial parameter values", "(model.params, model.initial)")
            raise SimulationError(f"the model diverges with its initial parameter values: {detail} "
                                  "(model.params, model.initial)")
        steps = (stop - prob.fit_segment()[0]) * model.substeps
        par = ({"workers": jacobian_map} if _LSQ_WORKERS and JACOBIAN_THREADS > 1 and len(th0) > 1
               and steps >= JACOBIAN_THREADS_MIN_STEPS else {})
        if bounded:
            par["bounds"] = (lb / s, ub / s)
        sol = least_squares(resid_s, th0 / s, x_scale="jac", max_nfev=max_nfev, method="trf", loss=loss,
                            f_scale=f_scale, ftol=ftol, **par)
        th, J = sol.x * s, sol.jac / s           # dr/dθ = (dr/dφ)/s
        ok, msg, nfev = bool(sol.success), str(sol.message), int(sol.nfev)
        if switches(model):
            # scipy's step (√ε·|θ|) can straddle a jump of a sign(state) model's simulation: columns of
            # 1e4 times their size were seen (Coulomb friction + a 1.3 Hz force), standard errors 1e4 too small
            J = stable_jacobian(resid_s, th / s, deferred, ub / s if bounded else None) / s
        elif loss != "linear":
            # scipy's jac is loss-modified; the covariance needs the plain residual's Jacobian at θ̂
            from scipy.optimize._numdiff import approx_derivative
            J = approx_derivative(resid_s, th / s, method="2-point") / s
    else:
        th, J, ok, msg, nfev = th0, np.zeros((yobs.size, 0)), True, "nothing to fit", 0
    m, x0 = unpack(th)
    Yh = simulate_full(m, prob, x0, partial)
    r = yobs - Yh[est[0]:stop]      # simulate_full uses the same segments: the fitted simulation
    rw = (r * w * sw).ravel()
    sse = float(rw @ rw)
    dof = max(rw.size - len(th), 1)
    ident = None
    if len(th):
        cov, ident = scaled_covariance(J, sse / dof, names, scores=score_rows(J, rw, yobs.shape[1]),
                                       ny=yobs.shape[1], output_var=np.mean(rw.reshape(-1, yobs.shape[1]) ** 2, axis=0))
    else:
        cov = np.zeros((0, 0))
    std = np.sqrt(np.clip(np.diag(cov), 0, None)) if len(th) else np.zeros(0)
    std = np.where(np.isnan(np.diag(cov)), np.nan, std) if len(th) else std
    return FitResult(m, x0, names, th, cov, std, Yh, r, J, sse, ok, msg, nfev, ident)
