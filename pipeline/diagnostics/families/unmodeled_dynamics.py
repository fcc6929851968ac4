"""``unmodeled_dynamics``: a missing state (contract §2: "a missing state, e.g. actuator or sensor lag"),
in two forms.

* **Input lag** (an actuator): a new state u_a' = (u − u_a)/τ that the equations see instead of u.
  Tested as the partial lag u → u − c·(u − u_a) at c = 0; refitted as the full lag with τ free.
* **Coupled state** (a second thermal mass, a compliant element): a new state z' = (s − z)/τ that
  exchanges with a dynamic state s through its own equation, s' = … + c·(z − s). Two nodes with
  separate capacities: c and 1/τ are independent (the general second-order linear extension of a
  first-order equation with one new pole and one new zero, −c τ p/(τ p + 1) seen from s). Tested at
  c = 0 (z runs but feeds nothing); refitted with c and τ free. Only in each dynamic equation on its
  own state (``Structure.dynamic_eqs``): a coupling of one mode's state into another mode's equation
  is not proposed.

Both are non-regular at τ = 0 and tested on a grid of τ (``TAUS`` × the sample time), the refit
starting from the best grid τ."""

from ...model import Rewrite, Term
from .base import Context, Family, Hypothesis, pname

TAUS = (1.0, 2.5, 6.0, 15.0, 40.0)


class UnmodeledDynamics(Family):
    id = "unmodeled_dynamics"
    null_is_current = True   # u − 0·(u − u_a) is u, s' + 0·(z − s) is s' (the new state runs but feeds nothing)

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return self._input_lags(ctx) + self._coupled_states(ctx)

    def _input_lags(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.input_rewrites}
        out = []
        for j, u in enumerate(m.inputs):
            if u in done:
                continue
            ua, tau, c = pname(m, f"{u}_lagged"), pname(m, "lag_tau", u), pname(m, "lag_share", u)
            x0 = float(ctx.U[0, j])
            for k in TAUS:
                out.append(Hypothesis(
                    self.id, f"{self.id}:{u}@{k:g}dt", coefs=[c], extra_params={tau: k * ctx.dt}, fixed=(tau,),
                    extra_states={ua: (f"({u} - {ua})/{tau}", x0)},
                    input_rewrites=[Rewrite(self.id, u, f"{u} - {c}*({u} - {ua})")], input=u,
                    info={"kind": "input_lag", "state": ua, "tau_name": tau, "x0": x0, "scale": 1.0}))
        return out

    def _coupled_states(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {t.target for t in m.terms if t.family == self.id}
        out = []
        for s in ctx.structure.dynamic_eqs:
            if s in done or s not in m.nominal_states:
                continue
            z, tau, c = pname(m, f"{s}_node"), pname(m, "node_tau", s), pname(m, "node_coupling", s)
            x0 = float(ctx.X[0, m.states.index(s)])
            term = Term(self.id, "expr", s, c, text=f"({z} - {s})")
            for k in TAUS:
                out.append(Hypothesis(
                    self.id, f"{self.id}:{s}:node@{k:g}dt", terms=[term], coefs=[c],
                    extra_params={tau: k * ctx.dt}, fixed=(tau,), extra_states={z: (f"({s} - {z})/{tau}", x0)},
                    equation=s, state=s, term=f"({z} - {s})",
                    info={"kind": "coupled_state", "state": z, "tau_name": tau, "x0": x0}))
        return out

    def estimate(self, dg, fit, cand):
        """The generic refit; a coupled state is then kept only where it is one: a time constant of at
        least half a sample (a faster one rescales the equation's time derivative, c·(z − s) ≈ −cτ·s',
        which the samples cannot tell from the equation's own parameters: the DaISy dryer refitted
        τ = 0.09 samples with cτ = −0.92), at most half the estimation window (a slower one is an
        offset or a drift in disguise), and a positive coupling (a passive storage: s is pulled towards
        z). A rejected coupled state lets the family's next significant hypothesis be refitted
        (``Diagnoser._fallbacks``)."""
        res = dg.refit(fit, cand)
        hyp = cand.hyp
        if res is None or hyp.info.get("kind") != "coupled_state":
            return res
        tau = float(res.model.params[hyp.info["tau_name"]])
        c = float(res.model.params[hyp.coefs[0]])
        span = (dg.prob.split.est[1] - dg.prob.split.est[0]) * dg.dt
        why = (f"time constant {tau / dg.dt:.3g} samples, below half a sample: not a storage these samples resolve"
               if tau < 0.5 * dg.dt else
               f"time constant {tau:.4g} s, above half the estimation window ({span:.4g} s): an offset or a drift"
               if tau > 0.5 * span else
               f"coupling {c:.4g} not positive: not a passive storage" if c <= 0 else None)
        if why is None:
            return res
        cand.reason = "refit rejected: " + why
        return None

    def refit_model(self, model, hyp, start):
        tau = hyp.info["tau_name"]
        if hyp.info.get("kind") == "coupled_state":      # c from the test's estimate, τ free from its grid value
            c = hyp.coefs[0]
            return model.extend(list(hyp.terms), {c: float(start.get(c, 0.0)), tau: float(hyp.extra_params[tau])},
                                extra_states=dict(hyp.extra_states))
        u, ua = hyp.input, hyp.info["state"]
        return model.extend([], {tau: float(hyp.extra_params[tau])},
                            input_rewrites=(Rewrite(self.id, u, ua),),
                            extra_states={ua: (f"({u} - {ua})/{tau}", hyp.info["x0"])})

    def mimics_hold(self, hyp, model, dt):
        """A lag of at most one sample on the only input: at frequencies well below the sampling rate a
        lag τ is a dead time τ, and a held input simulated as foh lags by half a sample
        (``Intersample.equivalent``); the switch shifts every input, so not with several."""
        return (hyp.info.get("kind") == "input_lag" and len(model.inputs) == 1
                and float(model.params.get(hyp.info["tau_name"], float("inf"))) <= dt)

    def describe(self, hyp, fit, val, sd):
        tau = hyp.info["tau_name"]
        tv = float(fit.model.params[tau])
        if hyp.info.get("kind") == "coupled_state":
            c = hyp.coefs[0]
            cv = float(fit.model.params[c])
            return ({"equation": hyp.equation, "state": hyp.state, "time_constant_s": tv,
                     "time_constant_std": sd.get(tau), "coupling": cv, "coupling_std": sd.get(c), "added_order": 1},
                    f"The state {hyp.state} exchanges with a missing state of time constant {tv:.4g} s "
                    f"(a second storage: a thermal mass, a compliant element), {cv:.4g}*({hyp.info['state']} - "
                    f"{hyp.state}) in its equation; adding that state")
        return ({"input": hyp.input, "time_constant_s": tv, "time_constant_std": sd.get(tau), "added_order": 1},
                f"The input {hyp.input} reaches the plant through a first-order lag of {tv:.4g} s (an actuator); "
                "adding that state")
