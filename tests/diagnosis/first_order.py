"""The first-order records of the Monte Carlo tests (test_hausman.py, test_input_direction.py,
test_input_coherence.py, test_noise_gate.py): a held-step input, the exact zero-order-hold response of
y' = −a y + b u (scipy.signal.lfilter), AR(1) output noise, and the nominal model written as a config
and loaded as the pipeline loads a user's record. Written here, sharing no code with the detector."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.signal import lfilter

from pipeline.config import load_config
from pipeline.diagnostics.adequacy import MATERIAL_R2
from pipeline.data import load_record, make_split
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model


def held_steps(rng: np.random.Generator, n: int) -> np.ndarray:
    """n samples of uniform levels in ±1, each held for 8–40 samples."""
    steps = np.repeat(rng.uniform(-1, 1, n // 8 + 1), rng.integers(8, 40, n // 8 + 1))[:n]
    return np.concatenate([steps, np.zeros(max(0, n - len(steps)))])


def zoh_first_order(u: np.ndarray, dt: float, a: float, b: float) -> np.ndarray:
    """y' = −a y + b u from rest, sampled every dt with u held between samples: exactly
    y_{k+1} = e^{−a dt} y_k + (b/a)(1 − e^{−a dt}) u_k."""
    e1 = np.exp(-a * dt)
    return lfilter([0.0, b / a * (1 - e1)], [1.0, -e1], u)


def ar1(rng: np.random.Generator, n: int, phi: float, burn: int = 300) -> np.ndarray:
    """n samples of an AR(1) process with unit innovations, after ``burn`` samples of warm-up."""
    return lfilter([1.0], [1.0, -phi], rng.standard_normal(n + burn))[burn:]


def p_and_share(n: int, row_of) -> tuple[np.ndarray, np.ndarray]:
    """The Monte Carlo loop of the size tests: p-values and explained shares (``r2``) of the test rows
    ``row_of(k)``, k = 0..n−1, in that order (so the records' random draws stay the same)."""
    rows = [row_of(k) for k in range(n)]
    return np.array([r.p_value for r in rows]), np.array([r.r2 for r in rows])


def assert_sized(p: np.ndarray, share: np.ndarray, phi: float, k: int = 1) -> None:
    """The size checks of an adequacy row on correct structures: it rejects at most 1.5 α at α = 5 % and
    1 %, the adequacy rule (p < 1 % and a share ≥ MATERIAL_R2) fires at most 1 % of the time,
    and (at φ = 0.5) it is not a test that never rejects. ``k``: the row's p-value is Bonferroni's over
    k tests (k·min p_i); the last check is then that one of them alone rejects at 5 % (p < k·5 %)."""
    assert np.mean(p < 0.05) <= 1.5 * 0.05
    assert np.mean(p < 0.01) <= 1.5 * 0.01
    assert np.mean((p < 0.01) & (share >= MATERIAL_R2)) <= 0.01
    assert np.mean(p < k * 0.05) >= 0.005 or phi == 0.9


def fitted_row(prob: Problem, model: Model, sensitivity, test):
    """Fit the nominal model by output error and run one input-term adequacy row on it: ``sensitivity``
    (fit, prob, j) and ``test`` (fit, prob, i, j, S, α) of :mod:`pipeline.diagnostics.adequacy`, input and
    output 0, α = 0.01. Returns (row, fit, prob); the sensitivity must exist."""
    with contextlib.redirect_stderr(io.StringIO()):
        fit = fit_output_error(model, prob)
    S = sensitivity(fit, prob, 0)
    assert S is not None
    return test(fit, prob, 0, 0, S, 0.01), fit, prob


def with_noise(x: np.ndarray, noise: np.ndarray, level: float = 0.05) -> np.ndarray:
    """x plus ``noise`` scaled to ``level`` × std(x)."""
    return x + level * np.std(x) / np.std(noise) * noise


def problem(folder: Path, dt: float, u: np.ndarray, y: np.ndarray, name: str = "r",
            diagnose: dict | None = None) -> tuple[Problem, Model]:
    """Write (t, u, y) and the nominal first-order config (a = b = 1 to start, 30 % validation) to
    ``folder`` and load them: the Problem and Model the pipeline would make of them."""
    folder.mkdir()
    pd.DataFrame({"t": dt * np.arange(len(u)), "u": u, "y": y}).to_csv(folder / "data.csv", index=False)
    cfg = {"name": name, "seed": 0,
           "data": {"path": "data.csv", "time": "t", "inputs": ["u"], "outputs": ["y"], "intersample": "zoh",
                    "remove_mean": False},
           "model": {"states": ["y"], "inputs": ["u"], "params": {"a": 1.0, "b": 1.0}, "free": ["a", "b"],
                     "equations": {"y": "-a*y + b*u"}, "initial": {"y": 0.0}},
           "split": {"validation_fraction": 0.3}}
    if diagnose is not None:
        cfg["diagnose"] = diagnose
    (folder / "c.yaml").write_text(yaml.safe_dump(cfg))
    lc = load_config(folder / "c.yaml")
    rec = load_record(lc)
    model = Model.from_config(lc)
    return Problem.from_record(rec, model, make_split(lc, rec), None), model
