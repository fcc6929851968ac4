"""A family's representative whose refit fails from every start is replaced by the family's next
significant hypotheses (engine ``Diagnoser._alternates`` / ``_fallbacks``): the linearised share ranks
hypotheses only near the current fit, and the first can be one that cannot be simulated (c·h² with
c > 0 runs away on a tank whose outflow is sqrt(h))."""

import numpy as np

from pipeline.diagnostics.engine import Candidate, Diagnoser
from pipeline.diagnostics.families.base import Hypothesis
from pipeline.diagnostics.stats import WaldResult


def _w(r2: float, stat: float) -> WaldResult:
    return WaldResult(np.zeros(1), np.eye(1), stat, 1, 1e-9, r2)


def _h(key: str) -> Hypothesis:
    return Hypothesis("static_nonlinearity", key, coefs=["c"])


def _diagnoser() -> Diagnoser:
    return Diagnoser.__new__(Diagnoser)   # _alternates and _fallbacks read no state


def test_alternates_are_ranked_deduplicated_and_capped():
    rep, tie = _h("h**2"), _h("h*u")
    same = _h("h*abs(h)")                                  # h**2's own column on a positive level
    small = _h("u**2")
    others = [_h(f"g{i}") for i in range(4)]
    sig = [(rep, _w(0.75, 40.0)), (same, _w(0.75, 40.0)), (tie, _w(0.70, 38.0)), (small, _w(0.3, 9.0))]
    sig += [(h, _w(0.6 - 0.05 * i, 30.0 - i)) for i, h in enumerate(others)]
    alt = _diagnoser()._alternates(rep, sig[0][1], sig, [tie])
    # at least half the representative's share (0.375), largest first, at most three; not the tie, not
    # h**2's duplicate, not u**2 (0.3 < 0.375)
    assert [h.key for h, _ in alt] == ["g0", "g1", "g2"]


def test_a_failed_representative_gets_its_alternates_refitted_and_says_so():
    dg = _diagnoser()
    a1, a2 = _h("sqrt(h)"), _h("sqrt(u)")
    failed = Candidate(_h("h**2"), _w(0.75, 40.0), 1e-12, [], reason="refit failed from 1 x the test's estimate: "
                       "the model diverges", places=6)
    failed.alternates = [(a1, _w(0.5, 30.0)), (a2, _w(0.49, 29.0))]
    ok = Candidate(_h("x**2"), _w(0.7, 35.0), 1e-10, [], places=6)
    ok.fit = object()                                      # refitted: no fallback
    ok.alternates = [(_h("tanh(x)"), _w(0.6, 30.0))]
    rejected = Candidate(_h("y**2"), _w(0.7, 35.0), 1e-10, [], reason="not refitted: ...", places=6)
    rejected.alternates = [(_h("tanh(y)"), _w(0.6, 30.0))]  # screened out, not failed: no fallback
    extra = dg._fallbacks([failed, ok, rejected])
    assert [c.hyp for c in extra] == [a1, a2]
    assert all(c.runner_up and c.places == 6 and c.p_family == 1e-12 and c.fit is None for c in extra)
    assert "refitted instead: sqrt(h), sqrt(u)" in failed.reason
