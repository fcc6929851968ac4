"""A nominal model whose fitted simulation stops on the validation part (NaN or divergence) is reported
and diagnosed, not refused: its validation numbers are over the samples before the stop, gains against
it are measured where both models are defined, and a failed adequacy row keeps the verdict honest."""

import json

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from pipeline.cli import main
from pipeline.diagnostics.gain import gain_ci

DT = 0.1


def _record(tmp_path):
    """x' = −x + u by solve_ivp (no code of the tool), 2 000 samples at 0.1 s, 1 % noise. The input is
    piecewise linear between knots every 5 s (exactly what ``foh`` interpolates); from 150 s on it swings
    negative, so the measured x goes below 0 on the validation part (the last 30 %)."""
    n = 2000
    t = np.arange(n) * DT
    rng = np.random.default_rng(7)
    knots = np.arange(0, n * DT + 5, 5.0)
    lv = rng.uniform(0.5, 2.0, len(knots))
    late = knots >= 150
    lv[late] = rng.uniform(-1.5, 0.3, late.sum())
    sol = solve_ivp(lambda tt, x: [-x[0] + np.interp(tt, knots, lv)], (0, t[-1]), [1.0], t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=0.05)
    x = sol.y[0] + 0.01 * rng.standard_normal(n)
    pd.DataFrame({"t": t, "u": np.interp(t, knots, lv), "x": x}).to_csv(tmp_path / "rec.csv", index=False)
    return knots, lv


def test_a_square_root_model_that_fails_below_zero_on_validation_is_reported_where_it_stops(tmp_path):
    """The user's belief, x' = −a·√x + b·u, fits the estimation part (x > 0 there) and takes √ of a
    negative x on the validation part. Before the thirty-fifth session the run stopped with exit 2. Now:
    exit 0; the stop time is where the fitted model's own solution (solve_ivp, an event at x = 0)
    crosses 0, to the next sample; the validation RMSE is that of the samples before (recomputed from
    simulation.csv); a failed ``validation_simulation`` row on validation data, verdict unexplained."""
    knots, lv = _record(tmp_path)
    cfg = {"name": "sqrt_below_zero", "seed": 0,
           "data": {"path": "rec.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh"},
           "model": {"states": ["x"], "inputs": ["u"], "params": {"a": 1.0, "b": 1.0}, "free": ["a", "b"],
                     "equations": {"x": "-a*sqrt(x) + b*u"}, "initial": {"x": "data"}},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    val = s["nominal"]["validation"]
    a, b = s["nominal"]["params"]["a"], s["nominal"]["params"]["b"]
    x0 = float(pd.read_csv(tmp_path / "rec.csv")["x"].iloc[0])

    def at_zero(tt, x):
        return x[0]
    at_zero.terminal, at_zero.direction = True, -1
    ref = solve_ivp(lambda tt, x: [-a * np.sqrt(max(x[0], 0.0)) + b * np.interp(tt, knots, lv)], (0, 200),
                    [x0], events=at_zero, rtol=1e-10, atol=1e-12, max_step=0.05)
    t0 = float(ref.t_events[0][0])
    assert 140 < t0 and t0 <= val["undefined_from_s"] <= t0 + 1.5 * DT
    sim = pd.read_csv(tmp_path / "run" / "simulation.csv")
    v = sim[sim["part"] == "validation"]
    ok = v["x_nominal"].notna()
    assert ok.sum() == val["samples"] and not v["x_nominal"][v["t"] >= val["undefined_from_s"]].notna().any()
    rmse = float(np.sqrt(np.mean((v["x"][ok] - v["x_nominal"][ok]) ** 2)))
    assert val["rmse_sim"] == pytest.approx(rmse, rel=1e-6)
    d = s["diagnosis"]
    row = next(r for r in d["adequacy"] if r["name"] == "validation_simulation")
    assert not row["passed"] and row["on"] == "final model, validation data"
    assert d["verdict"] == "unexplained_discrepancy"
    assert any(t.startswith("validation_simulation") for t in d["unexplained"]["failed_tests"])
    html = (tmp_path / "run" / "report.html").read_text(encoding="utf-8")
    assert "simulation stops at t = " in html and "over the samples before" in html


def test_a_gain_against_a_model_that_stops_is_measured_where_both_are_defined():
    """gain_ci with NaN rows in the model before (its simulation stopped): the same numbers as on the rows
    where both are defined, and it says how many those are; without NaN nothing changes."""
    rng = np.random.default_rng(1)
    before = rng.standard_normal((500, 1)) + np.sin(np.arange(500) / 20)[:, None]
    after = 0.5 * rng.standard_normal((500, 1))
    full = gain_ci(before, after)
    assert "samples_compared" not in full
    cut = before.copy()
    cut[380:] = np.nan
    g = gain_ci(cut, after)
    ref = gain_ci(before[:380], after[:380])
    assert g["samples_compared"] == 380 and g["samples"] == 500
    assert g["relative"] == ref["relative"] and g["ci95"] == ref["ci95"] and g["before"] == ref["before"]
    none = gain_ci(np.full((50, 1), np.nan), after[:50])
    assert none["samples_compared"] == 0 and none["ci95"] == [0.0, 0.0] and none["relative"] == 0.0
