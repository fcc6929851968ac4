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
@pytest.mark.parametrize("base,input_kind,magnitude,noise,seed,before", [
    ("msd", "prbs", "large", 0.02, 2005, "colored_noise"),
    ("pendulum", "band", "small", 0.1, 2003, "static_nonlinearity")])
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
    only (no term in the kinematic equation x' = v), K coefficients each."""
    from pipeline.diagnostics import engine
    seen = {}
    real = engine.Diagnoser.run

    def run(self, model, start=None):
        seen["dg"], seen["d"] = self, real(self, model, start)
        return seen["d"]

    monkeypatch.setattr(engine.Diagnoser, "run", run)
    _run(make_case("none", "msd", 1000, n=2000, out_dir=tmp_path))
    hyps = probe_hypotheses(seen["dg"].context(seen["d"].final, None))
    assert sorted(h.key for h in hyps) == [f"{NAME}:v:v", f"{NAME}:v:x"]
    assert all(len(h.coefs) == K and len(h.terms) == K for h in hyps)
    assert Structure.of(seen["d"].final.model).dynamic_eqs == ["v"]
