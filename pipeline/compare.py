"""Candidate structures for one state equation, compared (issues 3 and 4).

    d(eq)/dt = known(x, u, t) + Σ_i θ_i φ_i(x, u, t)

Each candidate (a term list from the config, the FROLS selection from a library, SINDy's active terms,
a Takagi–Sugeno model) is fitted by equation error — target ẋ − known with ẋ from the prefilter's
derivative estimate — with every configured estimator (LS, WLS, IV, ML, MAP, MCMC, RLS), then
simulated free-run with the nominal model's other equations and scored on the same blocked folds:

* free-run simulation RMSE per fold (blocked k-fold CV on the estimation part, contiguous folds,
  ``cv_gap`` samples excluded on each side; the simulation starts at the fold's first sample from the
  measured state when every state is measured, else from the record start),
* the regression residual's RMSE per fold (``cv_rmse_one_step``, a key kept under its first name),
  labelled by what it measures (``cv_rmse_one_step_kind``, ``cv_rmse_one_step_measures``; see
  ``one_step_measure``): here the target is the derivative estimate, so it is the equation error of
  d(eq)/dt in the state's unit per second, not a one-step-ahead prediction of the output,
* AIC, AICc, BIC, FPE (MATLAB definitions) and the course project's energy BIC k ln N + N ln(E/N)
  from the free-run residual on the estimation part, E = ∫e² dt ≈ Σe²·Δt the error energy (the
  ``energy`` field; seed case ``kar_p2a_series_parallel_energy`` defines E so),
* validation free-run RMSE (data never used for fitting).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from . import criteria, progress
from .config import LoadedConfig
from .data import Record, Split
from .errors import ConfigError, EstimationError, InputError
from .estimators import ESTIMATORS
from .expressions import parse, vectorize
from .model import Model
from .prefilter import derivative
from .selection import blocked_folds
from .jsonutil import clean as _clean
from .simulate import outputs, simulate_states


def one_step_measure(state: str, unit: str | None = None, method: str | None = None) -> dict:
    """The keys saying what a structure row's ``cv_rmse_one_step`` (RMS of ``target − Φθ`` on a fold)
    measures: the target is d ``state``/dt estimated from the data (by ``method``), so it is the
    equation error of the derivative in ``unit`` (config ``units``) per second, not a one-step-ahead
    prediction of the state (an auditor's record: 0.052 m/s against a one-step prediction RMSE of
    0.014 m for the true model)."""
    rate = f"{unit}/s" if unit else f"units of {state} per second"
    how = f"the {method} estimate of d{state}/dt" if method else f"d{state}/dt estimated from the data"
    return {"cv_rmse_one_step_kind": "equation_error",
            "cv_rmse_one_step_measures": (f"equation error of d{state}/dt, in {rate}: RMS of the regression residual "
                                          f"on the fold, with {how} as the target; not a one-step-ahead "
                                          f"prediction of {state}")}


@dataclass
class StructureResult:
    name: str
    estimator: str
    terms: list[str]
    theta: np.ndarray | None = None
    std: np.ndarray | None = None
    equation: str = ""
    energy: float | None = None
    crit: dict = field(default_factory=dict)
    cv_sim: list[float] = field(default_factory=list)
    cv_onestep: list[float] = field(default_factory=list)
    val_rmse: float | None = None
    error: str | None = None
    extra: dict = field(default_factory=dict)
    # what cv_onestep measures (one_step_measure's keys); empty when there is no cv_onestep
    onestep_measure: dict = field(default_factory=dict)

    @property
    def cv_mean(self) -> float:
        return float(np.mean(self.cv_sim)) if self.cv_sim else math.inf

    def record(self) -> dict:
        return {"name": self.name, "estimator": self.estimator, "terms": self.terms, "equation": self.equation,
                "theta": None if self.theta is None else list(self.theta),
                "theta_std": None if self.std is None else list(self.std),
                "n_params": len(self.terms) if self.theta is None else int(self.theta.size),
                "energy": self.energy, **self.crit,
                "cv_rmse_sim": self.cv_sim or None, "cv_mean": None if not self.cv_sim else self.cv_mean,
                # a fold whose simulation diverged scores inf: no spread then (np.std warned on inf - inf)
                "cv_sd": (None if len(self.cv_sim) < 2 or not np.all(np.isfinite(self.cv_sim))
                          else float(np.std(self.cv_sim, ddof=1))),
                "cv_rmse_one_step": self.cv_onestep or None,
                # added keys (the contract adds, never renames): what cv_rmse_one_step measures
                **{k: self.onestep_measure.get(k) if self.cv_onestep else None
                   for k in ("cv_rmse_one_step_kind", "cv_rmse_one_step_measures")},
                "validation_rmse_sim": self.val_rmse,
                "error": self.error}


@dataclass
class Comparison:
    results: list[StructureResult]
    selected: str | None
    frols: dict | None = None
    sindy: dict | None = None
    takagi_sugeno: dict | None = None
    warnings: list[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)


def _log(msg: str) -> None:
    print(f"[structures] {msg}", file=sys.stderr, flush=True)


class Comparer:
    def __init__(self, lc: LoadedConfig, rec: Record, split: Split, model: Model):
        self.lc, self.rec, self.split, self.model = lc, rec, split, model
        self.sc = lc.cfg.structures
        self.eq = self.sc.equation
        self.file = str(lc.path)
        if self.eq not in rec.outputs:
            raise ConfigError(f"state {self.eq!r} must be measured to fit its equation by equation error",
                              file=self.file, key="structures.equation")
        self.data = {**rec.outputs, **rec.inputs, "t": rec.t}
        self.allowed = set(model.states) | set(model.inputs) | {"t"}
        known = parse(self.sc.known, self.allowed | set(model.params), where="structures.known", file=self.file)
        self.known_text = known.text
        dc = self.sc.derivative
        dx, msg = derivative(rec.outputs[self.eq], rec.dt, dc.method, window=dc.window, polyorder=dc.polyorder,
                             warn=False)
        self.warnings = [msg] if msg else []
        self.target = dx - self._eval(known)
        # the regression target is a derivative estimate: its residual is an equation error of
        # d(eq)/dt (in the state's unit per second), not a one-step prediction of the output
        self.onestep_measure = one_step_measure(self.eq, lc.cfg.units.get(self.eq), dc.method)
        self.est_rows = np.arange(*split.est)
        self.all_measured = all(s in rec.outputs for s in model.states)
        self.out_names = list(rec.outputs)
        ts = self.sc.takagi_sugeno
        for v in (ts.inputs or []) if ts else []:
            if v not in self.data:
                raise ConfigError(f"{v!r} is not a measured signal (measured: {sorted(self.data)})",
                                  file=self.file, key="structures.takagi_sugeno.inputs")
        self.Y = np.column_stack([rec.outputs[k] for k in self.out_names])
        self.U = rec.u_matrix(list(model.inputs))

    # -- helpers -----------------------------------------------------------------------------------
    def _eval(self, expr, rows=None) -> np.ndarray:
        names = sorted(expr.names)
        missing = [n for n in names if n not in self.data and n not in self.model.params]
        if missing:
            raise ConfigError(f"{expr.text!r} uses {missing[0]!r}, which is not measured", file=self.file,
                              key="structures")
        args = [self.data[n] if n in self.data else self.model.params[n] for n in names]
        # a user's term may overflow on the data (exp(x*100)): its structure's rows then say "regressors
        # contain NaN or infinite values", without numpy's RuntimeWarning on stderr first
        with np.errstate(all="ignore"):
            v = np.broadcast_to(np.asarray(vectorize(expr, names)(*args), float), self.rec.t.shape)
        return v if rows is None else v[rows]

    def regressors(self, name: str, terms: list[str]) -> np.ndarray:
        cols = [self._eval(parse(t, self.allowed, where=f"structures.candidates.{name}", file=self.file))
                for t in terms]
        Phi = np.column_stack(cols)
        if len(terms) >= len(self.est_rows):
            raise InputError(f"{len(terms)} candidate terms but only {len(self.est_rows)} estimation samples; "
                             "expected fewer terms than samples", file=self.file, key=f"structures.candidates.{name}")
        return Phi

    def sim_model(self, terms: list[str], theta: np.ndarray, extra: dict[str, float] | None = None
                  ) -> tuple[Model, str]:
        """The nominal model with the candidate's equation; θ enters as parameters ``th_i`` (and
        ``extra`` ones, e.g. T–S centres), so the kernel is compiled once per structure, not per fit."""
        names = [f"th_{i}" for i in range(len(terms))]
        rhs = " + ".join([f"({self.known_text})"] + [f"{n}*({t})" for n, t in zip(names, terms)])
        vals = dict(zip(names, map(float, theta)))
        vals.update(extra or {})
        allowed = self.allowed | set(self.model.nominal_params) | set(vals)
        ex = parse(rhs, allowed, where="structures", file=self.file)
        eqs = dict(self.model.equations)
        eqs[self.eq] = ex
        params = {**{k: self.model.params[k] for k in self.model.nominal_params}, **vals}
        pretty = f"d{self.eq}/dt = {self.known_text} " + " ".join(f"{c:+.4g}*{t}" for c, t in zip(theta, terms))
        m = replace(self.model, equations=eqs, free=(), terms=(), delay=None, params=params,
                    nominal_params=tuple(params))
        return m, pretty

    def simulate(self, m: Model, start: int, stop: int) -> np.ndarray | None:
        x0 = np.array([self.Y[start, self.out_names.index(s)] if s in self.out_names else
                       (float(m.initial[s]) if not isinstance(m.initial[s], str) else 0.0) for s in m.states])
        t, U = self.rec.t[start:stop], self.U[start:stop]
        bound = 1e6 * max(1.0, float(np.max(np.abs(self.Y))))
        res = simulate_states(m, t, U, x0, bound=bound)
        if res.diverged_at is not None:
            return None
        return outputs(m, t, U, res.X, self.out_names)

    def fit_estimator(self, est: str, opts: dict, Phi: np.ndarray, rows: np.ndarray, terms: list[str]):
        y = self.target[rows]
        o = dict(opts)
        if est in ("map", "mcmc"):
            from .estimators.bayes import GaussianPrior
            o["prior"] = GaussianPrior(o.pop("prior_mean", 0.0), o.pop("prior_sd", 10.0) ** 2)
            if est == "mcmc":
                o.setdefault("seed", self.lc.cfg.seed)
                o.setdefault("nsteps", 2000)
        if est == "iv" and "instruments" not in o:
            # instruments: the terms evaluated on the free-run simulation of the LS model (auxiliary model)
            ls = ESTIMATORS["ls"](Phi[rows], y)
            m, _ = self.sim_model(terms, ls.theta)
            Yh = self.simulate(m, 0, self.split.est[1])
            if Yh is None:
                raise EstimationError("iv: the auxiliary LS model diverges; no instruments")
            sim_data = dict(self.data)
            for k, name in enumerate(self.out_names):
                sim_data[name] = np.concatenate([Yh[:, k], self.Y[self.split.est[1]:, k]])
            saved, self.data = self.data, sim_data
            try:
                Z = self.regressors("iv", terms)
            finally:
                self.data = saved
            o["instruments"] = Z[rows]
        if est in ("map", "mcmc") and "sigma" not in o:
            o["sigma"] = float(np.std(y - Phi[rows] @ ESTIMATORS["ls"](Phi[rows], y).theta))
        return ESTIMATORS[est](Phi[rows], y, **o)

    # -- one candidate ---------------------------------------------------------------------------------
    def evaluate(self, name: str, terms: list[str], est: str, opts: dict, fitter=None) -> StructureResult:
        r = StructureResult(name, est, list(terms), onestep_measure=dict(self.onestep_measure))
        try:
            Phi = self.regressors(name, terms) if fitter is None else None
            fit = (lambda rows: self.fit_estimator(est, opts, Phi, rows, terms)) if fitter is None else fitter
            e = fit(self.est_rows)
            r.theta = np.asarray(getattr(e, "theta_full", e.theta), float)
            r.std = None if e.cov is None else np.sqrt(np.clip(np.diag(e.cov), 0, None))
            if est == "rls" and getattr(e, "extra", None) and "theta_trajectory" in e.extra:
                r.extra["theta_trajectory"] = np.asarray(e.extra["theta_trajectory"])
                r.extra["t"] = self.rec.t[self.est_rows]
            m, r.equation = self.sim_model(getattr(e, "terms", terms), np.asarray(e.theta, float),
                                           getattr(e, "values", None))
            if fitter is not None:
                r.equation = f"d{self.eq}/dt = {self.known_text} + {name}"
            Yh = self.simulate(m, 0, len(self.rec.t))
            if Yh is None:
                r.error = "diverges in free-run simulation"
                return r
            es, vs = self.split.est_slice(), self.split.val_slice()
            res = self.Y[es] - Yh[es]
            n, p = res.shape[0], r.theta.size
            r.energy = float(np.sum(res ** 2) * self.rec.dt)   # E = ∫e² dt (seed 000's E column)
            r.crit = {"aic": criteria.aic(res, p), "aicc": criteria.aicc(res, p), "bic": criteria.bic(res, p),
                      "fpe": criteria.fpe(res, p), "bic_energy": criteria.bic_energy(r.energy, n, p)}
            r.val_rmse = float(np.sqrt(np.mean((self.Y[vs] - Yh[vs]) ** 2)))
            for train, val in self.folds:
                ef = fit(self.est_rows[train])
                th = np.asarray(ef.theta, float)
                mf, _ = self.sim_model(getattr(ef, "terms", terms), th, getattr(ef, "values", None))
                a, b = self.est_rows[val[0]], self.est_rows[val[-1]] + 1
                Yf = self.simulate(mf, a if self.all_measured else 0, b)
                r.cv_sim.append(math.inf if Yf is None else
                                float(np.sqrt(np.mean((self.Y[a:b] - Yf[-(b - a):]) ** 2))))
                if fitter is None:
                    rows = self.est_rows[val]
                    r.cv_onestep.append(float(np.sqrt(np.mean((self.target[rows] - Phi[rows] @ th) ** 2))))
        except (EstimationError, InputError) as exc:
            if isinstance(exc, ConfigError):
                raise
            r.error = str(exc)
        return r

    def run(self) -> Comparison:
        sc = self.sc
        cands = {k: list(v) for k, v in sc.candidates.items()}
        for name, terms in cands.items():
            if len(terms) >= len(self.est_rows):
                raise InputError(f"{len(terms)} candidate terms but only {len(self.est_rows)} estimation samples; "
                                 "expected fewer terms than samples", file=self.file, key=f"structures.candidates.{name}")
        # in fold order (fold f holds the f-th block of the estimation part): cv_rmse_sim[f] is that block's
        # score; the folds are contiguous blocks, so there is nothing random to seed
        self.folds = blocked_folds(len(self.est_rows), sc.cv_folds, sc.cv_gap)
        out = Comparison([], None, warnings=list(self.warnings),
                         settings={"equation": self.eq, "known": self.known_text, "folds": sc.cv_folds,
                                   "gap": sc.cv_gap, "derivative": sc.derivative.model_dump(),
                                   "cv_start": "measured state at the fold start" if self.all_measured
                                   else "record start",
                                   # record sample indices [start, stop) of fold f's validation block:
                                   # cv_rmse_sim[f] and cv_rmse_one_step[f] are scored there
                                   "fold_blocks": [[int(self.est_rows[v[0]]), int(self.est_rows[v[-1]]) + 1]
                                                   for _, v in self.folds]})
        if sc.library is not None:
            out.frols = self.run_frols()
            cands["frols"] = out.frols["terms"]
        if sc.sindy is not None:
            out.sindy = self.run_sindy()
            if out.sindy["terms"]:
                cands["sindy"] = out.sindy["terms"]
        ests = self.lc.cfg.estimator_list()
        pairs = [(name, terms, est, opts) for name, terms in cands.items() for est, opts in ests]
        with progress.stage("structures", total=len(pairs)):
            for name, terms, est, opts in progress.bar(pairs, len(pairs), "candidates × estimators"):
                out.results.append(self.evaluate(name, terms, est, opts))
        if sc.takagi_sugeno is not None:
            out.takagi_sugeno, res = self.run_takagi_sugeno()
            out.results.append(res)
        ok = [r for r in out.results if r.error is None and r.cv_sim and math.isfinite(r.cv_mean)]
        out.selected = min(ok, key=lambda r: (r.cv_mean, r.crit.get("bic", 0))).name if ok else None
        return out

    # -- generated candidates --------------------------------------------------------------------------
    def run_frols(self) -> dict:
        from .structures import frols
        from .structures import library as L
        lib_cfg = self.sc.library
        parts = []
        if lib_cfg.poly:
            parts.append(L.poly(list(lib_cfg.poly.vars), lib_cfg.poly.degree, include_bias=lib_cfg.poly.include_bias))
        for fam in ("tanh", "rational", "sign"):
            if getattr(lib_cfg, fam):
                parts.append(getattr(L, fam)(getattr(lib_cfg, fam)))
        if lib_cfg.terms:
            parts.append(L.from_terms(lib_cfg.terms))
        if not parts:
            raise ConfigError("empty library: give poly, tanh, rational, sign or terms", file=self.file,
                              key="structures.library")
        lib = parts[0]
        for p in parts[1:]:
            lib = lib + p
        P = lib.evaluate({k: v[self.est_rows] for k, v in self.data.items()})
        res = frols(P, self.target[self.est_rows], lib.names, criterion=lib_cfg.criterion,
                    max_terms=min(lib_cfg.max_terms, len(lib.names)))
        terms = [t.replace("^", "**") for t in res.terms]
        return {"terms": terms, "err": [float(e) for e in res.err[: len(res.names)]], "names": list(res.names),
                "criterion": lib_cfg.criterion, "criterion_values": [float(v) for v in res.criterion_values],
                "n_candidates": len(lib.names), "stop_reason": res.stop_reason}

    def run_sindy(self) -> dict:
        from .structures import library as L
        from .structures.sindy import fit_sindy
        cfg = self.sc.sindy
        lib = L.from_terms(cfg.terms) if cfg.terms else L.poly([self.eq], 3)
        rows = self.est_rows
        m = fit_sindy({k: v[rows] for k, v in self.data.items()}, [self.eq], lib, self.rec.t[rows], inputs=[],
                      optimizer=cfg.optimizer, threshold=cfg.threshold, x_dot=self.target[rows][:, None],
                      seed=self.lc.cfg.seed)
        active = [n for n, c in zip(lib.names, m.coef[0]) if c != 0]
        return {"equations": m.equations(), "terms": active, "threshold": m.threshold, "optimizer": m.optimizer,
                "cv": None if m.cv is None else {"thresholds": list(map(float, m.cv["thresholds"])),
                                                 "mean": list(map(float, m.cv["mean"])), "label": m.cv["label"]}}

    def run_takagi_sugeno(self):
        from .structures.takagi_sugeno import fit_takagi_sugeno, select_rules
        cfg = self.sc.takagi_sugeno
        ins = list(cfg.inputs or [self.eq])
        rules = list(cfg.rules)
        method = cfg.method
        Uall = np.column_stack([self.data[v] for v in ins])
        rows = self.est_rows
        sel = select_rules(Uall[rows], self.target[rows], rules, k=self.sc.cv_folds, gap=self.sc.cv_gap,
                           seed=self.lc.cfg.seed, method=method)
        K = int(sel["chosen"])

        class _TSFit:
            def __init__(s, ts):
                s.ts = ts
                s.theta = ts.theta.ravel()
                s.cov = None
                expr, s.values = _ts_expression(ts, ins)
                s.terms = [expr]

        def fitter(r):
            return _TSFit(fit_takagi_sugeno(Uall[r], self.target[r], K, method=method, seed=self.lc.cfg.seed))

        res = self.evaluate(f"takagi_sugeno_K{K}", [f"TS({', '.join(ins)}), {K} rules"], f"ts-{method}-ls", {},
                            fitter=_TSWrap(fitter))
        ts = fitter(rows).ts
        grid = np.linspace(Uall[rows, 0].min(), Uall[rows, 0].max(), 200)
        info = {"inputs": ins, "rules": K, "candidates": rules, "selection": _clean(sel),
                "centres": ts.centres.tolist(), "sigmas": np.broadcast_to(ts.sigmas, ts.centres.shape).tolist(),
                "theta": ts.theta.tolist(), "rule_text": ts.rules(), "grid": grid.tolist()}
        return info, res


class _TSWrap:
    """Adapts a Takagi–Sugeno fitter to ``evaluate``: theta is replaced by 1 for the expression term."""

    def __init__(self, fitter):
        self.fitter = fitter

    def __call__(self, rows):
        f = self.fitter(rows)
        f.theta_full = f.theta
        f.theta = np.ones(1)
        return f


def _ts_expression(ts, ins: list[str]) -> tuple[str, dict[str, float]]:
    """The T–S model as an expression with named parameters:
    Σ_k β_k(u)(θ_kᵀu + θ_k0) / Σ_k β_k(u), β_k = exp(−Σ_s ((u_s − m_ks)/σ_ks)²) (textbook eq. 2.165)."""
    sig = np.broadcast_to(ts.sigmas, ts.centres.shape)
    betas, num, vals = [], [], {}
    for k in range(ts.n_rules):
        parts = []
        for s_, v in enumerate(ins):
            vals[f"ts_m{k}_{s_}"] = float(ts.centres[k, s_])
            vals[f"ts_s{k}_{s_}"] = float(sig[k, s_])
            parts.append(f"(({v}) - ts_m{k}_{s_})**2/ts_s{k}_{s_}**2")
        b = "exp(-(" + " + ".join(parts) + "))"
        lin = []
        for s_, v in enumerate(ins):
            vals[f"ts_a{k}_{s_}"] = float(ts.theta[k, s_])
            lin.append(f"ts_a{k}_{s_}*({v})")
        vals[f"ts_b{k}"] = float(ts.theta[k, -1])
        lin.append(f"ts_b{k}")
        betas.append(b)
        num.append(f"{b}*({' + '.join(lin)})")
    return f"(({' + '.join(num)})/({' + '.join(betas)}))", vals
