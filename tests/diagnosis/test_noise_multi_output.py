"""Noise families on a record with two outputs (issue 8, "more than one output"; issue 9, noise
families on a structurally adequate model).

The record is made here with ``scipy.integrate.solve_ivp`` on continuous-time inputs, and its noise
with numpy / ``scipy.signal.lfilter``, sharing no code with the detector: two coupled thermal
capacities of :mod:`.two_capacity` with no structural error, measured as y1 = 1000 T1 and T2 (the
outputs differ 1000× in scale). Each test puts
one noise property on one or both outputs and asserts that it is named on the output(s) it was put on,
with its key parameter; the Hausman matrix on two outputs is checked against its explicit matrix form.
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp
from scipy.linalg import block_diag, toeplitz
from scipy.signal import lfilter

from pipeline.config import load_config
from pipeline.diagnostics.hausman import covariance_of_difference, covariance_of_difference_multi
from pipeline.runs import analyse

from .two_capacity import A1, A2, B1, B2, G, config, inputs

DT, N = 0.05, 3000
NOISE_FAMILIES = ["colored_noise", "heavy_tailed_noise", "heteroscedastic_noise"]


def _clean(seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    u1, u2 = inputs(seed)
    t = np.arange(N) * DT

    def f(s, x):
        return [B1 * u1(s) - A1 * x[0] + G * (x[1] - x[0]), B2 * u2(s) - A2 * x[1] - G * (x[1] - x[0])]

    sol = solve_ivp(f, (0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-11, max_step=DT)
    return t, {"u1": u1(t), "u2": u2(t), "y1": 1000 * sol.y[0], "T2": sol.y[1]}


def _noise(kind: str, clean: np.ndarray, level: float, rng: np.random.Generator, phi: float = 0.0):
    """Unit-variance noise of the kind (white Gaussian, AR(1) with φ, Student t₃, or a level that
    grows with |y − ȳ|) times ``level`` × std(clean)."""
    s = level * np.std(clean)
    if kind == "white":
        return s * rng.standard_normal(N)
    if kind == "ar":
        e = lfilter([1.0], [1.0, -phi], rng.standard_normal(N))
        return s * e / np.std(e)
    if kind == "t3":
        return s * rng.standard_t(3, N) / math.sqrt(3.0)
    if kind == "hetero":
        dev = np.abs(clean - clean.mean())
        return s * (0.2 + 1.6 * dev / dev.mean()) * rng.standard_normal(N)
    raise ValueError(kind)


def _run(tmp: Path, name: str, noise: dict[str, tuple], seed: int) -> dict:
    t, d = _clean(seed)
    rng = np.random.default_rng(seed + 7)
    for y, (kind, level, *phi) in noise.items():
        d[y] = d[y] + _noise(kind, d[y], level, rng, *phi)
    folder = tmp / name
    folder.mkdir()
    pd.DataFrame({"t": t, **d}).to_csv(folder / "data.csv", index=False)
    cfg = config(name, seed, ["offset", "static_nonlinearity"] + NOISE_FAMILIES)
    (folder / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(folder / "config.yaml")).summary["diagnosis"]


def test_coloured_noise_on_both_outputs_is_named_with_each_outputs_correlation_time(tmp_path):
    phis = {"y1": 0.8, "T2": 0.6}
    d = _run(tmp_path, "ar", {"y1": ("ar", 0.05, phis["y1"]), "T2": ("ar", 0.05, phis["T2"])}, 11)
    assert d["verdict"] == "discrepancy"
    f = d["findings"][0]
    assert f["family"] == "colored_noise" and f["outputs"] == ["y1", "T2"]
    for y, phi in phis.items():
        tau = f["per_output"][y]["correlation_time_s"]
        assert tau == pytest.approx(-DT / math.log(phi), rel=0.2), y
        assert f["per_output"][y]["noise_model"]["phi1"] == pytest.approx(phi, abs=0.1)
    g = f["gain"]
    assert g["metric"] == "validation_nll" and g["ci95"][0] > 0 and g["ci95"][0] <= g["relative"] <= g["ci95"][1]
    # the evidence is each output's own Ljung–Box test
    assert sorted(e["test"] for e in f["evidence"]) == ["ljung_box", "ljung_box[T2]"]
    assert all(e["p_value"] < 1e-6 for e in f["evidence"])


def test_heavy_tails_on_one_output_are_named_on_that_output_only(tmp_path):
    d = _run(tmp_path, "t3", {"y1": ("white", 0.05), "T2": ("t3", 0.05)}, 12)
    fams = [f["family"] for f in d["findings"]]
    assert fams[0] == "heavy_tailed_noise", fams
    f = d["findings"][0]
    assert f["outputs"] == ["T2"]
    assert 2.0 <= f["df"] <= 5.0           # ν = 3 put in
    assert "colored_noise" not in fams


def test_heteroscedastic_noise_on_one_output_is_named_with_a_growing_level(tmp_path):
    d = _run(tmp_path, "het", {"y1": ("hetero", 0.05), "T2": ("white", 0.05)}, 13)
    f = d["findings"][0]
    assert f["family"] == "heteroscedastic_noise" and f["outputs"] == ["y1"]
    vm = f["variance_model"]
    assert vm["b"] > 0 and "grows" in f["description"]


def test_white_noise_on_both_outputs_gives_no_noise_finding(tmp_path):
    d = _run(tmp_path, "white", {"y1": ("white", 0.05), "T2": ("white", 0.05)}, 14)
    assert d["findings"] == [] and d["verdict"] == "no_significant_discrepancy"


def test_two_output_covariance_of_the_difference_matches_the_explicit_matrix_form():
    """Var(θ̂_PEM − θ̂_OE) = P Σ Pᵀ, P = (J̃ᵀCJ̃)⁻¹J̃ᵀCF − (JᵀWJ)⁻¹JᵀW on the stacked outputs:
    J = [J₁; J₂], W = diag(w_j² I), F = blockdiag(F_j) the AR prediction-error filter matrices
    (output 2 white: F₂ = I), J̃ = FJ, C = diag(c_j² I), Σ = blockdiag(σ_j² H_j H_jᵀ); every matrix
    is built explicitly here. With one output the multi-output form equals the single-output one."""
    rng = np.random.default_rng(5)
    n = 200
    As = [np.array([0.7, -0.2]), np.zeros(0)]
    s2s, w, c = [0.3, 0.05], [2.0, 0.5], [1.5, 4.0]
    Js = [rng.standard_normal((n, 3)).cumsum(axis=0) / 10 for _ in range(2)]
    Fs, Hs = [], []
    for a in As:
        p = len(a)
        h = lfilter([1.0], np.r_[1.0, -a], np.r_[1.0, np.zeros(n - 1)])
        Hs.append(toeplitz(h, np.zeros(n)))
        F = np.zeros((n - p, n))
        for r, t in enumerate(range(p, n)):
            F[r, t] = 1.0
            F[r, t - 1 - np.arange(p)] = -a
        Fs.append(F)
    J = np.vstack(Js)
    W = block_diag(*[w[j] ** 2 * np.eye(n) for j in range(2)])
    F = block_diag(*Fs)
    C = block_diag(*[c[j] ** 2 * np.eye(Fs[j].shape[0]) for j in range(2)])
    Jt = F @ J
    P = np.linalg.inv(Jt.T @ C @ Jt) @ Jt.T @ C @ F - np.linalg.inv(J.T @ W @ J) @ J.T @ W
    Sig = block_diag(*[s2s[j] * Hs[j] @ Hs[j].T for j in range(2)])
    np.testing.assert_allclose(covariance_of_difference_multi(Js, As, s2s, w, c), P @ Sig @ P.T,
                               rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(covariance_of_difference_multi(Js[:1], As[:1], s2s[:1], w[:1], c[:1]),
                               covariance_of_difference(Js[0], As[0], s2s[0]), rtol=1e-10, atol=1e-16)
