"""Hidden-effect tests (issue 2): an effect is hidden in a synthetic record; the pipeline, given the
base system as the nominal model, must name it, place it in the right equation, estimate its key
parameter (within 20 %; frequency within 5 %; delay within 1.5 samples) and show a validation gain whose
95 % interval excludes zero. The truth comes from the generator, not from the pipeline."""

import pytest

from tests.synth import run_case

CASES = {
    "offset": ["msd", "tank", "dcmotor"],
    "output_offset": ["msd", "tank"],
    "cubic_stiffness": ["msd", "pendulum"],
    "coulomb_friction": ["msd", "dcmotor", "pendulum"],
    "periodic_disturbance": ["msd", "tank"],
    "input_delay": ["msd", "tank"],
}
PARAMS = [(fam, sysname, seed) for fam, systems in CASES.items() for sysname in systems for seed in (0, 1, 2)]


# known misses (family, system, seed) -> reason, run as strict xfails. Empty since the backward step's
# drop move: on (cubic_stiffness, pendulum, 1) the first round named th*abs(th) (the calibrated test's
# cubic p was 0.0044 there, Holm needing < 0.00077), the second the cubic; given the cubic, th*abs(th)
# gains +0.03 % (95 % interval -0.01 to +0.08 %) and is dropped, leaving the cubic (-35.09 vs -35.10).
KNOWN: dict = {}


def _params():
    return [pytest.param(f, s, k, id=f"{f}-{s}-{k}",
                         marks=[pytest.mark.xfail(strict=True, reason=KNOWN[(f, s, k)])] if (f, s, k) in KNOWN else [])
            for f, s, k in PARAMS]


@pytest.mark.parametrize("family,system,seed", _params())
def test_hidden_effect_is_found(tmp_path, family, system, seed):
    summary, syn = run_case(tmp_path, system, family, seed)
    truth = syn.truth
    diag = summary["diagnosis"]
    assert diag["verdict"] == "discrepancy"
    top = diag["findings"][0]
    assert top["family"] == family
    if family == "input_delay":
        dt = summary["data"]["sample_time"]
        assert abs(top["delay_s"] - truth["delay_s"]) <= 1.5 * dt
    elif family == "output_offset":
        assert top["output"] == truth["output"]
        assert top["value"] == pytest.approx(truth["value"], rel=0.2)
    elif family == "periodic_disturbance":
        assert top["equation"] == truth["equation"]
        assert top["frequency_hz"] == pytest.approx(truth["frequency_hz"], rel=0.05)
        assert top["amplitude"] == pytest.approx(truth["amplitude"], rel=0.2)
    else:
        assert top["equation"] == truth["equation"]
        assert top["coefficient"] == pytest.approx(truth["coefficient"], rel=0.2)
        if "term" in truth:
            assert top["term"] == truth["term"]
    gain = top["gain"]
    assert gain["metric"] == "validation_rmse_sim"
    assert gain["after"] < gain["before"]
    assert gain["relative"] == pytest.approx(1 - gain["after"] / gain["before"])
    assert gain["ci95"][0] > 0
    assert top["delta_bic"] < 0
    words = {"offset": "offset", "output_offset": "offset", "cubic_stiffness": "cubic",
             "coulomb_friction": "coulomb", "periodic_disturbance": "periodic", "input_delay": "dead time"}
    assert words[family] in top["description"].lower()
    assert all({"test", "statistic", "p_value"} <= set(e) for e in top["evidence"])
    # the finding's extension is in the selected model
    assert summary["selected_model"].startswith(f"nominal+{family}")


NULL = [(s, seed) for s in ("msd", "tank", "dcmotor", "pendulum") for seed in range(100, 105)]


def test_null_no_hidden_effect_gives_at_most_one_finding(tmp_path):
    """20 records with no hidden effect (4 base systems × 5 seeds): a finding on at most one."""
    with_findings = []
    for system, seed in NULL:
        summary, _ = run_case(tmp_path / f"{system}{seed}", system, "none", seed)
        if summary["diagnosis"]["findings"]:
            with_findings.append((system, seed, [f["family"] for f in summary["diagnosis"]["findings"]]))
        else:
            assert summary["diagnosis"]["verdict"] == "no_significant_discrepancy"
    assert len(with_findings) <= 1, with_findings


def test_equation_error_evidence_when_states_are_measured(tmp_path):
    """tank: every state measured, so the finding also carries the equation-error regression on the
    candidate term. It is evidence (significance and sign), not the estimate: noise in the measured
    regressors attenuates its slope (errors-in-variables); the finding's coefficient is the OE one."""
    summary, syn = run_case(tmp_path, "tank", "offset", 0)
    ev = {e["test"]: e for e in summary["diagnosis"]["findings"][0]["evidence"]}
    ee = ev["equation_error_wald[offset:h]"]
    assert ee["p_value"] < 1e-6
    assert ee["coefficient"][0] * syn.truth["coefficient"] > 0


def test_delay_evidence_includes_crosscorrelation_lag(tmp_path):
    """The measurement lags the nominal simulation (positive alignment lag, significant). The lag is
    shrunk toward 0 because the fitted nominal partly compensates the delay; the delay itself comes
    from the profile search, tested to 1.5 samples above."""
    for system in ("tank", "msd"):
        summary, syn = run_case(tmp_path / system, system, "input_delay", 0)
        ev = {e["test"]: e for e in summary["diagnosis"]["findings"][0]["evidence"]}
        lag = ev["output_simulation_crosscorrelation_lag"]
        assert 0 < lag["statistic"] <= syn.truth["delay_s"] / summary["data"]["sample_time"] + 1.5
        assert lag["p_value"] < 0.01


@pytest.mark.parametrize("kind,family", [("ar1", "colored_noise"), ("student_t", "heavy_tailed_noise"),
                                         ("hetero", "heteroscedastic_noise")])
def test_noise_family_end_to_end_with_report(tmp_path, kind, family):
    """Through the whole run (config, CLI path, report): a correctly structured model with a noise
    effect gets no structural finding and the noise family, gain on validation NLL."""
    import yaml

    from pipeline import synthetic
    from pipeline.cli import main
    syn = synthetic.generate("tank", "none", 7, noise=0.05, noise_kind=kind)
    syn.to_frame().to_csv(tmp_path / "r.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(synthetic.config_for(syn, "r.csv", seed=7)))
    assert main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    import json
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    fams = [f["family"] for f in s["diagnosis"]["findings"]]
    assert fams[0] == family, fams
    f = s["diagnosis"]["findings"][0]
    assert f["gain"]["metric"] == "validation_nll" and f["gain"]["ci95"][0] > 0
    # the noise tests are on the final model, in its own table; the nominal table holds the nominal only
    assert any(t["on"].endswith("(noise families)") for t in s["diagnosis"]["final_tests"])
    assert all(t["on"] == "nominal model, estimation data" for t in s["diagnosis"]["tests"])
    assert family in (tmp_path / "run" / "report.html").read_text()
