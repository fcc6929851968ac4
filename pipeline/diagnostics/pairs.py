"""Two causes that hide each other: the added-term test of one hypothesis given another.

On a mass–spring–damper with quadratic damping c_q·v|v| *and* Coulomb friction F_c·sgn(v), the
nominal model's refitted linear damping c·v absorbs most of either term alone: v|v| ≈ a·v − b·sgn(v)
over the record's velocities, so each term's added-term test, which projects out the current
parameters' sensitivities (Frisch–Waugh), sees only its small part outside span{v}. Neither test is
significant, yet together they remove most of the residual (an independent record, seed 2006 of
:mod:`pipeline.bench.two_causes`: the single shares 0.04 and 0.17, the pair's 0.80; the estimation RMSE
0.0118 → 0.0116 with v|v|, → 0.0107 with sgn v, → 0.0047 with both). This is *suppression* in regression
(Conger 1974; Cohen, Cohen, West & Aiken 2003, §3.4): with a in the model, b explains more than it
does alone. The same happens when a is strong: friction alone explaining 57 % of the residual with its
validation gain negative (−13 %), and v|v| explaining 9 % alone but 28 % more given the friction.

:func:`hidden_pairs` looks for it among the round's family representatives. The unfiltered
least-squares shares (the linearised refit's SSE drop, as :func:`stats.added_terms_test`'s ``share``)
are cheap: R²_b alone, R²_a alone and R²_ab together. An ordered pair (a, b) is *revealing* when
b's share given a, R²_ab − R²_a, is at least ``SYNERGY`` times R²_b (a's presence changes what b
explains, which two additive causes do not do: there R²_ab ≈ R²_a + R²_b). The ones with the largest
share given a get the full added-term test of b given a (:func:`stats.added_terms_test`, GLS +
fixed-b HAC, with a's columns beside the current parameters' and the residual with a's least-squares
part removed, the restricted residual of the score form), and its p-value is multiplied by 2F·m_a·m_b,
F the number of pairs of families and m a family's number of hypotheses: a weighted Bonferroni
correction over *every* ordered hypothesis pair the round could have formed (each ordered pair of
families gets α/2F, shared equally among its m_a·m_b hypothesis pairs; the weights sum to one, so the
union bound holds: Rosenthal & Rubin 1983; Westfall & Young 1993, §2.4). It bounds the size by α
whichever pairs the screen selected, as those are among them. The weights mirror the single tests
(Holm across families, Bonferroni within one): a jump's grid of 200 dates does not dilute the test of
two one-place terms (a plain count of hypothesis pairs, Σ m_a·m_b, was 180 000 on the mass–spring–damper
and left a pair with joint p = 6·10⁻⁸ not significant).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations
from typing import Sequence

import numpy as np

from . import stats

SYNERGY = 2.0    # b given a explains at least twice b's share alone
MAX_TESTS = 3    # the revealing pairs whose b explains most given a get the full test, at most this many


@dataclass
class Member:
    """One family's representative hypothesis: its key, family, output sensitivities (n, q) and the
    number of hypotheses its family tested (its factor in the Bonferroni correction)."""

    key: str
    family: str
    S: np.ndarray
    multiplicity: int


@dataclass
class Pair:
    a: int                      # indices into the members passed in: b is tested given a
    b: int
    shares: tuple[float, float, float]   # R²_a, R²_b alone and R²_ab together (unfiltered)
    wald: stats.WaldResult      # the added-term test of b given a
    factor: int                 # the weighted Bonferroni factor 2F·m_a·m_b
    p_value: float              # min(1, wald.p_value · factor)

    def detail(self, members: Sequence[Member]) -> str:
        a, b = members[self.a], members[self.b]
        ra, rb, rab = self.shares
        return (f"{b.key} explains {100 * rb:.3g} % of the residual's sum of squares alone and "
                f"{100 * (rab - ra):.3g} % more with {a.key} ({100 * ra:.3g} % alone; together {100 * rab:.3g} %); "
                f"its added-term Wald p given {a.key} is {self.wald.p_value:.3g} x {self.factor} (Bonferroni over "
                "the round's ordered hypothesis pairs, each ordered pair of families with an equal share of α)")


def share(e: np.ndarray, S0: np.ndarray) -> float:
    """1 − ‖e − S0 β‖²/‖e‖², β the least-squares fit of e on S0 (columns already projected off J)."""
    ee = float(e @ e)
    if ee <= 0 or not S0.size:
        return 0.0
    r = e - S0 @ np.linalg.lstsq(S0, e, rcond=None)[0]
    return float(min(max(1.0 - float(r @ r) / ee, 0.0), 1.0))


def n_family_pairs(members: Sequence[Member]) -> int:
    """F, the number of pairs of distinct families among the members (one member per family)."""
    fams = sorted({m.family for m in members})
    return len(fams) * (len(fams) - 1) // 2


def factor(members: Sequence[Member], i: int, j: int) -> int:
    """The weighted Bonferroni factor of the ordered pair (i, j): 2F·m_i·m_j (module docstring)."""
    return 2 * n_family_pairs(members) * members[i].multiplicity * members[j].multiplicity


def given(e: np.ndarray, J: np.ndarray, Sa: np.ndarray, Sb: np.ndarray) -> stats.WaldResult:
    """The added-term test of Sb with Sa beside the current parameters' J: e with its least-squares part
    on Sa⊥ = (I − J J⁺) Sa removed is the residual of the model with a (linearised), the restricted
    residual of the score form :func:`stats.added_terms_test` expects."""
    Ja = np.hstack([J, Sa]) if J.size else Sa
    basis = stats.column_basis(Ja)
    ea = e - basis @ (basis.T @ e)
    return stats.added_terms_test(ea, Ja, Sb, basis=basis)


def hidden_pairs(e: np.ndarray, J: np.ndarray, basis: np.ndarray | None, members: Sequence[Member],
                 alpha: float) -> list[Pair]:
    """The revealing ordered pairs (module docstring) whose test of b given a is significant after the
    weighted Bonferroni correction, smallest p first (ties by order). ``e``: the weighted estimation
    residual (stacked outputs); ``J``: the current parameters' sensitivities at the same rows;
    ``basis``: :func:`stats.column_basis` of J."""
    e = np.asarray(e, float).ravel()
    J = np.asarray(J, float).reshape(len(e), -1)
    proj = [m.S - basis @ (basis.T @ m.S) if basis is not None and basis.size else m.S for m in members]
    alone = [share(e, S0) for S0 in proj]
    together: dict[tuple[int, int], float] = {}
    found = []
    for i, j in permutations(range(len(members)), 2):
        if members[i].family == members[j].family:
            continue
        key = (min(i, j), max(i, j))
        if key not in together:
            together[key] = share(e, np.hstack([proj[i], proj[j]]))
        more = together[key] - alone[i]
        if more > 0 and more >= SYNERGY * alone[j]:
            found.append((more, i, j))
    out = []
    for _, i, j in sorted(found, key=lambda x: (-x[0], x[1], x[2]))[:MAX_TESTS]:
        w = given(e, J, members[i].S, members[j].S)
        f = factor(members, i, j)
        p = min(1.0, w.p_value * f)
        if p < alpha:
            out.append(Pair(i, j, (alone[i], alone[j], together[(min(i, j), max(i, j))]), w, f, p))
    return sorted(out, key=lambda x: x.p_value)
