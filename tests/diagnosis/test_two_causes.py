"""Issue 8, two causes at once: both named within ``max_findings``.

Records made by ``pipeline.bench.two_causes.record`` (``scipy.integrate.solve_ivp`` on a continuous-time
input, a sum of sines), sharing no code with the detector; a mass–spring–damper
m x'' = F(u) − c x' − k x + effects:

* friction + offset, as on a real positioning stage: − Fc·sgn(x') + d (sgn(x') smoothed as tanh(x'/1e-3),
  as a real friction characteristic is);
* input saturation + cubic stiffness: F(u) = clip(u, −L, L) and − k3 x³;
* a dead zone + offset, and input saturation + offset: F(u) = sgn(u)·max(|u| − w, 0) or clip(u, −L, L),
  and + d. Each cause alone leaves the other's smooth misfit in the validation residual, so neither
  extension's gain has an interval above 0 on its own: both are named by the loop's look-ahead
  (``Diagnoser._lookahead``), and the offset must reach the refits at all (``engine._share``).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.two_causes import record
from pipeline.config import load_config
from pipeline.runs import analyse


def _diagnosis(path: Path) -> dict:
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(path)).summary["diagnosis"]


def _families(path: Path) -> list[str]:
    return [f["family"] for f in _diagnosis(path)["findings"]]


@pytest.mark.parametrize("seed", [1002, 1003])
def test_friction_and_offset_both_named(tmp_path, seed):
    """In open loop a constant force d and a sensor offset d/k differ only in the start transient
    (x(0) = 0 is known): either offset form counts as the offset (seed 1003 names the sensor form)."""
    fams = _families(record(tmp_path, f"friction-offset-{seed}", seed, fc=0.15, d=0.2))
    assert "coulomb_friction" in fams and ("offset" in fams or "output_offset" in fams)


@pytest.mark.parametrize("seed", [1002, 1003])
def test_saturation_and_cubic_stiffness_both_named(tmp_path, seed):
    fams = _families(record(tmp_path, f"sat-cubic-{seed}", seed, L=0.6, k3=3.0))
    assert "input_saturation" in fams and "cubic_stiffness" in fams


@pytest.mark.parametrize("seed", [1002, 1003])
def test_dead_zone_and_offset_both_named(tmp_path, seed):
    """A dead zone of ±0.15 on the input and a force offset 0.2. The offset's added-term test is weak
    after its GLS filter (a near-constant sensitivity is nearly differenced away: 2 % of the residual on
    one record, where its refit removes 74 %), so the refit screen must use the unfiltered share; and
    whichever cause comes first, its gain alone is not bounded (−115 % to +88 % for a 49 % point gain
    on another seed), so both are named through the look-ahead, each with its gain given the other."""
    d = _diagnosis(record(tmp_path, f"deadzone-offset-{seed}", seed, w=0.15, d=0.2))
    fams = [f["family"] for f in d["findings"]]
    assert "dead_zone" in fams and ("offset" in fams or "output_offset" in fams)
    dz = next(f for f in d["findings"] if f["family"] == "dead_zone")
    assert dz["width"] == pytest.approx(0.15, rel=0.2)
    first = d["history"][0]["candidates"]
    # the offset was refitted in the first round (not screened out on its GLS share)
    assert any(c["family"] == "offset" and c.get("gain") for c in first)


@pytest.mark.parametrize("seed", [1002, 1003, 2003, 2004])
def test_saturation_and_offset_both_named(tmp_path, seed):
    """Seeds 1002 and 1003 name both without the look-ahead; 2003 and 2004 are the records on which
    the need for it was found (input saturation first, +45.5 % alone with the interval −58 % to +81 %)."""
    fams = _families(record(tmp_path, f"sat-offset-{seed}", seed, L=0.6, d=0.2))
    assert "input_saturation" in fams and ("offset" in fams or "output_offset" in fams)


@pytest.mark.parametrize("seed", [2006, 2007, 2011, 2012])
def test_quadratic_damping_and_friction_that_hide_each_other_are_both_named(tmp_path, seed):
    """c_q·v|v| (c_q = 1) and F_c·sgn v (F_c = 0.15) in one record: the refitted linear damping absorbs
    either term alone (on seed 2006 the estimation RMSE goes 0.0118 → 0.0116 with v|v|, → 0.0107 with
    sgn v, → 0.0047 with both), so no added-term test is significant, or only the friction's, whose gain
    alone is negative (seed 2012: −13 %); nothing is pending for the look-ahead. The test of one given
    the other (``pipeline.diagnostics.pairs``) starts it; both are named with their values as estimated
    together, the first with the evidence of that test."""
    d = _diagnosis(record(tmp_path, f"quaddamping-friction-{seed}", seed, cq=1.0, fc=0.15))
    by = {f["family"]: f for f in d["findings"]}
    assert {"quadratic_damping", "coulomb_friction"} <= set(by)
    # the model's v' = (u - c*v - k*x)/m + coefficient*term, m = 1
    assert -by["quadratic_damping"]["coefficient"] == pytest.approx(1.0, rel=0.2)
    assert -by["coulomb_friction"]["coefficient"] == pytest.approx(0.15, rel=0.2)
    first = d["findings"][0]
    assert "gain_given" in first and first["gain_given"]["ci95"][0] > 0
    assert any(e["test"].startswith("pair_wald[") and e["p_value"] < 0.01 for e in first["evidence"])


def test_a_delay_the_estimation_part_ranks_behind_a_lag_is_named_by_the_validation_part(tmp_path):
    """A 5-sample input delay and a force offset (seed 2013, a fresh seed of the two-causes bench): the
    estimation part ranks a first-order lag 3.7 criterion units (12.5 raw BIC units) ahead of the delay,
    "positive" evidence only, while the delay's validation error is 13 % lower (interval 10 to 15 %).
    With the tie rule alone (2 units) the lag was named, then a switch to zoh stood in for the rest of the
    delay; the delay is named now (within 1.5 samples), with the offset, and the lag's history row says
    that the round took the delay."""
    d = _diagnosis(record(tmp_path, "delay+offset-2013", 2013, tau=0.1, d=0.2))
    fams = [f["family"] for f in d["findings"]]
    assert "input_delay" in fams and ({"offset", "output_offset"} & set(fams))
    assert "unmodeled_dynamics" not in fams and "intersample" not in fams
    f = next(f for f in d["findings"] if f["family"] == "input_delay")
    assert abs(f["delay_s"] - 0.1) <= 1.5 * 0.02
    lag = [c for h in d["history"] for c in h.get("candidates", []) if c["hypothesis"].startswith("unmodeled_dynamics:u")
           and c["accepted"]]
    assert lag and all("not taken" in c["reason"] and "took input_delay" in c["reason"] for c in lag)
