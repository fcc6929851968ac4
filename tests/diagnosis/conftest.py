"""Shared fixtures of the diagnosis tests."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pipeline.data import Split
from pipeline.diagnostics.engine import Diagnoser
from pipeline.diagnostics.families import FAMILY_IDS
from pipeline.expressions import parse
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model


@pytest.fixture(scope="module")
def linear_msd():
    """A linear mass–spring–damper record (scipy.signal.lsim, 1 % noise), its fitted nominal model, a
    Diagnoser over every family and its context: (diagnoser, fit, context)."""
    rng = np.random.default_rng(0)
    n, dt = 1500, 0.02
    t = np.arange(n) * dt
    u = signal.lfilter([0.05], [1, -0.95], rng.normal(size=n)) * 8
    sys = signal.StateSpace([[0, 1], [-4.0, -0.6]], [[0], [1]], [[1, 0]], [[0]])
    _, y, _ = signal.lsim(sys, u, t, interp=True)
    y = y + 0.01 * rng.normal(size=n)
    allowed = {"x", "v", "u", "c", "k", "t"}
    m = Model(("x", "v"), ("u",), {"x": parse("v", allowed), "v": parse("u - c*v - k*x", allowed)}, {},
              {"c": 0.5, "k": 3.5}, ("c", "k"), {"x": 0.0, "v": 0.0}, intersample="foh", nominal_params=("c", "k"))
    prob = Problem(t, u[:, None], y[:, None], ["x"], Split((0, 1000), (1000, n)), bound=1e6)
    fit = fit_output_error(m, prob)
    dg = Diagnoser(prob, alpha=0.01, families=list(FAMILY_IDS), max_findings=1, seed=0, dt=dt)
    ctx = dg.context(fit, 0.7)
    return dg, fit, ctx
