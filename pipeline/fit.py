"""Fitting the free parameters of a grey-box model.

* Output error (always): minimise Σ_k ‖W (y_k − ŷ_k(θ))‖² over the estimation samples, ŷ the free-run
  simulation from sample 0 (scipy ``least_squares``, trust-region reflective, Jacobian by finite
  differences). W scales each output by 1/std so outputs of different units weigh alike.
* Equation error (a fast start when every state is measured): least squares on
  ẋ_k − f(x_k, u_k; θ) with ẋ from central differences.
* Standard errors from the Jacobian: cov(θ̂) = σ̂² (JᵀJ)⁻¹, σ̂² = SSE/(N − p) (Ljung 1999, eq. 9.18
  for the prediction-error estimate with white output noise).

The simulation runs from sample 0 over every sample up to the end of the estimation part, so
validation samples that come before it (e.g. Silverbox's "arrow") are simulated but never scored here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .data import Record, Split
from .errors import ConfigError, SimulationError
from .model import Model, rhs_vectorized
from .simulate import outputs, simulate_states


@dataclass
class Problem:
    """What a fit needs from the record: time, input, measured outputs and the split."""

    t: np.ndarray
    U: np.ndarray
    Y: np.ndarray                 # (N, ny) measured, model names in ``out_names``
    out_names: list[str]
    split: Split
    bound: float
    sim_start: int = 0            # fitting simulations start here (split.warmup), not at sample 0

    @classmethod
    def from_record(cls, rec: Record, model: Model, split: Split, warmup: int | None = None) -> "Problem":
        names = list(rec.outputs)
        Y = np.column_stack([rec.outputs[k] for k in names])
        scale = max(1.0, float(np.max(np.abs(Y))))
        start = 0 if warmup is None else max(0, split.est[0] - warmup)
        return cls(rec.t, rec.u_matrix(list(model.inputs)), Y, names, split, bound=1e6 * scale, sim_start=start)

    @property
    def weights(self) -> np.ndarray:
        sl = self.split.est_slice()
        s = np.std(self.Y[sl], axis=0)
        return 1.0 / np.where(s > 0, s, 1.0)


@dataclass
class FitResult:
    model: Model                 # with fitted parameter values
    x0: np.ndarray               # initial state at sample 0
    names: list[str]             # estimated quantities: free params then "x0.<state>"
    theta: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    Yhat: np.ndarray             # (N, ny) free-run simulated outputs over the whole record
    resid_est: np.ndarray        # (n_est, ny) y − ŷ on the estimation part
    jac: np.ndarray              # (n_est*ny, p) Jacobian of the weighted residual
    sse_w: float
    success: bool
    message: str
    nfev: int

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


def initial_state(model: Model, prob: Problem, values: dict[str, float] | None = None, at: int = 0) -> np.ndarray:
    """Resolve the initial state at sample ``at`` (0: the record start): numbers, "data" (the measured
    sample there) or estimates."""
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


def simulate_until(model: Model, prob: Problem, x0: np.ndarray, stop: int) -> np.ndarray | None:
    """Free-run outputs for samples [0, stop) (x0 at sample 0); None if the model diverges. With a
    warm-up (``prob.sim_start`` > 0) the simulation starts there from the configured initial state
    and the rows before it are NaN."""
    a = prob.sim_start
    if a > 0:
        x0 = initial_state(model, prob, at=a)
    res = simulate_states(model, prob.t[a:stop], prob.U[a:stop], x0, bound=prob.bound)
    if res.diverged_at is not None:
        return None
    Y = outputs(model, prob.t[a:stop], prob.U[a:stop], res.X, prob.out_names)
    if a == 0:
        return Y
    full = np.full((stop, Y.shape[1]), np.nan)
    full[a:] = Y
    return full


def simulate_full(model: Model, prob: Problem, x0: np.ndarray) -> np.ndarray:
    """Free-run outputs over the whole record from sample 0 (x0), never from a warm-up start: these are
    the reported numbers. SimulationError if the model diverges."""
    res = simulate_states(model, prob.t, prob.U, x0, bound=prob.bound)
    Yh = None if res.diverged_at is not None else outputs(model, prob.t, prob.U, res.X, prob.out_names)
    if Yh is None:
        raise SimulationError(f"the fitted model diverges on this record (parameters {model.params})")
    return Yh


def equation_error_start(model: Model, prob: Problem) -> dict[str, float] | None:
    """LS on ẋ − f(x, u; θ) when every state is measured (fast start for the output-error fit)."""
    if not all(s in prob.out_names for s in model.states) or not model.free:
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


def fit_output_error(model: Model, prob: Problem, *, start: dict[str, float] | None = None,
                     max_nfev: int = 200, loss="linear", f_scale: float = 1.0,
                     sample_weights: np.ndarray | None = None) -> FitResult:
    """Output-error fit of ``model.free`` (and initial states marked "estimate").

    ``loss``/``f_scale`` are passed to ``least_squares`` (a robust ρ, e.g. a Student-t negative
    log-likelihood as a callable of z = r²); ``sample_weights`` (n_est,) multiply each estimation
    sample's residual (weighted LS, e.g. 1/σ_k for a variance model)."""
    est = prob.split.est
    stop = est[1]
    w = prob.weights
    yobs = prob.Y[est[0]:stop]
    sw = np.ones((yobs.shape[0], 1)) if sample_weights is None else np.asarray(sample_weights, float)[:, None]
    x0_names = [f"x0.{s}" for s in model.states if model.initial[s] == "estimate"]
    names = list(model.free) + x0_names
    x0_base = initial_state(model, prob)
    th0 = np.array([(start or {}).get(k, model.params[k]) for k in model.free]
                   + [x0_base[model.states.index(n[3:])] for n in x0_names], dtype=float)
    nfree = len(model.free)
    penalty = np.full(yobs.size, 1e3)

    def unpack(th):
        m = model.with_params(dict(zip(model.free, th[:nfree])))
        x0 = x0_base.copy()
        for n, v in zip(x0_names, th[nfree:]):
            x0[model.states.index(n[3:])] = v
        return m, x0

    def resid(th):
        m, x0 = unpack(th)
        Yh = simulate_until(m, prob, x0, stop)
        if Yh is None or not np.all(np.isfinite(Yh[est[0]:stop])):
            return penalty
        return ((yobs - Yh[est[0]:stop]) * w * sw).ravel()

    if len(th0):
        r0 = resid(th0)
        if r0 is penalty:
            raise SimulationError("the model diverges with its initial parameter values; check the "
                                  "equations' signs, model.params and model.initial")
        sol = least_squares(resid, th0, x_scale="jac", max_nfev=max_nfev, method="trf", loss=loss,
                            f_scale=f_scale)
        th, J, ok, msg, nfev = sol.x, sol.jac, bool(sol.success), str(sol.message), int(sol.nfev)
    else:
        th, J, ok, msg, nfev = th0, np.zeros((yobs.size, 0)), True, "nothing to fit", 0
    m, x0 = unpack(th)
    Yh = simulate_full(m, prob, x0)
    r = yobs - Yh[est[0]:stop]
    rw = (r * w * sw).ravel()
    sse = float(rw @ rw)
    dof = max(rw.size - len(th), 1)
    cov = np.full((len(th), len(th)), np.nan)
    if len(th):
        try:
            cov = (sse / dof) * np.linalg.pinv(J.T @ J)
        except np.linalg.LinAlgError:
            pass
    std = np.sqrt(np.clip(np.diag(cov), 0, None)) if len(th) else np.zeros(0)
    return FitResult(m, x0, names, th, cov, std, Yh, r, J, sse, ok, msg, nfev)
