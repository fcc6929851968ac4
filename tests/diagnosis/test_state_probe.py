"""The ``state_nonlinearity`` adequacy row (pipeline/diagnostics/state_probe.py): Gaussian bumps of each
state in the equations that use it, tested jointly by the added-term test.

Records from the independent bench (solve_ivp; the spring force written out by hand there, not with
this project's model classes), test seeds: an x·exp(−x²) spring, a law no family's library holds,
ended ``colored_noise`` on white-noise records because no structural test was significant and the
smooth residual it leaves looked like coloured noise. Correct models (null records, white and AR
noise) must not fail the row."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.diagnostics.adequacy import MATERIAL_R2
from pipeline.diagnostics.families.base import Structure
from pipeline.diagnostics.state_probe import K, NAME, probe_hypotheses
from pipeline.runs import analyse


def _run(case):
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(Path(case.dir) / "config.yaml"))


# seeds outside the bench's tuning (0-2) and test (1000-1002) sets; on seeds 2000-2007 of these three
# settings the probe moved exactly these two of 24 records to ``unexplained_discrepancy`` and no other
# (the second record, pendulum band small 10 % noise seed 2003, is explained to the noise level by one
# tanh(th/s) since its knee is fitted: test_nonlinearity_form checks it is named only there)
@pytest.mark.parametrize("base,input_kind,magnitude,noise,seed,before", [
    ("msd", "prbs", "large", 0.02, 2005, "colored_noise")])
def test_an_out_of_library_spring_is_unexplained(tmp_path, base, input_kind, magnitude, noise, seed, before):
    """Before the probe: ``colored_noise`` (white noise!) and a partial ``static_nonlinearity`` finding
    with verdict ``discrepancy``. A partial finding may stay listed; the verdict must say unexplained."""
    case = make_case("xexp", base, seed, magnitude=magnitude, noise=noise, colour="white", input_kind=input_kind,
                     n=2000, out_dir=tmp_path)
    assert case.truth["kind"] == "out_of_vocabulary"
    d = _run(case).summary["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    assert "colored_noise" not in [f["family"] for f in d["findings"]]
    row = next(t for t in d["adequacy"] if t["name"] == NAME)
    assert not row["passed"] and row["explained_share"] >= MATERIAL_R2
    eq = "v" if base == "msd" else "w"
    assert f"equation of {eq}" in row["detail"]


@pytest.mark.parametrize("base,colour,input_kind", [("msd", "white", "band"), ("msd", "ar0.9", "held"),
                                                    ("pendulum", "ar0.5", "band"), ("tank", "white", "held"),
                                                    ("dcmotor", "ar0.9", "band"), ("twomode", "white", "band")])
def test_correct_models_pass_the_probe(tmp_path, base, colour, input_kind):
    case = make_case("none", base, 1001, noise=0.1, colour=colour, input_kind=input_kind, n=2000, out_dir=tmp_path)
    ctx = _run(case)
    row = next(t for t in ctx.summary["diagnosis"]["adequacy"] if t["name"] == NAME)
    assert row["passed"] or row["explained_share"] < MATERIAL_R2


def test_probe_hypotheses_sit_in_the_dynamic_equations(tmp_path, monkeypatch):
    """On a mass-spring-damper (x' = v, v' = …) the probe tests bumps of x and of v in the equation of v
    only (no term in the kinematic equation x' = v), K coefficients each, and a gain and K bumps of the
    measured state x added to its output (a sensor's static law)."""
    from pipeline.diagnostics import engine
    seen = {}
    real = engine.Diagnoser.run

    def run(self, model, start=None):
        seen["dg"], seen["d"] = self, real(self, model, start)
        return seen["d"]

    monkeypatch.setattr(engine.Diagnoser, "run", run)
    _run(make_case("none", "msd", 1000, n=2000, out_dir=tmp_path))
    hyps = probe_hypotheses(seen["dg"].context(seen["d"].final, None))
    assert sorted(h.key for h in hyps) == [f"{NAME}:output:x", f"{NAME}:v:v", f"{NAME}:v:x"]
    dyn = [h for h in hyps if h.output is None]
    assert all(len(h.coefs) == K and len(h.terms) == K and h.equation == "v" for h in dyn)
    out = next(h for h in hyps if h.output == "x")
    assert len(out.coefs) == K + 1 and all(t.is_output and t.target == "x" for t in out.terms)
    assert out.terms[0].text == "x"                      # the gain
    assert Structure.of(seen["d"].final.model).dynamic_eqs == ["v"]


# fresh seeds (outside the bench's sets); before the refitted probe both ended ``colored_noise`` on
# white noise: the linearised probe had p = 0.056 and 0.21 on residuals with lag-1 autocorrelation ~0.99.
# Since the five bumps' test refers to the joint degrees of freedom of its long-run covariance
# (hac.joint_design_dof) instead of the smallest column's, the linearised probe sees the PRBS record itself
# (p = 0.0045, 2.5 % of the residual: material), and the refit is not needed there.
@pytest.mark.parametrize("input_kind,seed,linear_sees_it", [("prbs", 2201, True), ("band", 2202, False)])
def test_a_smooth_residual_the_refitted_probe_explains_is_not_called_coloured_noise(tmp_path, input_kind, seed,
                                                                                     linear_sees_it):
    case = make_case("xexp", "msd", seed, magnitude="large", noise=0.02, colour="white", input_kind=input_kind,
                     n=2000, out_dir=tmp_path)
    d = _run(case).summary["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    assert "colored_noise" not in [f["family"] for f in d["findings"]]
    lin = next(t for t in d["adequacy"] if t["name"] == NAME)
    if linear_sees_it:
        assert not lin["passed"] and lin["explained_share"] >= MATERIAL_R2
        assert any(t.startswith(NAME + ":") for t in d["unexplained"]["failed_tests"])
        return
    assert lin["passed"]                      # the linearised probe alone did not see it
    row = next(t for t in d["adequacy"] if t["name"] == NAME + "_refit")
    assert not row["passed"] and row["explained_share"] >= MATERIAL_R2
    assert row["detail"].startswith("a static function of x that no family's term holds acts in the equation of v")
    assert "validation RMSE (free run)" in row["detail"]
    # the noise families were not run on a structure that misfits
    nf = {t["name"]: t for t in d["final_tests"] if t["on"].endswith("(noise families)")}
    assert nf["colored_noise"]["detail"].startswith("not tested")


@pytest.mark.parametrize("base,input_kind,noise", [("msd", "band", 0.02), ("dcmotor", "held", 0.02),
                                                   ("pendulum", "band", 0.1)])
def test_coloured_noise_on_a_correct_model_is_still_named(tmp_path, monkeypatch, base, input_kind, noise):
    """AR(0.9) noise on a correct model: the residual's colour is the noise's, and the refitted probe
    must not take it for a misfit. The cost gate is opened (on these records the linearised probe
    explains 0.2-0.8 % of the residual, under the gate's 1 %), so the refit runs and is judged."""
    from pipeline.diagnostics import engine
    monkeypatch.setattr(engine, "PROBE_REFIT_MIN_SHARE", 0.0)
    case = make_case("none", base, 2300, magnitude="medium", noise=noise, colour="ar0.9", input_kind=input_kind,
                     n=2000, out_dir=tmp_path)
    d = _run(case).summary["diagnosis"]
    assert [f["family"] for f in d["findings"]] == ["colored_noise"]
    row = next(t for t in d["adequacy"] if t["name"] == NAME + "_refit")
    assert row["passed"], row["detail"]
