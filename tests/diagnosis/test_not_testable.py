"""``diagnosis.not_testable``: a guard that keeps a hypothesis from being tested says so in the summary.
A first-order plant with a slow sinusoidal disturbance of 1.2 cycles in the estimation window, made by
scipy's solve_ivp: the residual's periodogram peaks there, and a periodic term needs two cycles."""

import contextlib
import io

import numpy as np
import pandas as pd
import yaml
from scipy.integrate import solve_ivp

from pipeline.config import load_config
from pipeline.runs import analyse


def test_a_periodic_peak_with_too_few_cycles_is_listed_as_not_testable(tmp_path):
    n, dt = 1000, 0.1
    t = np.arange(n) * dt
    est_span = 0.7 * n * dt                         # validation_fraction 0.3
    f = 1.2 / est_span
    u = lambda s: np.sin(1.3 * s) + 0.6 * np.sin(0.37 * s + 1.0)
    sol = solve_ivp(lambda s, x: -0.8 * x + 1.5 * u(s) + 0.6 * np.sin(2 * np.pi * f * s), (0, t[-1]), [0.0],
                    t_eval=t, rtol=1e-10, atol=1e-12, max_step=dt)
    y = sol.y[0] + 0.01 * np.random.default_rng(0).normal(size=n)
    pd.DataFrame({"t": t, "u": u(t), "x": y}).to_csv(tmp_path / "d.csv", index=False)
    cfg = {"name": "slow", "seed": 0,
           "data": {"path": "d.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh"},
           "model": {"states": ["x"], "inputs": ["u"], "params": {"a": 1.0, "b": 1.0}, "free": ["a", "b"],
                     "equations": {"x": "-a*x + b*u"}, "initial": {"x": 0.0}},
           "diagnose": {"families": ["periodic_disturbance"], "max_findings": 1}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(tmp_path / "c.yaml")).summary
    d = s["diagnosis"]
    assert not d["findings"]
    nt = [g for g in d["not_testable"] if g["family"] == "periodic_disturbance"]
    assert len(nt) == 1 and "cycles in the estimation window" in nt[0]["reason"]
    # each reason once, though the loop may propose it again
    assert len({(g["family"], g["reason"]) for g in d["not_testable"]}) == len(d["not_testable"])
