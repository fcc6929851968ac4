"""The config's safe expression language (diagnosis contract §1).

Grammar: numbers, names (states, inputs, params, ``t``), ``+ - * / **``, unary minus, parentheses and
the functions ``sin cos tan exp log sqrt abs sign tanh sinh cosh arctan minimum maximum clip``.
Expressions are parsed with :mod:`ast` and checked node by node against that whitelist; they are never
passed to ``eval``. A checked expression is turned into Python *source* over plain names, which
:mod:`pipeline.simulate` compiles into a numba kernel and :func:`vectorize` into a numpy function.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass

import numpy as np

from .errors import ConfigError

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
}
_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


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
    """Parse and check ``text``; ``allowed`` are the names it may use. Raises ConfigError naming the
    key (``where``) and the offending token."""
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ConfigError(f"expected an expression string, got {type(text).__name__}", file=file, key=where)
    src = str(text)
    try:
        tree = ast.parse(src.strip(), mode="eval").body
    except SyntaxError as exc:
        raise ConfigError(f"cannot parse expression {src!r} ({exc.msg})", file=file, key=where) from None
    names: set[str] = set()

    def check(node: ast.AST) -> None:
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise _bad(where, repr(node.value), "only numbers are allowed as constants", file)
        elif isinstance(node, ast.Name):
            if node.id not in allowed:
                raise _bad(where, node.id, f"unknown name (allowed: {', '.join(sorted(allowed))})", file)
            names.add(node.id)
        elif isinstance(node, ast.BinOp):
            if type(node.op) not in _BINOPS:
                raise _bad(where, type(node.op).__name__, "operator not allowed", file)
            check(node.left)
            check(node.right)
        elif isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.USub, ast.UAdd)):
                raise _bad(where, type(node.op).__name__, "operator not allowed", file)
            check(node.operand)
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                tok = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
                raise _bad(where, tok, f"unknown function (allowed: {', '.join(FUNCTIONS)})", file)
            if node.keywords:
                raise _bad(where, node.func.id, "keyword arguments are not allowed", file)
            arity = FUNCTIONS[node.func.id][0]
            if len(node.args) != arity:
                raise _bad(where, node.func.id, f"takes {arity} argument(s), got {len(node.args)}", file)
            for a in node.args:
                check(a)
        else:
            tok = ast.unparse(node) if hasattr(ast, "unparse") else type(node).__name__
            raise _bad(where, tok, f"{type(node).__name__} is not allowed in expressions", file)

    check(tree)
    return Expr(src, tree, frozenset(names))


def to_source(expr: Expr | ast.expr, rename: dict[str, str] | None = None, *, scalar: bool = False) -> str:
    """Python source for the expression with names substituted by ``rename`` (e.g. ``k -> p[2]``).
    ``scalar=True`` emits code for numba scalar kernels (builtin min/max, clip via min/max)."""
    rename = rename or {}
    node = expr.tree if isinstance(expr, Expr) else expr

    def gen(n: ast.AST) -> str:
        if isinstance(n, ast.Constant):
            return repr(float(n.value))
        if isinstance(n, ast.Name):
            return rename.get(n.id, n.id)
        if isinstance(n, ast.BinOp):
            r = n.right
            if (isinstance(n.op, ast.Pow) and isinstance(r, ast.Constant) and float(r.value).is_integer()
                    and abs(r.value) <= 16):
                # integer exponent: numba/numpy use repeated multiplication instead of pow()
                return f"({gen(n.left)} ** {int(r.value)})"
            return f"({gen(n.left)} {_BINOPS[type(n.op)]} {gen(n.right)})"
        if isinstance(n, ast.UnaryOp):
            return f"({'-' if isinstance(n.op, ast.USub) else '+'}{gen(n.operand)})"
        if isinstance(n, ast.Call):
            name = n.func.id
            args = [gen(a) for a in n.args]
            if name == "clip" and scalar:
                return f"min(max({args[0]}, {args[1]}), {args[2]})"
            fn = FUNCTIONS[name][2 if scalar else 1]
            return f"{fn}({', '.join(args)})"
        raise TypeError(type(n).__name__)  # unreachable for checked expressions

    return gen(node)


_VECTORIZED: dict[tuple[str, tuple[str, ...]], object] = {}


def vectorize(expr: Expr, arg_names: list[str]):
    """A numpy function ``f(*arrays)`` evaluating ``expr`` elementwise (names bound positionally);
    cached by expression text and argument names (a checked text always gives the same function)."""
    key = (expr.text, tuple(arg_names))
    if key not in _VECTORIZED:
        src = f"def _f({', '.join(arg_names)}):\n    return {to_source(expr)}\n"
        scope: dict = {"np": np}
        exec(compile(src, "<expression>", "exec"), scope)  # source generated from a checked AST only
        _VECTORIZED[key] = scope["_f"]
    return _VECTORIZED[key]
