"""Issue 8, more than one output and input: residual tests on every output × input, the cause found
on the output it acts on, and gains pooled over outputs on each output's own scale.

The record is made here with ``scipy.integrate.solve_ivp`` on continuous-time inputs (sums of sines),
sharing no code with the detector: two coupled thermal capacities,

    T1' = b1 u1 − a1 T1 + g (T2 − T1)          (measured in milli-units: y1 = 1000 T1)
    T2' = b2 u2 − a2 T2 − g (T2 − T1) + q u2²  (the hidden effect, on the second equation only)

The first output is 1000× larger than the second: a pooled raw RMSE would be output 1's alone. The
gain must be pooled on each output's scale (its RMSE over the measured output's standard deviation).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from pipeline.config import load_config
from pipeline.runs import analyse

from .two_capacity import A1, A2, B1, B2, G, config, inputs

def _record(tmp: Path, q: float, seed: int, n: int = 3000, dt: float = 0.05) -> Path:
    t = np.arange(n) * dt
    u1, u2 = inputs(seed)

    def f(s, x):
        T1, T2 = x
        a, b = u1(s), u2(s)
        return [B1 * a - A1 * T1 + G * (T2 - T1), B2 * b - A2 * T2 - G * (T2 - T1) + q * b ** 2]

    sol = solve_ivp(f, (0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-11, max_step=dt)
    T1, T2 = sol.y
    rng = np.random.default_rng(seed + 1)
    y1 = 1000 * T1 + 0.02 * np.std(1000 * T1) * rng.standard_normal(n)
    y2 = T2 + 0.02 * np.std(T2) * rng.standard_normal(n)
    d = tmp / f"mimo-q{q:g}-s{seed}"
    d.mkdir()
    pd.DataFrame({"t": t, "u1": u1(t), "u2": u2(t), "y1": y1, "T2": y2}).to_csv(d / "data.csv", index=False)
    cfg = config("mimo-two-scales", seed, ["offset", "static_nonlinearity", "input_saturation"])
    (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return d / "config.yaml"


def _run(path: Path) -> dict:
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(path)).summary


@pytest.mark.parametrize("seed", [1002, 1003])
def test_effect_on_the_second_output_is_found_and_its_gain_is_pooled_on_scale(tmp_path, seed):
    s = _run(_record(tmp_path, q=0.25, seed=seed))
    names = [r["name"] for r in s["diagnosis"]["tests"]]
    # every output has its own battery; every output × input pair its cross-correlation; the first
    # output and pair keep the contract's plain names
    for test in ("autocorrelation", "ljung_box", "fisher_g", "mean_t", "cusum", "cusum_squares"):
        assert test in names and f"{test}[T2]" in names
    assert "input_crosscorrelation" in names
    for pair in ("u2->y1", "u1->T2", "u2->T2"):
        assert f"input_crosscorrelation[{pair}]" in names
    rows = {r["name"]: r for r in s["diagnosis"]["tests"]}
    assert rows["ljung_box[T2]"]["p_value"] < 1e-6          # the second output's own battery sees it
    # and every row says which output (and input) it is on, the plainly named first ones too (an
    # auditor read ``input_crosscorrelation`` beside ``input_crosscorrelation[u2->x1]`` without knowing it)
    assert (rows["ljung_box"]["output"], rows["ljung_box[T2]"]["output"]) == ("y1", "T2")
    assert (rows["input_crosscorrelation"]["output"], rows["input_crosscorrelation"]["input"]) == ("y1", "u1")
    assert (rows["feedback_crosscorrelation"]["output"], rows["feedback_crosscorrelation"]["input"]) == ("y1", "u1")
    assert rows["input_crosscorrelation[u2->T2]"]["input"] == "u2" and "input" not in rows["mean_t"]
    assert all("output" in r for r in s["diagnosis"]["tests"] + s["diagnosis"]["final_tests"]
               if not r["name"].endswith("_noise") and r["name"] != "noise_families")
    first = s["diagnosis"]["findings"][0]
    assert first["family"] == "static_nonlinearity"
    assert first["equation"] == "T2" and "u2" in first["term"]
    g = first["gain"]
    assert g["metric"] == "validation_nrmse_sim_pooled"
    assert g["ci95"][0] > 0.05 and g["ci95"][0] <= g["relative"] <= g["ci95"][1]
    # pooled on scale: √(mean over outputs of (RMSE_i / sd_i)²), sd_i of the measured validation output
    data = pd.read_csv(tmp_path / f"mimo-q0.25-s{seed}" / "data.csv")
    a, b = s["data"]["validation"]
    val = data.iloc[a:b]
    for key, block in (("before", s["nominal"]), ("after", s["final"])):
        per = block["validation"]["per_output"]
        ratios = [per[y]["rmse_sim"] / np.std(val[y]) for y in ("y1", "T2")]
        assert g[key] == pytest.approx(np.sqrt(np.mean(np.square(ratios))), rel=0.02)
    per = s["final"]["validation"]["per_output"]
    assert per["T2"]["rmse_sim"] < 0.7 * s["nominal"]["validation"]["per_output"]["T2"]["rmse_sim"]


def test_null_two_output_record_has_no_finding(tmp_path):
    s = _run(_record(tmp_path, q=0.0, seed=1004))
    assert [f["family"] for f in s["diagnosis"]["findings"]] == []
    assert s["diagnosis"]["verdict"] == "no_significant_discrepancy"
