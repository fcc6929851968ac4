"""Records made by code that shares nothing with the pipeline (scipy ``solve_ivp``), shared by tests."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def thermal_tanh(n: int = 2000, dt: float = 0.05, seed: int = 5,
                 noise: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two coupled thermal nodes with a saturating loss beside the linear one,
    T1' = u1 − 0.8·T1 − 0.5·(T1 − T2) − 0.6·tanh(2·T1), T2' = u2 − 0.4·T2 − 0.5·(T2 − T1), on inputs
    held for 40 samples (uniform on [−1, 1]), integrated sample to sample by ``solve_ivp`` (rtol 1e-10;
    no step straddles a switch of the held input) from rest. The knee 1/2 lies near the state's spread,
    so fitted with c·tanh(T1/s) beside −a1·T1 the estimates of a1, c and s correlate beyond 0.99.
    Returns t (n,), U (n, 2), X (n, 2); ``noise`` > 0 adds white noise of that sd to X, drawn from the
    same generator after the inputs."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    U = np.repeat(rng.uniform(-1, 1, (n // 40 + 1, 2)), 40, axis=0)[:n]

    def rhs(tt, x):
        u1, u2 = U[min(int(tt / dt), n - 1)]
        return [u1 - 0.8 * x[0] - 0.5 * (x[0] - x[1]) - 0.6 * np.tanh(2 * x[0]), u2 - 0.4 * x[1] - 0.5 * (x[1] - x[0])]

    X = np.zeros((n, 2))
    for k in range(n - 1):
        X[k + 1] = solve_ivp(rhs, (t[k], t[k + 1]), X[k], rtol=1e-10, atol=1e-12).y[:, -1]
    if noise > 0:
        X += noise * rng.standard_normal((n, 2))
    return t, U, X
