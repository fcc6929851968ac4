"""``dead_zone``: the input does nothing inside ±w, u → sign(u)·maximum(abs(u) − w, 0). Regular at
w = 0 (the sensitivity is −sign(u) outside the band), so the Wald test is at w = 0. Only for inputs
that change sign (5 % of the estimation samples each way); a fitted w ≤ 0 is no dead zone."""

import numpy as np

from ...model import Rewrite
from .base import Context, Family, Hypothesis, pname


class DeadZone(Family):
    id = "dead_zone"
    null_is_current = True   # sign(u)·maximum(|u| − 0, 0) is u: the test reuses the fit's simulation

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.input_rewrites}
        out = []
        for j in ctx.inputs_changing_sign():
            u = m.inputs[j]
            if u in done:
                continue
            w = pname(m, "dead_zone", u)
            scale = float(np.std(ctx.U[slice(*ctx.est), j])) or 1.0
            out.append(Hypothesis(self.id, f"{self.id}:{u}", coefs=[w], input=u, info={"scale": scale},
                                  input_rewrites=[Rewrite(self.id, u, f"sign({u})*maximum(abs({u}) - {w}, 0)")]))
        return out

    def estimate(self, dg, fit, cand):
        res = dg.refit(fit, cand)
        if res is not None and res.model.params[cand.hyp.coefs[0]] <= 0:
            cand.reason = "fitted width not positive: no dead zone"
            return None
        return res

    def describe(self, hyp, fit, val, sd):
        w = val[hyp.coefs[0]]
        return ({"input": hyp.input, "width": w, "width_std": sd.get(hyp.coefs[0])},
                f"The input {hyp.input} has a dead zone: it does nothing within ±{w:.4g}; adding it")
