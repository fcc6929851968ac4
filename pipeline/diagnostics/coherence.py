"""Input–residual coherence: does the residual hold input dynamics at *any* frequency?

The cross-correlation test and the FIR model-error model look at the first 25 / 15 lags. A missing
lightly damped mode rings for hundreds of samples (ζ = 0.05 at 170 samples per period decays over 530
samples), so its residual correlates with the input at lags neither test sees, and the smooth residual
it left was named ``colored_noise``. The magnitude-squared coherence looks at every frequency:

    Ĉ²(f) = |Σ_k U_k(f)* E_k(f)|² / (Σ_k |U_k(f)|² · Σ_k |E_k(f)|²),

with U_k, E_k the DFTs of the mean-removed input and residual times the K = 2·NW − 1 discrete prolate
spheroidal (Slepian) tapers of time-bandwidth NW (Thomson 1982, "Spectrum estimation and harmonic
analysis", Proc. IEEE 70(9); multitaper coherence: Thomson & Chave 1991, in *Advances in Spectrum
Analysis and Array Processing* I, §2.6). Tapers instead of Welch segments: the same K degrees of
freedom at a resolution of ±NW/N instead of ±2K/N, so a mode of a few cycles per record is resolved.

Prewhitening. Both series are first filtered by their own AR(p) (Yule–Walker, p ≤ 20 by AIC,
:func:`stats.prewhiten_ar`). The coherence is unchanged by filtering either series, but its estimate is
not: the tapers average the cross-spectrum over ±NW/N, and where a spectrum is steep (held-step
inputs, a resonance) that average mixes unequal parts (a lightly damped mode seen through the raw
tapers had Ĉ² 0.3 where the prewhitened pair gives 0.96). Each filter is a function of its own series
only, so under the null the whitened residual is still independent of the whitened input, and its
flatter spectrum is what the equal-variance condition below asks for.

Null distribution. If the residual is Gaussian noise independent of the input whose spectrum is flat
within ±NW/N, the K tapered DFTs at one frequency are independent circular complex Gaussians of equal
variance (the tapers are orthonormal), and *given the input* Ĉ² is the squared correlation of a complex
regression through the origin of K values on K fixed regressors: Ĉ²(f) ~ Beta(1, K − 1),
P(Ĉ² > c) = (1 − c)^(K−1), whatever the input (Carter 1987, "Coherence and time delay estimation",
Proc. IEEE 75(2), the γ² = 0 case of eq. 23). The test takes the smallest p over a grid of frequencies
NW/N apart where the input has power (chosen from the input alone, so the null holds at each) with
Bonferroni over their number (neighbours overlap: conservative). The output-error fit makes the
residual orthogonal to the parameters' sensitivities, which lowers the coherence where they
concentrate: conservative again.

Effect size (for the adequacy rule ``MATERIAL_R2``): the share of the raw residual's power that the
input explains linearly at the significant frequencies, Σ_f (Ĉ² − 1/K)₊ S_ee(f) / Σ_f S_ee(f) over the
grid (1/K is Ĉ²'s null mean); the detail names the frequency with the largest coherence (where the
model fails). A resonance narrower than the ±NW/N band is found (its p-value) but its share is
understated: the transfer function's phase turns within the band and the average cancels part of it.

Monte Carlo (``tests/diagnosis/test_input_coherence.py``): rejection rates within MC error of α at 5 %
and 1 % for AR(1) noise φ = 0, 0.9, 0.98 on band-limited and held-step inputs (4 000 records each);
a missing mode of 150 samples per period (ζ = 0.05) behind a first-order model: significant in ≥ 90 %
of records where the cross-correlation and FIR tests reject in ≤ 20 %.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.signal.windows import dpss

from .stats import TestResult, prewhiten_ar

NW = 4.0                  # time-bandwidth product: resolution ±NW/N
N_TAPERS = 7              # K = 2·NW − 1 (the well-concentrated Slepian tapers): Beta(1, 6) under the null
MIN_SAMPLES = 64
PREWHITEN_PMAX = 20       # AR order (by AIC) of the prewhitening filters
INPUT_POWER_FLOOR = 1e-3  # frequencies where the input's power is below this share of its peak are not tested


@lru_cache(maxsize=4)
def _tapers(n: int) -> np.ndarray:
    return dpss(n, NW, N_TAPERS)


def input_coherence(e: np.ndarray, u: np.ndarray, alpha: float, dt: float = 1.0) -> TestResult | None:
    """The coherence test of the residual ``e`` against the input ``u`` (module docstring); None when
    the record is shorter than ``MIN_SAMPLES`` or the input has no power off DC."""
    e, u = np.asarray(e, float), np.asarray(u, float)
    if len(e) < MIN_SAMPLES:
        return None
    # prewhitened (module docstring): the coherence of the whitened pair is the raw pair's, but its
    # estimate no longer smears a sharp resonance over the taper band
    ew, _ = prewhiten_ar(e, PREWHITEN_PMAX)
    uw, _ = prewhiten_ar(u, PREWHITEN_PMAX)
    n = min(len(ew), len(uw))
    ew, uw, e = ew[len(ew) - n:], uw[len(uw) - n:], e[len(e) - n:]
    V = _tapers(n)
    K = V.shape[0]
    Uf = np.fft.rfft(V * (uw - uw.mean()), axis=1)
    Ef = np.fft.rfft(V * (ew - ew.mean()), axis=1)
    suu = np.sum(np.abs(Uf) ** 2, axis=0)
    see = np.sum(np.abs(Ef) ** 2, axis=0)
    sue = np.sum(np.conj(Uf) * Ef, axis=0)
    # the residual's own (raw) spectrum, for the share of its power the input explains
    see_raw = np.sum(np.abs(np.fft.rfft(V * (e - e.mean()), axis=1)) ** 2, axis=0)
    # a grid NW bins apart, from 2·NW bins (the removed mean and the near-real DFTs close to DC are
    # not the circular Gaussians the null assumes) to NW bins below Nyquist
    step = int(np.ceil(NW))
    grid = np.arange(2 * step, n // 2 - step + 1, step)
    if not len(grid) or not np.any(suu[grid] > 0):
        return None
    bins = grid[suu[grid] >= INPUT_POWER_FLOOR * float(np.max(suu[grid]))]
    if not np.any(see[bins] > 0):
        return None
    c2 = np.clip(np.abs(sue[bins]) ** 2 / np.maximum(suu[bins] * see[bins], np.finfo(float).tiny), 0.0, 1.0)
    p_bin = (1.0 - c2) ** (K - 1)
    m = len(bins)
    k = int(np.argmin(p_bin))
    p = float(min(1.0, m * p_bin[k]))
    sig = p_bin * m < alpha
    share = float(np.sum(np.maximum(c2[sig] - 1.0 / K, 0.0) * see_raw[bins][sig]) / np.sum(see_raw[grid]))
    f = bins[k] / (n * dt)
    t = TestResult("input_coherence", float(c2[k]), p, float(1.0 - (alpha / m) ** (1.0 / (K - 1))), p >= alpha,
                   f"largest input-residual coherence {c2[k]:.2f} at {f:.3g} Hz ({K} Slepian tapers, NW = {NW:g}; "
                   f"{m} frequencies tested, Bonferroni); the input explains {100 * share:.2g} % of the "
                   f"residual at the {int(sig.sum())} significant frequencies")
    t.r2 = share
    return t
