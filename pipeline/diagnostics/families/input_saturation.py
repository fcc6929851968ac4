"""``input_saturation``: an actuator limit, u → clip(u, −L, L) (sign-changing input) or minimum(u, L).

Non-regular at "no limit" (L = max|u| has a zero sensitivity), so it is tested on a grid: for L at the
``QUANTILES`` of |u| (or u), the partial clip u → u − c·(u − clip(u, ·, L)) is tested at c = 0 (its
sensitivity, −(u − clip), is regular); the refit is the full clip with L free, from the best grid L."""

import numpy as np

from ...model import Rewrite
from .base import Context, Family, Hypothesis, pname

QUANTILES = (0.97, 0.9, 0.8, 0.7)


def _clip(u: str, L: str, symmetric: bool) -> str:
    return f"clip({u}, -{L}, {L})" if symmetric else f"minimum({u}, {L})"


class InputSaturation(Family):
    id = "input_saturation"
    null_is_current = True   # u − 0·(u − clip(u, ·, L)) is u: the test reuses the fit's simulation

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.input_rewrites}
        sym = set(ctx.inputs_changing_sign())
        sl = slice(*ctx.est)
        out = []
        for j, u in enumerate(m.inputs):
            if u in done:
                continue
            x = ctx.U[sl, j]
            vals = np.abs(x) if j in sym else x
            if j not in sym and np.quantile(x, 0.5) <= 0:
                continue
            L, c = pname(m, "saturation", u), pname(m, "saturation_share", u)
            for q in QUANTILES:
                lv = float(np.quantile(vals, q))
                if lv <= 0:
                    continue
                clip = _clip(u, L, j in sym)
                out.append(Hypothesis(self.id, f"{self.id}:{u}@{q}", coefs=[c], extra_params={L: lv}, fixed=(L,),
                                      input_rewrites=[Rewrite(self.id, u, f"{u} - {c}*({u} - {clip})")], input=u,
                                      info={"symmetric": j in sym, "limit_name": L, "share_name": c,
                                            "scale": 1.0}))
        return out

    def refit_model(self, model, hyp, start):
        L = hyp.info["limit_name"]
        u = hyp.input
        return model.extend([], {L: float(hyp.extra_params[L])},
                            input_rewrites=(Rewrite(self.id, u, _clip(u, L, hyp.info["symmetric"])),))

    def describe(self, hyp, fit, val, sd):
        L = hyp.info["limit_name"]
        lv = float(fit.model.params[L])
        rng = f"±{lv:.4g}" if hyp.info["symmetric"] else f"at most {lv:.4g}"
        return ({"input": hyp.input, "limit": lv, "limit_std": sd.get(L),
                 "lower": -lv if hyp.info["symmetric"] else None},
                f"The input {hyp.input} saturates ({rng}): the plant never sees more; adding the limit")
