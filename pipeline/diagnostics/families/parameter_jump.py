"""``parameter_jump``: a free parameter changes abruptly at t_j, p → p + Δ·step(t − t_j).

Hypotheses: every free nominal parameter × t_j on a grid of ``GRID`` times inside the estimation window
(Δ tested at 0 with t_j fixed; the family's p-value is Bonferroni over all of them). The times of one
parameter form a screen group: only the time whose sensitivity explains most of the residual gets the
full test (``Diagnoser.screened_out``), and each sensitivity is simulated from t_j on only
(``Hypothesis.acts_from``). Estimate: a refit of Δ and the free parameters at every grid time, the one
with the lowest SSE (the least-squares break date, Bai 1997, Econometric Theory 13(3); the added-term
test's time is linearised at Δ = 0 and can be far from a large jump), then a golden-section search on
t_j between its neighbours (the grid refits converged to ``GRID_FTOL``, enough to rank the dates; the
search and the final refit to least_squares' default), then a scan of the dates the simulation can tell
apart within a sample of that optimum (``ParameterJump._sample_scan``), t_j fixed in the final refit and counted as an estimated parameter
(``Hypothesis.searched``) in ΔBIC and the likelihood-ratio test.

Test. The added-term Wald test of each (parameter, time) uses a HAC variance estimated from the current
residual, which carries the jump itself: a jump late in the window leaves a slow misfit there and the
test had little power (a 60 % jump of a thermal loss coefficient at 86 % of the window: 9 of 14
independent records not significant, named colored noise). On a record that is not long, each
parameter's jump is therefore also refitted at its least-squares date and tested by the likelihood
ratio with the effective sample size of the refit's residual, maximised over the date: Andrews' (1993)
sup-LR, p from the James–James–Siegmund tail (:func:`pipeline.diagnostics.stats.sup_lr_break_p`) with
the search's trimming ``LR_TRIM``; the family's p is Bonferroni over the Wald and the LR tests
(``engine._lr_screen``). Only in the first round, on the nominal model: after a finding, the residual
holds that extension's own approximation error (a Coulomb law fitted to a smoother friction), and a
searched break date fits whatever non-stationarity that leaves (the bench's pendulum Coulomb records
got a second finding, a jump of g_l). And lazily (``info['lr_lazy']``): only when no family's
added-term test is significant in that round, since a date search per parameter costs about as much
as the rest of the round (with it in every first round the tuning seeds' summed diagnosis time went
from 339 to 730 s)."""

from dataclasses import replace

import numpy as np

from ...fit import estimated_x0, fit_output_error
from ...model import Rewrite
from .base import Context, Family, Hypothesis, pname

GRID = 16
SEARCH_STEPS = 7
# the grid refits only rank the break dates: their SSE is converged to a relative GRID_FTOL, and to half
# a BIC unit on long records (ΔBIC ≈ N·ΔSSE/SSE), whichever is finer; the golden-section refits and the
# final refit use least_squares' default 1e-8
GRID_FTOL = 1e-4
GRID_FTOL_BIC = 0.5
# the likelihood-ratio screen's date search reaches half a grid step from the window's ends (the
# golden-section search between the best grid time's neighbours): the sup-LR law's trimming
LR_TRIM = 0.5 / (GRID + 1)


class ParameterJump(Family):
    id = "parameter_jump"
    null_is_current = True   # p + 0·step(t − t_j) and p·(1 + 0·t) are p: the test reuses the fit's simulation
    refit_alternates = True

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        m = ctx.model
        done = {rw.target for rw in m.param_rewrites}
        t0, t1 = ctx.t[ctx.est[0]], ctx.t[ctx.est[1] - 1]
        grid = t0 + (t1 - t0) * (np.arange(1, GRID + 1) / (GRID + 1))
        out = []
        for k in m.free:
            if k not in m.nominal_params or k in done:
                continue
            d, tj = pname(m, "jump", k), pname(m, "jump_time", k)
            for i, g in enumerate(grid):
                info = {"grid_step": float(grid[1] - grid[0]), "screen_group": k, "grid": tuple(float(x) for x in grid),
                        "scale": abs(m.params[k]) or 1.0}
                if i == GRID // 2 and ctx.first_round and not ctx.long_record:
                    # the jump of this parameter at its least-squares date, refitted at once and tested by
                    # the likelihood ratio maximised over the date (module docstring)
                    info.update(lr_screen=True, lr_lazy=True, lr_law="break", trim=LR_TRIM)
                out.append(Hypothesis(self.id, f"{self.id}:{k}@{g:.4g}", coefs=[d], extra_params={tj: float(g)},
                                      param_rewrites=[Rewrite(self.id, k, f"{k} + {d}*step(t - {tj})")],
                                      fixed=(tj,), searched=(tj,), parameter=k, acts_from=float(g), info=info))
        return out

    def estimate(self, dg, fit, cand):
        hyp = cand.hyp
        tj_name = next(iter(hyp.extra_params))
        step = hyp.info["grid_step"]
        # the added-term test's estimate, or 0 when there was none (its sensitivity could not be simulated)
        d0 = float(cand.wald.beta[0]) if cand.wald is not None and len(cand.wald.beta) else 0.0

        def refit(tj, **fit_kw):
            h = Hypothesis(**{**hyp.__dict__, "extra_params": {tj_name: float(tj)}, "acts_from": float(tj)})
            try:
                return fit_output_error(self.extend(fit.model, h, {hyp.coefs[0]: d0}), dg.prob, start=estimated_x0(fit), max_nfev=60,
                                        **fit_kw)
            except Exception as exc:  # noqa: BLE001 - re-raised below unless it is a simulation failure
                from ...errors import InputError
                if isinstance(exc, InputError):
                    return None
                raise

        # the added-term test's time is where a jump of 0 would start to help most; a large jump can sit far
        # from it (0.5 -> 0.9 at 72 s on a tank: tested at 33 s). Refit at every grid time and keep the
        # lowest SSE: the least-squares break date (Bai 1997), then refine between its neighbours
        near = list(hyp.info.get("grid", [hyp.extra_params[tj_name]]))
        e0, e1 = dg.prob.split.est
        ftol = min(GRID_FTOL, GRID_FTOL_BIC / ((e1 - e0) * dg.prob.Y.shape[1]))
        fits = [refit(tj, ftol=ftol) for tj in near]
        k = int(np.argmin([np.inf if f is None else f.sse_w for f in fits]))
        t0 = near[k]
        a, b = t0 - step, t0 + step
        gr = (np.sqrt(5) - 1) / 2
        c, d = b - gr * (b - a), a + gr * (b - a)
        fc, fd = refit(c), refit(d)
        sse = lambda f: np.inf if f is None else f.sse_w
        for _ in range(SEARCH_STEPS):
            if sse(fc) < sse(fd):
                b, d, fd = d, c, fc
                c = b - gr * (b - a)
                fc = refit(c)
            else:
                a, c, fc = c, d, fd
                d = a + gr * (b - a)
                fd = refit(d)
        best = fc if sse(fc) < sse(fd) else fd
        if best is None:
            return None
        best = self._sample_scan(dg, refit, best, float(best.model.params[tj_name]), tj_name)
        return fit_output_error(best.model, dg.prob, start=estimated_x0(best))

    @staticmethod
    def _sample_scan(dg, refit, best, tj, tj_name):
        """The best of the break dates within one sample of the golden-section optimum ``tj``, one per
        step of the simulation's own time resolution.

        The kernel evaluates ``step(t − t_j)`` at the RK4 stage times, ``t_k + i·h/2`` with h = Δt/substeps
        (:mod:`pipeline.simulate`), so the SSE is piecewise constant in t_j on intervals of width h/2, and
        the golden-section search, which assumes a strictly unimodal function, can stop on a plateau next
        to the best one when two of its points tie (a 0.5 → 0.8 thermal jump at 120 s placed at 119.91 s;
        the half-sample transient left at the jump had kurtosis 4.1 and was named heavy-tailed noise on
        Gaussian noise). Each plateau (t_k + (j−1)·h/2, t_k + j·h/2] within ±Δt of ``tj`` is simulated at
        its midpoint (inside it, whatever the rounding of the stage times) with the other parameters at
        the optimum's values, at most 4·substeps plateaus (substeps capped at 2, a coarser scan beyond),
        and the best one, if it is not the optimum's, is refitted: a few simulations and at most one
        refit, so the likelihood-ratio screen's date searches stay as cheap as before."""
        prob = dg.prob
        t = np.asarray(prob.t, float)
        e0, e1 = prob.split.est
        k = int(np.clip(np.searchsorted(t[e0:e1], tj), 1, e1 - e0 - 2)) + e0
        dt = float(t[k] - t[k - 1])
        if not np.isfinite(dt) or dt <= 0:
            return best
        sub = int(min(max(1, best.model.substeps), 2))
        r = dt / (2 * sub)
        here = int(np.ceil((tj - t[k]) / r))
        w, y = dg.w, prob.Y[e0:e1]

        def sse_sim(tj_try):
            Y = dg.sim_est(best.model.with_params({tj_name: float(tj_try)}), best.x0)
            return np.inf if Y is None else float(np.sum(((y - Y) * w) ** 2))

        s_here = sse_sim(tj)
        trials = [(sse_sim(t[k] + (j - 0.5) * r), j) for j in range(here - 2 * sub, here + 2 * sub + 1) if j != here]
        s_best, j = min(trials)
        if not s_best < s_here:
            return best
        f = refit(t[k] + (j - 0.5) * r)
        return f if f is not None and f.sse_w < best.sse_w else best

    def settled(self, model, hyp, values):
        """After t_j the rewrite ``p + Δ·step(t − t_j)`` is the constant p + Δ: the kernel computes
        p + Δ·1.0 = p + Δ, the same double as this sum, so the continued simulation is the same numbers."""
        k, d = hyp.parameter, hyp.coefs[0]
        return replace(model, params={**model.params, k: model.params[k] + values[d]})

    def describe(self, hyp, fit, val, sd):
        k = hyp.parameter
        tj_name = next(iter(hyp.extra_params))
        tj = float(fit.model.params[tj_name])
        before = float(fit.model.params[k])
        after = before + val[hyp.coefs[0]]
        return ({"parameter": k, "time_s": tj, "before": before, "after": after,
                 "change_std": sd.get(hyp.coefs[0])},
                f"The parameter {k} jumps from {before:.4g} to {after:.4g} at t = {tj:.4g} s; letting it change there")
