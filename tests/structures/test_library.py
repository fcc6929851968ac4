"""Term libraries: readable names, composition, parsing by whitelist (never eval), bad input."""

import builtins
import math

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.structures import library as lb
from pipeline.structures.library import Library, parse_term

COURSE_MODELS = {  # the course project's candidate structures M1..M5 as term lists
    "M1": ["tanh(x)", "1/(1+x**2)"],
    "M2": ["x**2", "sin(x)", "x**2/(x**2+1)"],
    "M3": ["x**3", "tanh(x)", "1/(1+x**2)"],
    "M4": ["x", "x**2", "x**3"],
    "M5": ["exp(-x**2)", "exp(-(x-1)**2)", "exp(-(x+1)**2)"],
}


def test_composition_names_and_values_at_a_point():
    lib = (lb.poly("x", 2) + lb.tanh("x")) * lb.sign("x")
    assert lib.names == ["sign(x)", "x*sign(x)", "x**2*sign(x)", "tanh(x)*sign(x)"]
    x = -0.7
    got = lib.evaluate({"x": np.array([x])})[0]
    s = -1.0
    np.testing.assert_allclose(got, [s, x * s, x * x * s, math.tanh(x) * s], rtol=1e-15)


def test_union_removes_duplicates_and_keeps_order():
    lib = lb.poly("x", 2) + lb.poly("x", 3, include_bias=False) + lb.tanh("x")
    assert lib.names == ["1", "x", "x**2", "x**3", "tanh(x)"]


def test_multivariate_polynomial_names_and_cross_terms():
    assert lb.poly(["x", "v"], 2).names == ["1", "x", "v", "x**2", "x*v", "v**2"]
    assert lb.poly(["x", "v"], 2, include_bias=False, interactions=False).names == ["x", "v", "x**2", "v**2"]
    vals = lb.poly(["x", "v"], 3).evaluate({"x": np.array([2.0]), "v": np.array([3.0])})[0]
    # 1, x, v, x², xv, v², x³, x²v, xv², v³
    np.testing.assert_allclose(vals, [1, 2, 3, 4, 6, 9, 8, 12, 18, 27])


def test_product_library_counts_each_pair_once():
    a = Library(["x", "v"])
    assert (a * a).names == ["x*x", "x*v", "v*v"]


def test_lagged_terms_shift_the_signal():
    u = np.arange(10.0)
    y = 10 * np.arange(10.0)
    lib = Library(["u(t-2)", "y(t-1)", "u(t-2)*y(t-1)"])
    assert lib.max_lag == 2
    full = lib.evaluate({"u": u, "y": y})
    assert np.all(np.isnan(full[:2, 0])) and np.isnan(full[0, 1])
    P = lib.evaluate({"u": u, "y": y}, drop_initial=True)
    k = np.arange(2, 10)
    np.testing.assert_array_equal(P[:, 0], u[k - 2])
    np.testing.assert_array_equal(P[:, 1], y[k - 1])
    np.testing.assert_array_equal(P[:, 2], u[k - 2] * y[k - 1])
    assert lb.lags("u", 3).names == ["u(t-1)", "u(t-2)", "u(t-3)"]


def test_narx_candidate_count_lags_10_degree_4():
    lib = lb.narx("y", "u", ny=10, nu=10, degree=4)
    assert len(lib) == math.comb(20 + 4, 4)  # monomials of degree <= 4 in 20 variables
    assert "y(t-1)*u(t-3)" in lib.names and "u(t-10)**4" in lib.names


@pytest.mark.parametrize("model", sorted(COURSE_MODELS))
def test_course_models_parse_and_round_trip(model):
    terms = COURSE_MODELS[model]
    lib = lb.from_terms(terms)
    assert lib.names == terms  # config names are kept verbatim (they are already canonical)
    assert [parse_term(n).name for n in lib.names] == terms


def test_course_model_values():
    x = np.array([0.5, -2.0])
    M2 = lb.from_terms(COURSE_MODELS["M2"]).evaluate({"x": x})
    np.testing.assert_allclose(M2, np.column_stack([x**2, np.sin(x), x**2 / (x**2 + 1)]))
    M5 = lb.from_terms(COURSE_MODELS["M5"]).evaluate({"x": x})
    np.testing.assert_allclose(M5, np.column_stack([np.exp(-x**2), np.exp(-(x - 1) ** 2), np.exp(-(x + 1) ** 2)]))


def test_generators_rbf_sign_saturation_sinusoids():
    assert lb.rbf("x", [-1, 0, 1]).names == ["exp(-(x+1)**2)", "exp(-x**2)", "exp(-(x-1)**2)"]
    r = lb.rbf("x", [0.5], width=0.5)
    assert r.names == ["exp(-(x-0.5)**2/0.25)"]
    np.testing.assert_allclose(r.evaluate({"x": np.array([1.0])}), [[math.exp(-1.0)]])
    s = lb.sign("v", eps=0.01)
    assert s.names == ["tanh(v/0.01)"]
    np.testing.assert_allclose(s.evaluate({"v": np.array([0.005])}), [[math.tanh(0.5)]])
    sat = lb.saturation("v", 2)
    assert sat.names == ["clip(v,-2,2)"]
    np.testing.assert_array_equal(sat.evaluate({"v": np.array([-5.0, 1.0, 3.0])})[:, 0], [-2, 1, 2])
    sn = lb.sinusoids([1, 2.5])
    assert sn.names == ["sin(t)", "cos(t)", "sin(2.5*t)", "cos(2.5*t)"]
    t = np.array([0.3])
    np.testing.assert_allclose(sn.evaluate({"t": t})[0], [math.sin(0.3), math.cos(0.3), math.sin(0.75), math.cos(0.75)])
    assert lb.rational("x").names == ["1/(1+x**2)"]


@pytest.mark.parametrize("name", ["-x**2", "(-x)**2", "x-(y-z)", "x/(y*z)", "2**x**2", "(2**x)**2",
                                  "u(t-3)*tanh(y(t-1))", "sqrt(abs(x))+log(1+x**2)", "arctan(x)/cosh(x)"])
def test_canonical_names_round_trip_and_keep_meaning(name):
    t = parse_term(name)
    assert parse_term(t.name).name == t.name
    rng = np.random.default_rng(1)
    data = {k: rng.uniform(0.2, 0.9, 12) for k in ("x", "y", "z", "u")}
    np.testing.assert_allclose(t.evaluate(data), parse_term(t.name).evaluate(data))


def test_scalar_closure_matches_vector_evaluation():
    for name in ["x**3-2*x*v", "tanh(x/0.1)", "clip(v,-1,1)", "1/(1+x**2)", "sign(v)*abs(x)**1.5"]:
        t = parse_term(name)
        for x, v in [(0.3, -1.7), (-2.0, 0.4)]:
            vec = t.evaluate({"x": np.array([x]), "v": np.array([v])})[0]
            assert t.scalar()({"x": x, "v": v}) == pytest.approx(vec, rel=1e-14)


def test_parsing_and_evaluation_never_call_eval(monkeypatch):
    def forbidden(*a, **k):
        raise AssertionError("eval/exec called")

    for fn in ("eval", "exec"):  # (ast.parse itself uses compile in "parse only" mode)
        monkeypatch.setattr(builtins, fn, forbidden)
    lib = lb.from_terms(COURSE_MODELS["M3"]) + lb.narx("y", "u", 2, 2, 2)
    out = lib.evaluate({"x": np.ones(5), "y": np.ones(5), "u": np.ones(5)})
    assert out.shape == (5, len(lib))


@pytest.mark.parametrize("bad", ["__import__('os')", "x.real", "x[0]", "lambda: 1", "'x'", "f(x)", "u(t+1)",
                                 "x if v else 1", "x == 1", "sin(x, v)", "True", "1j", "x @ v", "exp",
                                 "sin(x, key=1)", "x +", "().__class__"])
def test_bad_term_name_raises_input_error_naming_the_term(bad):
    with pytest.raises(InputError) as exc:
        parse_term(bad)
    assert repr(bad) in str(exc.value) or bad in str(exc.value)
    assert "expected" in str(exc.value)


def test_empty_library_raises():
    with pytest.raises(InputError, match="library is empty"):
        Library([])
    with pytest.raises(InputError, match="library is empty"):
        lb.from_terms([])


def test_missing_variable_and_ragged_data_raise():
    with pytest.raises(InputError, match="'v'"):
        Library(["x*v"]).evaluate({"x": np.ones(3)})
    with pytest.raises(InputError, match="samples"):
        Library(["x*v"]).evaluate({"x": np.ones(3), "v": np.ones(4)})


def test_more_terms_than_samples_raises():
    data = {"x": np.linspace(-1, 1, 5), "y": np.zeros(5)}
    with pytest.raises(InputError, match="6 candidate terms for 5 samples"):
        lb.fit_least_squares(lb.poly("x", 5), data, "y")


def test_least_squares_fit_of_a_declared_structure():
    x = np.linspace(-2, 2, 50)
    y = 0.5 * np.tanh(x) - 1.5 / (1 + x**2)
    np.testing.assert_allclose(lb.fit_least_squares(lb.from_terms(COURSE_MODELS["M1"]), {"x": x, "y": y}, "y"),
                               [0.5, -1.5], atol=1e-12)
