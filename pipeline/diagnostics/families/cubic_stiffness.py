"""``cubic_stiffness``: an odd cubic restoring term ``c*x**3`` (Duffing) in the equation of the
velocity of position x (every dynamic equation only with ``diagnose.couplings``)."""

from .base import Context, Family, Hypothesis, additive, present


class CubicStiffness(Family):
    id = "cubic_stiffness"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return [additive(self.id, ctx.model, eq, f"{x}**3", suffix=x) for eq, x in
                ctx.structure.pairs("positions", ctx.couplings) if not present(ctx.model, f"{x}**3", eq)]

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"equation": hyp.equation, "term": hyp.term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0])},
                f"A cubic stiffness term {hyp.term} is missing from the equation of {hyp.equation}: adding "
                f"{c:.4g}*{hyp.term}")
