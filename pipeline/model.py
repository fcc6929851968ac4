"""Grey-box model: the nominal ODE from the config plus extensions written in the expression language.

    d(state)/dt = nominal(state, ũ, t; p̃) + Σ_j c_j · term_j(states, ũ, t; p)

An extension is one of (all written as checked expressions of :mod:`pipeline.expressions`):

* an additive term ``c * expr`` in a state equation (``x**3``, ``sign(v)``, ``sqrt(h)``, ``u**2``, ...), or
  on a measured output (a sensor offset ``c * 1``);
* a rewrite of an input, ``ũ = g(u, ...)`` (saturation ``clip(u, -L, L)``, a dead zone
  ``sign(u)*maximum(abs(u) - w, 0)``, or a new state: ``u → u_a`` with ``u_a' = (u - u_a)/tau``);
* a rewrite of a parameter, ``p̃ = g(p, t)`` (a jump ``k + dk*step(t - tj)``, a drift ``k*(1 + r*t)``);
* an extra state with its own equation (an actuator lag);
* a state limit (the state is clamped to [lo, hi] after every integration step: overflow, end stop).

The nominal right-hand side is compiled once per structure; extensions are evaluated inside the same
kernel by a small stack machine (see :mod:`pipeline.simulate`), so testing a hypothesis never
recompiles; on a long record an accepted model's and a refit's extensions are compiled into their own
kernel (:meth:`Model.compiled`), with the same numbers. The input delay acts on the sampled input
before the kernel.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass, field, replace

import numpy as np

from .config import LoadedConfig
from .expressions import Expr, parse, parse_eval

_LEGACY = {"const": "1", "out_const": "1", "pow": "{var}**{power}", "sign": "sign({var})",
           "absprod": "{var}*abs({var})", "sin": "sin(2*pi*{freq}*t)", "cos": "cos(2*pi*{freq}*t)"}


@dataclass(frozen=True)
class Term:
    """One additive term ``coef * expr`` in a state equation, or on a measured output (``out_const``
    kinds and ``on="output"``). ``kind`` names a shorthand (const, pow, sign, absprod, sin, cos,
    out_const) or is ``expr`` with the expression text in ``text``."""

    family: str
    kind: str
    target: str               # state equation, or measured output name
    coef: str                 # parameter name of the coefficient
    var: str | None = None    # state of the shorthand kinds
    power: int = 1
    freq: str | None = None   # parameter name of the frequency (Hz) for sin/cos
    text: str | None = None   # the expression, for kind "expr"
    on: str = "state"         # "state" or "output"

    def __post_init__(self):
        if self.kind == "out_const":
            object.__setattr__(self, "on", "output")

    @property
    def label(self) -> str:
        if self.kind == "expr":
            return str(self.text)
        return _LEGACY[self.kind].format(var=self.var, power=self.power, freq=self.freq)

    @property
    def is_output(self) -> bool:
        return self.on == "output"


@dataclass(frozen=True)
class Rewrite:
    """``target`` (an input or a parameter) is replaced by ``text`` wherever the nominal model uses it."""

    family: str
    target: str
    text: str


@dataclass(frozen=True)
class Limit:
    """State ``state`` clamped to [lo, hi] (parameter names, or None for no bound on that side).
    ``rate``: the state whose motion the limit stops (the velocity of a position at an end stop): it is
    set to 0 when the limit is reached while moving outward (an inelastic stop)."""

    family: str
    state: str
    lo: str | None = None
    hi: str | None = None
    rate: str | None = None


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
    delay_inputs: tuple[str, ...] = ()  # the inputs that delay acts on; () = every input
    nominal_params: tuple[str, ...] = field(default=())
    input_rewrites: tuple[Rewrite, ...] = ()
    param_rewrites: tuple[Rewrite, ...] = ()
    limits: tuple[Limit, ...] = ()
    nominal_states: tuple[str, ...] = ()   # compiled states; extra states (extensions) follow them
    # additive state terms compiled into the simulation kernel instead of interpreted (a speed choice
    # with no effect on the equations: see :meth:`compiled` and :mod:`pipeline.simulate`)
    kernel_terms: tuple[Term, ...] = ()
    # the same for input and parameter rewrites and for extra states' equations (:meth:`compiled`)
    kernel_rewrites: tuple[Rewrite, ...] = ()
    kernel_states: tuple[str, ...] = ()
    # (lower, upper) of free parameters (config model.bounds; ±inf for no bound): respected by the fits
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self):
        if not self.nominal_states:
            object.__setattr__(self, "nominal_states", tuple(self.states))

    @property
    def extra_states(self) -> tuple[str, ...]:
        return self.states[len(self.nominal_states):]

    def names(self) -> set[str]:
        """Names an extension expression may use."""
        return set(self.states) | set(self.inputs) | set(self.params) | {"t"}

    def expr(self, text: str, where: str = "extension") -> Expr:
        """Parse an extension's expression against this model's names (cached per text)."""
        return _parse_cached(text, frozenset(self.names()), where)

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
                    intersample=lc.cfg.data.intersample, nominal_params=tuple(m.params),
                    bounds={k: (-math.inf if lo is None else float(lo), math.inf if hi is None else float(hi))
                            for k, (lo, hi) in m.bounds.items()})
        if m.input_delay is not None:  # a known dead time (config key model.input_delay): fixed
            name = fresh_name(model, "input_delay_s")
            model = replace(model, params={**model.params, name: float(m.input_delay)}, delay=name,
                            delay_inputs=tuple(m.delayed_inputs or ()))
        return model

    @property
    def param_names(self) -> list[str]:
        return list(self.params)

    def with_params(self, values: dict[str, float]) -> "Model":
        p = dict(self.params)
        p.update({k: float(v) for k, v in values.items()})
        return replace(self, params=p)

    def extend(self, terms: list[Term], new_params: dict[str, float], delay: str | None = None, *,
               delay_inputs: tuple[str, ...] = (), input_rewrites: tuple = (), param_rewrites: tuple = (), limits: tuple = (),
               extra_states: dict[str, tuple[str, float]] | None = None) -> "Model":
        """A copy with extensions; ``new_params`` (coefficients, frequencies, limits, delay...) become
        free. ``delay``: the parameter of a new input delay, acting on ``delay_inputs`` (every input
        when empty). ``extra_states``: name -> (equation text, initial value). A new name that is already a
        nominal (user) parameter is a programming error: use :func:`fresh_name`."""
        clash = [k for k in new_params if k in self.nominal_params]
        if clash:
            raise ValueError(f"generated parameter {clash[0]!r} would overwrite the model's own parameter")
        p = dict(self.params)
        p.update(new_params)
        states, eqs, init = self.states, dict(self.equations), dict(self.initial)
        if extra_states:
            names = set(self.names()) | set(extra_states) | set(new_params)
            for name, (text, x0) in extra_states.items():
                eqs[name] = _parse_cached(text, frozenset(names), f"extension state {name}")
                init[name] = float(x0)
            states = states + tuple(extra_states)
        return replace(self, params=p, free=self.free + tuple(k for k in new_params if k not in self.free),
                       terms=self.terms + tuple(terms), delay=delay or self.delay,
                       delay_inputs=tuple(delay_inputs) if delay else self.delay_inputs, states=states,
                       equations=eqs, initial=init, input_rewrites=self.input_rewrites + tuple(input_rewrites),
                       param_rewrites=self.param_rewrites + tuple(param_rewrites),
                       limits=self.limits + tuple(limits))

    def compiled(self) -> "Model":
        """The same model with its extensions compiled into its own simulation kernel
        (:func:`pipeline.simulate.get_kernel`, one compile per structure, cached on disk) instead of
        evaluated by the kernel's interpreter: the additive state terms, the input and parameter
        rewrites and the extra states' equations (a state limit is data, not code, and is applied
        the same way either way). Each interpreted term costs about as much as the whole nominal
        right-hand side, so a model that many later hypotheses extend (an accepted finding), or that a
        refit simulates a hundred times, simulates several times faster. Extensions added to it later
        are interpreted as before."""
        return replace(self, kernel_terms=tuple(t for t in self.terms
                                                if not t.is_output and t.target in self.nominal_states),
                       kernel_rewrites=self.param_rewrites + self.input_rewrites,
                       kernel_states=self.extra_states)

    def term_expr(self, term: Term) -> Expr:
        return self.expr(term.label, f"term {term.coef}")

    def describe_equations(self) -> dict[str, str]:
        """The (extended) model's equations written out in the expression language, with input and
        parameter rewrites substituted, so each line can be pasted back into a config."""
        subst = {rw.target: parse_eval(f"({rw.text})").body for rw in self.input_rewrites}
        psub = {rw.target: parse_eval(f"({rw.text})").body for rw in self.param_rewrites}
        out = {}
        for s in self.states:
            tree = self.equations[s].tree
            if s in self.nominal_states:
                tree = _substitute(tree, {**subst, **psub})
            txt = ast.unparse(tree)
            for t in self.terms:
                if not t.is_output and t.target == s:
                    txt += f" + {t.coef}*{_wrap(t.label)}"
            out[s] = txt
        return out


def switches(model: "Model") -> bool:
    """Does a state equation of ``model`` (with its rewrites and terms written out) hold sign() of an
    expression of a state: a right-hand side that jumps as the state crosses zero. Fixed-step RK4 across
    such a switch gives a step whose result jumps when an intermediate stage's state changes sign, so the
    simulated output is a discontinuous function of the parameters (jumps of about 1e-4 on a
    mass–spring–damper with Coulomb friction), and finite differences need a step where the quotient is
    stable (:func:`pipeline.fit.stable_jacobian`, ``engine.Diagnoser.sensitivity``). Kept on the instance
    (the model is immutable): every hypothesis' test of a round asks it of the same model."""
    known = model.__dict__.get("_switches")
    if known is not None:
        return known
    states = set(model.states)
    found = any(isinstance(node, ast.Call) and getattr(node.func, "id", None) == "sign" and any(
                    isinstance(n, ast.Name) and n.id in states for a in node.args for n in ast.walk(a))
                for text in model.describe_equations().values() for node in ast.walk(ast.parse(text, mode="eval")))
    object.__setattr__(model, "_switches", found)
    return found


def _wrap(text: str) -> str:
    node = parse_eval(text).body
    return text if isinstance(node, (ast.Name, ast.Constant, ast.Call)) or (
        isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Pow))) else f"({text})"


def _substitute(tree: ast.expr, repl: dict[str, ast.expr]) -> ast.expr:
    class T(ast.NodeTransformer):
        def visit_Name(self, node):
            return repl.get(node.id, node)
    import copy
    return T().visit(copy.deepcopy(tree))


_PARSED: dict = {}


def _parse_cached(text: str, names: frozenset, where: str) -> Expr:
    key = (text, names)
    if key not in _PARSED:
        _PARSED[key] = parse(text, set(names), where=where)
    return _PARSED[key]


def fresh_name(model: "Model", base: str) -> str:
    """``base``, or ``base_2``, ``base_3``... : the first that is not a nominal parameter, state, input or
    declared output of the model (extension parameters of the model itself may be reused by name)."""
    taken = set(model.nominal_params) | set(model.states) | set(model.inputs) | set(model.output_exprs)
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name


def term_values(kind: str, z: np.ndarray | None, t: np.ndarray, power: int = 1, freq: float = 0.0) -> np.ndarray:
    """Values of one shorthand extension term on arrays (kept for the synthetic generator's helpers)."""
    if kind in ("const", "out_const"):
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


def _env(model: Model, X: np.ndarray, U: np.ndarray, t: np.ndarray) -> dict[str, np.ndarray | float]:
    """Values of every name on arrays: states, effective inputs and parameters (rewrites applied), t."""
    from .expressions import vectorize
    env: dict = {s: X[:, i] for i, s in enumerate(model.states) if i < X.shape[1]}
    raw_u = {u: U[:, j] for j, u in enumerate(model.inputs)}
    env.update(raw_u)
    env.update(model.params)
    env["t"] = t

    def ev(text, scope):
        e = model.expr(text)
        names = sorted(e.names)
        return np.broadcast_to(np.asarray(vectorize(e, names)(*[scope[n] for n in names]), float), t.shape)

    raw = dict(env)
    for rw in model.param_rewrites:
        env[rw.target] = ev(rw.text, raw)
    for rw in model.input_rewrites:
        env[rw.target] = ev(rw.text, raw)
    return env


def term_on(model: Model, term: Term, X: np.ndarray, U: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Values of ``term``'s expression (without its coefficient) along states X, inputs U, time t."""
    from .expressions import vectorize
    env = _env(model, X, U, t)
    e = model.term_expr(term)
    names = sorted(e.names)
    return np.broadcast_to(np.asarray(vectorize(e, names)(*[env[n] for n in names]), float), t.shape)


def rhs_vectorized(model: Model, X: np.ndarray, U: np.ndarray, t: np.ndarray) -> np.ndarray:
    """f(x, u, t; θ) of the (extended) model evaluated row-wise on arrays (N, nx), (N, nu), (N,)
    (the nominal states' equations; extra states need their own, unmeasured, values in X)."""
    from .expressions import vectorize
    env = _env(model, X, U, t)
    out = []
    for s in model.states[:X.shape[1]]:
        e = model.equations[s]
        names = sorted(e.names)
        out.append(np.broadcast_to(np.asarray(vectorize(e, names)(*[env[n] for n in names]), float), t.shape))
    out = np.column_stack(out).astype(float)
    for term in model.terms:
        if term.is_output or term.target not in model.states[:X.shape[1]]:
            continue
        out[:, model.states.index(term.target)] += model.params[term.coef] * term_on(model, term, X, U, t)
    return out
