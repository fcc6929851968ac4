"""Effect families (diagnosis contract §2). Each family proposes hypotheses for the current model: the
extension terms it would add and their new parameters. Detection and refitting are generic (see
:mod:`pipeline.diagnostics.engine`); a family only knows *what* to add and how to describe it.

Adding a family: one class here with ``id`` and ``hypotheses(ctx)``, and one line in ``REGISTRY``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field

import numpy as np

from ..model import Model, Term, fresh_name


@dataclass
class Structure:
    """Which states are positions (x in x' = v) and velocities, and which equations are dynamic."""

    dynamic_eqs: list[str]
    positions: list[str]
    velocities: list[str]

    @classmethod
    def of(cls, model: Model) -> "Structure":
        """From the parsed equations, not their text: ``x' = (v)`` and ``x' = v`` are the same."""
        kin = {s: model.equations[s].tree.id for s in model.states
               if isinstance(model.equations[s].tree, ast.Name) and model.equations[s].tree.id in model.states}
        dyn = [s for s in model.states if s not in kin]
        if not kin:
            return cls(dyn or list(model.states), list(model.states), list(model.states))
        return cls(dyn, list(kin), list(dict.fromkeys(kin.values())))


@dataclass
class Hypothesis:
    family: str
    key: str                          # unique label, e.g. "cubic_stiffness:v:x"
    terms: list[Term]
    coefs: list[str]                  # new coefficient parameters (tested, start at 0)
    extra_params: dict[str, float] = field(default_factory=dict)  # e.g. frequency, free in the refit
    equation: str | None = None
    term: str | None = None
    output: str | None = None


def _pname(model: Model, *parts: str) -> str:
    """A generated parameter name that no parameter of the model (the user's included) already has."""
    base = "_".join(p.replace("*", "").replace("(", "").replace(")", "") for p in parts)
    return fresh_name(model, base)


def _present(model: Model, kind: str, target: str, var: str | None = None) -> bool:
    return any(t.kind == kind and t.target == target and t.var == var for t in model.terms)


class _StateTermFamily:
    id = ""
    kind = ""
    power = 1
    role = "positions"   # which states the term depends on

    def hypotheses(self, model: Model, st: Structure, **_) -> list[Hypothesis]:
        out = []
        for eq in st.dynamic_eqs:
            for var in getattr(st, self.role):
                if _present(model, self.kind, eq, var):
                    continue
                c = _pname(model, self.id, eq, var)
                term = Term(self.id, self.kind, eq, c, var=var, power=self.power)
                out.append(Hypothesis(self.id, f"{self.id}:{eq}:{var}", [term], [c], equation=eq,
                                      term=term.label))
        return out


class CubicStiffness(_StateTermFamily):
    id, kind, power, role = "cubic_stiffness", "pow", 3, "positions"


class QuadraticDamping(_StateTermFamily):
    id, kind, role = "quadratic_damping", "absprod", "velocities"


class CoulombFriction(_StateTermFamily):
    """sign(v) for velocity states that change sign: for a state of one sign, sign(v) is the constant
    of the ``offset`` family and is not proposed (at least 2 % of samples must have each sign)."""

    id, kind, role = "coulomb_friction", "sign", "velocities"

    def hypotheses(self, model: Model, st: Structure, X=None, **kw) -> list[Hypothesis]:
        hyps = super().hypotheses(model, st)
        if X is None:
            return hyps
        keep = []
        for h in hyps:
            z = X[:, model.states.index(h.terms[0].var)]
            if min(np.mean(z > 0), np.mean(z < 0)) >= 0.02:
                keep.append(h)
        return keep


class Offset:
    id = "offset"

    def hypotheses(self, model: Model, st: Structure, **_) -> list[Hypothesis]:
        out = []
        for eq in st.dynamic_eqs:
            if _present(model, "const", eq):
                continue
            c = _pname(model, "offset", eq)
            out.append(Hypothesis(self.id, f"offset:{eq}", [Term(self.id, "const", eq, c)], [c], equation=eq,
                                  term="1"))
        return out


class OutputOffset:
    id = "output_offset"

    def hypotheses(self, model: Model, st: Structure, outputs: list[str], **_) -> list[Hypothesis]:
        out = []
        for y in outputs:
            if _present(model, "out_const", y):
                continue
            c = _pname(model, "output_offset", y)
            out.append(Hypothesis(self.id, f"output_offset:{y}", [Term(self.id, "out_const", y, c)], [c],
                                  output=y))
        return out


class PeriodicDisturbance:
    """a·sin(2πft) + b·cos(2πft) in a dynamic equation, f from the residual periodogram (Fisher's g)."""

    id = "periodic_disturbance"

    def hypotheses(self, model: Model, st: Structure, freq_hz: float | None = None, **_) -> list[Hypothesis]:
        if not freq_hz or freq_hz <= 0:
            return []
        k = sum(1 for t in model.terms if t.kind == "sin")
        out = []
        for eq in st.dynamic_eqs:
            a, b, f = (_pname(model, "periodic", eq, f"sin{k}"), _pname(model, "periodic", eq, f"cos{k}"),
                       _pname(model, "freq", eq, str(k)))
            terms = [Term(self.id, "sin", eq, a, freq=f), Term(self.id, "cos", eq, b, freq=f)]
            out.append(Hypothesis(self.id, f"periodic:{eq}", terms, [a, b], extra_params={f: float(freq_hz)},
                                  equation=eq, term=f"sin/cos(2*pi*{freq_hz:.4g}*t)"))
        return out


class InputDelay:
    """u(t − d): tested through the output sensitivity to d at d = 0; estimated by a profile search."""

    id = "input_delay"

    def hypotheses(self, model: Model, st: Structure, **_) -> list[Hypothesis]:
        if model.delay is not None or not model.inputs:
            return []
        return [Hypothesis(self.id, "input_delay", [], [fresh_name(model, "input_delay_s")])]


REGISTRY = {f.id: f for f in (Offset(), OutputOffset(), CubicStiffness(), QuadraticDamping(),
                              CoulombFriction(), PeriodicDisturbance(), InputDelay())}


def amplitude_phase(a: float, b: float) -> tuple[float, float]:
    """a sin + b cos = A sin(ωt + φ)."""
    return float(np.hypot(a, b)), float(np.arctan2(b, a))
