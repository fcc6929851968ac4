"""Terms: named functions of named signals, parsed from their names (``x**3``, ``tanh(x)``,
``u(t-2)``, ``x*v``) with :mod:`ast` against a whitelist — never ``eval``.

Grammar: numbers, variable names, ``+ - * / **``, unary minus, the functions in :data:`FUNCTIONS`
and the lag syntax ``u(t-2)`` (signal ``u`` delayed by 2 samples; ``u(t)`` is ``u``). Every term has a
canonical readable name; re-parsing the name gives the same term. Used by :mod:`.library`.
"""

from __future__ import annotations

import ast
import math
from typing import Mapping

import numpy as np

from pipeline.errors import InputError
from pipeline.expressions import parse_eval

FUNCTIONS = {
    "sin": (np.sin, 1), "cos": (np.cos, 1), "tan": (np.tan, 1), "exp": (np.exp, 1),
    "log": (np.log, 1), "sqrt": (np.sqrt, 1), "abs": (np.abs, 1), "sign": (np.sign, 1),
    "tanh": (np.tanh, 1), "sinh": (np.sinh, 1), "cosh": (np.cosh, 1), "arctan": (np.arctan, 1),
    "clip": (np.clip, 3),  # saturation clip(x, lo, hi)
}
MAX_NAME = 400
_NAN = float("nan")


def _sgn(x):
    return float((x > 0) - (x < 0)) if x == x else _NAN


def _safe(f):
    def g(*a):
        try:
            return f(*a)
        except ValueError:
            return _NAN
        except OverflowError:
            return math.inf
    return g


# scalar (Python float) versions used by ODE right-hand sides, where numpy's per-call overhead dominates
SCALAR_FUNCTIONS = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "exp": _safe(math.exp), "log": _safe(math.log),
    "sqrt": _safe(math.sqrt), "abs": abs, "sign": _sgn, "tanh": math.tanh, "sinh": _safe(math.sinh),
    "cosh": _safe(math.cosh), "arctan": math.atan, "clip": lambda x, lo, hi: min(max(x, lo), hi),
}
_PREC = {"+": 1, "-": 1, "*": 2, "/": 2, "neg": 3, "**": 4}


def _fmt_num(v: float) -> str:
    v = float(v)
    if v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return repr(v)


# ----------------------------------------------------------------------------------- expression nodes
class _Node:
    prec = 5  # precedence for printing: 1 + -, 2 * /, 3 unary minus, 4 **, 5 atom


class _Num(_Node):
    def __init__(self, v: float):
        self.v = float(v)
        self.prec = 5 if self.v >= 0 else 3

    def fmt(self):
        return _fmt_num(self.v)

    def ev(self, data, n, cache):
        return np.full(n, self.v)

    def sc(self):
        v = self.v
        return lambda env: v

    def lag(self):
        return 0

    def names(self):
        return set()


class _Var(_Node):
    def __init__(self, name: str, delay: int = 0):
        self.name, self.delay = name, int(delay)

    def fmt(self):
        return f"{self.name}(t-{self.delay})" if self.delay else self.name

    def ev(self, data, n, cache):
        k = self.fmt()
        if k in cache:
            return cache[k]
        if self.name not in data:
            raise InputError(
                f"variable {self.name!r} is not in the data; expected one of {sorted(data)}", key=self.name
            )
        x = data[self.name]
        if self.delay:
            out = np.full(n, np.nan)
            if self.delay < n:
                out[self.delay:] = x[: n - self.delay]
        else:
            out = x
        cache[k] = out
        return out

    def lag(self):
        return self.delay

    def sc(self):
        if self.delay:
            raise InputError(f"term with {self.fmt()} cannot be evaluated at a single instant; expected no lags")
        name = self.name
        return lambda env: env[name]

    def names(self):
        return {self.name}


class _Neg(_Node):
    prec = 3

    def __init__(self, a):
        self.a = a

    def fmt(self):
        s = self.a.fmt()
        return "-" + (f"({s})" if self.a.prec < 3 else s)

    def ev(self, data, n, cache):
        return -self.a.ev(data, n, cache)

    def sc(self):
        fa = self.a.sc()
        return lambda env: -fa(env)

    def lag(self):
        return self.a.lag()

    def names(self):
        return self.a.names()


class _Bin(_Node):
    def __init__(self, op, a, b):
        self.op, self.a, self.b = op, a, b
        self.prec = _PREC[op]

    def fmt(self):
        p = self.prec
        sa, sb = self.a.fmt(), self.b.fmt()
        if self.op == "**":
            left_paren, right_paren = self.a.prec <= p, self.b.prec < 3
        else:
            left_paren, right_paren = self.a.prec < p, self.b.prec <= p
        sa = f"({sa})" if left_paren else sa
        sb = f"({sb})" if right_paren else sb
        return f"{sa}{self.op}{sb}"

    def ev(self, data, n, cache):
        if self.op == "**" and isinstance(self.b, _Num) and isinstance(self.a, _Var):
            k = self.fmt()
            if k not in cache:  # powers of signals are reused by many monomials
                cache[k] = self.a.ev(data, n, cache) ** self.b.v
            return cache[k]
        a, b = self.a.ev(data, n, cache), self.b.ev(data, n, cache)
        if self.op == "+":
            return a + b
        if self.op == "-":
            return a - b
        if self.op == "*":
            return a * b
        if self.op == "/":
            return a / b
        return a ** b

    def lag(self):
        return max(self.a.lag(), self.b.lag())

    def sc(self):
        fa, fb, op = self.a.sc(), self.b.sc(), self.op
        if op == "+":
            return lambda env: fa(env) + fb(env)
        if op == "-":
            return lambda env: fa(env) - fb(env)
        if op == "*":
            return lambda env: fa(env) * fb(env)
        if op == "/":
            def div(env):
                a, b = fa(env), fb(env)
                return a / b if b != 0 else (math.copysign(math.inf, a) if a != 0 else _NAN)
            return div

        def pw(env):
            try:
                r = fa(env) ** fb(env)
            except ZeroDivisionError:
                return math.inf
            except OverflowError:
                return math.inf
            return r if type(r) is float or type(r) is int else _NAN
        return pw

    def names(self):
        return self.a.names() | self.b.names()


class _Call(_Node):
    def __init__(self, fn, args):
        self.fn, self.args = fn, list(args)

    def fmt(self):
        return f"{self.fn}(" + ",".join(a.fmt() for a in self.args) + ")"

    def ev(self, data, n, cache):
        f = FUNCTIONS[self.fn][0]
        return f(*[a.ev(data, n, cache) for a in self.args])

    def lag(self):
        return max(a.lag() for a in self.args)

    def sc(self):
        f = SCALAR_FUNCTIONS[self.fn]
        args = [a.sc() for a in self.args]
        if len(args) == 1:
            a0 = args[0]
            return lambda env: f(a0(env))
        return lambda env: f(*[a(env) for a in args])

    def names(self):
        return set().union(*[a.names() for a in self.args])


# ------------------------------------------------------------------------------------------- parsing
_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


def _bad(term: str, what: str) -> InputError:
    return InputError(
        f"term {term!r} does not parse: {what}; expected numbers, variable names, + - * / **, "
        f"unary minus, functions {sorted(FUNCTIONS)} or a lag like u(t-2)"
    )


def _lag_of(arg: ast.AST) -> int | None:
    """``t`` -> 0, ``t-k`` -> k (k a non-negative integer), otherwise None."""
    if isinstance(arg, ast.Name) and arg.id == "t":
        return 0
    if (
        isinstance(arg, ast.BinOp) and isinstance(arg.op, ast.Sub) and isinstance(arg.left, ast.Name)
        and arg.left.id == "t" and isinstance(arg.right, ast.Constant) and type(arg.right.value) is int
        and arg.right.value >= 0
    ):
        return arg.right.value
    return None


def _convert(node: ast.AST, term: str) -> _Node:
    if isinstance(node, ast.Constant):
        if type(node.value) not in (int, float):
            raise _bad(term, f"constant {node.value!r} is not a real number")
        return _Num(node.value)
    if isinstance(node, ast.Name):
        if node.id in FUNCTIONS:
            raise _bad(term, f"function {node.id!r} used without arguments")
        return _Var(node.id)
    if isinstance(node, ast.UnaryOp):
        if isinstance(node.op, ast.USub):
            inner = _convert(node.operand, term)
            return _Num(-inner.v) if isinstance(inner, _Num) and inner.v > 0 else _Neg(inner)
        if isinstance(node.op, ast.UAdd):
            return _convert(node.operand, term)
        raise _bad(term, f"unary operator {type(node.op).__name__} is not allowed")
    if isinstance(node, ast.BinOp):
        op = _BINOPS.get(type(node.op))
        if op is None:
            raise _bad(term, f"operator {type(node.op).__name__} is not allowed")
        return _Bin(op, _convert(node.left, term), _convert(node.right, term))
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name):
            raise _bad(term, "only plain function names may be called")
        if node.keywords:
            raise _bad(term, "keyword arguments are not allowed")
        name = node.func.id
        if name in FUNCTIONS:
            arity = FUNCTIONS[name][1]
            if len(node.args) != arity or any(isinstance(a, ast.Starred) for a in node.args):
                raise _bad(term, f"{name} takes {arity} argument(s)")
            return _Call(name, [_convert(a, term) for a in node.args])
        if len(node.args) == 1 and (k := _lag_of(node.args[0])) is not None:
            return _Var(name, k)
        raise _bad(term, f"{name!r} is neither an allowed function nor a lag like {name}(t-2)")
    raise _bad(term, f"{type(node).__name__} is not allowed")


def parse_term(name: str) -> "Term":
    """Parse a term name (``"x**3"``, ``"1/(1+x**2)"``, ``"u(t-2)*y(t-1)"``) into a :class:`Term`.

    Uses :func:`ast.parse` and a whitelist of node types; anything else (attributes, subscripts,
    calls of other names, strings, lambdas...) raises :class:`InputError` naming the term.
    """
    if isinstance(name, Term):
        return name
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"term {name!r}: expected a non-empty string such as 'x**2' or 'tanh(x)'")
    if len(name) > MAX_NAME:
        raise _bad(name[:40] + "...", f"longer than {MAX_NAME} characters")
    try:
        tree = parse_eval(name.strip())
    except SyntaxError as exc:
        raise _bad(name, f"syntax error ({exc.msg})") from None
    return Term(_convert(tree.body, name))


# --------------------------------------------------------------------------------------- term/library
class Term:
    """One regressor φ(data) with a canonical readable name (re-parsing the name gives the term)."""

    def __init__(self, node: _Node):
        self._node = node
        self.name = node.fmt()

    def __repr__(self):
        return f"Term({self.name!r})"

    def __eq__(self, other):
        return isinstance(other, Term) and other.name == self.name

    def __hash__(self):
        return hash(self.name)

    @property
    def max_lag(self) -> int:
        return self._node.lag()

    @property
    def variables(self) -> set[str]:
        return self._node.names()

    def current_variables(self) -> set[str]:
        """Signals used without delay (a term of the target at delay 0 would leak the answer)."""
        out, stack = set(), [self._node]
        while stack:
            nd = stack.pop()
            if isinstance(nd, _Var) and nd.delay == 0:
                out.add(nd.name)
            stack.extend(getattr(nd, "args", []) + [getattr(nd, k) for k in ("a", "b") if hasattr(nd, k)])
        return out

    def is_one(self) -> bool:
        return isinstance(self._node, _Num) and self._node.v == 1.0

    def scalar(self):
        """Compiled closure ``env -> float`` (env maps names to Python floats); no lags allowed."""
        return self._node.sc()

    def __mul__(self, other: "Term") -> "Term":
        if self.is_one():
            return other
        if other.is_one():
            return self
        return Term(_Bin("*", self._node, other._node))

    def evaluate(self, data: Mapping[str, np.ndarray], _n: int | None = None, _cache=None) -> np.ndarray:
        arrays, n = _check_data(data) if _n is None else (data, _n)
        with np.errstate(all="ignore"):
            out = np.asarray(self._node.ev(arrays, n, {} if _cache is None else _cache), dtype=float)
        return np.broadcast_to(out, (n,)) if out.ndim == 0 else out


def _check_data(data: Mapping[str, np.ndarray]) -> tuple[dict, int]:
    if not isinstance(data, Mapping) or not data:
        raise InputError("data: expected a non-empty mapping of signal name -> 1-D array")
    arrays, n = {}, None
    for k, v in data.items():
        a = np.asarray(v, dtype=float)
        if a.ndim == 2 and 1 in a.shape:
            a = a.ravel()
        if a.ndim != 1:
            raise InputError(f"data[{k!r}] has shape {a.shape}; expected a 1-D array", key=k)
        if n is None:
            n = a.size
        elif a.size != n:
            raise InputError(f"data[{k!r}] has {a.size} samples; expected {n} like the other signals", key=k)
        arrays[k] = a
    return arrays, n
