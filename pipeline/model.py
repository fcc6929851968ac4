"""Grey-box model: the nominal ODE from the config plus additive extension terms.

    d(state)/dt = nominal(state, u, t; p) + Σ_j c_j · term_j(state, t)

An extension never changes the compiled nominal right-hand side: its terms are rows of a small table
(kind, equation, variable, coefficient index) that the kernel evaluates (see :mod:`pipeline.simulate`).
Output-side extensions (``output_offset``) and the input delay act outside the ODE.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .config import LoadedConfig
from .expressions import Expr

# kernel codes of additive term kinds
KIND_CODES = {"const": 0, "pow": 1, "sign": 2, "absprod": 3, "sin": 4, "cos": 5}


@dataclass(frozen=True)
class Term:
    """One additive extension term ``coef * term`` in a state equation (or an output offset)."""

    family: str
    kind: str                 # const | pow | sign | absprod | sin | cos | out_const
    target: str               # state equation, or measured output name for out_const
    coef: str                 # parameter name of the coefficient
    var: str | None = None    # state the term depends on
    power: int = 1
    freq: str | None = None   # parameter name of the frequency (Hz) for sin/cos

    @property
    def label(self) -> str:
        if self.kind in ("const", "out_const"):
            return "1"
        if self.kind == "pow":
            return f"{self.var}**{self.power}"
        if self.kind == "sign":
            return f"sign({self.var})"
        if self.kind == "absprod":
            return f"{self.var}*abs({self.var})"
        return f"{self.kind}(2*pi*{self.freq}*t)"


@dataclass(frozen=True)
class Model:
    """Nominal structure + parameter values + extension terms. Immutable; ``extend`` returns a copy."""

    states: tuple[str, ...]
    inputs: tuple[str, ...]
    equations: dict[str, Expr]
    output_exprs: dict[str, Expr]
    params: dict[str, float]            # nominal params first, then extension params (insertion order)
    free: tuple[str, ...]
    initial: dict[str, object]          # state -> float | "data" | "estimate"
    substeps: int = 1
    intersample: str = "zoh"
    terms: tuple[Term, ...] = ()
    delay: str | None = None            # parameter name of the input delay (seconds)
    nominal_params: tuple[str, ...] = field(default=())

    @classmethod
    def from_config(cls, lc: LoadedConfig) -> "Model":
        m = lc.cfg.model
        init = m.initial
        if not isinstance(init, dict):
            init = {s: init for s in m.states}
        initial = {s: init.get(s, 0.0) for s in m.states}
        model = cls(states=tuple(m.states), inputs=tuple(m.inputs), equations=dict(lc.equations),
                    output_exprs=dict(lc.output_exprs), params={k: float(v) for k, v in m.params.items()},
                    free=tuple(m.free), initial=initial, substeps=m.substeps,
                    intersample=lc.cfg.data.intersample, nominal_params=tuple(m.params))
        if m.input_delay is not None:  # a known dead time (config key model.input_delay): fixed
            name = fresh_name(model, "input_delay_s")
            model = replace(model, params={**model.params, name: float(m.input_delay)}, delay=name)
        return model

    @property
    def param_names(self) -> list[str]:
        return list(self.params)

    def with_params(self, values: dict[str, float]) -> "Model":
        p = dict(self.params)
        p.update({k: float(v) for k, v in values.items()})
        return replace(self, params=p)

    def extend(self, terms: list[Term], new_params: dict[str, float], delay: str | None = None) -> "Model":
        """A copy with extra terms; ``new_params`` (coefficients, frequencies, delay) become free. A new
        name that is already a nominal (user) parameter is a programming error: use :func:`fresh_name`."""
        clash = [k for k in new_params if k in self.nominal_params]
        if clash:
            raise ValueError(f"generated parameter {clash[0]!r} would overwrite the model's own parameter")
        p = dict(self.params)
        p.update(new_params)
        return replace(self, params=p, free=self.free + tuple(k for k in new_params if k not in self.free),
                       terms=self.terms + tuple(terms), delay=delay or self.delay)

    def term_table(self) -> tuple[np.ndarray, ...]:
        """Arrays (eq, kind, var, power, coef_idx, freq_idx) for the kernel (out_const excluded)."""
        names = self.param_names
        rows = [t for t in self.terms if t.kind != "out_const"]
        eq = np.array([self.states.index(t.target) for t in rows], dtype=np.int64)
        kind = np.array([KIND_CODES[t.kind] for t in rows], dtype=np.int64)
        var = np.array([self.states.index(t.var) if t.var else 0 for t in rows], dtype=np.int64)
        pw = np.array([t.power for t in rows], dtype=np.int64)
        pc = np.array([names.index(t.coef) for t in rows], dtype=np.int64)
        pf = np.array([names.index(t.freq) if t.freq else -1 for t in rows], dtype=np.int64)
        return eq, kind, var, pw, pc, pf

    def describe_equations(self) -> dict[str, str]:
        """Readable equations of the (extended) model, e.g. for the report."""
        out = {}
        for s in self.states:
            txt = self.equations[s].text
            for t in self.terms:
                if t.kind != "out_const" and t.target == s:
                    txt += f" + {t.coef}*{t.label}"
            out[s] = txt
        return out


def fresh_name(model: "Model", base: str) -> str:
    """``base``, or ``base_2``, ``base_3``... : the first that is not a nominal parameter, state, input or
    declared output of the model (extension parameters of the model itself may be reused by name)."""
    taken = set(model.nominal_params) | set(model.states) | set(model.inputs) | set(model.output_exprs)
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name


def term_values(kind: str, z: np.ndarray | None, t: np.ndarray, power: int = 1, freq: float = 0.0) -> np.ndarray:
    """Values of one extension term (as the kernel evaluates it) on arrays."""
    if kind == "const":
        return np.ones_like(t, dtype=float)
    if kind == "pow":
        return z ** power
    if kind == "sign":
        return np.sign(z)
    if kind == "absprod":
        return z * np.abs(z)
    if kind == "sin":
        return np.sin(2 * np.pi * freq * t)
    if kind == "cos":
        return np.cos(2 * np.pi * freq * t)
    raise ValueError(kind)


def rhs_vectorized(model: Model, X: np.ndarray, U: np.ndarray, t: np.ndarray) -> np.ndarray:
    """f(x, u, t; θ) of the (extended) model evaluated row-wise on arrays (N, nx), (N, nu), (N,)."""
    from .expressions import vectorize
    args = list(model.states) + list(model.inputs) + list(model.nominal_params) + ["t"]
    vals = [X[:, i] for i in range(X.shape[1])] + [U[:, j] for j in range(len(model.inputs))]
    vals += [model.params[k] for k in model.nominal_params] + [t]
    out = np.column_stack([np.broadcast_to(np.asarray(vectorize(model.equations[s], args)(*vals), float), t.shape)
                           for s in model.states])
    for term in model.terms:
        if term.kind == "out_const":
            continue
        z = X[:, model.states.index(term.var)] if term.var else None
        fz = model.params[term.freq] if term.freq else 0.0
        out[:, model.states.index(term.target)] += model.params[term.coef] * term_values(term.kind, z, t, term.power, fz)
    return out
