"""Issue 9 on the independent bench's records (``pipeline.bench.independent``: solve_ivp, effects
written out without the detector's classes), unseen seeds 1002–1004:

* out-of-vocabulary records (backlash, hysteresis, a wrong linear order, a nonlinearity x·exp(−x²)
  that no library holds, a cubic sensor law, a stiffness modulated in time, a slew-limited actuator)
  × 3 seeds: the final verdict is ``unexplained_discrepancy`` (a family that
  explains part of it may be listed as a partial finding); backlash and a missing mode on held-step
  inputs, whose smooth residuals an AR noise model would take, fail the input-direction and the
  input-residual coherence tests respectively;
* null records (7 base systems × noise levels × colours × 2 seeds = 42): at most 5 % false alarms,
  scored by the bench's own ``null_outcome`` (any finding the noise does not justify; coloured noise
  is justified on an AR record), and never an ``unexplained_discrepancy`` verdict counted as fine.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.diagnosis import null_outcome
from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse

OOV = ["backlash", "hysteresis", "wrong_order", "xexp", "sensor_law", "modulated_stiffness", "rate_limit"]
SEEDS = (1002, 1003, 1004)


def _summary(tmp_path: Path, family: str, base: str, seed: int, **kw) -> tuple[dict, dict]:
    case = make_case(family, base, seed, out_dir=tmp_path, **kw)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    return case.truth, s


# Out-of-vocabulary records still not called unexplained: none of these 21. They are caught by the
# input cross-correlation / model-error model, by significant added-term tests no extension explains
# (structural_wald), by the OE-vs-PEM Hausman test of the coloured-noise refit (hysteresis 1002), by the
# parameter-stability row (modulated_stiffness 1004, which had been named coloured noise), or
# (backlash 1004) because a structural test is still significant after the partial unmodeled_dynamics
# finding, which keeps the noise families from explaining the coloured rest.
# (Tried and not kept: a second-order model-error model found 11/12 with the old Newey-West test and
# false-alarmed on 11/42 null records; with the calibrated test it found 4/12; a held-out version did
# not separate them.)
KNOWN: dict = {}    # (family, seed) -> why it is not yet unexplained (a strict xfail)


def _oov(family, seed):
    if (family, seed) in KNOWN:
        return pytest.param(family, seed, marks=pytest.mark.xfail(strict=True, reason=KNOWN[(family, seed)]))
    return pytest.param(family, seed)


@pytest.mark.slow
@pytest.mark.parametrize("family,seed", [_oov(f, s) for f in OOV for s in SEEDS])
def test_out_of_vocabulary_is_unexplained(tmp_path, family, seed):
    _, s = _summary(tmp_path, family, "msd", seed)
    assert s["diagnosis"]["verdict"] == "unexplained_discrepancy"
    assert s["diagnosis"]["unexplained"]["failed_tests"]          # and says where it fails
    # and why no cause is named: the refits it lists are the last round's, each lowering the validation
    # error and not accepted (pipeline.diagnostics.why)
    why = s["diagnosis"]["unexplained"]["why"]
    assert why["sentence"]
    last = s["diagnosis"]["history"][-1]["candidates"]
    for r in why["refitted"]:
        c = next(c for c in last if r["hypothesis"].endswith(c["hypothesis"]))
        assert not c["accepted"] and c["gain"]["relative"] == r["relative"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("base", ["msd", "pendulum", "dcmotor"])
@pytest.mark.parametrize("seed", SEEDS)
def test_backlash_on_held_steps_is_unexplained_not_coloured_noise(tmp_path, base, seed):
    """A play in the actuator driven by held steps leaves a smooth residual that the linear tests miss
    and an AR noise model would take (on the tuning seeds, 4 of 6 such records ended "colored_noise");
    the input-direction adequacy test names where it fails."""
    _, s = _summary(tmp_path, "backlash", base, seed, input_kind="held")
    d = s["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    assert "colored_noise" not in [f["family"] for f in d["findings"]]
    assert any(t.startswith("input_direction") for t in d["unexplained"]["failed_tests"])


@pytest.mark.slow
@pytest.mark.parametrize("base", ["tank", "dcmotor"])
@pytest.mark.parametrize("seed", SEEDS)
def test_missing_mode_on_held_steps_fails_the_coherence_test(tmp_path, base, seed):
    """A wrong linear order (an extra lightly damped mode, ω = 3/τ, ζ = 0.05) driven by held steps rings
    at lags beyond the cross-correlation and FIR tests; on the tuning seeds 2 of 6 such records ended
    "colored_noise". The input-residual coherence names where the model fails, and the noise families
    are not run on it."""
    _, s = _summary(tmp_path, "wrong_order", base, seed, input_kind="held")
    d = s["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    assert "colored_noise" not in [f["family"] for f in d["findings"]]
    assert any(t.startswith("input_coherence") for t in d["unexplained"]["failed_tests"])


NULL_GRID = [(base, noise, colour, seed)
             for base in ("msd", "pendulum", "tank", "dcmotor", "dcmotor2", "twomode", "mimo")
             for noise, colour in ((0.02, "white"), (0.1, "white"), (0.05, "ar0.5"))
             for seed in (1002, 1003)]


@pytest.mark.slow
def test_null_records_false_alarm_rate_at_most_5_percent(tmp_path):
    alarms = []
    for k, (base, noise, colour, seed) in enumerate(NULL_GRID):
        truth, s = _summary(tmp_path / str(k), "none", base, seed, noise=noise, colour=colour)
        out = null_outcome(truth, s["diagnosis"]["findings"])
        if out["any_false_alarm"] or s["diagnosis"]["verdict"] == "unexplained_discrepancy":
            alarms.append((base, noise, colour, seed, s["diagnosis"]["verdict"],
                           [f["family"] for f in s["diagnosis"]["findings"]]))
    assert len(NULL_GRID) >= 40
    assert len(alarms) <= 0.05 * len(NULL_GRID), alarms
