"""The config's expression language: whitelist parsing (never eval) and exact numeric translation."""

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.expressions import parse, to_source, vectorize

ALLOWED = {"x", "v", "u", "k", "c", "t"}


@pytest.mark.parametrize("text,token", [
    ("__import__('os')", "__import__"),
    ("x.real", "x.real"),
    ("x[0]", "x[0]"),
    ("lambda: 1", "lambda"),
    ("'a'", "'a'"),
    ("open('f')", "open"),
    ("y + 1", "y"),
    ("x if v else u", "if"),
    ("x < v", "<"),
    ("sin(x, v)", "sin"),
    ("clip(x, lo=1, hi=2)", "clip"),
    ("x @ v", "MatMult"),
    ("[x]", "[x]"),
])
def test_rejected_with_key_and_token(text, token):
    with pytest.raises(ConfigError) as ei:
        parse(text, ALLOWED, where="model.equations.v", file="cfg.yaml")
    msg = str(ei.value)
    assert "cfg.yaml" in msg and "model.equations.v" in msg and token in msg


def test_syntax_error_names_the_key():
    with pytest.raises(ConfigError, match="model.equations.x.*cannot parse"):
        parse("x +* 2", ALLOWED, where="model.equations.x")


def test_vectorized_matches_numpy():
    e = parse("-k*x - c*v*abs(v) + sign(v)*tanh(u) + clip(x, -0.5, 0.5)**2 + minimum(x, v) - t/2",
              ALLOWED)
    f = vectorize(e, ["x", "v", "u", "k", "c", "t"])
    rng = np.random.default_rng(0)
    x, v, u, t = rng.normal(size=(4, 50))
    k, c = 4.0, 0.6
    ref = -k * x - c * v * np.abs(v) + np.sign(v) * np.tanh(u) + np.clip(x, -0.5, 0.5) ** 2 + np.minimum(x, v) - t / 2
    np.testing.assert_allclose(f(x, v, u, k, c, t), ref, rtol=1e-14)


def test_scalar_source_uses_renamed_names_and_minmax_for_clip():
    e = parse("clip(x, -1, 1) + k", ALLOWED)
    src = to_source(e, {"x": "xs[0]", "k": "p[2]"}, scalar=True)
    assert src == "min(max(xs[0], -1.0), 1.0) + p[2]"
    assert e.names == frozenset({"x", "k"})


def test_integer_exponents_are_emitted_as_integers():
    """x**3 compiles to multiplications (2x kernel speed), not pow(x, 3.0); values unchanged."""
    e = parse("x**3 - v**-2 + u**0.5", {"x", "v", "u"})
    src = to_source(e)
    assert src == "x ** 3 - v ** (-2.0) + u ** 0.5"  # v**-2 is a unary minus on 2: left as a float power
    x, v, u = np.array([1.5, -2.0]), np.array([0.5, 3.0]), np.array([4.0, 9.0])
    np.testing.assert_allclose(vectorize(e, ["x", "v", "u"])(x, v, u), x ** 3 - v ** -2.0 + u ** 0.5, rtol=1e-15)


# precedence cases: every generated source evaluates as Python evaluates the original text
@pytest.mark.parametrize("text", [
    "x - (v - u)", "x / (v * u)", "x / v * u", "-x ** 2", "(-x) ** 2", "x ** -v", "2 ** 3 ** x",
    "(x + v) * (u - k)", "-(x + v)", "x - -v", "x * -v / +u", "(x ** 2) ** 3", "x ** (v + 1)",
    "k - c*v*abs(v) - (x - 1)**3 / (1 + x**2)", "x - v - u - k", "x / v / u", "pi * x",
])
def test_generated_source_keeps_the_value(text):
    e = parse(text, ALLOWED)
    rng = np.random.default_rng(1)
    vals = {n: rng.uniform(0.5, 1.5, 5) for n in ("x", "v", "u", "k", "c")}
    args = sorted(vals)
    got = vectorize(e, args)(*[vals[a] for a in args])
    ref = eval(text, {"abs": np.abs, "pi": np.pi}, dict(vals))  # the test's own reference, not the code's
    np.testing.assert_allclose(got, ref, rtol=1e-13)


def test_long_flat_sum_and_product_compile():
    names = [f"a{i}" for i in range(600)]
    e = parse(" + ".join(names) + " - " + " * ".join(names[:300]), set(names))
    src = to_source(e)
    assert "(" not in src
    vals = [np.full(2, 0.999)] * 600
    np.testing.assert_allclose(vectorize(e, names)(*vals), 600 * 0.999 - 0.999 ** 300)


@pytest.mark.parametrize("text,what", [
    ("1e999 * x", "too large"), ("1" + "0" * 400 + " * x", "too large"), ("x + 1/0", "not a finite"),
    ("x * log(-1)", "not a finite"), ("x*(" * 100 + "x" + ")" * 100, "nested too deeply"),
    ("-" * 300 + "x", "nested too deeply"), (" + ".join(["x"] * 4000), "too large|more than"),
    ("x" * 30000, "characters"), ("", "empty"), ("sin(" * 100 + "x" + ")" * 100, "nested too deeply"),
])
def test_limits_give_one_clear_error(text, what):
    with pytest.raises(ConfigError, match=what) as ei:
        parse(text, ALLOWED, where="model.equations.v", file="cfg.yaml")
    assert "cfg.yaml: model.equations.v" in str(ei.value)


def test_redundant_parentheses_are_not_nesting():
    assert parse("(" * 200 + "x" + ")" * 200, ALLOWED).names == frozenset({"x"})


def test_pi_and_nfkc():
    e = parse("ｋ * sin(2*pi*t)", ALLOWED)
    assert e.names == frozenset({"k", "t"})
    np.testing.assert_allclose(vectorize(e, ["k", "t"])(2.0, 0.25), 2.0)
