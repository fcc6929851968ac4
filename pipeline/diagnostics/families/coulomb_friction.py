"""``coulomb_friction``: dry friction ``c*sign(v)`` in the equation of velocity v itself. Only for
velocities that change sign (at least 2 % of the simulated samples of each sign): for a state of one
sign, sign(v) is the constant of the ``offset`` family."""

import numpy as np

from .base import Context, Family, Hypothesis, additive, present


class CoulombFriction(Family):
    id = "coulomb_friction"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        out = []
        for eq, v in ctx.structure.pairs("velocities", ctx.couplings):
            z = ctx.state(v)
            if present(ctx.model, f"sign({v})", eq) or min(np.mean(z > 0), np.mean(z < 0)) < 0.02:
                continue
            out.append(additive(self.id, ctx.model, eq, f"sign({v})", suffix=v))
        return out

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"equation": hyp.equation, "term": hyp.term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0])},
                f"Coulomb friction {hyp.term} is missing from the equation of {hyp.equation}: adding "
                f"{c:.4g}*{hyp.term}")
