"""``parameter_drift``: a free parameter changes slowly over the record, p → p·(1 + r·t) (r relative,
per second; tested at r = 0)."""

from ...model import Rewrite
from .base import Context, Family, Hypothesis, pname


class ParameterDrift(Family):
    id = "parameter_drift"
    null_is_current = True   # p + 0·step(t − t_j) and p·(1 + 0·t) are p: the test reuses the fit's simulation

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.param_rewrites}
        out = []
        span = float(ctx.t[ctx.est[1] - 1] - ctx.t[ctx.est[0]]) or 1.0
        for k in m.free:
            if k not in m.nominal_params or k in done:
                continue
            r = pname(m, "drift", k)
            out.append(Hypothesis(self.id, f"{self.id}:{k}", coefs=[r],
                                  param_rewrites=[Rewrite(self.id, k, f"{k}*(1 + {r}*t)")], parameter=k,
                                  info={"scale": 1.0 / span}))
        return out

    def describe(self, hyp, fit, val, sd):
        r = val[hyp.coefs[0]]
        k = hyp.parameter
        p0 = float(fit.model.params[k])
        word = "grows" if r > 0 else "falls"
        return ({"parameter": k, "rate_per_s": r, "rate_std": sd.get(hyp.coefs[0]), "absolute_rate_per_s": p0 * r,
                 "form": f"{k}*(1 + rate_per_s*t)"},
                f"The parameter {k} {word} by {100 * abs(r):.3g} % per second ({k} = {p0:.4g}·(1 {'+' if r > 0 else '−'} "
                f"{abs(r):.3g}·t)); letting it drift")
