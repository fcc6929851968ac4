"""Reference set-ups of Tsang-Billings S1-S4 (seed_cases.md section 6): multisine input drawn with
random.Random(12345), RK4 with a 1 ms step, 290 samples every 0.04 s, zero initial state."""

from __future__ import annotations

import functools
import math
import random

import numpy as np

H = 0.04
N_SAMPLES = 290
DT = 1e-3
SUB = 40  # RK4 steps per sample


@functools.lru_cache(maxsize=None)
def multisine(n_sines: int = 40, seed: int = 12345, interleaved: bool = False):
    """f_i ~ U(0.02, 1.5) Hz then phi_i ~ U(0, 2 pi) (all f first, then all phi; ``interleaved`` draws
    (f_i, phi_i) pairs instead)."""
    rng = random.Random(seed)
    if interleaved:
        pairs = [(rng.uniform(0.02, 1.5), rng.uniform(0, 2 * math.pi)) for _ in range(n_sines)]
        f = [p[0] for p in pairs]
        ph = [p[1] for p in pairs]
    else:
        f = [rng.uniform(0.02, 1.5) for _ in range(n_sines)]
        ph = [rng.uniform(0, 2 * math.pi) for _ in range(n_sines)]
    return np.array(f), np.array(ph)


def u_of_t(t, n_sines=40, interleaved=False):
    f, ph = multisine(n_sines, interleaved=interleaved)
    t = np.asarray(t, dtype=float)
    return math.sqrt(2.0 / n_sines) * np.sin(2 * np.pi * f[:, None] * t.ravel()[None, :] + ph[:, None]).sum(0).reshape(t.shape)


def _input_grid(interleaved=False):
    n_steps = (N_SAMPLES - 1) * SUB
    tg = np.arange(2 * n_steps + 1) * (DT / 2)  # values at t, t + dt/2, t + dt
    return u_of_t(tg, interleaved=interleaved)


@functools.lru_cache(maxsize=None)
def simulate(system: str, interleaved: bool = False):
    """Noise-free (t, u, y) samples of S1 (= S2/S3 deterministic part) or S4."""
    ug = _input_grid(interleaved)
    n_steps = (N_SAMPLES - 1) * SUB
    ys = [0.0]
    if system == "S1":
        y, v = 0.0, 0.0

        def fs(y, v, u):
            return v, (1.25 * u - 0.7 * v - y) / 0.25

        for k in range(n_steps):
            u0, u1, u2 = ug[2 * k], ug[2 * k + 1], ug[2 * k + 2]
            k1y, k1v = fs(y, v, u0)
            k2y, k2v = fs(y + 0.5 * DT * k1y, v + 0.5 * DT * k1v, u1)
            k3y, k3v = fs(y + 0.5 * DT * k2y, v + 0.5 * DT * k2v, u1)
            k4y, k4v = fs(y + DT * k3y, v + DT * k3v, u2)
            y += DT / 6 * (k1y + 2 * k2y + 2 * k3y + k4y)
            v += DT / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            if (k + 1) % SUB == 0:
                ys.append(y)
    elif system == "S4":
        y = 0.0

        def f4(y, u):
            return (u - y - 0.16 * y * y) / 0.2

        for k in range(n_steps):
            u0, u1, u2 = ug[2 * k], ug[2 * k + 1], ug[2 * k + 2]
            k1 = f4(y, u0)
            k2 = f4(y + 0.5 * DT * k1, u1)
            k3 = f4(y + 0.5 * DT * k2, u1)
            k4 = f4(y + DT * k3, u2)
            y += DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            if (k + 1) % SUB == 0:
                ys.append(y)
    else:
        raise ValueError(system)
    t = np.arange(N_SAMPLES) * H
    return t, ug[:: 2 * SUB].copy(), np.array(ys)


def output_noise(seed: int, sigma: float) -> np.ndarray:
    """e_k = random.Random(seed).gauss(0, sigma), k = 0..289."""
    rng = random.Random(seed)
    return np.array([rng.gauss(0.0, sigma) for _ in range(N_SAMPLES)])
