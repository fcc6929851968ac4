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
    assert src == "(min(max(xs[0], (-1.0)), 1.0) + p[2])"
    assert e.names == frozenset({"x", "k"})


def test_integer_exponents_are_emitted_as_integers():
    """x**3 compiles to multiplications (2x kernel speed), not pow(x, 3.0); values unchanged."""
    e = parse("x**3 - v**-2 + u**0.5", {"x", "v", "u"})
    src = to_source(e)
    assert "(x ** 3)" in src and "** 0.5)" in src  # v**-2 is a unary minus on 2: left as a float power
    x, v, u = np.array([1.5, -2.0]), np.array([0.5, 3.0]), np.array([4.0, 9.0])
    np.testing.assert_allclose(vectorize(e, ["x", "v", "u"])(x, v, u), x ** 3 - v ** -2.0 + u ** 0.5, rtol=1e-15)
