"""``unmodeled_dynamics``' coupled-state form: where it is proposed, and which refits it keeps.

The refit is replaced here by a stub returning chosen values, so each guard of
``UnmodeledDynamics.estimate`` is exercised by itself: a time constant below half a sample (the DaISy
dryer's τ = 0.09 samples, cτ = −0.92: a rescaled time derivative), above half the estimation window
(an offset or a drift), a coupling not positive (not a passive storage). The named behaviour on
records (12/12 right on solve_ivp records) is in ``test_families_independent.py``."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.diagnostics.engine import Candidate
from pipeline.diagnostics.families import REGISTRY
from pipeline.diagnostics.families.base import Context, Structure
from pipeline.expressions import parse
from pipeline.model import Model

DT = 0.1


def _ctx():
    allowed = {"x", "v", "u", "c", "k", "t"}
    m = Model(("x", "v"), ("u",), {"x": parse("v", allowed), "v": parse("u - c*v - k*x", allowed)}, {},
              {"c": 0.5, "k": 4.0}, ("c", "k"), {"x": 0.0, "v": 0.0}, intersample="foh", nominal_params=("c", "k"))
    n = 200
    t = np.arange(n) * DT
    return Context(m, Structure.of(m), t, np.zeros((n, 1)), np.zeros((n, 1)), ["x"],
                   np.ones((n, 2)), (0, 140), DT)


def test_the_coupled_state_is_proposed_in_each_dynamic_equation_on_its_own_state():
    """x' = v is kinematic: only v gets a coupled state (and the input its lag), five τ each."""
    hyps = REGISTRY["unmodeled_dynamics"].hypotheses(_ctx())
    coupled = [h for h in hyps if h.info["kind"] == "coupled_state"]
    assert {(h.equation, h.state) for h in coupled} == {("v", "v")}
    assert len(coupled) == 5 and len(hyps) == 10
    assert all(h.terms[0].label == f"({h.info['state']} - v)" for h in coupled)


@pytest.mark.parametrize("tau,c,kept,why", [
    (0.5, 2.0, True, None),
    (0.009, -120.0, False, "below half a sample"),
    (8.0, 2.0, False, "above half the estimation window"),
    (0.5, -0.3, False, "not a passive storage"),
])
def test_a_refitted_coupled_state_is_kept_only_where_it_is_one(tau, c, kept, why):
    fam = REGISTRY["unmodeled_dynamics"]
    hyp = next(h for h in fam.hypotheses(_ctx()) if h.info["kind"] == "coupled_state")
    refit = SimpleNamespace(model=SimpleNamespace(params={hyp.info["tau_name"]: tau, hyp.coefs[0]: c}))
    dg = SimpleNamespace(refit=lambda fit, cand: refit, dt=DT,
                         prob=SimpleNamespace(split=SimpleNamespace(est=(0, 140))))   # a 14 s window
    cand = Candidate(hyp, None, 0.0, [])
    got = fam.estimate(dg, None, cand)
    assert (got is refit) == kept
    if why:
        assert cand.reason.startswith("refit rejected: ") and why in cand.reason
