"""A saturating spring c·tanh(x/s) is named with its own scale, not the state's spread
(``families/static_nonlinearity.py``, ``StaticNonlinearity.estimate``).

Records from ``scipy.integrate.solve_ivp`` on held input levels (no pipeline code): a mass-spring-damper
with two inputs, x'' = −k x − c x' + b1 u1 + b2 u2 − 1.5·tanh(x/s), s = 0.2 or 0.5, 2 % white noise
(the independent probe's ``ti_tanh_lo`` / ``ti_tanh05_lo``). The term was tested and refitted at the
state's spread (0.54 and 0.78 here): −2.87·tanh(x/0.54), then a second tanh of coefficient 62, verdict
"unexplained". The scale is now estimated: one finding, scale and coefficient within 20 %.
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

DT, N = 0.05, 3000
K, C, B1, B2, F = 4.0, 0.6, 1.0, 0.5, -1.5


def _held(rng: np.random.Generator) -> np.ndarray:
    """Levels U(−2, 2) held for 10–60 samples."""
    u = np.empty(N)
    k = 0
    while k < N:
        h = int(rng.integers(10, 61))
        u[k:k + h] = rng.uniform(-2.0, 2.0)
        k += h
    return u


def _record(path: Path, seed: int, s: float) -> None:
    rng = np.random.default_rng(seed)
    u1, u2 = _held(rng), _held(rng)
    t = np.arange(N) * DT
    x = np.zeros((N, 2))
    for k in range(N - 1):       # one integration per sample interval: the input is held there
        f = lambda _t, z, a=u1[k], b=u2[k]: [z[1], -K * z[0] - C * z[1] + B1 * a + B2 * b + F * np.tanh(z[0] / s)]
        x[k + 1] = solve_ivp(f, (t[k], t[k + 1]), x[k], method="DOP853", rtol=1e-10, atol=1e-12).y[:, -1]
    y = x[:, 0] + 0.02 * np.std(x[:, 0]) * rng.standard_normal(N)
    pd.DataFrame({"t": t, "u1": u1, "u2": u2, "x": y}).to_csv(path, index=False)


@pytest.mark.parametrize("seed, s", [(3, 0.2), (4, 0.5)])
def test_a_tanh_spring_is_named_with_its_scale(tmp_path, seed, s):
    _record(tmp_path / "r.csv", seed, s)
    cfg = {"name": "tanh", "seed": 0,
           "data": {"path": "r.csv", "time": "t", "inputs": ["u1", "u2"], "outputs": ["x"], "intersample": "zoh"},
           "model": {"states": ["x", "v"], "inputs": ["u1", "u2"], "params": {"k": 4.0, "c": 0.6, "b1": 1.0, "b2": 0.5},
                     "free": ["k", "c", "b1", "b2"], "equations": {"x": "v", "v": "-k*x - c*v + b1*u1 + b2*u2"},
                     "initial": {"x": 0.0, "v": 0.0}},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(tmp_path / "c.yaml")).summary["diagnosis"]
    f = d["findings"]
    assert [(x["family"], x.get("equation")) for x in f] == [("static_nonlinearity", "v")], \
        [x["description"] for x in f]
    assert f[0]["term"].startswith("tanh(x/")
    assert f[0]["scale"] == pytest.approx(s, rel=0.2)
    assert f[0]["coefficient"] == pytest.approx(F, rel=0.2)
    assert d["verdict"] == "discrepancy"
