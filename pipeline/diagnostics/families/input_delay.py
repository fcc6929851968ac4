"""``input_delay``: the inputs act as u(t − d). On a model with several inputs the delay of every
input and the delay of each input alone are separate hypotheses (one actuator of two with a transport
delay: a common delay cannot fit it, and a first-order lag on that input would be named instead).

Tested through the output sensitivity to d at d = 0, and, since that linearisation has little power for
a delay of many samples, by the likelihood ratio of each hypothesis' refit (``engine._lr_screen``; the
searched delay counted as a second χ² degree of freedom). Estimated by a profile search (weighted SSE
over integer delays, a parabola through the best one and its neighbours for the fractional part), then
one refit of all free parameters at that delay; when the profile's best is below a quarter sample,
from the added-term test's joint estimate instead. A refit that ends below a quarter sample is not a
dead time the record can resolve (the same floor as the start's): it is dropped. On an independent
pendulum record with Coulomb friction (tanh(w/ε) fitted as sign(w)), a refit from the test's estimate of
0.25 samples ended at 0.033 samples and was named as a third finding with a 3 % gain: a phase
correction of the friction model's remainder."""

import numpy as np

from ...fit import estimated_x0, fit_output_error
from ...model import fresh_name
from .base import Context, Family, Hypothesis


class InputDelay(Family):
    id = "input_delay"
    # the test's linearisation at d = 0 (the sensitivity −∂ŷ/∂u·u̇) understates a delay of several
    # samples, so its R² is no guide to the refit's SSE drop: always refitted (engine._screen)
    screened = False

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        if ctx.model.delay is not None or not ctx.model.inputs:
            return []
        name = fresh_name(ctx.model, "input_delay_s")
        # each delay is also refitted at once and tested by the likelihood ratio (engine._lr_screen), its
        # delay counted twice in the χ² degrees of freedom for the profile search over [0, max_delay_s]
        info = {"step": 0.5 * ctx.dt, "lr_screen": True, "lr_extra_dof": 1}
        out = [Hypothesis(self.id, "input_delay", coefs=[name], info=dict(info))]
        if len(ctx.model.inputs) > 1:
            out += [Hypothesis(self.id, f"input_delay:{u}", coefs=[name], input=u, info=dict(info))
                    for u in ctx.model.inputs]
        return out

    @staticmethod
    def _delayed(model, hyp, d: float):
        return model.extend([], {hyp.coefs[0]: float(d)}, delay=hyp.coefs[0],
                            delay_inputs=(hyp.input,) if hyp.input else ())

    def extend(self, model, hyp, values=None):
        return self._delayed(model, hyp, (values or {}).get(hyp.coefs[0], 0.0))

    def mimics_hold(self, hyp, model, dt):
        """A dead time of at most one sample on every input: a held input simulated as foh lags by half
        a sample (``Intersample.equivalent``)."""
        return not hyp.input and float(model.params.get(hyp.coefs[0], np.inf)) <= dt

    def step(self, dg) -> float:
        return 0.5 * dg.dt

    def estimate(self, dg, fit, cand):
        y = dg.prob.Y[dg.prob.split.est_slice()]
        kmax = max(1, min(int(round(dg.max_delay / dg.dt)), len(y) // 4))
        sse = []
        for k in range(kmax + 1):
            Yh = dg.sim_est(self._delayed(fit.model, cand.hyp, k * dg.dt), fit.x0)
            sse.append(np.inf if Yh is None else float(np.sum(((y - Yh) * dg.w) ** 2)))
        k0 = int(np.argmin(sse))
        frac = 0.0
        if 0 < k0 < kmax:
            s0, s1, s2 = sse[k0 - 1], sse[k0], sse[k0 + 1]
            den = s0 - 2 * s1 + s2
            frac = float(np.clip(0.5 * (s0 - s2) / den, -0.5, 0.5)) if den > 0 else 0.0
        d = (k0 + frac) * dg.dt
        if d < 0.25 * dg.dt:
            # the profile holds the other parameters at their fitted values, which have absorbed part
            # of a short delay (as a phase lag); the added-term test's estimate is the joint linearised
            # one (the other parameters partialled out, Frisch–Waugh): refit from it instead
            b = float(cand.wald.beta[0]) if cand.wald is not None and len(cand.wald.beta) else 0.0
            if not 0.25 * dg.dt <= b <= kmax * dg.dt:
                cand.reason = "best delay below a quarter sample"
                return None
            d = b
        f = fit_output_error(self._delayed(fit.model, cand.hyp, d), dg.prob, start=estimated_x0(fit))
        d_fit = float(f.model.params[f.model.delay])
        if d_fit < 0.25 * dg.dt:
            cand.reason = (f"refitted delay {d_fit / dg.dt:.3g} samples, below a quarter sample: a phase correction, "
                           "not a dead time these samples resolve")
            return None
        return f

    def describe(self, hyp, fit, val, sd):
        d = float(fit.model.params[fit.model.delay])
        out = {"delay_s": d, "delay_std": sd.get(hyp.coefs[0])}
        if hyp.input:
            out["input"] = hyp.input
            return out, f"The input {hyp.input} acts with a dead time of {d:.4g} s; delaying it"
        if len(fit.model.inputs) > 1:
            return out, f"Every input acts with a dead time of {d:.4g} s; delaying them"
        return out, f"The input acts with a dead time of {d:.4g} s; delaying it"
