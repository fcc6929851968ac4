"""The config's safe expression language (diagnosis contract §1).

Grammar: numbers, names (states, inputs, params, ``t``), the constant ``pi``, ``+ - * / **``, unary
minus, parentheses and the functions ``sin cos tan exp log sqrt abs sign tanh sinh cosh arctan minimum
maximum clip step`` (``step(x)`` is 1 for x ≥ 0, else 0). Limits (one clear error each): at most ``MAX_CHARS`` characters, ``MAX_NODES`` syntax
nodes and nesting depth ``MAX_DEPTH``; constants finite; a constant subexpression (no names) must
evaluate to a finite number (``1/0`` and ``log(-1)`` are errors at parse time, not at run time).
Text is NFKC-normalised first, as Python normalises identifiers (fullwidth ``ｋ`` is ``k``).
Generated source has no redundant parentheses (a 500-term sum is flat), so it never reaches Python's
nesting limits.
Expressions are parsed with :mod:`ast` and checked node by node against that whitelist; they are never
passed to ``eval``. A checked expression is turned into Python *source* over plain names, which
:mod:`pipeline.simulate` compiles into a numba kernel and :func:`vectorize` into a numpy function.
"""

from __future__ import annotations

import ast
import math
import threading
import unicodedata
from dataclasses import dataclass

import numpy as np

from .errors import ConfigError

_PARSE_LOCK = threading.Lock()


def parse_eval(src: str) -> ast.Expression:
    """``ast.parse(src, mode="eval")`` under one process-wide lock.

    CPython 3.11 builds the Python AST objects (``ast2obj``) with a recursion counter kept in
    interpreter-wide state and seeded from the *calling thread's* depth; when a thread switch lands
    inside that conversion (a garbage collection running a Python finaliser is enough) and the other
    thread parses too, the first parse fails with ``SystemError: AST constructor recursion depth
    mismatch`` (cpython gh-106905; reproduced here with four threads). The diagnosis engine refits
    candidates in threads, each building models from expressions, so every parse in this package
    goes through this function.
    """
    with _PARSE_LOCK:
        return ast.parse(src, mode="eval")


FUNCTIONS = {
    # name: (arity, numpy source, scalar (numba) source template)
    "sin": (1, "np.sin", "np.sin"),
    "cos": (1, "np.cos", "np.cos"),
    "tan": (1, "np.tan", "np.tan"),
    "exp": (1, "np.exp", "np.exp"),
    "log": (1, "np.log", "np.log"),
    "sqrt": (1, "np.sqrt", "np.sqrt"),
    "abs": (1, "np.abs", "abs"),
    "sign": (1, "np.sign", "np.sign"),
    "tanh": (1, "np.tanh", "np.tanh"),
    "sinh": (1, "np.sinh", "np.sinh"),
    "cosh": (1, "np.cosh", "np.cosh"),
    "arctan": (1, "np.arctan", "np.arctan"),
    "minimum": (2, "np.minimum", "min"),
    "maximum": (2, "np.maximum", "max"),
    "clip": (3, "np.clip", None),
    "step": (1, None, None),       # Heaviside: 1 for x >= 0, else 0 (a parameter jump at a time)
}
_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
CONSTANTS = {"pi": math.pi}
MAX_CHARS = 20_000
MAX_NODES = 5_000
MAX_DEPTH = 60


@dataclass(frozen=True)
class Expr:
    """A checked expression: its text, its AST and the names it uses."""

    text: str
    tree: ast.expr
    names: frozenset[str]


def _bad(where: str, token: str, why: str, file: str | None) -> ConfigError:
    return ConfigError(f"{why}: {token!r}", file=file, key=where)


def parse(text: str | int | float, allowed: set[str], *, where: str = "expression",
          file: str | None = None) -> Expr:
    """Parse and check ``text``; ``allowed`` are the names it may use (``pi`` is always allowed).
    Raises ConfigError naming the key (``where``) and the offending token."""
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ConfigError(f"expected an expression string, got {type(text).__name__}", file=file, key=where)
    if isinstance(text, float) and not math.isfinite(text):
        raise ConfigError(f"expected a finite number, got {text!r}", file=file, key=where)
    src = unicodedata.normalize("NFKC", str(text))
    if len(src) > MAX_CHARS:
        raise ConfigError(f"expression of {len(src)} characters; at most {MAX_CHARS} are allowed",
                          file=file, key=where)
    if not src.strip():
        raise ConfigError("empty expression", file=file, key=where)
    try:
        tree = parse_eval(src.strip()).body
    except SyntaxError as exc:
        raise ConfigError(f"cannot parse expression ({exc.msg})", file=file, key=where) from None
    except (RecursionError, MemoryError, ValueError):
        raise ConfigError(f"expression too large or nested too deeply to parse (at most {MAX_NODES} terms "
                          f"and operators, {MAX_DEPTH} levels)", file=file, key=where) from None
    names: set[str] = set()
    count = [0]

    def check(node: ast.AST, depth: int) -> None:
        count[0] += 1
        if count[0] > MAX_NODES:
            raise ConfigError(f"expression has more than {MAX_NODES} terms and operators", file=file, key=where)
        if depth > MAX_DEPTH:
            raise ConfigError(f"expression nested too deeply (at most {MAX_DEPTH} levels)", file=file, key=where)
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise _bad(where, repr(node.value), "only numbers are allowed as constants", file)
            try:
                ok = math.isfinite(float(node.value))
            except OverflowError:
                ok = False
            if not ok:
                txt = str(node.value)
                raise _bad(where, txt if len(txt) < 40 else txt[:20] + "...",
                           "number too large (not a finite double)", file)
        elif isinstance(node, ast.Name):
            if node.id in CONSTANTS:
                return
            if node.id not in allowed:
                raise _bad(where, node.id, f"unknown name (allowed: {', '.join(sorted(allowed))}, pi)", file)
            names.add(node.id)
        elif isinstance(node, ast.BinOp):
            if type(node.op) not in _BINOPS:
                raise _bad(where, type(node.op).__name__, "operator not allowed", file)
            # left-leaning chains (a + b + c ...) are iterated, not recursed, so long sums are fine
            chain = [node]
            while isinstance(chain[-1].left, ast.BinOp) and type(chain[-1].left.op) in _BINOPS:
                chain.append(chain[-1].left)
                count[0] += 1
                if count[0] > MAX_NODES:
                    raise ConfigError(f"expression has more than {MAX_NODES} terms and operators",
                                      file=file, key=where)
            check(chain[-1].left, depth + 1)
            for b in chain:
                check(b.right, depth + 1)
        elif isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.USub, ast.UAdd)):
                raise _bad(where, type(node.op).__name__, "operator not allowed", file)
            check(node.operand, depth + 1)
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                tok = node.func.id if isinstance(node.func, ast.Name) else _unparse(node.func)
                raise _bad(where, tok, f"unknown function (allowed: {', '.join(FUNCTIONS)})", file)
            if node.keywords:
                raise _bad(where, node.func.id, "keyword arguments are not allowed", file)
            arity = FUNCTIONS[node.func.id][0]
            if len(node.args) != arity:
                raise _bad(where, node.func.id, f"takes {arity} argument(s), got {len(node.args)}", file)
            for a in node.args:
                check(a, depth + 1)
        else:
            raise _bad(where, _unparse(node), f"{type(node).__name__} is not allowed in expressions", file)

    check(tree, 0)
    _check_constant_subexpressions(tree, where, file)
    return Expr(src, tree, frozenset(names))


def _unparse(node: ast.AST) -> str:
    try:
        txt = ast.unparse(node)
    except Exception:  # noqa: BLE001 - only used to name a token in a message
        txt = type(node).__name__
    return txt if len(txt) <= 60 else txt[:57] + "..."


def _has_name(node: ast.AST) -> bool:
    funcs = {id(n.func) for n in ast.walk(node) if isinstance(n, ast.Call)}
    return any(isinstance(n, ast.Name) and n.id not in CONSTANTS and id(n) not in funcs for n in ast.walk(node))


def _check_constant_subexpressions(tree: ast.expr, where: str, file: str | None) -> None:
    """Evaluate every maximal subexpression without names (numpy semantics); non-finite is an error."""
    todo = [tree]
    while todo:
        node = todo.pop()
        if not isinstance(node, ast.expr) or isinstance(node, (ast.Constant, ast.Name)):
            continue
        if not _has_name(node):
            with np.errstate(all="ignore"):
                try:
                    f = vectorize(Expr("", node, frozenset()), [])
                    val = float(np.asarray(f(), float))
                except (ArithmeticError, ValueError, TypeError):
                    val = float("nan")
            if not math.isfinite(val):
                raise ConfigError(f"the constant subexpression {_unparse(node)!r} is not a finite number",
                                  file=file, key=where)
            continue
        todo.extend(node.args if isinstance(node, ast.Call) else ast.iter_child_nodes(node))


_PREC = {ast.Add: 1, ast.Sub: 1, ast.Mult: 2, ast.Div: 2, ast.Pow: 4}


def to_source(expr: Expr | ast.expr, rename: dict[str, str] | None = None, *, scalar: bool = False) -> str:
    """Python source for the expression with names substituted by ``rename`` (e.g. ``k -> p[2]``).
    ``scalar=True`` emits code for numba scalar kernels (builtin min/max, clip via min/max).
    Constants are emitted as float literals, so numpy semantics hold (1/0 is inf, never an exception).
    Parentheses only where precedence needs them: left-leaning chains are emitted iteratively and flat."""
    rename = rename or {}
    node = expr.tree if isinstance(expr, Expr) else expr

    def prec(n: ast.AST) -> int:
        if isinstance(n, ast.BinOp):
            return _PREC[type(n.op)]
        if isinstance(n, ast.UnaryOp):
            return 3
        return 5

    def wrap(n: ast.AST, need: int) -> str:
        s = gen(n)
        return f"({s})" if prec(n) < need else s

    def gen(n: ast.AST) -> str:
        if isinstance(n, ast.Constant):
            return repr(float(n.value))
        if isinstance(n, ast.Name):
            if n.id in CONSTANTS and n.id not in rename:
                return repr(CONSTANTS[n.id])
            return rename.get(n.id, n.id)
        if isinstance(n, ast.BinOp):
            if isinstance(n.op, ast.Pow):
                r = n.right
                base = wrap(n.left, 5)
                if isinstance(r, ast.Constant) and float(r.value).is_integer() and abs(r.value) <= 16:
                    # integer exponent: numba/numpy use repeated multiplication instead of pow()
                    return f"{base} ** {int(r.value)}"
                return f"{base} ** {wrap(r, 4)}"
            # a left-leaning chain of the same precedence level, emitted without nesting
            chain = [n]
            while (isinstance(chain[-1].left, ast.BinOp) and not isinstance(chain[-1].left.op, ast.Pow)
                   and _PREC[type(chain[-1].left.op)] == _PREC[type(n.op)]):
                chain.append(chain[-1].left)
            lvl = _PREC[type(n.op)]
            parts = [wrap(chain[-1].left, lvl)]
            for b in reversed(chain):
                parts.append(f" {_BINOPS[type(b.op)]} {wrap(b.right, lvl + 1)}")
            return "".join(parts)
        if isinstance(n, ast.UnaryOp):
            return f"{'-' if isinstance(n.op, ast.USub) else '+'}{wrap(n.operand, 4)}"
        if isinstance(n, ast.Call):
            name = n.func.id
            args = [gen(a) for a in n.args]
            if name == "clip" and scalar:
                return f"min(max({args[0]}, {args[1]}), {args[2]})"
            if name == "step":
                return f"(1.0 if {args[0]} >= 0.0 else 0.0)" if scalar else f"np.heaviside({args[0]}, 1.0)"
            fn = FUNCTIONS[name][2 if scalar else 1]
            return f"{fn}({', '.join(args)})"
        raise TypeError(type(n).__name__)  # unreachable for checked expressions

    return gen(node)


_VECTORIZED: dict[tuple[str, tuple[str, ...]], object] = {}


def vectorize(expr: Expr, arg_names: list[str]):
    """A numpy function ``f(*arrays)`` evaluating ``expr`` elementwise (names bound positionally);
    cached by expression text and argument names (a checked text always gives the same function)."""
    key = (expr.text or ast.dump(expr.tree), tuple(arg_names))
    if key not in _VECTORIZED:
        src = f"def _f({', '.join(arg_names)}):\n    return {to_source(expr)}\n"
        scope: dict = {"np": np}
        exec(compile(src, "<expression>", "exec"), scope)  # source generated from a checked AST only
        _VECTORIZED[key] = scope["_f"]
    return _VECTORIZED[key]
