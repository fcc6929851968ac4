"""The run folder, determinism, the CLI and the report (on the embedded demo)."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io
import yaml

from pipeline.cli import main
from pipeline.config import load_config
from pipeline.data import load_record

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "demo.yaml"


def test_demo_names_cubic_stiffness(demo_runs):
    s = json.loads((demo_runs[0] / "summary.json").read_text())
    assert s["schema"] == "sysid-summary/1"
    assert s["diagnosis"]["verdict"] == "discrepancy"
    f = s["diagnosis"]["findings"][0]
    assert (f["family"], f["equation"], f["term"]) == ("cubic_stiffness", "v", "x**3")
    # the demo hides k3 = -3.328 (python -m pipeline.synthetic msd cubic_stiffness --seed 0)
    assert f["coefficient"] == pytest.approx(-3.328, rel=0.05)
    for key in ("run_id", "config_sha256", "data_sha256", "nominal", "diagnosis", "models", "selected_model"):
        assert key in s
    assert set(s["nominal"]["params"]) == {"c", "k"}
    assert s["nominal"]["validation"]["rmse_sim"] > 5 * s["final"]["validation"]["rmse_sim"]


def test_parameter_intervals_use_the_covariances_degrees_of_freedom(demo_runs):
    """summary.json's param_ci95 (an extension of contract §3) is θ̂ ± t σ with Student's t at each
    parameter's own ν = identifiability.covariance_dof_by_param (floored at 1), computed here with
    scipy; covariance_dof is the smallest of them (the regions'); the report states the multipliers and ν."""
    from scipy import stats as sps
    s = json.loads((demo_runs[0] / "summary.json").read_text())
    html = (demo_runs[0] / "report.html").read_text(encoding="utf-8")
    for which in ("nominal", "final"):
        blk = s[which]
        nu = blk["identifiability"]["covariance_dof"]
        own = blk["identifiability"]["covariance_dof_by_param"]
        assert nu is not None and nu > 0
        assert set(own) == set(blk["param_ci95"]) and min(own.values()) == pytest.approx(nu, rel=1e-12)
        for name, (lo, hi) in blk["param_ci95"].items():
            v, sd = blk["params"][name], blk["param_std"][name]
            t = sps.t.isf(0.025, max(own[name], 1.0))
            assert lo == pytest.approx(v - t * sd, rel=1e-8, abs=1e-12)
            assert hi == pytest.approx(v + t * sd, rel=1e-8, abs=1e-12)
    ident = s["nominal"]["identifiability"]
    t_nom = sps.t.isf(0.025, max(ident["covariance_dof"], 1.0))
    if max(ident["covariance_dof_by_param"].values()) > 1.05 * ident["covariance_dof"]:
        t_lo = sps.t.isf(0.025, max(ident["covariance_dof_by_param"].values()))
        assert f"with t from {t_lo:.3g} to {t_nom:.3g}" in html
    else:
        assert f"θ̂ ± {t_nom:.3g}σ" in html or f"θ̂ ± {t_nom:.3g}".rstrip("0") in html


def test_two_runs_give_byte_identical_summary(demo_runs):
    a, b = demo_runs
    assert (a / "summary.json").read_bytes() == (b / "summary.json").read_bytes()


def test_run_folder_contents(demo_runs):
    a, b = demo_runs
    for f in ("report.html", "summary.json", "config.resolved.yaml", "metrics.json", "params.yaml", "manifest.json"):
        assert (a / f).is_file(), f
    assert not (b / "report.html").exists()  # diagnose: no HTML
    man = json.loads((a / "manifest.json").read_text())
    assert re.fullmatch(r"[0-9a-f]{64}", man["data_sha256"])
    assert man["seed"] == 0 and "numpy" in man["versions"] and "dirty" in man["git"]
    s = json.loads((a / "summary.json").read_text())
    assert man["data_sha256"] == s["data_sha256"]
    assert s["run_id"].startswith("demo-") and s["run_id"] == man["run_id"]
    resolved = yaml.safe_load((a / "config.resolved.yaml").read_text())
    assert resolved["model"]["free"] == ["c", "k"]


def test_report_has_the_sections_a_reader_needs(demo_runs):
    html = (demo_runs[0] / "report.html").read_text()
    for needle in ("What the simulation gets wrong", "Why, the fix, and its worth", "cubic_stiffness",
                   "95 % confidence ellipses", "Residual tests", "validation data", "ΔBIC", "ljung_box"):
        assert needle in html, needle
    assert html.count("data:image/png;base64,") >= 7
    assert "<script" not in html


def test_run_id_depends_on_config_and_data_not_clock(tmp_path):
    shutil.copy(DEMO, tmp_path / "demo.yaml")
    shutil.copy(ROOT / "data" / "demo.csv", tmp_path / "demo.csv")
    cfg = yaml.safe_load(DEMO.read_text())
    cfg["data"]["path"] = "demo.csv"
    (tmp_path / "demo.yaml").write_text(yaml.safe_dump(cfg))
    id1 = load_config(tmp_path / "demo.yaml").sha256()
    cfg["diagnose"]["alpha"] = 0.05
    (tmp_path / "demo.yaml").write_text(yaml.safe_dump(cfg))
    assert load_config(tmp_path / "demo.yaml").sha256() != id1


def test_report_escapes_text_it_did_not_write():
    """Autoescape: text that reaches the report from findings (descriptions, equations) cannot inject
    HTML or script into the page."""
    import contextlib
    import io

    from pipeline.report import render_report
    from pipeline.runs import analyse
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(DEMO))
    ctx.summary["diagnosis"]["findings"][0]["description"] = "<script>alert(1)</script> & <b>x</b>"
    html = render_report(ctx)
    assert "&lt;script&gt;alert(1)&lt;/script&gt; &amp; &lt;b&gt;x&lt;/b&gt;" in html
    assert "<script" not in html


def test_parquet_and_mat_loaders_match_csv(tmp_path):
    df = pd.read_csv(ROOT / "data" / "demo.csv")
    df.to_parquet(tmp_path / "d.parquet")
    scipy.io.savemat(tmp_path / "d.mat", {c: df[c].to_numpy()[None, :] for c in df.columns})
    cfg = yaml.safe_load(DEMO.read_text())
    recs = []
    for name in ("d.parquet", "d.mat"):
        cfg["data"]["path"] = name
        (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
        recs.append(load_record(load_config(tmp_path / "c.yaml")))
    for r in recs:
        np.testing.assert_array_equal(r.outputs["x"], df["x"].to_numpy())
        np.testing.assert_array_equal(r.inputs["u"], df["u"].to_numpy())
        assert r.dt == pytest.approx(0.02)


def test_cli_usage_error_is_exit_2(capsys):
    assert main(["report"]) == 2
    assert main(["frobnicate", "x.yaml"]) == 2


def test_bounds_keep_a_fit_physical_where_the_unbounded_one_fails_on_validation(tmp_path):
    """An independent-bench record (solve_ivp; test seed 1002): a tank h' = b·u − a·√h whose outflow
    coefficient jumps 0.5 → 0.9 at 84 s. The nominal least-squares optimum is a = −0.0002, b = −0.022;
    simulated on the validation part it takes √ of a negative level at t = 187.4 s. Until the
    thirty-fifth session the run stopped there (exit 2); now it completes and says so: the nominal
    model's validation numbers are over the samples before, a failed adequacy row on validation data
    makes the verdict unexplained, and the report marks where the simulation stops. With
    ``model.bounds`` a ≥ 0, b ≥ 0 the run completes too; the bound that holds is named."""
    from pipeline.bench.independent.case import make_case
    case = make_case("parameter_jump", "tank", 1002, magnitude="large", noise=0.02, colour="ar0.5",
                     input_kind="band", n=2000, out_dir=tmp_path)
    cfg_path = Path(case.dir) / "config.yaml"
    assert main(["report", str(cfg_path), "--out", str(tmp_path / "free")]) == 0
    s = json.loads((tmp_path / "free" / "summary.json").read_text())
    val = s["nominal"]["validation"]
    assert val["undefined_from_s"] == pytest.approx(187.4) and val["samples"] == 1874 - 1400
    assert s["nominal"]["params"]["b"] < 0 and val["fit_percent"] < 0   # the level drains against the input
    d = s["diagnosis"]
    row = next(r for r in d["adequacy"] if r["name"] == "validation_simulation")
    assert not row["passed"] and row["on"] == "final model, validation data" and "t = 187.4 s" in row["detail"]
    assert d["verdict"] == "unexplained_discrepancy"
    html = (tmp_path / "free" / "report.html").read_text(encoding="utf-8")
    assert "simulation stops at t = 187.4 s" in html
    cfg = yaml.safe_load(cfg_path.read_text())
    cfg["model"]["bounds"] = {"a": [0, None], "b": [0, None]}
    (Path(case.dir) / "bounded.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["report", str(Path(case.dir) / "bounded.yaml"), "--out", str(tmp_path / "bounded")]) == 0
    s = json.loads((tmp_path / "bounded" / "summary.json").read_text())
    p = s["nominal"]["params"]
    assert p["a"] >= 0 and p["b"] >= 0 and s["nominal"]["at_bound"]
    page = (tmp_path / "bounded" / "report.html").read_text(encoding="utf-8")
    assert "On a bound of <code>model.bounds</code>: " + ", ".join(s["nominal"]["at_bound"]) in page
    assert s["diagnosis"]["verdict"] != "no_significant_discrepancy"
    # the model written back keeps the bounds, so a rerun of it fits the same way
    ext = yaml.safe_load((tmp_path / "bounded" / "extended.yaml").read_text())
    assert ext["model"]["bounds"] == {"a": [0, None], "b": [0, None]}


def test_families_tried_keeps_an_accepted_family_accepted():
    """A family named in round 1 whose remaining hypotheses are not significant in round 3 (the dryer:
    the input lag named, the coupled state left) is listed as accepted, not as "not significant"; a
    family whose candidate met the rule but was not taken (another explained more) does not read
    "accepted"; other families keep their last reason."""
    from pipeline.runs import NOT_TAKEN, _tried
    history = [
        {"candidates": [{"family": "unmodeled_dynamics", "reason": "refit rejected: too fast"},
                        {"family": "unmodeled_dynamics", "reason": "accepted"},
                        {"family": "state_saturation", "reason": "accepted"},
                        {"family": "offset", "reason": "not significant after Holm correction"}]},
        {"candidates": [{"family": "unmodeled_dynamics", "reason": "not significant after Holm correction"},
                        {"family": "offset", "reason": "refit failed: diverged"}]},
    ]
    got = {r["family"]: r["reason"] for r in _tried(history, {"unmodeled_dynamics"})}
    assert got == {"unmodeled_dynamics": "accepted", "state_saturation": NOT_TAKEN, "offset": "refit failed: diverged"}



def test_families_tried_says_when_the_backward_step_removed_a_finding():
    """A family accepted in its round whose finding the backward step dropped (a lag made redundant by a
    later delay) or swapped out is neither "accepted" nor "not taken: another extension explained
    more": it says what the step did. A family that is still a finding stays "accepted"."""
    from pipeline.runs import _tried
    history = [{"candidates": [{"family": "unmodeled_dynamics", "reason": "accepted"},
                               {"family": "offset", "reason": "accepted"}]},
               {"candidates": [{"family": "cubic_stiffness", "reason": "accepted"}]},
               {"candidates": [{"family": "input_delay", "reason": "accepted"}]}]
    moves = [{"move": "drop", "family": "unmodeled_dynamics", "short": "unmodeled_dynamics:u@1dt dropped"},
             {"move": "swap", "family": "offset", "short": "output_offset:x in place of offset:v"}]
    got = {r["family"]: r["reason"] for r in _tried(history, {"cubic_stiffness", "input_delay", "output_offset"}, moves)}
    assert got["unmodeled_dynamics"] == "accepted, then removed by the backward step: unmodeled_dynamics:u@1dt dropped"
    assert got["offset"] == "accepted, then removed by the backward step: output_offset:x in place of offset:v"
    assert got["cubic_stiffness"] == got["input_delay"] == "accepted"
