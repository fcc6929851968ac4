"""``quadratic_damping``: drag ``c*v*abs(v)`` in the equation of velocity v itself."""

from .base import Context, Family, Hypothesis, additive, present


class QuadraticDamping(Family):
    id = "quadratic_damping"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return [additive(self.id, ctx.model, eq, f"{v}*abs({v})", suffix=v) for eq, v in
                ctx.structure.pairs("velocities", ctx.couplings) if not present(ctx.model, f"{v}*abs({v})", eq)]

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"equation": hyp.equation, "term": hyp.term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0])},
                f"Quadratic damping {hyp.term} is missing from the equation of {hyp.equation}: adding "
                f"{c:.4g}*{hyp.term}")
