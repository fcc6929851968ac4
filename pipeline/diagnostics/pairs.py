"""Two causes that hide each other: the joint added-term test of a pair of hypotheses.

On a mass–spring–damper with quadratic damping c_q·v|v| *and* Coulomb friction F_c·sgn(v), the
nominal model's refitted linear damping c·v absorbs most of either term alone: v|v| ≈ a·v − b·sgn(v)
over the record's velocities, so each term's added-term test, which projects out the current
parameters' sensitivities (Frisch–Waugh), sees only its small part outside span{v}. Neither test is
significant, yet together they remove most of the residual (an independent record, seed 2006 of
:mod:`pipeline.bench.two_causes`: the single shares 0.04 and 0.08, the pair's 0.68; the estimation RMSE
0.0118 → 0.0116 with v|v|, → 0.0107 with sgn v, → 0.0047 with both). This is *suppression* in regression
(Conger 1974; Cohen, Cohen, West & Aiken 2003, §3.4): the pair explains more than the sum of what its
members explain separately.

:func:`suppressed_pair` looks for it among the round's family representatives. The unfiltered
least-squares shares (the linearised refit's SSE drop, as :func:`stats.added_terms_test`'s ``share``)
of each member and of the pair are cheap; a pair is *suppressed* when its share is at least
``SYNERGY`` times the sum of its members'. The largest such pairs get the full added-term test
(:func:`stats.added_terms_test`, GLS + fixed-b HAC) on both members' columns, and its p-value is
multiplied by the number of hypothesis pairs the round could have formed (Σ m_a m_b over pairs of
families, m the number of a family's hypotheses): Bonferroni over *all* pairs bounds the size by α
whichever pairs were selected for the test (the selected ones are a subset of them).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Callable, Sequence

import numpy as np

from . import stats

SYNERGY = 2.0    # a pair is suppressed when it explains at least twice the sum of its members' shares
MAX_TESTS = 2    # the suppressed pairs explaining most get the full test, at most this many


@dataclass
class Member:
    """One family's representative hypothesis: its key, family, output sensitivities (n, q) and the
    number of hypotheses its family tested (its factor in the Bonferroni count)."""

    key: str
    family: str
    S: np.ndarray
    multiplicity: int


@dataclass
class Pair:
    a: int                      # indices into the members passed in
    b: int
    share: float                # the pair's unfiltered share of the residual's sum of squares
    shares: tuple[float, float]  # each member's alone
    wald: stats.WaldResult      # the joint added-term test
    n_pairs: int                # the Bonferroni count
    p_value: float              # min(1, wald.p_value · n_pairs)

    def detail(self, members: Sequence[Member]) -> str:
        a, b = members[self.a], members[self.b]
        return (f"{a.key} and {b.key} together explain {100 * self.share:.3g} % of the residual's sum of squares, "
                f"alone {100 * self.shares[0]:.3g} % and {100 * self.shares[1]:.3g} % (each is absorbed by the "
                f"current parameters); joint added-term Wald p {self.wald.p_value:.3g} x {self.n_pairs} "
                "hypothesis pairs (Bonferroni)")


def share(e: np.ndarray, S0: np.ndarray) -> float:
    """1 − ‖e − S0 β‖²/‖e‖², β the least-squares fit of e on S0 (columns already projected off J)."""
    ee = float(e @ e)
    if ee <= 0 or not S0.size:
        return 0.0
    r = e - S0 @ np.linalg.lstsq(S0, e, rcond=None)[0]
    return float(min(max(1.0 - float(r @ r) / ee, 0.0), 1.0))


def n_pairs(members: Sequence[Member]) -> int:
    """Σ over pairs of distinct families of m_a·m_b: the hypothesis pairs the round could form."""
    return int(sum(a.multiplicity * b.multiplicity for a, b in combinations(members, 2)
                   if a.family != b.family))


def suppressed_pair(e: np.ndarray, basis: np.ndarray | None, members: Sequence[Member], alpha: float,
                    test: Callable[[np.ndarray], stats.WaldResult]) -> Pair | None:
    """The suppressed pair (module docstring) with the smallest Bonferroni p-value below ``alpha``, or
    None. ``e``: the weighted estimation residual (stacked outputs); ``basis``: an orthonormal basis of
    the current parameters' sensitivities (:func:`stats.column_basis`); ``test``: the added-term test
    of stacked columns against the current fit."""
    e = np.asarray(e, float).ravel()
    proj = [m.S - basis @ (basis.T @ m.S) if basis is not None and basis.size else m.S for m in members]
    alone = [share(e, S0) for S0 in proj]
    found = []
    for i, j in combinations(range(len(members)), 2):
        if members[i].family == members[j].family:
            continue
        s = share(e, np.hstack([proj[i], proj[j]]))
        if s >= SYNERGY * (alone[i] + alone[j]) and s > 0:
            found.append((s, i, j))
    if not found:
        return None
    count = n_pairs(members)
    best = None
    for s, i, j in sorted(found, key=lambda x: (-x[0], x[1], x[2]))[:MAX_TESTS]:
        w = test(np.hstack([members[i].S, members[j].S]))
        p = min(1.0, w.p_value * count)
        if p < alpha and (best is None or p < best.p_value):
            best = Pair(i, j, s, (alone[i], alone[j]), w, count, p)
    return best
