"""Term libraries that are linear in the parameters: y ≈ Σ θ_j φ_j(data).

A *term* is a named function of named signals (``x**3``, ``tanh(x)``, ``u(t-2)``, ``x*v``); a
:class:`Library` is an ordered list of distinct terms.  Libraries compose as in pysindy
(de Silva et al. 2020): ``A + B`` is the union (concatenation without duplicates) and ``A * B`` the
pairwise products (tensored library).  ``evaluate(data)`` gives the regressor matrix Φ (N × n_terms)
used by ERR/FROLS (Billings 2013, ch. 3), SINDy (Brunton et al. 2016) and plain least squares.

Names are parsed with :mod:`ast` against a whitelist — never ``eval`` — so candidate structures can
be written in a config as term lists, e.g. ``["tanh(x)", "1/(1+x**2)"]``.  Grammar: numbers,
variable names, ``+ - * / **``, unary minus, the functions in :data:`FUNCTIONS` and the lag syntax
``u(t-2)`` (signal ``u`` delayed by 2 samples; ``u(t)`` is ``u``).  ``t`` is the time column.
"""

from __future__ import annotations

import itertools
from typing import Iterable, Mapping, Sequence

import numpy as np

from pipeline.errors import InputError
from pipeline.structures.terms import Term, _Bin, _check_data, _fmt_num, _Num, _Var, parse_term

__all__ = ["Library", "Term", "parse_term", "from_terms", "poly", "tanh", "rational", "rbf", "sign", "saturation",
           "sinusoids", "lags", "narx", "fit_least_squares"]



class Library:
    """Ordered, duplicate-free list of terms; ``+`` union, ``*`` pairwise products (pysindy style)."""

    def __init__(self, terms: Iterable["Term | str"]):
        seen, out = set(), []
        for t in terms:
            t = parse_term(t)
            if t.name not in seen:
                seen.add(t.name)
                out.append(t)
        if not out:
            raise InputError("library is empty; expected at least one term (e.g. ['x', 'x**2'])")
        self.terms: list[Term] = out

    @property
    def names(self) -> list[str]:
        return [t.name for t in self.terms]

    @property
    def max_lag(self) -> int:
        return max(t.max_lag for t in self.terms)

    @property
    def variables(self) -> set[str]:
        return set().union(*[t.variables for t in self.terms])

    def __len__(self):
        return len(self.terms)

    def __iter__(self):
        return iter(self.terms)

    def __repr__(self):
        head = ", ".join(self.names[:8])
        return f"Library([{head}{', ...' if len(self) > 8 else ''}], n_terms={len(self)})"

    def __add__(self, other: "Library") -> "Library":
        return Library(self.terms + _as_library(other).terms)

    def __mul__(self, other: "Library") -> "Library":
        other = _as_library(other)
        prods, seen = [], set()
        for a in self.terms:
            for b in other.terms:
                pair = frozenset([a.name, b.name])
                if pair in seen:  # b*a duplicates a*b
                    continue
                seen.add(pair)
                prods.append(a * b)
        return Library(prods)

    def evaluate(self, data: Mapping[str, np.ndarray], drop_initial: bool = False) -> np.ndarray:
        """Regressor matrix Φ, shape (N, n_terms), float64, column-major (Fortran order).

        Delayed signals are NaN for the first ``max_lag`` rows; ``drop_initial=True`` removes those
        rows (N − max_lag rows are returned).
        """
        arrays, n = _check_data(data)
        missing = self.variables - set(arrays)
        if missing:
            raise InputError(
                f"library uses variable(s) {sorted(missing)} not in the data; available: {sorted(arrays)}"
            )
        start = self.max_lag if drop_initial else 0
        if start >= n:
            raise InputError(f"data has {n} samples; expected more than the library's max lag {self.max_lag}")
        out = np.empty((n - start, len(self.terms)), dtype=float, order="F")
        cache: dict = {}
        with np.errstate(all="ignore"):
            for j, t in enumerate(self.terms):
                node = t._node
                if isinstance(node, _Bin) and node.op == "*":  # product straight into its column
                    a = node.a.ev(arrays, n, cache)
                    b = node.b.ev(arrays, n, cache)
                    np.multiply(a[start:], b[start:], out=out[:, j])
                else:
                    out[:, j] = node.ev(arrays, n, cache)[start:]
        return out


def _as_library(x) -> Library:
    if isinstance(x, Library):
        return x
    if isinstance(x, (Term, str)):
        return Library([x])
    return Library(x)


def from_terms(term_names: Sequence[str]) -> Library:
    """Library from a list of term names (config entry point), e.g. ``["x", "x**2", "x**3"]``."""
    if isinstance(term_names, str):
        term_names = [term_names]
    return Library(term_names)


# ---------------------------------------------------------------------------------------- generators
def _vars(variables) -> list[Term]:
    if isinstance(variables, (str, Term)):
        variables = [variables]
    out = [parse_term(v) for v in variables]
    if not out:
        raise InputError("no variables given; expected at least one signal name such as 'x'")
    return out


def _monomial(factors: Sequence[Term]) -> Term:
    node = None
    for v, grp in itertools.groupby(factors, key=lambda t: t.name):
        p = len(list(grp))
        f = parse_term(v)._node
        f = f if p == 1 else _Bin("**", f, _Num(p))
        node = f if node is None else _Bin("*", node, f)
    return Term(node)


def poly(variables, degree: int, include_bias: bool = True, interactions: bool = True) -> Library:
    """All monomials of the variables up to ``degree`` (``1``, ``x``, ``v``, ``x**2``, ``x*v``, ...)."""
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree < 0:
        raise InputError(f"poly: degree = {degree!r}; expected a non-negative integer")
    vs = _vars(variables)
    terms: list[Term] = [Term(_Num(1))] if include_bias else []
    for d in range(1, degree + 1):
        if interactions:
            combos = itertools.combinations_with_replacement(vs, d)
        else:
            combos = ([v] * d for v in vs)
        terms.extend(_monomial(c) for c in combos)
    return Library(terms)


def tanh(variables) -> Library:
    """``tanh(x)`` for each variable."""
    return Library([f"tanh({v.name})" for v in _vars(variables)])


def rational(variables) -> Library:
    """``1/(1+x**2)`` for each variable."""
    return Library([f"1/(1+{_paren(v)}**2)" for v in _vars(variables)])


def _paren(v: Term) -> str:
    return v.name if isinstance(v._node, _Var) else f"({v.name})"


def _shift(v: Term, c: float) -> str:
    if c == 0:
        return v.name
    return f"{_paren(v)}{'-' if c > 0 else '+'}{_fmt_num(abs(c))}"


def rbf(variable, centres: Sequence[float], width: float = 1.0) -> Library:
    """Gaussian radial basis functions exp(−(x−c)²/w²) (textbook membership convention, eq. 2.164)."""
    (v,) = _vars(variable)
    if not width > 0:
        raise InputError(f"rbf: width = {width!r}; expected a positive number")
    den = "" if width == 1 else f"/{_fmt_num(width * width)}"
    terms = []
    for c in centres:
        inner = _shift(v, float(c))
        inner = f"({inner})" if c != 0 or not isinstance(v._node, _Var) else inner
        terms.append(f"exp(-{inner}**2{den})")
    return Library(terms)


def sign(variables, eps: float | None = None) -> Library:
    """``sign(x)`` or, with ``eps``, the smoothed sign ``tanh(x/eps)`` (Coulomb friction)."""
    vs = _vars(variables)
    if eps is None:
        return Library([f"sign({v.name})" for v in vs])
    if not eps > 0:
        raise InputError(f"sign: eps = {eps!r}; expected a positive smoothing width")
    return Library([f"tanh({_paren(v)}/{_fmt_num(eps)})" for v in vs])


def saturation(variables, limit: float = 1.0) -> Library:
    """Saturation ``clip(x,-a,a)``."""
    if not limit > 0:
        raise InputError(f"saturation: limit = {limit!r}; expected a positive number")
    a = _fmt_num(limit)
    return Library([f"clip({v.name},-{a},{a})" for v in _vars(variables)])


def sinusoids(omegas: Sequence[float], time: str = "t") -> Library:
    """``sin(w*t)`` and ``cos(w*t)`` for angular frequencies w (rad per unit of ``t``)."""
    terms = []
    for w in omegas:
        if not w > 0:
            raise InputError(f"sinusoids: frequency {w!r}; expected a positive angular frequency")
        arg = time if w == 1 else f"{_fmt_num(w)}*{time}"
        terms += [f"sin({arg})", f"cos({arg})"]
    return Library(terms)


def lags(signal: str, delays: Iterable[int] | int) -> Library:
    """Delayed samples ``u(t-1)``, ``u(t-2)``, ... (``delays`` an int n means 1..n)."""
    if isinstance(delays, (int, np.integer)):
        delays = range(1, int(delays) + 1)
    return Library([f"{signal}(t-{int(d)})" if d else f"{signal}(t)" for d in delays])


def narx(output: str, inputs: Sequence[str] | str, ny: int, nu: int, degree: int,
         include_bias: bool = True, input_delay: int = 1) -> Library:
    """Polynomial NARX candidates: monomials up to ``degree`` of y(t-1..t-ny) and u(t-d..t-d-nu+1)."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    vars_ = [f"{output}(t-{i})" for i in range(1, ny + 1)]
    for u in inputs:
        vars_ += [f"{u}(t-{i})" if i else f"{u}(t)" for i in range(input_delay, input_delay + nu)]
    return poly(vars_, degree, include_bias=include_bias)


def fit_least_squares(lib: Library, data: Mapping[str, np.ndarray], target: str) -> np.ndarray:
    """Least-squares coefficients of a declared structure y(t) ≈ Σ θ_j φ_j (e.g. model M1..M5).

    Rows where delayed regressors are undefined (the first ``max_lag``) are dropped.
    """
    lib = lib if isinstance(lib, Library) else Library(lib)
    if target not in data:
        raise InputError(f"target {target!r} is not in the data; expected one of {sorted(data)}")
    P = lib.evaluate(data, drop_initial=True)
    y = np.asarray(data[target], dtype=float)[lib.max_lag:]
    if P.shape[1] > P.shape[0]:
        raise InputError(f"{P.shape[1]} candidate terms for {P.shape[0]} samples; expected fewer terms than samples")
    bad = ~np.all(np.isfinite(P), axis=0)
    if bad.any():
        raise InputError(f"terms {[lib.names[j] for j in np.flatnonzero(bad)[:5]]} are not finite on the data; "
                         "expected finite regressors")
    return np.linalg.lstsq(P, y, rcond=None)[0]
