"""Output-error fitting: recovery, honest standard errors, equation-error start, estimated x0."""

import numpy as np
import pytest

from pipeline.data import Split
from pipeline.fit import Problem, equation_error_start, fit_output_error
from pipeline.synthetic import _nominal, generate


def _problem(syn, names, noise_free=False):
    Y = syn.y[:, None]
    n = len(syn.t)
    return Problem(syn.t, syn.u[:, None], Y, names, Split((0, int(0.7 * n)), (int(0.7 * n), n)), bound=1e6)


def test_recovers_parameters_from_wrong_start():
    syn = generate("msd", "none", 0, noise=0.0)
    m = _nominal("msd").with_params({"c": 1.2, "k": 2.5})
    fit = fit_output_error(m, _problem(syn, ["x"]))
    assert dict(zip(fit.names, fit.theta)) == pytest.approx({"c": 0.6, "k": 4.0}, rel=1e-5)


def test_standard_errors_match_monte_carlo_spread():
    """cov = σ̂²(JᵀJ)⁻¹ should describe the spread of estimates over noise realisations (±30 %)."""
    est, sds = [], []
    for seed in range(30):
        syn = generate("tank", "none", seed, noise=0.05, n=1200)
        fit = fit_output_error(_nominal("tank"), _problem(syn, ["h"]))
        est.append(fit.theta)
        sds.append(fit.std)
    emp = np.std(est, axis=0, ddof=1)
    assert np.mean(sds, axis=0) == pytest.approx(emp, rel=0.3)
    assert np.mean(est, axis=0) == pytest.approx([0.5, 1.0], rel=0.01)


def test_equation_error_start_when_states_measured():
    syn = generate("tank", "none", 0, noise=0.0)
    m = _nominal("tank").with_params({"a": 2.0, "b": 3.0})
    start = equation_error_start(m, _problem(syn, ["h"]))
    assert start["a"] == pytest.approx(0.5, rel=0.02) and start["b"] == pytest.approx(1.0, rel=0.02)


def test_estimated_initial_state():
    from dataclasses import replace
    syn = generate("tank", "none", 0, noise=0.0)
    m = _nominal("tank")
    from pipeline.simulate import simulate_states
    X = simulate_states(m, syn.t, syn.u[:, None], np.array([1.7])).X[:, 0]
    prob = Problem(syn.t, syn.u[:, None], X[:, None], ["h"], Split((0, 2000), (2000, 3000)), bound=1e6)
    fit = fit_output_error(replace(m, initial={"h": "estimate"}), prob)
    assert dict(zip(fit.names, fit.theta))["x0.h"] == pytest.approx(1.7, rel=1e-5)


def test_refit_is_abandoned_only_when_it_stays_above_the_bound():
    """abandon_above: a fit from a start whose error is far above the bound, which cannot reach it
    within abandon_after simulations, raises RefitAbandoned; a fit that gets below it runs to the end
    (and gives the same answer as without the option)."""
    from pipeline.errors import RefitAbandoned
    syn = generate("msd", "none", 0, noise=0.0)
    prob = _problem(syn, ["x"])
    good = fit_output_error(_nominal("msd"), prob)
    bad_start = _nominal("msd").with_params({"c": 6.0, "k": 0.4})
    with pytest.raises(RefitAbandoned, match="abandoned after 8 simulations"):
        fit_output_error(bad_start, prob, abandon_above=1e-12, abandon_after=8)
    again = fit_output_error(_nominal("msd"), prob, abandon_above=1.0 + good.sse_w * 1e3, abandon_after=8)
    np.testing.assert_array_equal(again.theta, good.theta)


def test_threaded_jacobian_gives_the_serial_fit_and_abandons_at_the_same_simulation(monkeypatch):
    """fit_output_error evaluates the finite-difference Jacobian's columns in threads (scipy's
    ``workers``). The fit must be the serial one bit for bit (parameters, Jacobian, SSE, evaluation
    count), and a refit abandoned mid-Jacobian must stop at the same simulation with the same message:
    the abandon rule is replayed on the threaded results in column order."""
    import pipeline.fit as F
    from pipeline.errors import RefitAbandoned
    if not F._LSQ_WORKERS:
        pytest.skip("this scipy's least_squares takes no workers")
    syn = generate("msd", "none", 0, noise=0.02)
    prob = _problem(syn, ["x"])
    start = _nominal("msd").with_params({"c": 1.2, "k": 2.5})

    monkeypatch.setattr(F, "JACOBIAN_THREADS_MIN_STEPS", 0)      # this short record takes the threaded path too

    def run(threads, **kw):
        monkeypatch.setattr(F, "JACOBIAN_THREADS", threads)
        try:
            return fit_output_error(start, prob, **kw)
        except RefitAbandoned as exc:
            return str(exc)

    pools = []
    real_pool = F.ThreadPoolExecutor
    monkeypatch.setattr(F, "ThreadPoolExecutor", lambda **kw: pools.append(kw) or real_pool(**kw))
    serial = run(1)
    assert not pools
    threaded = run(4)
    assert pools                                                  # the threaded path ran
    assert np.array_equal(serial.theta, threaded.theta) and np.array_equal(serial.jac, threaded.jac)
    assert serial.sse_w == threaded.sse_w and serial.nfev == threaded.nfev
    # abandoned inside a Jacobian (the 2nd and 3rd simulations are its columns): same count, same message
    for after in (2, 3, 5):
        a, b = run(1, abandon_above=1e-12, abandon_after=after), run(4, abandon_above=1e-12, abandon_after=after)
        assert isinstance(a, str) and a == b and f"after {after} simulations" in a


def test_a_refit_starts_from_the_current_fits_estimated_initial_state():
    """A refit of an extension (engine.refit, the families' searches) passes the current fit's estimated
    initial states as ``start`` (fit.estimated_x0). Refitting the fitted model itself from there, its first
    simulation is the fit's own (SSE equal, so a refit abandoned above the current error is never
    abandoned at its null); without it x0 restarts from the measured first sample, which on a noisy
    record is worse than the current fit, and the same refit is abandoned at once."""
    from dataclasses import replace
    from pipeline.errors import RefitAbandoned
    from pipeline.fit import estimated_x0
    from pipeline.simulate import simulate_states
    syn = generate("tank", "none", 0, noise=0.0)
    m = replace(_nominal("tank"), initial={"h": "estimate"})
    X = simulate_states(m, syn.t, syn.u[:, None], np.array([1.7])).X[:, 0]
    y = X + 0.05 * np.random.default_rng(1).standard_normal(len(X))
    prob = Problem(syn.t, syn.u[:, None], y[:, None], ["h"], Split((0, 2000), (2000, 3000)), bound=1e6)
    fit = fit_output_error(m, prob)
    x0 = estimated_x0(fit)
    assert list(x0) == ["x0.h"] and x0["x0.h"] == pytest.approx(1.7, abs=0.05) and abs(y[0] - x0["x0.h"]) > 0.01
    again = fit_output_error(fit.model, prob, start=x0, abandon_above=fit.sse_w * (1 + 1e-9), abandon_after=1)
    assert again.sse_w <= fit.sse_w * (1 + 1e-9)
    with pytest.raises(RefitAbandoned):
        fit_output_error(fit.model, prob, abandon_above=fit.sse_w * (1 + 1e-9), abandon_after=1)


# ------------------------------------------------------------------ model.bounds
def _first_order_case(tmp_path, bounds=None, a=0.5, b=2.0, n=600, dt=0.1, noise=0.02, seed=0):
    """x' = −a x + b u, zoh input, exact discretisation x_{k+1} = e^{−aΔ} x_k + (b/a)(1 − e^{−aΔ}) u_k
    (closed form, not the project's integrator), Gaussian noise; the config's model and Problem."""
    import pandas as pd
    import yaml
    from pipeline.config import load_config
    from pipeline.model import Model
    from pipeline.runs import load_record, make_split
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 20), 20)
    x = np.zeros(n)
    f = np.exp(-a * dt)
    for k in range(n - 1):
        x[k + 1] = f * x[k] + b / a * (1 - f) * u[k]
    pd.DataFrame({"t": np.arange(n) * dt, "u": u, "y": x + noise * rng.standard_normal(n)}).to_csv(
        tmp_path / "rec.csv", index=False)
    cfg = {"name": "fo", "seed": 0, "data": {"path": "rec.csv", "time": "t", "inputs": ["u"], "outputs": ["y"]},
           "model": {"states": ["y"], "inputs": ["u"], "params": {"a": 0.2, "b": 1.0}, "free": ["a", "b"],
                     "equations": {"y": "-a*y + b*u"}, "initial": 0.0}}
    if bounds:
        cfg["model"]["bounds"] = bounds
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    lc = load_config(tmp_path / "c.yaml")
    rec = load_record(lc)
    model = Model.from_config(lc)
    return model, Problem.from_record(rec, model, make_split(lc, rec), None)


def test_inactive_bounds_leave_the_fit_as_it_is(tmp_path):
    from pipeline.fit import at_bounds
    free, prob = _first_order_case(tmp_path)
    bounded, _ = _first_order_case(tmp_path, bounds={"a": [0, 10], "b": [None, 100]})
    assert bounded.bounds == {"a": (0.0, 10.0), "b": (-np.inf, 100.0)}
    f0, f1 = fit_output_error(free, prob), fit_output_error(bounded, prob)
    assert f1.theta == pytest.approx(f0.theta, rel=1e-6) and f1.std == pytest.approx(f0.std, rel=1e-4)
    assert f0.theta == pytest.approx([0.5, 2.0], rel=0.02)
    assert at_bounds(f1) == []


def test_an_active_bound_holds_and_is_reported(tmp_path):
    """The loss coefficient is 0.5; bounded to at most 0.3 the fit sits on the bound, b takes the
    constrained optimum, and the error is above the unconstrained fit's."""
    from pipeline.fit import at_bounds
    free, prob = _first_order_case(tmp_path)
    bounded, _ = _first_order_case(tmp_path, bounds={"a": [0, 0.3]})
    f0, f1 = fit_output_error(free, prob), fit_output_error(bounded, prob)
    a1 = dict(zip(f1.names, f1.theta))["a"]
    assert a1 == pytest.approx(0.3, abs=1e-9) and a1 <= 0.3
    assert at_bounds(f1) == ["a"] and f1.sse_w > 1.5 * f0.sse_w
    # a start outside the bounds (an equation-error estimate, a refit's linearised value) is moved in
    f2 = fit_output_error(bounded, prob, start={"a": 2.0, "b": 5.0})
    assert dict(zip(f2.names, f2.theta))["a"] == pytest.approx(0.3, abs=1e-9)
