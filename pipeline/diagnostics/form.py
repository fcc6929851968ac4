"""Is a static nonlinearity one of the library's forms, or a form no single term holds?

The static families name a *form*: ``cubic_stiffness`` is k3·x³, ``static_nonlinearity`` one term of a
library (tanh(x/L), x·|x|, √x, x², …). When the loop accepts a library term and then, in a later round,
another static term in the **same state and the same equation**, the data have rejected the first form
for that nonlinearity: the later extension was accepted against the model holding the first one by the
held-out gain test and the likelihood-ratio test (:func:`.refit_criteria.lr_against`, effective sample size).
That is a test of "the nonlinearity in x is f₁(x)" at level α, and the sum the loop built (tanh + x³ +
x·|x| for a softening-then-reversing spring x·exp(−x²/x₀²)) is a series approximation of an unknown
function, not two or three causes. A careful analyst would write "a nonlinearity in x of a form the
library does not hold, approximated by …", which is the contract's ``unexplained_discrepancy`` with the
terms as partial findings (issue 9: "a family that explains part of it may be listed as a partial
finding, but the verdict … says that the model still fails").

Only groups holding a ``static_nonlinearity`` term count: Coulomb friction plus quadratic damping on the
same velocity (sign(v) and v·|v|) are two named physical causes that often act together, and neither is
a library form chosen among many.

The row is an adequacy row (:mod:`.adequacy`): ``p_value`` is the likelihood-ratio p of the first later
term in the group, ``r2`` the share of the estimation residual sum of squares (weighted, as fitted) that
the later terms removed, so the row fails adequacy only when that share is material (``MATERIAL_R2``),
as every other row.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass

from ..expressions import CONSTANTS, FUNCTIONS, parse_eval
from . import stats

STATIC_FORMS = ("static_nonlinearity", "cubic_stiffness", "quadratic_damping", "coulomb_friction")
LIBRARY = "static_nonlinearity"


@dataclass(frozen=True)
class Accepted:
    """One accepted extension, as the form test needs it."""

    family: str
    equation: str | None
    term: str | None
    lr_p: float           # likelihood-ratio p of this extension against the model before it
    lr_statistic: float
    sse_before: float     # weighted estimation SSE of the model before and after this extension
    sse_after: float


def variables(term: str | None) -> tuple[str, ...]:
    """The names a term's expression uses, the whitelisted functions and constants left out (e.g.
    tanh(x/0.6) → (x,)); read from the expression's own syntax tree, so 1e-05 is a number, not a name."""
    if not term:
        return ()
    try:
        tree = parse_eval(term)
    except SyntaxError:
        return ()
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    return tuple(sorted(names - set(FUNCTIONS) - set(CONSTANTS)))


def _share(group: list[Accepted]) -> float:
    """The share of the residual sum of squares the group's later terms removed."""
    return 1.0 - group[-1].sse_after / group[1].sse_before


def form_test(accepted: list[Accepted]) -> stats.TestResult | None:
    """The ``nonlinearity_form`` row, or None when no state has two static forms in one equation."""
    groups: dict[tuple, list[Accepted]] = {}
    for a in accepted:
        v = variables(a.term) if a.family in STATIC_FORMS else ()
        if len(v) == 1:
            groups.setdefault((a.equation, v[0]), []).append(a)
    hits = [(k, g) for k, g in groups.items() if len(g) >= 2 and any(a.family == LIBRARY for a in g)]
    if not hits:
        return None
    # the group whose later terms removed the largest share of the residual
    (eq, var), g = max(hits, key=lambda kg: _share(kg[1]))
    r2 = _share(g)
    terms = " + ".join(a.term for a in g)
    return stats.TestResult(
        "nonlinearity_form", float(g[1].lr_statistic), float(g[1].lr_p), None, False,
        f"the nonlinearity in {var} in the equation of {eq} is not one library form: after "
        f"{g[0].term} ({g[0].family}) the data still needed {', '.join(a.term for a in g[1:])} "
        f"(likelihood-ratio p = {g[1].lr_p:.3g}; {100 * r2:.2g} % of the residual); the sum {terms} "
        "approximates a function of a form the library does not hold", r2=float(r2))
