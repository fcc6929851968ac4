"""The base of every effect family (diagnosis contract §2): a template method, as pysindy's
``BaseOptimizer`` owns ``fit`` and a new optimizer writes ``_reduce``.

The engine (:mod:`pipeline.diagnostics.engine`) owns the generic machinery: the output sensitivity of
a hypothesis' tested parameters at their null values, the HAC Wald test, the refit (retried from smaller
starts), the held-out gain and the acceptance test. A family writes

* ``hypotheses(ctx)``: where the cause could act (physically sensible by default);
* ``extend(model, hyp, values)``: the extended model, in the model's expression language (the default
  applies the hypothesis' additive terms, input/parameter rewrites, extra states and limits);
* optionally ``refit_model`` / ``estimate``: the model that is refitted when it differs from the tested
  one (e.g. a saturation tested as a partial clip, refitted as a clip with a free limit), or a search;
* ``describe(hyp, fit)``: the finding's key parameters (contract names) and its sentence.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field, replace

import numpy as np

from ...model import Limit, Model, Rewrite, Term


@dataclass
class Structure:
    """Which states are positions (x in x' = v) and velocities, and which equations are dynamic."""

    dynamic_eqs: list[str]
    positions: list[str]
    velocities: list[str]
    kin: dict[str, str] = field(default_factory=dict)   # position -> its velocity (x' = v)

    @classmethod
    def of(cls, model: Model) -> "Structure":
        """From the parsed equations, not their text: ``x' = (v)`` and ``x' = v`` are the same."""
        states = model.nominal_states
        kin = {s: model.equations[s].tree.id for s in states
               if isinstance(model.equations[s].tree, ast.Name) and model.equations[s].tree.id in states}
        dyn = [s for s in states if s not in kin]
        if not kin:
            return cls(dyn or list(states), list(states), list(states), {})
        return cls(dyn, list(kin), list(dict.fromkeys(kin.values())), kin)

    def pairs(self, role: str, couplings: bool = False) -> list[tuple[str, str]]:
        """(equation, state) pairs where a term in ``state`` is physically sensible: a velocity term in
        the velocity's own equation, a position term in the equation of its velocity (x' = v → v');
        every dynamic equation with every such state when ``couplings`` is asked for."""
        states = self.positions if role == "positions" else self.velocities
        if couplings:
            return [(eq, s) for eq in self.dynamic_eqs for s in states]
        out = []
        for s in states:
            eq = self.kin.get(s, s) if role == "positions" else s
            if eq in self.dynamic_eqs:
                out.append((eq, s))
        return out


@dataclass
class Context:
    """What a family may look at when it proposes hypotheses."""

    model: Model
    structure: Structure
    t: np.ndarray
    U: np.ndarray                  # (N, nu) measured inputs
    Y: np.ndarray                  # (N, ny) measured outputs
    out_names: list[str]
    X: np.ndarray                  # (N, nx) simulated states of the current fit
    est: tuple[int, int]           # estimation rows
    dt: float
    freq_hz: float | None = None   # residual periodogram peak (Fisher's g)
    couplings: bool = False
    long_record: bool = False      # simulations cost milliseconds here: no extra refits (engine._long)
    first_round: bool = False      # the diagnosis' first round of tests, on the nominal model
    resid: np.ndarray | None = None   # (n_est, ny) weighted estimation residual of the current fit
    skipped: list = field(default_factory=list)   # (family, reason): guards that removed hypotheses

    def inputs_changing_sign(self, share: float = 0.05) -> list[int]:
        sl = slice(*self.est)
        return [j for j in range(len(self.model.inputs))
                if min(np.mean(self.U[sl, j] > 0), np.mean(self.U[sl, j] < 0)) >= share]

    def state(self, name: str) -> np.ndarray:
        return self.X[:, self.model.states.index(name)]


@dataclass
class Hypothesis:
    family: str
    key: str                                       # unique label, e.g. "cubic_stiffness:v:x"
    terms: list[Term] = field(default_factory=list)
    coefs: list[str] = field(default_factory=list)  # tested parameters (the Wald test is at `null`)
    null: dict[str, float] = field(default_factory=dict)   # their no-effect values (default 0)
    extra_params: dict[str, float] = field(default_factory=dict)  # fixed in the test, free in the refit
    input_rewrites: list[Rewrite] = field(default_factory=list)
    param_rewrites: list[Rewrite] = field(default_factory=list)
    limits: list[Limit] = field(default_factory=list)
    extra_states: dict[str, tuple[str, float]] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()                    # new parameters held fixed in the refit
    equation: str | None = None
    term: str | None = None
    output: str | None = None
    input: str | None = None
    parameter: str | None = None
    state: str | None = None
    info: dict = field(default_factory=dict)
    # the extension equals the current model before this time whatever its coefficients (a jump at
    # t_j): the added-term test then simulates the perturbed model only from there, resumed from the
    # current model's own simulated state (the rows before are the fit's own simulation)
    acts_from: float | None = None
    # new parameters the family estimates by a search and holds fixed in the refit (a jump's time):
    # counted as estimated parameters in ΔBIC and in the likelihood-ratio test's degrees of freedom
    searched: tuple[str, ...] = ()


class Family:
    """Base class; see the module docstring."""

    id: str = ""
    stage: str = "structural"     # "structural" (the find-extend loop), "noise" or "pre" (before the loop)
    # the hypothesis at its null is the current model (checked by the conformance test): the added-term
    # test then reuses the fit's simulation; additive terms are recognised without it
    null_is_current: bool = False
    # the added-term test's R² approximates the refit's SSE drop, so the engine may skip the refit of a
    # candidate explaining far less than the strongest one (engine._screen); False: always refitted
    screened: bool = True
    # the family's hypotheses are alternative forms whose linearised shares at the current fit do not
    # rank their refits (a library of terms): its next significant hypotheses (engine._alternates) are
    # refitted beside the representative, and the refits' ΔBIC decides
    refit_alternates: bool = False

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        raise NotImplementedError

    def extend(self, model: Model, hyp: Hypothesis, values: dict[str, float] | None = None) -> Model:
        params = {c: float(hyp.null.get(c, 0.0)) for c in hyp.coefs}
        params.update(hyp.extra_params)
        params.update(values or {})
        m = model.extend(list(hyp.terms), params, input_rewrites=tuple(hyp.input_rewrites),
                         param_rewrites=tuple(hyp.param_rewrites), limits=tuple(hyp.limits),
                         extra_states=dict(hyp.extra_states) or None)
        if hyp.fixed:
            m = replace(m, free=tuple(k for k in m.free if k not in hyp.fixed))
        return m

    def refit_model(self, model: Model, hyp: Hypothesis, start: dict[str, float]) -> Model:
        """The model the refit starts from (default: the tested extension at the Wald estimate)."""
        return self.extend(model, hyp, start)

    def settled(self, model: Model, hyp: Hypothesis, values: dict[str, float]) -> Model | None:
        """For a hypothesis with ``acts_from``: a model without the extension's programs that equals the
        extension (``extend(model, hyp, values)``) at every time after ``acts_from`` (a jump that has
        happened is a constant parameter), so the added-term test's simulation can continue with the
        current model's own kernel once the sample interval holding ``acts_from`` is passed; None: the
        extension is simulated to the end."""
        return None

    def mimics_hold(self, hyp: Hypothesis, model: Model, dt: float) -> bool:
        """Whether this extension, as fitted in ``model``, could be a wrong intersample assumption in
        disguise (a held input simulated as foh lags it by about half a sample,
        ``Intersample.equivalent``): the backward step (:func:`.revisit.to_switch`) then weighs the
        switch in its place. Default: no."""
        return False

    def describe(self, hyp: Hypothesis, fit, val: dict, sd: dict) -> tuple[dict, str]:
        """Key parameters (contract §2 names) and the subject of the finding's sentence."""
        c0 = hyp.coefs[0]
        return ({"equation": hyp.equation, "term": hyp.term, "coefficient": val[c0],
                 "coefficient_std": sd.get(c0)},
                f"{hyp.family} {hyp.term} is missing from the equation of {hyp.equation}: adding "
                f"{val[c0]:.4g}*{hyp.term}")


def pname(model: Model, *parts: str) -> str:
    """A generated parameter name no parameter of the model (the user's included) already has."""
    from ...model import fresh_name
    base = "_".join(p.replace("*", "").replace("(", "").replace(")", "").replace("/", "")
                    .replace(" ", "").replace(",", "").replace(".", "").replace("-", "m") for p in parts)
    return fresh_name(model, base)


def present(model: Model, label: str, target: str) -> bool:
    return any(t.label == label and t.target == target for t in model.terms)


_AUTO = object()


def additive(family: str, model: Model, eq: str, text: str, *, output: bool = False, name: str | None = None,
             suffix=_AUTO, **desc) -> Hypothesis:
    """The common hypothesis: ``c * text`` added to equation ``eq`` (or to measured output ``eq``); the
    coefficient is named ``<name or family>_<eq>[_<suffix>]`` (suffix: the term text by default)."""
    suffix = text if suffix is _AUTO else suffix
    c = pname(model, name or family, eq, *([suffix] if suffix else []))
    term = Term(family, "expr", eq, c, text=text, on="output" if output else "state")
    label = desc.pop("term", text)      # the name of the term, when its text is a domain-safe form of it
    return Hypothesis(family, f"{family}:{eq}" + (f":{suffix}" if suffix else ""), [term], [c],
                      equation=None if output else eq, output=eq if output else None, term=label, **desc)


class StateTermFamily(Family):
    """A family of one additive term ``c * template(z)`` of a state z, placed where it is physically
    sensible (:meth:`Structure.pairs`: a position term in its velocity's equation, a velocity term in
    its own; every dynamic equation with ``diagnose.couplings``). A subclass sets ``role``
    ("positions" or "velocities"), ``template`` (with ``{z}``) and ``noun`` (the sentence's subject),
    and may narrow :meth:`admissible`."""

    role: str = "positions"
    template: str = "{z}"
    noun: str = "A term"

    def admissible(self, ctx: Context, z: str) -> bool:
        return True

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        out = []
        for eq, z in ctx.structure.pairs(self.role, ctx.couplings):
            term = self.template.format(z=z)
            if not present(ctx.model, term, eq) and self.admissible(ctx, z):
                out.append(additive(self.id, ctx.model, eq, term, suffix=z))
        return out

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"equation": hyp.equation, "term": hyp.term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0])},
                f"{self.noun} {hyp.term} is missing from the equation of {hyp.equation}: adding {c:.4g}*{hyp.term}")
