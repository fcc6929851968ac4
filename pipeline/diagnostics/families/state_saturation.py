"""``state_saturation``: a state cannot pass a limit (overflow, end stop): clamped to x ≤ L.

Tested on a grid of L at the ``QUANTILES`` of the simulated state, and, for a measured state that the
simulation carries past every measured value, at the largest measured value: a restoring term
−c·maximum(x − L, 0) is tested at c = 0 (a soft version of the limit, regular), in the state's own
equation (an overflow) or, for a position x' = v, in its velocity's equation (a stiff spring beyond an
end stop). The refit is the hard limit (the state clamped after every step, a position's velocity
stopped there) with L free, from the best grid L."""

import numpy as np

from ...model import Limit
from .base import Context, Family, Hypothesis, Structure, additive, pname

QUANTILES = (0.97, 0.9, 0.8)


class StateSaturation(Family):
    id = "state_saturation"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {lim.state for lim in m.limits}
        sl = slice(*ctx.est)
        out = []
        for s in m.nominal_states:
            if s in done:
                continue
            x = ctx.state(s)[sl]
            if not np.all(np.isfinite(x)) or np.ptp(x) == 0:
                continue
            L = pname(m, "limit", s)
            # where the push acts: a position's end stop pushes on its velocity (a stiff spring
            # beyond the stop), any other state's limit on the state itself (an overflow)
            eq = ctx.structure.kin.get(s, s)
            levels = [(str(q), float(np.quantile(x, q))) for q in QUANTILES]
            if s in ctx.out_names:
                # a measured state the simulation carries past every measured value: the data's own
                # largest value is the natural candidate limit
                ymax = float(np.max(ctx.Y[sl, ctx.out_names.index(s)]))
                if ymax < float(np.max(x)):
                    levels.insert(0, ("measured_max", ymax))
            for q, lv in levels:
                h = additive(self.id, m, eq, f"maximum({s} - {L}, 0)", name="limit_push")
                h.key = f"{self.id}:{s}@{q}"
                h.extra_params = {L: lv}
                h.fixed = (L,)
                h.null = {}
                h.state = s
                # the hard limit at the measured maximum is also refitted and LR-tested (engine._lr_screen)
                h.info = {"limit_name": L, **({"lr_screen": True} if q == "measured_max" else {})}
                out.append(h)
        return out

    def refit_model(self, model, hyp, start):
        L = hyp.info["limit_name"]
        # a position's limit is an end stop: its velocity stops there (inelastic), or the refit could
        # not follow a stop that holds the position while the force pushes on
        rate = Structure.of(model).kin.get(hyp.state)
        return model.extend([], {L: float(hyp.extra_params[L])},
                            limits=(Limit(self.id, hyp.state, hi=L, rate=rate),))

    def describe(self, hyp, fit, val, sd):
        L = hyp.info["limit_name"]
        lv = float(fit.model.params[L])
        return ({"state": hyp.state, "limit": lv, "limit_std": sd.get(L), "side": "upper"},
                f"The state {hyp.state} cannot pass {lv:.4g} (an overflow or an end stop); adding the limit")
