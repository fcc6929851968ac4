"""A nominal model that reproduces the record to rounding error is not diagnosed.

An independent probe fitted x' = b·u to its exact solution for a held input (x_{k+1} = x_k + b·u_k·dt, a
cumulative sum, no noise): free-run RMSE 3e-14, and the run named "the parameter b jumps from 1 to 1 at
t = 29.11 s" (BIC 1318 better), coloured and heavy-tailed noise. Every test reads floating-point
rounding as a signal. The record here is that cumulative sum (numpy, not the project's simulator)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pandas as pd
import yaml

from pipeline.cli import main


def _record(tmp_path, noise: float):
    rng = np.random.default_rng(5)
    n, dt = 3000, 0.02
    u = np.repeat(rng.standard_normal(n // 10), 10)
    x = np.concatenate([[0.0], np.cumsum(u[:-1] * dt)])         # exact zoh solution of x' = u
    x = x + noise * np.std(x) * rng.standard_normal(n)
    pd.DataFrame({"t": np.arange(n) * dt, "u": u, "x": x}).to_csv(tmp_path / "d.csv", index=False)
    cfg = {"name": "integrator", "seed": 0,
           "data": {"path": "d.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "zoh"},
           "model": {"states": ["x"], "inputs": ["u"], "params": {"b": 0.8}, "free": ["b"],
                     "equations": {"x": "b*u"}, "initial": {"x": 0.0}},
           "split": {"validation_fraction": 0.3}, "diagnose": {"families": "all", "max_findings": 3}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    return (json.loads((tmp_path / "run" / "summary.json").read_text())["diagnosis"],
            (tmp_path / "run" / "report.html").read_text(encoding="utf-8"))


def test_an_exact_fit_is_not_diagnosed(tmp_path):
    d, html = _record(tmp_path, 0.0)
    assert d["verdict"] == "no_significant_discrepancy" and d["findings"] == []
    assert "rounding error" in d["rounding_level"] and d["families_tested"] == []
    rows = d["tests"] + d["final_tests"]
    assert rows and all(not r["tested"] and "rounding error" in r["detail"] for r in rows)
    assert "Nothing to diagnose: the nominal model reproduces the record to rounding error" in html


def test_a_record_with_measurement_noise_is_diagnosed(tmp_path):
    """1e-6 of the output's spread (far below any sensor, far above rounding): the tests run."""
    d, _ = _record(tmp_path, 1e-6)
    assert "rounding_level" not in d and d["families_tested"]
    assert any(r["tested"] for r in d["tests"])
