"""Which fired candidates the engine refits (Diagnoser._screen): the largest linearised shares, at most
MAX_REFITS families; a family's near-tie runner-up comes with its representative and takes no other
family's place (a two-mode record lost its cubic stiffness when two runner-ups filled the slots)."""

from __future__ import annotations

from types import SimpleNamespace

from pipeline.diagnostics.engine import MAX_REFITS, Candidate, Diagnoser
from pipeline.diagnostics.families import Hypothesis


def _cand(family: str, share: float, runner_up: bool = False, r2: float | None = None) -> Candidate:
    """A fired candidate whose added terms remove ``share`` of the residual (unfiltered) and ``r2`` of the
    GLS-filtered one (the same unless given)."""
    w = SimpleNamespace(r2=share if r2 is None else r2, share=share)
    return Candidate(Hypothesis(family, f"{family}:{share}"), w, 0.0, [], runner_up=runner_up)


def test_runner_ups_do_not_take_the_place_of_other_families():
    fams = ["static_nonlinearity", "periodic_disturbance", "cubic_stiffness", "state_saturation", "dead_zone"]
    todo = [_cand(fams[0], 0.23), _cand(fams[0], 0.22, True), _cand(fams[1], 0.20), _cand(fams[1], 0.20, True),
            _cand(fams[2], 0.15), _cand(fams[3], 0.11), _cand(fams[4], 0.019)]
    kept = Diagnoser._screen(todo)
    primaries = [c.hyp.family for c in kept if not c.runner_up]
    assert primaries == fams[:MAX_REFITS]                     # the 4 largest shares, cubic stiffness included
    assert sorted(c.hyp.family for c in kept if c.runner_up) == sorted(fams[:2])
    assert "under 0.2" in todo[-1].reason


def test_a_runner_up_of_a_family_not_refitted_is_not_refitted():
    todo = [_cand("offset", 0.9), _cand("cubic_stiffness", 0.1), _cand("cubic_stiffness", 0.09, True)]
    kept = Diagnoser._screen(todo)
    assert [c.hyp.family for c in kept] == ["offset"]
    assert todo[2].reason == "not refitted: its family's representative was not refitted"


def test_the_screen_ranks_by_the_unfiltered_share_not_the_gls_one():
    """A force offset beside an input dead zone (an independent record): the GLS filter nearly differences
    the offset's near-constant sensitivity (2.1 % of the filtered residual) while a least-squares step on
    the residual itself removes 74 %; ranked by the filtered share it fell under a fifth of the dead
    zone's 25 % and was never refitted."""
    todo = [_cand("dead_zone", 0.30, r2=0.25), _cand("offset", 0.74, r2=0.021), _cand("cubic_stiffness", 0.063, r2=0.014)]
    kept = Diagnoser._screen(todo)
    assert sorted(c.hyp.family for c in kept) == ["dead_zone", "offset"]
    assert todo[2].reason.startswith("not refitted: its added terms explain 6.3 % of the residual, under 0.2 x the 74 %")
