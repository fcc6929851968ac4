"""The two shortcuts of the added-term tests (issue 8, Silverbox speed) give the tests they replace.

* ``Hypothesis.acts_from`` (a jump at t_j): the sensitivity is simulated from just before t_j on,
  resumed from the current fit's simulated state. It must equal the full simulation's sensitivity,
  with a warm-up start and with a second experiment whose time restarts at 0 (cascaded tanks).
* ``info['screen_group']`` (a jump's grid of times for one parameter): only the time whose sensitivity
  explains the largest share by OLS gets the full test; the family's p-value (Bonferroni over every
  hypothesis) is then never smaller than with every time tested, so its size stays bounded.

Data: scipy ``lsim`` of a mass-spring-damper with a stiffness jump (no code of the detector)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pipeline.data import Split
from pipeline.diagnostics.engine import Diagnoser
from pipeline.diagnostics.families import FAMILY_IDS, REGISTRY
from pipeline.expressions import parse
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model


def _record(rng, n, dt, k_after=None, t_jump=None):
    t = np.arange(n) * dt
    u = signal.lfilter([0.05], [1, -0.95], rng.normal(size=n)) * 8
    if k_after is None:
        sys = signal.StateSpace([[0, 1], [-4.0, -0.6]], [[0], [1]], [[1, 0]], [[0]])
        _, y, _ = signal.lsim(sys, u, t, interp=True)
    else:   # piecewise: the state carried over at the jump
        j = int(round(t_jump / dt))
        s1 = signal.StateSpace([[0, 1], [-4.0, -0.6]], [[0], [1]], [[1, 0]], [[0]])
        s2 = signal.StateSpace([[0, 1], [-k_after, -0.6]], [[0], [1]], [[1, 0]], [[0]])
        _, y1, x1 = signal.lsim(s1, u[:j + 1], t[:j + 1], interp=True)
        _, y2, _ = signal.lsim(s2, u[j:], t[j:] - t[j], X0=x1[-1], interp=True)
        y = np.concatenate([y1[:-1], y2])
    return t, u, y + 0.01 * rng.normal(size=n)


def _model():
    allowed = {"x", "v", "u", "c", "k", "t"}
    return Model(("x", "v"), ("u",), {"x": parse("v", allowed), "v": parse("u - c*v - k*x", allowed)}, {},
                 {"c": 0.5, "k": 3.5}, ("c", "k"), {"x": 0.0, "v": 0.0}, intersample="foh",
                 nominal_params=("c", "k"))


def _setting(kind: str):
    rng = np.random.default_rng(3)
    dt = 0.02
    if kind == "warmup":       # estimation from sample 400, its simulation from 100 (a warm-up)
        t, u, y = _record(rng, 2400, dt, k_after=5.0, t_jump=30.0)
        prob = Problem(t, u[:, None], y[:, None], ["x"], Split((400, 1800), (1800, 2400)), bound=1e6,
                       warmup_start=100)
    else:                      # two experiments, each with its own time axis from 0
        t1, u1, y1 = _record(rng, 1200, dt, k_after=5.0, t_jump=12.0)
        t2, u2, y2 = _record(rng, 800, dt)
        t, u, y = np.concatenate([t1, t2]), np.concatenate([u1, u2]), np.concatenate([y1, y2])
        prob = Problem(t, u[:, None], y[:, None], ["x"], Split((0, 1200), (1200, 2000)), bound=1e6,
                       restarts=(1200,))
    fit = fit_output_error(_model(), prob)
    dg = Diagnoser(prob, alpha=0.01, families=list(FAMILY_IDS), max_findings=1, seed=0, dt=dt)
    return dg, fit, dg.context(fit, None)


@pytest.mark.parametrize("kind", ["warmup", "two_experiments"])
def test_a_resumed_jump_sensitivity_equals_the_full_simulation(kind):
    dg, fit, ctx = _setting(kind)
    hyps = REGISTRY["parameter_jump"].hypotheses(ctx)
    assert hyps and all(h.acts_from is not None for h in hyps)
    for h in hyps:
        fast = dg.sensitivity(fit, h, ctx.X)
        h.acts_from = None
        full = dg.sensitivity(fit, h, ctx.X)
        assert fast is not None and full is not None
        # the same recursion from the same stored state: equal to rounding
        np.testing.assert_allclose(fast, full, rtol=0, atol=1e-9 * np.max(np.abs(full)))
        assert np.max(np.abs(full)) > 0


def test_after_the_jump_the_current_models_kernel_continues_with_the_same_numbers(monkeypatch):
    """``Family.settled``: past the sample interval holding t_j the jumped parameter is a constant, so
    the sensitivity simulation continues with the current model (no interpreted rewrite). Only a few
    rows are simulated with the rewrite, and the result is the full simulation's bit for bit (a
    time-invariant model: the same floating-point operations in the same order)."""
    import pipeline.diagnostics.engine as E
    dg, fit, ctx = _setting("warmup")
    rows = []
    real = E.simulate_states

    def spy(model, t, *a, **k):
        rows.append((bool(model.param_rewrites), len(t)))
        return real(model, t, *a, **k)

    monkeypatch.setattr(E, "simulate_states", spy)
    for h in REGISTRY["parameter_jump"].hypotheses(ctx)[::5]:
        rows.clear()
        fast = dg.sensitivity(fit, h, ctx.X)
        rewritten = [n for rw, n in rows if rw]
        assert rewritten and max(rewritten) <= dg.RESUME_BACK + 2
        assert sum(n for rw, n in rows if not rw) > 50        # the rest, with the current model
        h.acts_from = None
        full = dg.sensitivity(fit, h, ctx.X)
        np.testing.assert_array_equal(fast, full)


def test_the_screened_jump_test_is_conservative_and_keeps_one_time_per_parameter():
    dg, fit, ctx = _setting("warmup")
    hyps = REGISTRY["parameter_jump"].hypotheses(ctx)
    sens = [dg.sensitivity(fit, h, ctx.X) for h in hyps]
    skip = dg.screened_out(fit, hyps, sens)
    kept = [h for h in hyps if id(h) not in skip]
    assert sorted(h.parameter for h in kept) == ["c", "k"]        # one time per parameter
    full = [dg.statistic(fit, S) for S in sens]
    p_all = min(w.p_value for w in full) * len(hyps)
    p_kept = min(w.p_value for h, w in zip(hyps, full) if id(h) not in skip) * len(hyps)
    assert p_kept >= p_all
    # the kept time of k is the grid time nearest the true jump (30 s) and the test still fires
    hk = next(h for h in kept if h.parameter == "k")
    grid = sorted({h.acts_from for h in hyps})
    assert abs(hk.acts_from - 30.0) <= (grid[1] - grid[0])
    assert p_kept < 0.01


def test_the_engine_names_the_jump_with_the_shortcuts():
    """End to end on the warm-up record: the first finding is the stiffness jump near 30 s."""
    dg, fit, _ = _setting("warmup")
    dg.families = ["parameter_jump", "parameter_drift", "cubic_stiffness", "offset"]
    diag = dg.run(_model())
    f = diag.findings[0]
    assert (f["family"], f["parameter"]) == ("parameter_jump", "k")
    assert abs(f["time_s"] - 30.0) < 0.05 * 2400 * 0.02
    assert abs(f["after"] - 5.0) < 0.2 * 5.0
