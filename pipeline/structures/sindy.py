"""SINDy: sparse identification of nonlinear dynamics (Brunton, Proctor & Kutz 2016, PNAS 113(15),
3932–3937; with control, SINDYc: Brunton, Proctor & Kutz 2016, IFAC-PapersOnLine 49(18)).

ẋ = Θ(x, u) Ξ with Θ the term library (:mod:`pipeline.structures.library`) and Ξ sparse.  The
derivatives come from pysindy's differentiation methods (finite differences, Savitzky–Golay
smoothed finite differences, spectral), the sparse regression from pysindy's optimizers (STLSQ —
sequentially thresholded least squares, Brunton et al. 2016, Algorithm in SI; SR3 — Zheng et al.
2019 / Champion et al. 2020, with the L0 weight λ = threshold²/(2ν) so the hard threshold equals
``threshold``).  The threshold is chosen by blocked cross-validation
(:mod:`pipeline.selection`) scored on the **free-run simulation** of each validation block: the
discovered equations are integrated with :func:`scipy.integrate.solve_ivp` from the measured state
at the start of the block, driven by the measured input held constant between samples (zero-order
hold), and compared with the measured states.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import pysindy as ps
from scipy.integrate import solve_ivp

from pipeline.errors import InputError, SimulationError
from pipeline.selection import blocked_folds
from pipeline.structures.library import Library

DIFFERENTIATION = {
    "finite_difference": lambda: ps.FiniteDifference(order=2),
    "smoothed_finite_difference": lambda: ps.SmoothedFiniteDifference(),
    "spectral": lambda: ps.SpectralDerivative(),
}
OPTIMIZERS = ("stlsq", "sr3")


def _optimizer(name: str, threshold: float, alpha: float):
    if name == "stlsq":
        return ps.STLSQ(threshold=threshold, alpha=alpha, unbias=True)
    if name == "sr3":
        nu = 1.0
        return ps.SR3(reg_weight_lam=ps.SR3.calculate_l0_weight(threshold, nu), relax_coeff_nu=nu,
                      regularizer="L0", unbias=True, max_iter=100)
    raise InputError(f"sindy: optimizer {name!r}; expected one of {list(OPTIMIZERS)}")


@dataclass
class SindyModel:
    """ẋ_i = Σ_j coef[i, j] φ_j(x, u) for the states ``states`` and inputs ``inputs``."""

    states: list[str]
    inputs: list[str]
    library: Library
    coef: np.ndarray
    threshold: float
    optimizer: str
    cv: dict | None = field(default=None, repr=False)

    def equations(self, precision: int = 3) -> list[str]:
        """Readable equations, ``"x' = 1.000 v"`` (pysindy's ``model.equations()`` style)."""
        out = []
        for name, row in zip(self.states, self.coef):
            parts = []
            for c, term in zip(row, self.library.names):
                if round(c, precision) == 0:
                    continue
                parts.append(f"{c:.{precision}f}" if term == "1" else f"{c:.{precision}f} {term}")
            rhs = " + ".join(parts) if parts else f"{0:.{precision}f}"
            out.append(f"{name}' = {rhs.replace('+ -', '- ')}")
        return out

    def active(self) -> Library | None:
        keep = np.flatnonzero(np.any(self.coef != 0, axis=0))
        return Library([self.library.terms[j] for j in keep]) if keep.size else None

    def rhs_fn(self):
        """f(x, u) -> ẋ evaluating only the terms with a non-zero coefficient."""
        keep = np.flatnonzero(np.any(self.coef != 0, axis=0))
        terms = [self.library.terms[j] for j in keep]
        coef = self.coef[:, keep]
        names = self.states + self.inputs
        fns = [t.scalar() for t in terms]
        zero = np.zeros(len(self.states))

        def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
            if not fns:
                return zero
            env = dict(zip(names, [*map(float, x), *map(float, u)]))
            return coef @ np.array([fn(env) for fn in fns])

        return f

    def simulate(self, x0: Sequence[float], t: np.ndarray, u: np.ndarray | None = None,
                 rtol: float = 1e-6, atol: float = 1e-9) -> np.ndarray:
        """Free-run simulation at the sample times ``t`` with the input ``u`` (N × n_inputs) held
        constant over each sample interval (zero-order hold); raises SimulationError on blow-up."""
        t = np.asarray(t, dtype=float)
        n = t.size
        ni = len(self.inputs)
        if ni:
            if u is None:
                raise InputError(f"simulate: model has inputs {self.inputs}; expected an input array u")
            u = np.asarray(u, dtype=float).reshape(n, ni)
        else:
            u = np.zeros((n, 0))
        f = self.rhs_fn()
        x = np.empty((n, len(self.states)))
        x[0] = np.asarray(x0, dtype=float)
        scale = 1e6 * (1.0 + np.max(np.abs(x[0])))

        def rhs(tt, xx):
            k = min(max(int(np.searchsorted(t, tt, side="right")) - 1, 0), n - 1)
            return f(xx, u[k])

        # one solve_ivp call per run of constant input would be exact; instead integrate the whole
        # record with the step capped at the sample interval so each ZOH jump is resolved
        dt = float(np.min(np.diff(t))) if n > 1 else 1.0
        sol = solve_ivp(rhs, (t[0], t[-1]), x[0], t_eval=t, rtol=rtol, atol=atol, max_step=dt,
                        method="RK45")
        if not sol.success or sol.y.shape[1] != n or not np.all(np.isfinite(sol.y)) \
                or np.max(np.abs(sol.y)) > scale:
            raise SimulationError(f"sindy model diverged in free-run simulation ({sol.message})")
        return sol.y.T


def _derivative(method, X: np.ndarray, t: np.ndarray) -> np.ndarray:
    if method is None:
        method = "finite_difference"
    if isinstance(method, str):
        if method not in DIFFERENTIATION:
            raise InputError(f"sindy: differentiation {method!r}; expected one of {sorted(DIFFERENTIATION)}")
        method = DIFFERENTIATION[method]()
    return np.asarray(method(X, t))


def _prepare(data, states, inputs, lib, t):
    if not isinstance(lib, Library):
        lib = Library(lib)
    if lib.max_lag:
        raise InputError("sindy: the library uses delayed signals; expected a continuous-time library "
                         "of the current states and inputs")
    states, inputs = list(states), list(inputs or [])
    for k in states + inputs:
        if k not in data:
            raise InputError(f"sindy: signal {k!r} is not in the data; expected one of {sorted(data)}")
    extra = lib.variables - set(states) - set(inputs)
    if extra:
        raise InputError(f"sindy: library uses {sorted(extra)} which are neither states {states} nor inputs {inputs}")
    X = np.column_stack([np.asarray(data[k], dtype=float) for k in states])
    U = np.column_stack([np.asarray(data[k], dtype=float) for k in inputs]) if inputs else np.zeros((X.shape[0], 0))
    t = np.asarray(t, dtype=float)
    if t.ndim == 0:
        t = np.arange(X.shape[0]) * float(t)
    if t.shape[0] != X.shape[0] or np.any(np.diff(t) <= 0):
        raise InputError(f"sindy: t must be {X.shape[0]} strictly increasing sample times (or a sample interval)")
    theta = lib.evaluate({**{k: X[:, i] for i, k in enumerate(states)},
                          **{k: U[:, i] for i, k in enumerate(inputs)}})
    if theta.shape[1] > theta.shape[0]:
        raise InputError(f"sindy: {theta.shape[1]} candidate terms for {theta.shape[0]} samples; "
                         "expected fewer terms than samples")
    return lib, states, inputs, X, U, t, theta


def _fit_rows(theta, Xdot, rows, optimizer, threshold, alpha):
    opt = _optimizer(optimizer, threshold, alpha)
    with warnings.catch_warnings():  # pysindy warns when a threshold removes every term
        warnings.simplefilter("ignore")
        opt.fit(theta[rows], Xdot[rows])
    return np.atleast_2d(np.asarray(opt.coef_, dtype=float))


def simulation_nmse(model: SindyModel, X: np.ndarray, U: np.ndarray, t: np.ndarray) -> float:
    """Free-run simulation error: Σ‖x_sim − x‖² / Σ‖x − mean x‖² over the record (inf on blow-up)."""
    try:
        xs = model.simulate(X[0], t, U)
    except InputError:
        return float("inf")
    den = float(np.sum((X - X.mean(axis=0)) ** 2)) or 1.0
    return float(np.sum((xs - X) ** 2) / den)


def fit_sindy(
    data: Mapping[str, np.ndarray],
    states: Sequence[str],
    library: Library | Sequence[str],
    t: np.ndarray | float,
    inputs: Sequence[str] | None = None,
    optimizer: str = "stlsq",
    threshold: float | Sequence[float] = 0.1,
    differentiation=None,
    alpha: float = 1e-6,
    cv_folds: int = 4,
    cv_gap: int = 5,
    seed: int = 0,
    x_dot: np.ndarray | None = None,
) -> SindyModel:
    """Fit ẋ = Θ(x, u) Ξ.  A sequence of thresholds is chosen by blocked CV on free-run simulation.

    ``differentiation``: ``"finite_difference"`` (default), ``"smoothed_finite_difference"``,
    ``"spectral"`` or a pysindy differentiation object; ``x_dot`` overrides it.  Derivatives are
    computed once on the whole record, so ``cv_gap`` should cover the differentiation stencil
    (half the Savitzky–Golay window, 5 samples by default) as well as any lag.
    """
    lib, states, inputs, X, U, t, theta = _prepare(data, states, inputs, library, t)
    Xdot = np.asarray(x_dot, dtype=float).reshape(X.shape) if x_dot is not None else _derivative(differentiation, X, t)
    ok = np.all(np.isfinite(Xdot), axis=1) & np.all(np.isfinite(theta), axis=1)
    thresholds = np.atleast_1d(np.asarray(threshold, dtype=float))
    if np.any(thresholds < 0):
        raise InputError(f"sindy: threshold {threshold!r}; expected non-negative values")
    cv = None
    if thresholds.size > 1:
        folds = blocked_folds(X.shape[0], cv_folds, cv_gap, seed)
        table = np.empty((thresholds.size, len(folds)))
        for a, thr in enumerate(thresholds):
            for f, (train, val) in enumerate(folds):
                rows = train[ok[train]]
                m = SindyModel(states, inputs, lib, _fit_rows(theta, Xdot, rows, optimizer, thr, alpha), thr, optimizer)
                table[a, f] = simulation_nmse(m, X[val], U[val], t[val])
        mean = table.mean(axis=1)
        best = int(np.argmin(mean))
        cv = {"thresholds": thresholds, "scores": table, "mean": mean, "chosen": float(thresholds[best]),
              "label": "free-run simulation error (NMSE)", "folds": cv_folds, "gap": cv_gap, "seed": seed}
        thr = float(thresholds[best])
    else:
        thr = float(thresholds[0])
    coef = _fit_rows(theta, Xdot, np.flatnonzero(ok), optimizer, thr, alpha)
    return SindyModel(states, inputs, lib, coef, thr, optimizer, cv)


__all__ = ["SindyModel", "fit_sindy", "simulation_nmse"]
