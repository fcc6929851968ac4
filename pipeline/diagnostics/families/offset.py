"""``offset``: a constant unmodelled force or bias ``c`` in a dynamic state equation."""

from .base import Context, Family, Hypothesis, additive, present


class Offset(Family):
    id = "offset"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return [additive(self.id, ctx.model, eq, "1", suffix=None) for eq in ctx.structure.dynamic_eqs
                if not present(ctx.model, "1", eq)]

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"equation": hyp.equation, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0]), "term": "1"},
                f"A constant offset of {c:.4g} is missing from the equation of {hyp.equation}: adding it")
