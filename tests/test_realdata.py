"""Real measured data (../shared/datasets). Skipped when absent, required when SYSID_REQUIRE_REALDATA=1."""

import contextlib
import io
from pathlib import Path

import pytest
import yaml

from pipeline.config import load_config
from pipeline.runs import analyse
from tests.seedcases import require_dataset

ROOT = Path(__file__).resolve().parents[1]


def _analyse_shipped(tmp_path, config: str, dataset: str, ctx: bool = False):
    """The shipped config ``configs/<config>`` run on ``../shared/datasets/<dataset>``; its summary (or
    the whole run context with ``ctx``)."""
    path = require_dataset(dataset)
    cfg = yaml.safe_load((ROOT / "configs" / config).read_text())
    cfg["data"]["path"] = str(path)
    (tmp_path / config).write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        run = analyse(load_config(tmp_path / config))
    return run if ctx else run.summary


@pytest.mark.realdata
def test_silverbox_names_cubic_stiffness_and_extended_model_reaches_1_5_mV(tmp_path):
    """Linear MSD fitted on the multisine part (samples 40 650 on), means removed, foh; validated on
    the arrow (samples 0–40 400). Issue 2: cubic_stiffness named; extended free-run RMSE ≤ 1.5 mV
    (linear ≈ 14 mV; a careful grey-box Duffing fit ≈ 1 mV)."""
    s = _analyse_shipped(tmp_path, "silverbox.yaml", "silverbox/SNLS80mV.csv")
    assert s["data"]["estimation"] == [40650, 131072] and s["data"]["validation"] == [0, 40400]
    lin = s["nominal"]["validation"]["rmse_sim"]
    assert 0.010 < lin < 0.018  # the "about 14 mV"
    f = s["diagnosis"]["findings"][0]
    assert (f["family"], f["equation"], f["term"]) == ("cubic_stiffness", "v", "x**3")
    assert f["coefficient"] < 0  # hardening spring: v' = ... + c*x**3 with c < 0
    after_cubic = f["gain"]["after"]
    assert after_cubic <= 0.0015
    # issue 8: with the causes found, the arrow's free-run RMSE is at most 1.0 mV
    assert s["final"]["validation"]["rmse_sim"] <= 0.0010
    assert f["gain"]["ci95"][0] > 0 and f["delta_bic"] < 0
    # the configured foh's straight lines are the next cause: the input is band-limited (its in-band
    # deficit (wT)^2/12 came out as an apparent feedthrough -b*T^2/12*u, about -0.038*u); with it the
    # arrow's RMSE falls below 0.5 mV (0.93 mV before; careful grey boxes and black boxes reach 0.3-0.4)
    bl = [x for x in s["diagnosis"]["findings"] if x["family"] == "intersample"]
    assert bl and bl[0]["chosen"] == "bandlimited" and bl[0]["configured"] == "foh"
    assert bl[0]["gain"]["ci95"][0] > 0.3
    assert s["final"]["validation"]["rmse_sim"] <= 0.0005
    # the verdict says what is still wrong: any failed adequacy row is named in the summary
    d = s["diagnosis"]
    if d["verdict"] == "unexplained_discrepancy":
        assert d["unexplained"]["failed_tests"] and d["unexplained"]["families_tried"]
    # Silverbox is open loop: its multisine cannot be whitened by the feedback test's AR prewhitening (a
    # line spectrum is predictable from its past), so a failing row must not claim a closed loop outright
    fb = next(t for t in d["tests"] if t["name"] == "feedback_crosscorrelation")
    assert fb["passed"] or ("either the input responds to the output" in fb["detail"]
                            and "not white after prewhitening" in fb["detail"])
    # the history says which candidate each iteration took: the others that met the acceptance rule in
    # the first iteration (x*abs(x) and the state limit beside the cubic) read "not taken", not "accepted"
    first = d["history"][0]["candidates"]
    met = [c for c in first if c["accepted"]]
    assert len(met) >= 2
    assert [c["hypothesis"] for c in met if c["reason"] == "accepted"] == ["cubic_stiffness:v:x"]
    assert all(c["reason"] == "met the acceptance rule, not taken: iteration 1 took cubic_stiffness:v:x"
               for c in met if c["hypothesis"] != "cubic_stiffness:v:x")


@pytest.mark.realdata
def test_silverbox_second_record_names_the_same_cause_and_its_model_predicts_the_arrow(tmp_path):
    """The Silverbox's second record (Schroeder80mV: multisines over the whole record, on which nothing was
    tuned), with the same linear nominal belief (configs/silverbox_schroeder.yaml): the cubic spring is
    named again, and the model found on this record, simulated without refitting on the *first* record's
    arrow (SNLS80mV, samples 0-40 400, another excitation the fit never saw), meets issue 8's arrow
    target of 1.0 mV there, where the linear model fitted on the same record misses by more than 10 mV."""
    import numpy as np
    from pipeline.data import load_record, make_split, remove_means
    from pipeline.fit import Problem, initial_state, simulate_full
    ctx = _analyse_shipped(tmp_path, "silverbox_schroeder.yaml", "silverbox/Schroeder80mV.csv", ctx=True)
    s = ctx.summary
    assert s["data"]["estimation"] == [2000, 87000] and s["data"]["validation"] == [89000, 131072]
    f = s["diagnosis"]["findings"][0]
    assert (f["family"], f["equation"], f["term"]) == ("cubic_stiffness", "v", "x**3")
    assert f["coefficient"] < 0 and f["gain"]["ci95"][0] > 0
    assert s["nominal"]["validation"]["rmse_sim"] > 0.010
    assert s["final"]["validation"]["rmse_sim"] <= 0.0010      # this record's own validation part
    # the first record, as configs/silverbox.yaml reads it (means of its multisine part removed)
    cfg = yaml.safe_load((ROOT / "configs" / "silverbox.yaml").read_text())
    cfg["data"]["path"] = str(require_dataset("silverbox/SNLS80mV.csv"))
    (tmp_path / "arrow.yaml").write_text(yaml.safe_dump(cfg))
    lc = load_config(tmp_path / "arrow.yaml")
    rec = load_record(lc)
    split = make_split(lc, rec)
    remove_means(rec, split)
    arrow = slice(0, 40400)

    def arrow_rmse(model):
        prob = Problem.from_record(rec, model, split, lc.cfg.split.warmup)
        yh = simulate_full(model, prob, initial_state(model, prob))
        return float(np.sqrt(np.mean((prob.Y[arrow] - yh[arrow]) ** 2)))

    assert arrow_rmse(ctx.diag.final.model) <= 0.0010
    assert arrow_rmse(ctx.diag.nominal.model) > 0.010


@pytest.mark.realdata
def test_silverbox_mat_file_loads_like_csv(tmp_path):
    import numpy as np
    from pipeline.data import load_record
    csv = require_dataset("silverbox/SNLS80mV.csv")
    mat = require_dataset("silverbox/SNLS80mV.mat")
    cfg = yaml.safe_load((ROOT / "configs" / "silverbox.yaml").read_text())
    recs = []
    for p in (csv, mat):
        cfg["data"]["path"] = str(p)
        (tmp_path / "sb.yaml").write_text(yaml.safe_dump(cfg))
        recs.append(load_record(load_config(tmp_path / "sb.yaml")))
    # the CSV holds 5 significant digits (|x| < 0.31): half a unit in the last place is 5e-6
    np.testing.assert_allclose(recs[0].outputs["x"], recs[1].outputs["x"], rtol=0, atol=5.0001e-6)
    assert recs[0].n == recs[1].n == 131072


@pytest.mark.realdata
def test_cascaded_tanks_uses_its_two_records_as_given(tmp_path):
    """configs/cascaded_tanks.yaml: the estimation and validation records of the benchmark file (side by
    side in one CSV) are two experiments. The validation record is simulated from its own initial state
    (its first measured level), not as a continuation of the estimation record, and its samples are
    never fitted. The linear grey-box misses a lot on validation data (published linear grey-box
    ≈ 0.94 V free-run RMSE; physical sqrt-outflow models ≈ 0.3–0.4 V)."""
    import numpy as np
    csv = require_dataset("cascaded_tanks/dataBenchmark.csv")
    cfg = yaml.safe_load((ROOT / "configs" / "cascaded_tanks.yaml").read_text())
    cfg["data"]["path"] = str(csv)
    cfg["diagnose"] = {"families": ["offset"], "max_findings": 1}
    (tmp_path / "ct.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(tmp_path / "ct.yaml"))
    s = ctx.summary
    assert s["data"]["n_samples"] == 2048
    assert s["data"]["estimation"] == [0, 1024] and s["data"]["validation"] == [1024, 2048]
    assert ctx.prob.segments() == [(0, 1024), (1024, 2048)]
    raw = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3))
    np.testing.assert_array_equal(ctx.prob.Y[:1024, 0], raw[:, 2])      # yEst
    np.testing.assert_array_equal(ctx.prob.Y[1024:, 0], raw[:, 3])      # yVal
    np.testing.assert_array_equal(ctx.prob.U[1024:, 0], raw[:, 1])      # uVal
    # the validation simulation starts at the validation record's own first level
    assert ctx.diag.nominal.Yhat[1024, 0] == pytest.approx(raw[0, 3], abs=1e-12)
    assert 0.6 < s["nominal"]["validation"]["rmse_sim"] < 1.6


@pytest.mark.realdata
def test_dryer_names_the_transport_delay_and_no_invented_nonlinearity(tmp_path):
    """configs/dryer.yaml (DaISy dryer, two-column text read as data.format: table): a first-order model
    without dead time. Issue 8: input_delay of about 2-3 samples first, and no static nonlinearity,
    stiffness, friction or saturation invented for a near-linear process."""
    s = _analyse_shipped(tmp_path, "dryer.yaml", "daisy_dryer/dryer.dat")
    assert s["data"]["n_samples"] == 1000
    f = s["diagnosis"]["findings"]
    assert f[0]["family"] == "input_delay" and 2.0 <= f[0]["delay_samples"] <= 3.5
    invented = {"static_nonlinearity", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
                "input_saturation", "dead_zone", "state_saturation"}
    assert not invented & {x["family"] for x in f}
    assert s["final"]["validation"]["rmse_sim"] < 0.5 * s["nominal"]["validation"]["rmse_sim"]
    # a coupled state refits here to τ ≈ 0.03–0.09 samples (cτ ≈ −0.9: a rescaled time derivative, not a
    # storage the samples resolve); it is rejected and the input lag refitted in its place
    lagged = [x for x in f if x["family"] == "unmodeled_dynamics"]
    assert all(x.get("input") and x["time_constant_s"] >= 0.5 * s["data"]["sample_time"] for x in lagged), lagged
    tried = {r["family"]: r["reason"] for r in s["diagnosis"]["unexplained"]["families_tried"]} \
        if s["diagnosis"]["unexplained"] else {}
    assert not lagged or tried.get("unmodeled_dynamics", "accepted") == "accepted"


@pytest.mark.realdata
def test_heating_system_is_unexplained_and_not_blamed_on_noise(tmp_path):
    """configs/heating_system.yaml (DaISy heating, first-order linear thermal model). Issue 9: the
    nominal residual holds input dynamics (the model-error model explains most of it), no family's
    extension is supported by the estimation part, so the verdict is ``unexplained_discrepancy`` and the
    noise families are "not tested" (before: "colored_noise", RMSE 8.133 -> 8.133).

    Why V**2 is not named: written by hand, b*V**2 in place of b*V fits the *estimation* part worse
    (free-run RMSE 3.84 vs 3.44 °C) although it extrapolates better to the validation part (4.12 vs
    8.13 °C), with an ambient temperature of 69 °C; c*V**2 added beside b*V (the family's extension)
    lowers the estimation RMSE by 0.08 % and the validation RMSE only to 7.69 °C. A test on the
    estimation data cannot prefer the lamp law. Asserted here so the claims stay true."""
    path = require_dataset("daisy_heating_system/heating_system.dat")
    s = _analyse_shipped(tmp_path, "heating_system.yaml", "daisy_heating_system/heating_system.dat")
    d = s["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    assert not d["findings"]
    assert any(t.startswith("model_error_model") for t in d["unexplained"]["failed_tests"])
    noise = {"colored_noise", "heavy_tailed_noise", "heteroscedastic_noise"}
    assert not noise & {f["family"] for f in d["findings"]}
    # where the validation part goes beyond the estimation part, from the raw file: the voltage takes
    # levels 6 and 7 V never seen in estimation (which has 3, 4, 8, 9 V), and the temperature falls
    # below the estimation minimum
    import numpy as np
    raw = np.loadtxt(path)
    e0, e1 = s["data"]["estimation"]
    v0, v1 = s["data"]["validation"]
    cov = {r["signal"]: r for r in s["data"]["coverage"]}
    assert cov["V"]["estimation_levels"] == sorted(set(raw[e0:e1, 1])) == [3, 4, 8, 9]
    assert cov["V"]["new_levels"] == [6, 7]
    below = np.mean(raw[v0:v1, 2] < raw[e0:e1, 2].min())
    assert below > 0.05 and cov["T"]["validation_outside_share"] == pytest.approx(below, abs=1e-12)

    cfg = yaml.safe_load((ROOT / "configs" / "heating_system.yaml").read_text())
    cfg["data"]["path"] = str(path)
    cfg["diagnose"] = {"families": []}
    cfg["model"]["equations"]["T"] = "-a*(T - Ta) + b*V**2"
    cfg["model"]["params"]["b"] = 0.01
    (tmp_path / "v2.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        v2 = analyse(load_config(tmp_path / "v2.yaml")).summary["nominal"]
    lin = s["nominal"]
    assert v2["estimation"]["rmse_sim"] > lin["estimation"]["rmse_sim"]
    assert v2["validation"]["rmse_sim"] < 0.6 * lin["validation"]["rmse_sim"]
    # and its better extrapolation comes with an ambient temperature no laboratory has (Ta = 69 °C;
    # the linear model's is 14 °C): the V**2 model moves the whole operating point, not the lamp law
    assert v2["params"]["Ta"] > 50 > 25 > lin["params"]["Ta"]
    # the lamp law as the family tests it, c*V**2 added beside b*V: the estimation part gains almost
    # nothing (3.438 -> 3.435 °C) and the validation error stays far from the 4.1 °C of b*V**2
    cfg["model"]["equations"]["T"] = "-a*(T - Ta) + b*V + c*V**2"
    cfg["model"]["params"].update({"b": 0.1, "c": 0.0})
    cfg["model"]["free"] = ["a", "b", "c", "Ta"]
    (tmp_path / "vv2.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        both = analyse(load_config(tmp_path / "vv2.yaml")).summary["nominal"]
    assert both["estimation"]["rmse_sim"] > 0.995 * lin["estimation"]["rmse_sim"]
    assert both["validation"]["rmse_sim"] > 0.9 * lin["validation"]["rmse_sim"] > 1.5 * v2["validation"]["rmse_sim"]


@pytest.mark.realdata
def test_cascaded_tanks_full_diagnosis_does_not_end_as_coloured_noise(tmp_path):
    """configs/cascaded_tanks.yaml with every family: offsets and sqrt outflow are significant on the
    nominal model and refitted, but no extension lowers the validation error with 95 % confidence (the
    validation residual is one slow wave). The structural Wald row must then fail adequacy, so the verdict is
    ``unexplained_discrepancy`` and the noise stage does not run (a bug let a 26 % share count as 0 %
    when the loop stopped before max_findings, and the verdict was "colored_noise")."""
    run = _analyse_shipped(tmp_path, "cascaded_tanks.yaml", "cascaded_tanks/dataBenchmark.csv", ctx=True)
    s = run.summary
    d = s["diagnosis"]
    assert d["verdict"] in ("unexplained_discrepancy", "discrepancy")
    fams = [f["family"] for f in d["findings"]]
    assert "colored_noise" not in fams
    if d["verdict"] == "unexplained_discrepancy":
        sw = next(t for t in d["adequacy"] if t["name"] == "structural_wald")
        assert not sw["passed"] and sw["explained_share"] >= 0.02
    # with k2*k4 no longer a free product (h1 is not measured), the nominal model has no structurally
    # unidentifiable pair, and the square-root outflow is significant after Holm and refitted: its
    # validation RMSE is far below the linear model's 1.12 V (published square-root grey boxes reach
    # 0.3-0.4 V), but the smooth validation residual leaves the gain's interval unbounded
    assert "k4" not in (s["nominal"]["identifiability"].get("unidentifiable") or [])
    sq = [c for c in d["history"][0]["candidates"]
          if c["family"] == "static_nonlinearity" and "sqrt(" in c["hypothesis"]]
    assert sq and all("Holm" not in c["reason"] and c.get("gain") for c in sq)
    assert min(c["gain"]["after"] for c in sq) < 0.75 < s["nominal"]["validation"]["rmse_sim"]
    # and the reason says that the record cannot bound the gain, not that the gain is near 0
    for c in sq:
        assert c["gain"]["ci95"][0] <= -99 and "unbounded below" in c["reason"]
        assert f"{100 * c['gain']['relative']:+.1f} %" in c["reason"]
    # and the verdict says why in one paragraph: an offset and the square-root outflow lower the
    # validation error alike, and the record cannot bound either gain
    if d["verdict"] == "unexplained_discrepancy":
        why = d["unexplained"]["why"]
        kinds = {r["family"]: r["kind"] for r in why["refitted"]}
        assert kinds.get("static_nonlinearity") == "unbounded" and kinds.get("offset") == "unbounded"
        assert "(offset, static_nonlinearity)" in why["sentence"] and "do not say which cause" in why["sentence"]
        from pipeline.report.view import first_screen
        assert any(w.startswith("Why no cause is named:") for w in first_screen(s)["warnings"])
        # section 4 ("Why, the fix, and its worth") holds the same answer with one row per refitted
        # extension, not only "No finding"
        from pipeline.report import render_report
        sec4 = render_report(run).split('id="findings"')[1].split('id="models"')[0]
        assert "Why no cause is named" in sec4
        for r in why["refitted"]:
            assert f"<code>{r['hypothesis']}</code>" in sec4
        assert sec4.count("unbounded below</td>") == sum(r["kind"] == "unbounded" for r in why["refitted"])
        # and a figure draws what the two best refits of different causes would change: the models kept
        # for it are the ones whose validation gains the table reports (their RMSE is the gain's "after")
        import numpy as np
        shown = run.diag.unaccepted
        assert [lab.split(":")[0] for lab, _ in shown] == ["offset", "static_nonlinearity"]
        after = {c["hypothesis"]: c["gain"]["after"] for c in d["history"][-1]["candidates"] if c.get("gain")}
        val = run.prob.split.val_slice()
        for lab, fit in shown:
            hyp = lab.split(" (not accepted")[0]
            rmse = float(np.sqrt(np.mean((run.prob.Y[val] - fit.Yhat[val]) ** 2)))
            assert rmse == pytest.approx(after[hyp], rel=1e-12) and rmse < 0.75
            assert f"{100 * (1 - rmse / s['nominal']['validation']['rmse_sim']):+.1f} %" in lab
        assert 'alt="final model and the refitted extensions that were not accepted' in sec4


@pytest.mark.realdata
def test_ballbeam_is_unexplained_and_flagged_as_closed_loop(tmp_path):
    """configs/ballbeam.yaml (DaISy ball and beam, x'' = k*a - c*v): the plant is open-loop unstable, so
    the record comes from a feedback loop. Issue 9: the negative-lag input-residual correlation is
    reported as a sign of closed-loop data, no cause is named on a model whose free-run simulation
    cannot follow the record, and the coloured residual is not called noise."""
    s = _analyse_shipped(tmp_path, "ballbeam.yaml", "daisy_ballbeam/ballbeam.dat")
    d = s["diagnosis"]
    fb = next(t for t in d["tests"] if t["name"] == "feedback_crosscorrelation")
    assert not fb["passed"] and fb["p_value"] < 0.01 and "closed loop" in fb["detail"]
    assert fb["informational"] is True     # about the data: shown, not part of the verdict
    assert d["verdict"] == "unexplained_discrepancy" and not d["findings"]
    assert d["unexplained"]["failed_tests"]
    # a friction-type term is significant; its refit (started from the current fit, x0 included) is
    # evaluated on the validation part, not abandoned
    cand = {c["family"]: c for c in d["history"][0]["candidates"]}
    assert cand["coulomb_friction"]["reason"] == "validation error not lower with 95 % confidence"
