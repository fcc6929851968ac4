"""The two coupled thermal capacities of the multi-output tests (test_multi_output.py,
test_noise_multi_output.py): their sum-of-sines inputs and the nominal config. Written here, sharing
no code with the detector; the records are made by each test with ``scipy.integrate.solve_ivp``.

    T1' = b1 u1 − a1 T1 + g (T2 − T1),   T2' = b2 u2 − a2 T2 − g (T2 − T1),

measured as y1 = 1000 T1 (milli-units) and T2, so the two outputs differ 1000× in scale."""

from __future__ import annotations

import numpy as np

A1, A2, G, B1, B2 = 0.5, 0.3, 0.2, 1.0, 0.8


def inputs(seed: int):
    """Two continuous-time inputs, each a sum of 6 sines (0.01–0.4 Hz, random phases) × 0.25."""
    rng = np.random.default_rng(seed)
    f1, f2 = rng.uniform(0.01, 0.4, 6), rng.uniform(0.01, 0.4, 6)
    p1, p2 = rng.uniform(0, 2 * np.pi, 6), rng.uniform(0, 2 * np.pi, 6)
    u1 = lambda s: 0.5 * np.sum(np.sin(2 * np.pi * f1 * np.asarray(s)[..., None] + p1), axis=-1) / 2
    u2 = lambda s: 0.5 * np.sum(np.sin(2 * np.pi * f2 * np.asarray(s)[..., None] + p2), axis=-1) / 2
    return u1, u2


def config(name: str, seed: int, families: list[str], max_findings: int = 2) -> dict:
    """The nominal linear model (parameters started off the truth) on data.csv, foh, 30 % validation."""
    return {
        "name": name, "seed": seed,
        "data": {"path": "data.csv", "time": "t", "inputs": ["u1", "u2"], "outputs": ["y1", "T2"],
                 "intersample": "foh", "remove_mean": False},
        "model": {"states": ["y1", "T2"], "inputs": ["u1", "u2"],
                  "params": {"a1": 0.45, "a2": 0.35, "g": 0.2, "b1": 1.0, "b2": 0.8},
                  "free": ["a1", "a2", "g", "b1", "b2"],
                  "equations": {"y1": "1000*b1*u1 - a1*y1 + g*(1000*T2 - y1)",
                                "T2": "b2*u2 - a2*T2 - g*(T2 - y1/1000)"},
                  "initial": {"y1": 0.0, "T2": 0.0}},
        "split": {"validation_fraction": 0.3},
        "diagnose": {"families": list(families), "alpha": 0.01, "max_findings": max_findings},
    }
