"""``unmodeled_dynamics``: a missing first-order lag on an input (an actuator), a new state
u_a' = (u − u_a)/τ that the equations see instead of u.

Non-regular at τ = 0, so it is tested on a grid of τ (``TAUS`` × the sample time): the partial lag
u → u − c·(u − u_a) is tested at c = 0; the refit is the full lag with τ free, from the best grid τ."""

from ...model import Rewrite
from .base import Context, Family, Hypothesis, pname

TAUS = (1.0, 2.5, 6.0, 15.0, 40.0)


class UnmodeledDynamics(Family):
    id = "unmodeled_dynamics"
    null_is_current = True   # u − 0·(u − u_a) is u (the lag state runs but feeds nothing): the test reuses the fit's simulation

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.input_rewrites}
        out = []
        for j, u in enumerate(m.inputs):
            if u in done:
                continue
            ua, tau, c = pname(m, f"{u}_lagged"), pname(m, "lag_tau", u), pname(m, "lag_share", u)
            x0 = float(ctx.U[ctx.est[0], j]) if ctx.est[0] == 0 else float(ctx.U[0, j])
            for k in TAUS:
                out.append(Hypothesis(
                    self.id, f"{self.id}:{u}@{k:g}dt", coefs=[c], extra_params={tau: k * ctx.dt}, fixed=(tau,),
                    extra_states={ua: (f"({u} - {ua})/{tau}", x0)},
                    input_rewrites=[Rewrite(self.id, u, f"{u} - {c}*({u} - {ua})")], input=u,
                    info={"state": ua, "tau_name": tau, "x0": x0, "scale": 1.0}))
        return out

    def refit_model(self, model, hyp, start):
        u, ua, tau = hyp.input, hyp.info["state"], hyp.info["tau_name"]
        return model.extend([], {tau: float(hyp.extra_params[tau])},
                            input_rewrites=(Rewrite(self.id, u, ua),),
                            extra_states={ua: (f"({u} - {ua})/{tau}", hyp.info["x0"])})

    def mimics_hold(self, hyp, model, dt):
        """A lag of at most one sample on the only input: at frequencies well below the sampling rate a
        lag τ is a dead time τ, and a held input simulated as foh lags by half a sample
        (``Intersample.equivalent``); the switch shifts every input, so not with several."""
        return len(model.inputs) == 1 and float(model.params.get(hyp.info["tau_name"], float("inf"))) <= dt

    def describe(self, hyp, fit, val, sd):
        tau = hyp.info["tau_name"]
        tv = float(fit.model.params[tau])
        return ({"input": hyp.input, "time_constant_s": tv, "time_constant_std": sd.get(tau), "added_order": 1},
                f"The input {hyp.input} reaches the plant through a first-order lag of {tv:.4g} s (an actuator); "
                "adding that state")
