"""The intersample choice adds no parameter, so its likelihood-ratio row (q = 0) only says that the
weighted SSE fell; the estimation-part rule for equal parameter counts is ΔBIC < 0, with the BIC the
choice is ranked by (log det of the residual covariance). With several outputs the two can disagree:
on the independent bench a two-output record got an intersample finding with ΔBIC = +0.8.

The record is made here: a first-order system driven by a smooth input and simulated with the input
linearly interpolated between samples (scipy.signal.lsim, i.e. foh), configured as zoh."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.diagnostics import engine, intersample_stage
from pipeline.diagnostics.engine import Diagnoser
from pipeline.fit import fit_output_error
from pipeline.runs import analyse
from tests.diagnosis.first_order import problem


def _foh_record(tmp_path):
    rng = np.random.default_rng(5)
    n, dt = 1000, 0.1
    t = dt * np.arange(n)
    u = sum(rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
            for f in (0.05, 0.13, 0.31, 0.6, 1.1))
    _, y, _ = signal.lsim(signal.lti([2.0], [1.0, 2.0]), u, t, interp=True)
    y = y + 0.002 * np.std(y) * rng.standard_normal(n)
    return problem(tmp_path / "r", dt, u, y)


def _stage(prob, model):
    dg = Diagnoser(prob, alpha=0.01, families=[], max_findings=1, seed=0, dt=0.1)
    fit = fit_output_error(model, prob)
    with contextlib.redirect_stderr(io.StringIO()):
        return dg.inter.run(fit, np.random.default_rng(0))


def test_foh_is_chosen_when_it_lowers_the_bic(tmp_path):
    prob, model = _foh_record(tmp_path)
    _, finding, hist = _stage(prob, model)
    assert finding is not None and finding["chosen"] == "foh"
    assert finding["delta_bic"] < 0


def test_a_lower_sse_with_a_higher_bic_is_not_accepted(tmp_path, monkeypatch):
    """The same record with the BIC of every foh (and band-limited) fit raised above the zoh fit's (as a
    log-det BIC can rise on two outputs while the weighted SSE falls): the SSE still falls, the gain is
    still positive, and the choice is refused, with the reason."""
    prob, model = _foh_record(tmp_path)
    real = intersample_stage.bic_of
    monkeypatch.setattr(intersample_stage, "bic_of", lambda fit, searched=0: real(fit, searched)
                        + (1e6 if fit.model.intersample != "zoh" else 0.0))
    _, finding, hist = _stage(prob, model)
    assert finding is None
    row = next(r for r in hist["candidates"] if r["hypothesis"] == "foh")
    assert row["gain"]["ci95"][0] > 0 and row["delta_bic"] > 0
    assert not row["accepted"] and "BIC not lower" in row["reason"]


# A wrong foh on a held (PRBS) input is a lag of about half a sample: a fitted input delay or a one-step
# input lag mimics it within 1–2 BIC units at the price of a parameter. The physical cause is preferred
# only when its BIC beats the intersample choice by engine.INTERSAMPLE_TIE_BIC (10, Kass & Raftery's
# "very strong"), both with the round's effective sample size (Diagnoser.inter_wins). Records from the
# independent bench (solve_ivp on the held input, the config says foh); before the margin these were named input_delay (seed 1002) and unmodeled_dynamics (seed 1008).
@pytest.mark.parametrize("seed,magnitude", [(1002, "medium"), (1008, "small"), (1008, "medium")])
def test_intersample_preferred_to_a_delay_that_only_mimics_it(tmp_path, seed, magnitude):
    case = make_case("intersample", "pendulum", seed, magnitude=magnitude, noise=0.02, colour="ar0.9",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    assert case.truth["params"]["configured"] == "foh" and case.truth["params"]["chosen"] == "zoh"
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(Path(case.dir) / "config.yaml"))
    d = ctx.summary["diagnosis"]
    first = d["findings"][0]
    assert first["family"] == "intersample" and first["chosen"] == "zoh" and first["configured"] == "foh"
    # the delay was refitted and accepted as well: it lost on the margin, not on its own test
    cands = {c["hypothesis"]: c for c in ctx.diag.history[0]["candidates"]}
    rival = [c for k, c in cands.items() if k.startswith(("input_delay", "unmodeled_dynamics")) and c.get("accepted")]
    assert rival and all(c["delta_bic_eff"] > first["delta_bic_eff"] - engine.INTERSAMPLE_TIE_BIC for c in rival)
    # and the finding says so: the configured foh with half a sample more dead time is its runner-up, and
    # the description says that these data cannot tell the two apart
    twin = [r for r in first["runners_up"] if r["family"] == "input_delay"]
    assert len(twin) == 1 and abs(twin[0]["gain"]["relative"] - first["gain"]["relative"]) < 0.01
    assert "cannot tell a held input from a half-sample dead time" in first["description"]


def test_the_switch_and_a_lag_are_compared_with_the_effective_sample_size(tmp_path):
    """Test seed 1000 of the independent bench: a held input configured as foh, through the tank, 2 %
    AR(0.9) noise. A first-order lag of 0.7 samples fits the estimation part 34 raw BIC units better than
    the switch to zoh, but raw differences on this residual are about 19 times too large: with the
    effective sample size the lag is 1.7 units ahead, inside the 10 the switch is allowed, and the switch
    also has the larger validation gain. It was named the lag before."""
    case = make_case("intersample", "tank", 1000, magnitude="small", noise=0.02, colour="ar0.9",
                     input_kind="held", n=2000, out_dir=tmp_path)
    assert case.truth["params"]["configured"] == "foh" and case.truth["params"]["chosen"] == "zoh"
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(Path(case.dir) / "config.yaml"))
    first = ctx.summary["diagnosis"]["findings"][0]
    assert first["family"] == "intersample" and first["chosen"] == "zoh"
    cands = {c["hypothesis"]: c for c in ctx.diag.history[0]["candidates"]}
    lag = next(c for k, c in cands.items() if k.startswith("unmodeled_dynamics") and c.get("accepted"))
    # by raw ΔBIC the lag would have been chosen; with the effective sample size it is within the margin
    assert lag["delta_bic"] < first["delta_bic"] - engine.INTERSAMPLE_TIE_BIC
    assert lag["delta_bic_eff"] > first["delta_bic_eff"] - engine.INTERSAMPLE_TIE_BIC
    assert lag["gain"]["relative"] < first["gain"]["relative"]


def test_a_dead_time_the_validation_part_prefers_is_not_given_to_the_switch(tmp_path):
    """The other side (test seed 1001): a 3.6-sample dead time through the tank, a smooth input rightly
    configured as foh, 10 % AR(0.9) noise. A switch to zoh explains half a sample of the delay: 150 raw
    BIC units behind it, only 3.2 effective units. The validation part separates them (the delay's gain
    22 %, the switch's 5.7 %), so the delay is named."""
    case = make_case("input_delay", "tank", 1001, magnitude="medium", noise=0.1, colour="ar0.9",
                     input_kind="band", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(Path(case.dir) / "config.yaml"))
    d = ctx.summary["diagnosis"]
    assert d["findings"][0]["family"] == "input_delay"
    assert "intersample" not in [f["family"] for f in d["findings"]]
    rows = {c["hypothesis"]: c for c in ctx.diag.history[0]["candidates"]}
    switch, delay = rows["zoh"], rows["input_delay"]
    assert switch["accepted"] and delay["accepted"]
    # the raw margin alone would name the delay; the effective one would not (a switch's ΔBIC_eff is its
    # raw ΔBIC scaled by N_eff/N, the delay's with its parameter's ln N_eff): the validation part decides
    assert delay["delta_bic"] < switch["delta_bic"] - engine.INTERSAMPLE_TIE_BIC
    assert delay["gain"]["relative"] > switch["gain"]["relative"] + 0.1
