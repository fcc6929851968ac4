"""What the structure stage's ``cv_rmse_one_step`` is (audit D5): for a continuous-time structure the
regression target is dx/dt estimated from the data, so the number is the equation error of dx/dt (in
the state's unit per second), not a one-step-ahead prediction of x; the summary row says so in added
keys (``cv_rmse_one_step`` keeps its name) and the report's column is labelled from them."""

import contextlib
import io
import json

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from pipeline.cli import main
from pipeline.prefilter import derivative
from pipeline.selection import blocked_folds

DT = 0.05
CANDIDATES = {"M1": ["x", "x**3"], "M2": ["tanh(x)"]}


def _u(t):
    return 1.5 * np.sin(0.4 * t) + np.sin(1.3 * t + 0.5)


@pytest.fixture(scope="module")
def ct_run(tmp_path_factory):
    """x' = −x − 0.5 x³ + u integrated by solve_ivp, 1 cm measurement noise, x in metres."""
    d = tmp_path_factory.mktemp("onestep")
    t = np.arange(600) * DT
    sol = solve_ivp(lambda tt, z: [-z[0] - 0.5 * z[0] ** 3 + _u(tt)], (0, t[-1]), [0.0], t_eval=t,
                    rtol=1e-10, atol=1e-12)
    x = sol.y[0] + 0.01 * np.random.default_rng(11).standard_normal(t.size)
    pd.DataFrame({"t": t, "u": _u(t), "x": x}).to_csv(d / "ct.csv", index=False, float_format="%.12g")
    cfg = {"name": "onestep", "seed": 3,
           "data": {"path": "ct.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh"},
           "model": {"states": ["x"], "inputs": ["u"], "params": {"a": 1.0}, "free": ["a"],
                     "equations": {"x": "-a*x + u"}},
           "diagnose": {"max_findings": 0},
           "structures": {"equation": "x", "known": "u", "candidates": CANDIDATES, "cv_folds": 4},
           "estimators": ["ls"], "units": {"x": "m"}}
    (d / "ct.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with contextlib.redirect_stderr(io.StringIO()):
        assert main(["report", str(d / "ct.yaml"), "--out", str(d / "out")]) == 0
    s = json.loads((d / "out" / "summary.json").read_text())
    return t, x, s, (d / "out" / "report.html").read_text(encoding="utf-8")


def _rows(s):
    return {m["name"]: m for m in s["models"] if m.get("estimator") == "ls" and "cv_rmse_one_step" in m}


def test_a_derivative_target_is_labelled_equation_error_in_the_summary(ct_run):
    _, _, s, _ = ct_run
    rows = _rows(s)
    assert set(rows) == set(CANDIDATES)
    for m in rows.values():
        assert m["cv_rmse_one_step"] and len(m["cv_rmse_one_step"]) == 4   # the key keeps its name
        assert m["cv_rmse_one_step_kind"] == "equation_error"
        assert m["cv_rmse_one_step_measures"].startswith("equation error of dx/dt, in m/s")
        assert "not a one-step-ahead prediction of x" in m["cv_rmse_one_step_measures"]


def test_the_value_is_the_rms_of_the_derivative_regression_residual_not_a_one_step_prediction(ct_run):
    """Recomputed from scratch: LS on target = savgol dx/dt − u over each fold's estimation rows, RMS of
    target − Φθ on the fold's block; the one-step-ahead prediction of x by the same fitted ODE (RK4
    from each measured x[k] to t[k+1], foh input) is a different number, in metres."""
    t, x, s, _ = ct_run
    m = _rows(s)["M1"]
    dc = s["structures"]["settings"]["derivative"]
    dx, _ = derivative(x, DT, dc["method"], window=dc["window"], polyorder=dc["polyorder"], warn=False)
    u = _u(t)
    target = dx - u
    Phi = np.column_stack([x, x ** 3])
    e0, e1 = s["data"]["estimation"]
    est = np.arange(e0, e1)
    eqerr, onestep = [], []
    for train, val in blocked_folds(len(est), 4, s["structures"]["settings"]["gap"]):
        th = np.linalg.lstsq(Phi[est[train]], target[est[train]], rcond=None)[0]
        rows = est[val]
        eqerr.append(np.sqrt(np.mean((target[rows] - Phi[rows] @ th) ** 2)))
        k = rows[rows + 1 < len(t)]
        f = lambda xx, tau: th[0] * xx + th[1] * xx ** 3 + (u[k] + (u[k + 1] - u[k]) * tau / DT)
        xk, h = x[k].copy(), DT / 20
        for i in range(20):
            tau = i * h
            k1 = f(xk, tau)
            k2 = f(xk + h / 2 * k1, tau + h / 2)
            k3 = f(xk + h / 2 * k2, tau + h / 2)
            k4 = f(xk + h * k3, tau + h)
            xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        onestep.append(np.sqrt(np.mean((x[k + 1] - xk) ** 2)))
    assert m["cv_rmse_one_step"] == pytest.approx(eqerr, rel=1e-6)
    # the equation error of dx/dt is several times the one-step prediction error of x here
    assert np.mean(m["cv_rmse_one_step"]) > 2 * np.mean(onestep)


def test_the_report_column_and_note_say_equation_error(ct_run):
    _, _, _, html = ct_run
    table = html.split("Candidate structures for dx/dt")[1].split("</table>")[0]
    assert "<th>CV RMSE equation error (dx/dt)</th>" in table and "CV RMSE one-step" not in table
    note = html.split("Candidate structures for dx/dt")[1].split("</table>")[1].split("</p>")[0]
    assert "equation error of dx/dt, in m/s" in note and "not a one-step-ahead prediction of x" in note
    assert "unless a column says one-step or equation error" in html
