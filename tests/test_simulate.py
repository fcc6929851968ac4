"""Simulation kernel against closed-form responses; zoh vs foh; divergence detection."""

import numpy as np
import pytest

from pipeline.expressions import parse
from pipeline.model import Model, Term
from pipeline.simulate import simulate_outputs, simulate_states
from pipeline.errors import SimulationError


def _model(eqs, params, states, intersample="zoh", substeps=1):
    allowed = set(states) | {"u", "t"} | set(params)
    return Model(states=tuple(states), inputs=("u",), equations={s: parse(e, allowed) for s, e in eqs.items()},
                 output_exprs={}, params=dict(params), free=(), initial={s: 0.0 for s in states},
                 substeps=substeps, intersample=intersample, nominal_params=tuple(params))


def test_msd_step_response_matches_closed_form():
    """x'' + 2ζω x' + ω² x = u, unit step: x = (1 − e^{−ζωt}(cos ω_d t + ζ/√(1−ζ²) sin ω_d t))/ω²."""
    m = _model({"x": "v", "v": "(u - c*v - k*x)/m"}, {"m": 1.0, "c": 0.6, "k": 4.0}, ["x", "v"])
    t = np.arange(2001) * 0.01
    X = simulate_states(m, t, np.ones((len(t), 1)), np.zeros(2)).X
    wn, z = 2.0, 0.15
    wd = wn * np.sqrt(1 - z * z)
    ref = (1 - np.exp(-z * wn * t) * (np.cos(wd * t) + z / np.sqrt(1 - z * z) * np.sin(wd * t))) / wn ** 2
    np.testing.assert_allclose(X[:, 0], ref, atol=1e-8)


def test_zoh_and_foh_ramp_first_order():
    """x' = −x + u with u sampled from a ramp u(t) = t. foh reproduces the ramp response
    t − 1 + e^{−t}; zoh is the response to the staircase (exact: x_{k+1} = e^{−h}x_k + (1−e^{−h})u_k)."""
    t = np.arange(501) * 0.02
    U = t[:, None].copy()
    mf = _model({"x": "-x + u"}, {}, ["x"], "foh")
    mz = _model({"x": "-x + u"}, {}, ["x"], "zoh")
    xf = simulate_states(mf, t, U, np.zeros(1)).X[:, 0]
    xz = simulate_states(mz, t, U, np.zeros(1)).X[:, 0]
    np.testing.assert_allclose(xf, t - 1 + np.exp(-t), atol=1e-9)
    h = 0.02
    ref = np.zeros_like(t)
    for k in range(len(t) - 1):
        ref[k + 1] = np.exp(-h) * ref[k] + (1 - np.exp(-h)) * U[k, 0]
    np.testing.assert_allclose(xz, ref, atol=1e-9)
    assert np.max(np.abs(xf - xz)) > 5e-3  # the choice matters


def test_extension_terms_equal_writing_them_in_the_equation():
    base = _model({"x": "v", "v": "u - 0.5*v - 4*x"}, {}, ["x", "v"])
    full = _model({"x": "v", "v": "u - 0.5*v - 4*x - 2*x**3 + 0.3 - 0.2*sign(v) + 0.1*sin(2*3.141592653589793*0.7*t)"},
                  {}, ["x", "v"])
    ext = base.extend([Term("cubic_stiffness", "pow", "v", "a", var="x", power=3),
                       Term("offset", "const", "v", "b"), Term("coulomb_friction", "sign", "v", "c", var="v"),
                       Term("periodic_disturbance", "sin", "v", "d", freq="f")],
                      {"a": -2.0, "b": 0.3, "c": -0.2, "d": 0.1, "f": 0.7})
    t = np.arange(1000) * 0.01
    U = np.sin(1.3 * t)[:, None]
    np.testing.assert_allclose(simulate_states(ext, t, U, np.zeros(2)).X, simulate_states(full, t, U, np.zeros(2)).X,
                               atol=1e-12)


def test_generic_kernel_with_two_inputs_and_with_none():
    """The generic kernel is unrolled over the model's own states and inputs: an extension on a model
    with two inputs (each interpolated with foh, over 3 sub-steps) and on one without inputs gives the
    response of the same equations written out (lean kernel); a limit without any program runs the
    generic kernel's program-free path and must clamp the state."""
    from pipeline.model import Limit
    t = np.arange(2000) * 0.01
    U2 = np.column_stack([np.sin(1.3 * t), np.sign(np.sin(0.4 * t))])

    def two(eq_v):
        allowed = {"x", "v", "u1", "u2", "t"}
        return Model(states=("x", "v"), inputs=("u1", "u2"), output_exprs={}, params={}, free=(),
                     equations={"x": parse("v", allowed), "v": parse(eq_v, allowed)}, initial={"x": 0.0, "v": 0.0},
                     substeps=3, intersample="foh", nominal_params=())
    ext = two("u1 - 0.5*v - 4*x + 0.3*u2").extend(
        [Term("static_nonlinearity", "expr", "v", "a", text="u2*x"), Term("offset", "const", "v", "b")],
        {"a": -0.7, "b": 0.2})
    full = two("u1 - 0.5*v - 4*x + 0.3*u2 - 0.7*u2*x + 0.2")
    np.testing.assert_allclose(simulate_states(ext, t, U2, np.zeros(2)).X, simulate_states(full, t, U2, np.zeros(2)).X,
                               atol=1e-12)
    none = Model(states=("x",), inputs=(), output_exprs={}, params={}, free=(), equations={"x": parse("-x", {"x"})},
                 initial={"x": 1.0}, substeps=2, nominal_params=())
    Z = np.zeros((len(t), 1))
    x = simulate_states(none.extend([Term("offset", "const", "x", "d")], {"d": 0.5}), t, Z, np.ones(1)).X[:, 0]
    np.testing.assert_allclose(x, 0.5 + 0.5 * np.exp(-t), atol=1e-9)       # x' = -x + 0.5, x(0) = 1
    lim = two("u1 - 0.5*v - 4*x + 0.3*u2").extend([], {"hi": 0.05}, limits=(Limit("state_saturation", "x", None, "hi", "v"),))
    free = simulate_states(two("u1 - 0.5*v - 4*x + 0.3*u2"), t, U2, np.zeros(2)).X[:, 0]
    clamped = simulate_states(lim, t, U2, np.zeros(2)).X[:, 0]
    assert free.max() > 0.1 and clamped.max() == 0.05
    below = free < 0.04
    np.testing.assert_array_equal(clamped[:np.argmax(~below)], free[:np.argmax(~below)])


def test_compiled_terms_simulate_bit_for_bit_like_interpreted_ones():
    """An accepted model's terms compiled into its kernel (Model.compiled) give the interpreter's
    numbers to the last bit, alone, under foh with substeps, and with a later hypothesis of every
    extension kind on top (a term, an input rewrite, a parameter jump, a limit, an extra state)."""
    from pipeline.model import Limit, Rewrite
    from pipeline.simulate import _programs_cached
    base = _model({"x": "v", "v": "u - c*v - k*x"}, {"c": 0.5, "k": 4.0}, ["x", "v"], "foh", 3)
    acc = base.extend([Term("cubic_stiffness", "pow", "v", "a", var="x", power=3),
                       Term("static_nonlinearity", "expr", "v", "b", text="x*abs(x)"),
                       Term("coulomb_friction", "sign", "v", "cf", var="v")],
                      {"a": -2.0, "b": 0.4, "cf": -0.2})
    comp = acc.compiled()
    assert len(_programs_cached(comp).progs) == 0 and len(_programs_cached(acc).progs) == 3
    t = np.arange(3000) * 0.01
    U = (np.sin(1.3 * t) + 0.5 * np.sign(np.sin(0.21 * t)))[:, None]
    later = [
        dict(terms=[Term("quadratic_damping", "expr", "v", "q", text="v*abs(v)")], new_params={"q": -0.3}),
        dict(terms=[], new_params={"L": 0.8}, input_rewrites=(Rewrite("input_saturation", "u", "clip(u, -L, L)"),)),
        dict(terms=[], new_params={"dk": 1.5}, param_rewrites=(Rewrite("parameter_jump", "k", "k + dk*step(t - 12)"),)),
        dict(terms=[], new_params={"hi": 0.15}, limits=(Limit("state_saturation", "x", None, "hi", "v"),)),
        dict(terms=[], new_params={"tau": 0.4}, input_rewrites=(Rewrite("unmodeled_dynamics", "u", "u_a"),),
             extra_states={"u_a": ("(u - u_a)/tau", 0.0)}),
    ]
    pairs = [(acc, comp)] + [(acc.extend(**kw), comp.extend(**kw)) for kw in later]
    for interp, compiled in pairs:
        x0 = np.zeros(len(interp.states))
        a = simulate_states(interp, t, U, x0).X
        b = simulate_states(compiled, t, U, x0).X
        assert np.all(np.isfinite(a)) and np.max(np.abs(a[:, 0])) > 0.05
        assert np.array_equal(a, b)


def test_compiled_rewrites_and_extra_states_simulate_bit_for_bit_like_interpreted_ones():
    """Model.compiled also writes input and parameter rewrites and extra states' equations into the
    kernel (refits of a saturation, a jump, a drift or a lag on a long record simulate 2-3x faster).
    Every extension kind, compiled, gives the interpreter's numbers to the last bit: alone, with any
    other kind interpreted on top of it, and with both compiled; parameter rewrites that read t
    included (the compiled kernel must use the interpreter's stage times)."""
    from pipeline.model import Limit, Rewrite
    from pipeline.simulate import _programs_cached
    base = _model({"x": "v", "v": "u - c*v - k*x + 0.1*sin(t)"}, {"c": 0.5, "k": 4.0}, ["x", "v"], "foh", 3)
    t = np.arange(3000) * 0.01 + 0.37
    U = (np.sin(1.3 * t) + 0.5 * np.sign(np.sin(0.21 * t)))[:, None]
    kinds = {
        "term": dict(terms=[Term("quadratic_damping", "expr", "v", "q", text="v*abs(v)")], new_params={"q": -0.3}),
        "saturation": dict(terms=[], new_params={"L": 0.8},
                           input_rewrites=(Rewrite("input_saturation", "u", "clip(u, -L, L)"),)),
        "jump": dict(terms=[], new_params={"dk": 1.5},
                     param_rewrites=(Rewrite("parameter_jump", "k", "k + dk*step(t - 12.005)"),)),
        "drift": dict(terms=[], new_params={"r": 0.05}, param_rewrites=(Rewrite("parameter_drift", "c", "c*(1 + r*t)"),)),
        "limit": dict(terms=[], new_params={"hi": 0.15}, limits=(Limit("state_saturation", "x", None, "hi", "v"),)),
        "lag": dict(terms=[], new_params={"tau": 0.4}, input_rewrites=(Rewrite("unmodeled_dynamics", "u", "u_a"),),
                    extra_states={"u_a": ("(u - u_a)/tau", 0.0)}),
    }
    for name in ("saturation", "jump", "drift", "lag"):
        comp = base.extend(**kinds[name]).compiled()
        assert len(_programs_cached(comp).progs) == 0, name
    checked = 0
    for first, a in kinds.items():
        for second, b in kinds.items():
            ra = {r.target for r in a.get("input_rewrites", ()) + a.get("param_rewrites", ())}
            rb = {r.target for r in b.get("input_rewrites", ()) + b.get("param_rewrites", ())}
            if first == second or ra & rb:      # the families never rewrite a name twice
                continue
            interp = base.extend(**a).extend(**b)
            x0 = np.zeros(len(interp.states))
            ref = simulate_states(interp, t, U, x0).X
            assert np.all(np.isfinite(ref)) and np.max(np.abs(ref[:, 0])) > 0.05
            for m in (base.extend(**a).compiled().extend(**b), interp.compiled()):
                assert np.array_equal(simulate_states(m, t, U, x0).X, ref), (first, second)
            checked += 1
    assert checked == 28
    # a compiled rewrite is written after the interpreted ones: rewriting its name again is refused
    twice = base.extend(**kinds["saturation"]).compiled().extend(
        [], {"w": 0.1}, input_rewrites=(Rewrite("dead_zone", "u", "sign(u)*maximum(abs(u) - w, 0)"),))
    with pytest.raises(ValueError, match="rewritten again"):
        simulate_states(twice, t, U, np.zeros(2))


def test_the_kernel_without_programs_is_the_generic_kernels_arithmetic():
    """A model with nothing left to interpret but a state limit (or compiled rewrites) runs the unrolled
    kernel ``simulate1`` instead of the generic one: the same numbers to the last bit, with a nominal
    equation that reads t, under foh with sub-steps, from a record that does not start at 0."""
    from pipeline.model import Limit, Rewrite
    from pipeline.simulate import _programs_cached, get_kernel
    base = _model({"x": "v", "v": "u - c*v - k*x + 0.1*sin(t)"}, {"c": 0.5, "k": 4.0}, ["x", "v"], "foh", 3)
    t = np.arange(3000) * 0.01 + 0.37
    U = (np.sin(1.3 * t) + 0.5 * np.sign(np.sin(0.21 * t)))[:, None]
    models = [base.extend([], {"hi": 0.15}, limits=(Limit("state_saturation", "x", None, "hi", "v"),)),
              base.extend([], {"lo": -0.1}, limits=(Limit("state_saturation", "v", "lo", None, None),)),
              base.extend([], {"dk": 1.5}, param_rewrites=(Rewrite("parameter_jump", "k", "k + dk*step(t - 12.005)"),)).compiled()]
    for m in models:
        pr = _programs_cached(m)
        generic, _, unrolled = get_kernel(m)
        p = np.array([m.params[k] for k in m.param_names])
        x0 = np.zeros(len(m.states))
        a, b = np.empty((len(t), 2)), np.empty((len(t), 2))
        assert generic(U, t, 3, True, p, x0, pr.code, pr.consts, pr.progs, pr.limits, 1e12, a) == -1
        assert unrolled(U, t, 3, True, p, x0, pr.limits, 1e12, b) == -1
        assert np.array_equal(a, b) and np.array_equal(simulate_states(m, t, U, x0).X, a)
    assert np.max(a[:, 0]) > 0.3        # the jump's record moves


def test_kernel_lookup_by_structure_never_returns_another_structures_kernel():
    """get_kernel is looked up by the model's structure (names, equations, terms), not by its source:
    models with the same names and parameter values but other equations, or other compiled terms,
    must each run their own kernel. Each is checked against its closed form or its interpreted form,
    after the other one has been simulated (so a stale lookup would return the wrong kernel)."""
    t = np.arange(201) * 0.01
    U = np.zeros((len(t), 1))
    decay = _model({"x": "-a*x + u"}, {"a": 1.5}, ["x"])
    grow = _model({"x": "a*x + u"}, {"a": 1.5}, ["x"])
    for m, sign in ((decay, -1), (grow, 1), (decay, -1)):
        x = simulate_states(m.with_params({"a": 1.5}), t, U, np.ones(1)).X[:, 0]
        np.testing.assert_allclose(x, np.exp(sign * 1.5 * t), rtol=1e-8)
    base = _model({"x": "v", "v": "u - 0.5*v - 4*x"}, {}, ["x", "v"])
    U = np.sin(1.3 * t)[:, None]
    cubes = base.extend([Term("cubic_stiffness", "pow", "v", "a", var="x", power=3)], {"a": -2.0})
    squares = base.extend([Term("static_nonlinearity", "pow", "v", "a", var="x", power=2)], {"a": -2.0})
    outs = []
    for m in (cubes, squares, cubes):
        a = simulate_states(m.compiled(), t, U, np.full(2, 0.5)).X
        np.testing.assert_array_equal(a, simulate_states(m, t, U, np.full(2, 0.5)).X)
        outs.append(a)
    assert np.max(np.abs(outs[0] - outs[1])) > 1e-3      # the two structures do differ here


def test_divergence_is_caught_not_hung():
    """x' = x², x(0) = 1 blows up at t = 1."""
    m = _model({"x": "x*x + 0*u"}, {}, ["x"])
    t = np.arange(300) * 0.01
    res = simulate_states(m, t, np.zeros((300, 1)), np.ones(1), bound=1e8)
    assert res.diverged_at is not None and 95 <= res.diverged_at <= 101
    assert np.isnan(res.X[-1, 0])
    with pytest.raises(SimulationError, match="diverged at sample"):
        simulate_outputs(m, t, np.zeros((300, 1)), np.ones(1), ["x"], bound=1e8)


def test_input_delay_shifts_the_response():
    m = _model({"x": "-x + u"}, {}, ["x"], "foh").extend([], {"d": 0.1}, delay="d")
    m0 = _model({"x": "-x + u"}, {}, ["x"], "foh")
    t = np.arange(400) * 0.01
    U = (t >= 1.0).astype(float)[:, None]
    x = simulate_states(m, t, U, np.zeros(1)).X[:, 0]
    x0 = simulate_states(m0, t, U, np.zeros(1)).X[:, 0]
    np.testing.assert_allclose(x[10:], x0[:-10], atol=1e-9)


def test_rhs_vectorized_matches_the_written_out_equation():
    from pipeline.expressions import vectorize
    from pipeline.model import rhs_vectorized
    base = _model({"x": "v", "v": "u - c*v - 4*x"}, {"c": 0.5}, ["x", "v"])
    ext = base.extend([Term("cubic_stiffness", "pow", "v", "a", var="x", power=3),
                       Term("periodic_disturbance", "cos", "v", "d", freq="f")], {"a": -2.0, "d": 0.1, "f": 0.7})
    rng = np.random.default_rng(0)
    X, U, t = rng.normal(size=(50, 2)), rng.normal(size=(50, 1)), np.linspace(0, 3, 50)
    full = parse("u - 0.5*v - 4*x - 2*x**3 + 0.1*cos(2*3.141592653589793*0.7*t)", {"x", "v", "u", "t"})
    ref = vectorize(full, ["x", "v", "u", "t"])(X[:, 0], X[:, 1], U[:, 0], t)
    got = rhs_vectorized(ext, X, U, t)
    np.testing.assert_allclose(got[:, 1], ref, atol=1e-12)
    np.testing.assert_allclose(got[:, 0], X[:, 1])


def test_extension_code_that_points_outside_the_value_vector_is_refused(monkeypatch):
    """The generic kernel indexes without bounds checks, so every slot of its register code is checked
    before the call: a slot read past the value vector, a result written over the state (instead of a
    slot of its own), a program value past the vector and a powi exponent outside 1..POWI_MAX each give
    a ValueError, and the untampered code simulates."""
    import pipeline.simulate as sim
    from dataclasses import replace as dc_replace
    base = _model({"x": "v", "v": "u - 0.5*v - 4*x"}, {}, ["x", "v"])
    m = base.extend([Term("cubic_stiffness", "pow", "v", "a", var="x", power=3)], {"a": -2.0})
    good = sim.programs(m)
    assert good.code[0, 0] == 16 and good.code[0, 2] == 3     # x**3 as repeated multiplication
    t = np.arange(50) * 0.01
    U = np.sin(t)[:, None]

    def run(pr):
        monkeypatch.setattr(sim, "_programs_cached", lambda model: pr)
        return simulate_states(m, t, U, np.zeros(2))
    assert np.all(np.isfinite(run(good).X))
    bad = []
    for row, col, value in ((0, 1, good.size), (1, 3, 0), (0, 2, 9)):
        code = good.code.copy()
        code[row, col] = value
        bad.append(dc_replace(good, code=code))
    progs = good.progs.copy()
    progs[0, 4] = good.size
    bad.append(dc_replace(good, progs=progs))
    for pr in bad:
        with pytest.raises(ValueError, match="refers past"):
            run(pr)
