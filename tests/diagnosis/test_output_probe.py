"""A sensor's static nonlinearity (y = x + c·x³) that no family holds: the ``state_nonlinearity`` probe
also tests the measured output (a gain and Gaussian bumps of the measured state added to the output),
so the run says "unexplained" instead of calling the smooth residual coloured noise.

Records made here by ``scipy.integrate.solve_ivp`` on a continuous-time multisine input (no code shared
with the detector). Before the output probe, the sensor records below ended ``colored_noise`` on white
measurement noise (the independent bench's generator with a cubic sensor law, seed 0: 4 of 18 records
with 2 % white noise)."""

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
from pipeline.diagnostics import stats
from pipeline.runs import analyse

DT = 0.02
NOISE = {"colored_noise", "heavy_tailed_noise", "heteroscedastic_noise"}


def _sensor_record(folder: Path, seed: int, share: float, noise: float, phi: float = 0.0, n: int = 2000) -> Path:
    """x'' = u − 0.6 x' − 4 x with u a continuous eight-sine signal, integrated by ``solve_ivp`` (dense,
    rtol 1e-10); measured y = x + c·(x − x̄)³ with std(c·(x − x̄)³) = ``share``·std(x), plus AR(1)(``phi``)
    noise of standard deviation ``noise``·std(x). The config is the linear model with c and k free, foh
    (the input is smooth)."""
    rng = np.random.default_rng(seed)
    f, ph, a = rng.uniform(0.05, 0.8, 8), rng.uniform(0, 2 * np.pi, 8), rng.uniform(0.5, 1.0, 8)
    t = np.arange(n) * DT

    def u(s):
        return float(np.sum(a * np.sin(2 * np.pi * f * s + ph))) / 2

    sol = solve_ivp(lambda s, z: [z[1], u(s) - 0.6 * z[1] - 4.0 * z[0]], (0.0, t[-1]), [0.0, 0.0], t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=DT)
    x = sol.y[0]
    d = x - x.mean()
    c3 = share * np.std(x) / np.std(d ** 3) if share > 0 else 0.0
    w = np.random.default_rng(seed + 7).standard_normal(n)
    e = np.empty(n)
    e[0] = w[0] / np.sqrt(1 - phi ** 2)
    for k in range(1, n):
        e[k] = phi * e[k - 1] + w[k]
    y = x + c3 * d ** 3 + noise * np.std(x) * e / np.std(e)
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"t": t, "u": [u(s) for s in t], "x": y}).to_csv(folder / "data.csv", index=False)
    cfg = {"name": "sensor", "seed": seed,
           "data": {"path": "data.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh",
                    "remove_mean": False},
           "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": 1.0, "c": 0.5, "k": 3.5},
                     "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"},
                     "initial": {"x": 0.0, "v": 0.0}},
           "split": {"validation_fraction": 0.3}, "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (folder / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder / "config.yaml"


def _diagnosis(path: Path) -> dict:
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(path)).summary["diagnosis"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_cubic_sensor_law_is_unexplained_not_coloured_noise(tmp_path, seed):
    """A cubic sensor law worth 15 % of the output's spread, 2 % white noise: no family holds it, so the
    verdict is unexplained; the probe of the measured output fails adequacy and says where."""
    d = _diagnosis(_sensor_record(tmp_path / "s", seed, share=0.15, noise=0.02))
    assert d["verdict"] == "unexplained_discrepancy"
    assert not NOISE & {f["family"] for f in d["findings"]}
    row = next(t for t in d["adequacy"] if t["name"] == "state_nonlinearity")
    assert not row["passed"] and "the measured output x" in row["detail"]


def test_coloured_noise_on_a_linear_sensor_stays_coloured_noise(tmp_path):
    """The other side: the same plant with a linear sensor and AR(1) noise (φ = 0.9, 10 %): the output
    probe finds nothing, and the colour is the noise's."""
    d = _diagnosis(_sensor_record(tmp_path / "s", 0, share=0.0, noise=0.1, phi=0.9))
    assert [f["family"] for f in d["findings"]] == ["colored_noise"]
    row = next(t for t in d["adequacy"] if t["name"] == "state_nonlinearity")
    assert row["passed"]


def test_determined_drops_a_column_the_parameters_already_produce():
    """``stats.determined``: a probe column inside the span of J (an output gain beside a free input
    gain) is rounding noise after the projection and is dropped, and the Wald test on the kept directions
    is the test on the other two columns up to the HAC design correction (the Wald statistic of a joint
    test is invariant to an invertible reparametrisation of the added columns); with nothing collinear
    the columns are returned as they are, so existing probes' tests do not change at all."""
    rng = np.random.default_rng(3)
    n = 600
    J = rng.standard_normal((n, 2))
    S = np.column_stack([rng.standard_normal(n), J @ [0.3, -1.2], rng.standard_normal(n)])
    e = 0.2 * S[:, 0] + rng.standard_normal(n)
    basis = stats.column_basis(J)
    kept = stats.determined(S, basis)
    assert kept.shape[1] == 2
    assert stats.determined(S[:, [0, 2]], basis) is not None
    assert np.array_equal(stats.determined(S[:, [0, 2]], basis), S[:, [0, 2]])
    a = stats.added_terms_test(e, J, kept)
    b = stats.added_terms_test(e, J, S[:, [0, 2]])
    assert a.statistic == pytest.approx(b.statistic, rel=1e-2) and a.dof == b.dof == 2
    # and a rounding-noise column kept as a regressor is what the reduction prevents: the projected
    # collinear column is at the rounding level, 1e-12 of the others
    Sp = S - basis @ (basis.T @ S)
    assert np.linalg.norm(Sp[:, 1]) < 1e-12 * np.linalg.norm(Sp[:, 0])
