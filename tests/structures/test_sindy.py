"""SINDy (Brunton, Proctor & Kutz 2016) through pysindy: Duffing recovery, free-run simulation, CV threshold."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pipeline.errors import InputError
from pipeline.structures.library import poly
from pipeline.structures.sindy import fit_sindy, simulation_nmse

DELTA, ALPHA, BETA = 0.3, 1.0, 2.0
TRUE = {"x'": {"v": 1.0}, "v'": {"x": -ALPHA, "v": -DELTA, "x**3": -BETA, "u": 1.0}}


def u_of(t):
    return 0.8 * np.sin(0.7 * t) + 0.5 * np.cos(1.9 * t + 0.3)


def duffing(T=40.0, dt=0.01, x0=(1.0, 0.0)):
    """Clean record of x' = v, v' = -δv - αx - βx³ + u(t) (smooth input, tight tolerances)."""
    t = np.arange(0.0, T, dt)
    sol = solve_ivp(lambda tt, z: [z[1], -DELTA * z[1] - ALPHA * z[0] - BETA * z[0] ** 3 + u_of(tt)],
                    (0, t[-1]), list(x0), t_eval=t, method="DOP853", rtol=1e-11, atol=1e-12)
    return t, {"x": sol.y[0], "v": sol.y[1], "u": u_of(t)}


@pytest.fixture(scope="module")
def record():
    return duffing()


def coef_dict(model):
    return [{n: c for n, c in zip(model.library.names, row) if c != 0} for row in model.coef]


@pytest.mark.parametrize("optimizer", ["stlsq", "sr3"])
def test_recovers_duffing_equations_within_2_percent(record, optimizer):
    t, data = record
    model = fit_sindy(data, ["x", "v"], poly(["x", "v", "u"], 3), t, inputs=["u"], optimizer=optimizer,
                      threshold=0.1)
    got = coef_dict(model)
    for eq, row in zip(["x'", "v'"], got):
        assert set(row) == set(TRUE[eq])
        for name, c in TRUE[eq].items():
            assert row[name] == pytest.approx(c, rel=0.02)


def test_equations_are_readable(record):
    t, data = record
    model = fit_sindy(data, ["x", "v"], poly(["x", "v", "u"], 3), t, inputs=["u"], threshold=0.1)
    eqs = model.equations(precision=2)
    assert eqs[0] == "x' = 1.00 v"
    assert eqs[1].startswith("v' = ") and "- 2.00 x**3" in eqs[1] and "- 0.30 v" in eqs[1] and "1.00 u" in eqs[1]


def test_discovered_model_simulates_the_record_free_run(record):
    t, data = record
    model = fit_sindy(data, ["x", "v"], poly(["x", "v", "u"], 3), t, inputs=["u"], threshold=0.1)
    sl = slice(0, 1500)
    X = np.column_stack([data["x"], data["v"]])[sl]
    xs = model.simulate(X[0], t[sl], data["u"][sl, None])
    assert np.max(np.abs(xs - X)) < 0.02 * np.max(np.abs(X))
    assert simulation_nmse(model, X, data["u"][sl, None], t[sl]) < 1e-3
    # a wrong model (cubic term dropped) is visibly worse on the same free-run score
    wrong = type(model)(model.states, model.inputs, model.library, model.coef.copy(), 0.1, "stlsq")
    wrong.coef[1, model.library.names.index("x**3")] = 0.0
    assert simulation_nmse(wrong, X, data["u"][sl, None], t[sl]) > 100 * simulation_nmse(model, X, data["u"][sl, None], t[sl])


def test_threshold_chosen_by_blocked_cv_on_free_run_simulation():
    t, data = duffing(T=24.0, dt=0.02)
    rng = np.random.default_rng(7)
    noisy = {k: v + (0.01 * rng.normal(size=v.size) if k in ("x", "v") else 0) for k, v in data.items()}
    thresholds = [0.0, 0.1, 0.5]  # 0: noise-fitted spurious terms; 0.5 > |δ| = 0.3 removes the damping term
    model = fit_sindy(noisy, ["x", "v"], poly(["x", "v", "u"], 3), t, inputs=["u"], threshold=thresholds,
                      differentiation="smoothed_finite_difference", cv_folds=3, cv_gap=10, seed=0)
    cv = model.cv
    assert cv["label"].startswith("free-run simulation error")
    assert cv["scores"].shape == (3, 3)
    assert model.threshold == cv["chosen"] == 0.1
    assert cv["mean"][0] > 3 * cv["mean"][1] and cv["mean"][2] > 10 * cv["mean"][1]
    assert set(coef_dict(model)[1]) == set(TRUE["v'"])


def test_bad_input(record):
    t, data = record
    lib = poly(["x", "v", "u"], 3)
    with pytest.raises(InputError, match="differentiation"):
        fit_sindy(data, ["x", "v"], lib, t, inputs=["u"], differentiation="magic")
    with pytest.raises(InputError, match="optimizer"):
        fit_sindy(data, ["x", "v"], lib, t, inputs=["u"], optimizer="lasso")
    with pytest.raises(InputError, match="neither states"):
        fit_sindy(data, ["x", "v"], lib, t)
    short = {k: v[:15] for k, v in data.items()}
    with pytest.raises(InputError, match="20 candidate terms for 15 samples"):
        fit_sindy(short, ["x", "v"], lib, t[:15], inputs=["u"])
    with pytest.raises(InputError, match="delayed"):
        fit_sindy(data, ["x", "v"], ["x(t-1)"], t)
