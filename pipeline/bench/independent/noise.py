"""Measurement noise added to the noise-free outputs.

Per output j, σ_j = level × std(y_j) (level 0.01–0.10). Unit innovations w_k are standard normal, or
Student t with ν degrees of freedom scaled by √((ν−2)/ν) to unit variance (ν = 3: heavy tails, infinite
kurtosis). Colour: the stationary AR(1) e_k = φ e_{k−1} + √(1−φ²) w_k, e_0 = w_0 (unit variance for
every k; correlation φ^|τ|, correlation time −dt/ln φ). Heteroscedastic: the unit noise is multiplied by
s_k = a' + b'|y_k − ȳ| with (a', b') ∝ ((1−β), β/mean|y − ȳ|) normalised so that mean(s_k²) = 1, so σ_j
stays the root-mean-square noise level; the truth gets σ_k = a + b|y_k − ȳ| in output units.
"""

from __future__ import annotations

import numpy as np


def innovations(rng: np.random.Generator, n: int, dist: str = "normal", df: float = 3.0) -> np.ndarray:
    if dist == "student_t":
        return rng.standard_t(df, size=n) * np.sqrt((df - 2.0) / df)
    return rng.standard_normal(n)


def ar1(w: np.ndarray, phi: float) -> np.ndarray:
    """Stationary AR(1) with unit variance driven by unit-variance w."""
    if phi == 0.0:
        return w.copy()
    e = np.empty_like(w)
    e[0] = w[0]
    c = np.sqrt(1.0 - phi * phi)
    for k in range(1, len(w)):
        e[k] = phi * e[k - 1] + c * w[k]
    return e


def add_noise(rng: np.random.Generator, Y: np.ndarray, level: float, *, phi: float = 0.0,
              dist: str = "normal", df: float = 3.0, hetero: float | None = None) -> tuple[np.ndarray, dict]:
    """Noisy copy of Y (N, ny) and the noise truth (σ per output, variance models)."""
    n, ny = Y.shape
    out = Y.copy()
    info: dict = {"sigma": [], "phi": phi, "dist": dist}
    if dist == "student_t":
        info["df"] = df
    for j in range(ny):
        sig = level * float(np.std(Y[:, j]))
        e = ar1(innovations(rng, n, dist, df), phi)
        if hetero is not None:
            ybar = float(np.mean(Y[:, j]))
            dev = np.abs(Y[:, j] - ybar)
            a1, b1 = 1.0 - hetero, hetero / float(np.mean(dev))
            s = a1 + b1 * dev
            c = 1.0 / float(np.sqrt(np.mean(s ** 2)))
            e = e * s * c
            info.setdefault("variance_model", []).append(
                {"formula": "sigma_k = a + b*|y_k - ybar|", "a": sig * a1 * c, "b": sig * b1 * c, "ybar": ybar})
        out[:, j] += sig * e
        info["sigma"].append(sig)
    return out, info
