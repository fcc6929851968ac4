"""A noise model's relative gain is the drop of the errors' scale that its likelihood gain equals
(``noise.nll_scale_gain``: 1 − exp(−ΔNLL/n_outputs)), not a ratio of NLL values, which changed with
the output's unit (an auditor's record: 36.9 % in metres, 31.8 % in millimetres, reported as "lowers
the validation RMSE by"). Closed form: AR(1) noise of coefficient φ on a correct structure, whitened
by the noise model, has innovation σ against the marginal σ/√(1 − φ²), so the gain tends to
1 − √(1 − φ²).

The record is made by ``scipy.integrate.solve_ivp`` (a mass–spring–damper on a held random-step input)
with AR(0.95) noise from ``scipy.signal.lfilter``: no code shared with the detector."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest
import yaml
from scipy.integrate import solve_ivp
from scipy.signal import lfilter

from pipeline.config import load_config
from pipeline.diagnostics.noise import nll_scale_gain
from pipeline.report import view
from pipeline.runs import analyse

PHI, N, DT = 0.95, 1200, 0.05


def _record(scale: float) -> np.ndarray:
    rng = np.random.default_rng(7)
    t = np.arange(N) * DT
    u = np.repeat(rng.uniform(-2, 2, N // 8 + 1), 8)[:N]
    z, x = np.zeros(2), np.zeros(N)
    for i in range(N):
        x[i] = z[0]
        if i < N - 1:
            z = solve_ivp(lambda _t, s: [s[1], u[i] - 0.6 * s[1] - 4.0 * s[0]], (t[i], t[i + 1]), z,
                          rtol=1e-10, atol=1e-12).y[:, -1]
    x = x + lfilter([1.0], [1.0, -PHI], 0.003 * rng.standard_normal(N))
    return np.c_[t, scale * u, scale * x]


def _summary(tmp_path, name: str, scale: float) -> dict:
    d = tmp_path / name
    d.mkdir()
    np.savetxt(d / "r.csv", _record(scale), delimiter=",", header="t,u,x", comments="", fmt="%.10g")
    cfg = {"name": name, "seed": 0,
           "data": {"path": "r.csv", "time": "t", "inputs": ["u"], "outputs": ["x"]},
           "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": 1.0, "c": 0.6, "k": 4.0},
                     "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"},
                     "initial": {"x": 0.0, "v": 0.0}},
           "split": {"validation_fraction": 0.3},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (d / "c.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(d / "c.yaml")).summary


def test_nll_scale_gain_is_the_gaussian_scale_ratio():
    """For Gaussian errors the NLL per sample is ln σ + ½ ln 2πe: a drop ln(σ_b/σ_a) gives 1 − σ_a/σ_b;
    over two outputs the summed drop gives the geometric mean of the two ratios."""
    assert nll_scale_gain(math.log(2.0), 1) == pytest.approx(0.5, rel=1e-12)
    assert nll_scale_gain(math.log(2.0) + math.log(8.0), 2) == pytest.approx(0.75, rel=1e-12)
    assert nll_scale_gain(-math.log(2.0), 1) == pytest.approx(-1.0, rel=1e-12)


def test_coloured_noise_gain_is_unit_free_and_near_its_closed_form(tmp_path):
    s_m, s_mm = _summary(tmp_path, "metres", 1.0), _summary(tmp_path, "millimetres", 1000.0)
    f_m, f_mm = s_m["diagnosis"]["findings"][0], s_mm["diagnosis"]["findings"][0]
    assert f_m["family"] == f_mm["family"] == "colored_noise"
    g, g_mm = f_m["gain"], f_mm["gain"]
    assert g["metric"] == "validation_nll" and g["before"] != pytest.approx(g_mm["before"], abs=1.0)
    # the same record in other units: the NLLs shift by ln 1000, the gain and its interval do not
    assert g_mm["relative"] == pytest.approx(g["relative"], rel=1e-6)
    assert g_mm["ci95"] == pytest.approx(g["ci95"], rel=1e-6)
    assert g["relative"] == pytest.approx(nll_scale_gain(g["before"] - g["after"], 1), rel=1e-9)
    assert g["ci95"] == pytest.approx([nll_scale_gain(a, 1) for a in g["absolute_ci95"]], rel=1e-9)
    # 1 − √(1 − 0.95²) = 0.688; measured 0.693 on 360 validation samples, interval 0.646 to 0.734
    truth = 1.0 - math.sqrt(1.0 - PHI ** 2)
    assert abs(g["relative"] - truth) < 0.03 and g["ci95"][0] < truth < g["ci95"][1]
    # the first screen says likelihood, not RMSE, and that the simulation is the one before
    text = " ".join(view.first_screen(s_m)["lines"])
    assert "negative log-likelihood per sample" in text and "lowers the validation RMSE" not in text
    assert "does not change the free-run simulation" in text and "The free-run fit is unchanged" in text
