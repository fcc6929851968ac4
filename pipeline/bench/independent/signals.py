"""Continuous-time inputs u(t) for the independent generator.

Every signal is a function of continuous time, evaluated by the integrator at whatever instants it
needs, plus the list of its discontinuities (``breakpoints``) so the integrator can stop exactly at
each jump and never step over one. Kinds:

* :class:`BandLimited`: u(t) = mean + Σ_j a cos(2π f_j t + φ_j), f_j = j/T for f_j ≤ cutoff (a
  multisine on the record's frequency grid), φ_j uniform on [0, 2π), a set so that the record's
  standard deviation is ``std`` (a multisine with equal amplitudes a has variance J a²/2).
  Smooth (no breakpoints): linear interpolation between samples (foh) is the right intersample
  assumption for it, up to the curvature error ≤ dt² max|ü|/8.
* :class:`Held`: piecewise constant with random levels and random durations that are whole numbers
  of samples, so the level changes only at sampling instants and zero-order hold is exact.
* :func:`prbs`: a maximum-length binary sequence (Fibonacci LFSR, x^10 + x^7 + 1, period 1023;
  Ljung 1999 §13.3) held for ``clock`` samples per bit, levels mean ± std.
* :class:`Delayed`, :class:`Mapped`, :class:`Play`: u(t − d), a static map g(u(t)), and the backlash
  (play) operator, built on any of the above.

Multi-input signals are :class:`Stack` objects; every signal returns an array of shape (n_inputs,)
for a scalar t (``value``) and (len(t), n_inputs) for an array (``sample``).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


class Signal:
    """Base: ``value(t)`` for scalar t, ``sample(t)`` for an array, ``breakpoints`` (sorted)."""

    n_inputs: int = 1
    breakpoints: np.ndarray = np.zeros(0)

    def value(self, t: float) -> np.ndarray:
        return self.sample(np.array([t]))[0]

    def sample(self, t: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass
class BandLimited(Signal):
    """Multisine with random phases on the grid f_j = j·df, 0 < f_j ≤ cutoff."""

    freqs: np.ndarray
    phases: np.ndarray
    amp: float
    mean: float = 0.0

    def __post_init__(self) -> None:
        self.breakpoints = np.zeros(0)
        self._w = 2 * np.pi * np.asarray(self.freqs, float)

    @classmethod
    def make(cls, rng: np.random.Generator, *, duration: float, cutoff: float, std: float,
             mean: float = 0.0) -> "BandLimited":
        df = 1.0 / duration
        freqs = df * np.arange(1, int(np.floor(cutoff / df + 1e-9)) + 1)
        if len(freqs) == 0:
            raise ValueError("cutoff below one cycle per record")
        phases = rng.uniform(0.0, 2 * np.pi, size=len(freqs))
        return cls(freqs, phases, std * np.sqrt(2.0 / len(freqs)), mean)

    def value(self, t: float) -> np.ndarray:
        return np.array([self.mean + self.amp * float(np.sum(np.cos(self._w * t + self.phases)))])

    def sample(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        out = np.full(t.shape, self.mean)
        for w, ph in zip(self._w, self.phases):   # loop over frequencies: O(N J) without an (N, J) array
            out += self.amp * np.cos(w * t + ph)
        return out[:, None]


@dataclass
class Held(Signal):
    """u(t) = levels[i] for switch[i] ≤ t < switch[i+1] (switch[0] = t0; the last level holds on)."""

    switch: np.ndarray      # start time of each level, increasing
    levels: np.ndarray

    def __post_init__(self) -> None:
        self.switch = np.asarray(self.switch, float)
        self.levels = np.asarray(self.levels, float)
        self.breakpoints = self.switch[1:].copy()
        self._sw, self._lv = self.switch.tolist(), self.levels.tolist()

    def _index(self, t):
        return np.clip(np.searchsorted(self.switch, t, side="right") - 1, 0, len(self.levels) - 1)

    def value(self, t: float) -> np.ndarray:
        # scalar path (called by the integrator at every stage): bisect on plain lists is ~20x faster
        i = bisect.bisect_right(self._sw, t) - 1
        return np.array([self._lv[min(max(i, 0), len(self._lv) - 1)]])

    def sample(self, t: np.ndarray) -> np.ndarray:
        return self.levels[self._index(np.asarray(t, float))][:, None]

    @classmethod
    def make(cls, rng: np.random.Generator, *, dt: float, n: int, min_samples: int, max_samples: int,
             std: float, mean: float = 0.0, low: float | None = None) -> "Held":
        starts, k = [], 0
        while k < n:
            starts.append(k)
            k += int(rng.integers(min_samples, max_samples + 1))
        levels = mean + std * rng.standard_normal(len(starts))
        if low is not None:
            levels = np.maximum(levels, low)
        return cls(np.array(starts) * dt, levels)


def lfsr_bits(n_bits: int, state: int) -> np.ndarray:
    """Maximum-length sequence of x^10 + x^7 + 1 (taps 10 and 7), from a nonzero 10-bit state."""
    state &= 0x3FF
    if state == 0:
        state = 1
    out = np.empty(n_bits, dtype=np.int8)
    for i in range(n_bits):
        bit = ((state >> 9) ^ (state >> 6)) & 1
        out[i] = state & 1
        state = ((state << 1) | bit) & 0x3FF
    return out


def prbs(rng: np.random.Generator, *, dt: float, n: int, clock: int, std: float, mean: float = 0.0) -> Held:
    """PRBS held for ``clock`` samples per bit, levels mean ± std (its standard deviation is std)."""
    nb = int(np.ceil(n / clock))
    bits = lfsr_bits(nb, int(rng.integers(1, 1024)))
    return Held(np.arange(nb) * clock * dt, mean + std * (2.0 * bits - 1.0))


@dataclass
class Stack(Signal):
    """Several single-input signals side by side (a multi-input u(t))."""

    parts: list[Signal]

    def __post_init__(self) -> None:
        self.n_inputs = sum(p.n_inputs for p in self.parts)
        bps = [p.breakpoints for p in self.parts if len(p.breakpoints)]
        self.breakpoints = np.unique(np.concatenate(bps)) if bps else np.zeros(0)

    def value(self, t: float) -> np.ndarray:
        return np.concatenate([p.value(t) for p in self.parts])

    def sample(self, t: np.ndarray) -> np.ndarray:
        return np.column_stack([p.sample(t) for p in self.parts])


@dataclass
class Delayed(Signal):
    """u(t − d), holding u(0) for t < d (the input before the record is its first value)."""

    inner: Signal
    delay: float

    def __post_init__(self) -> None:
        self.n_inputs = self.inner.n_inputs
        self.breakpoints = np.concatenate([[self.delay], self.inner.breakpoints + self.delay])

    def value(self, t: float) -> np.ndarray:
        return self.inner.value(max(t - self.delay, 0.0))

    def sample(self, t: np.ndarray) -> np.ndarray:
        return self.inner.sample(np.maximum(np.asarray(t, float) - self.delay, 0.0))


@dataclass
class Mapped(Signal):
    """A static map of one channel: u_j(t) → g(u_j(t)) (saturation, dead zone)."""

    inner: Signal
    fn: Callable[[np.ndarray], np.ndarray]
    channel: int = 0

    def __post_init__(self) -> None:
        self.n_inputs = self.inner.n_inputs
        self.breakpoints = self.inner.breakpoints

    def value(self, t: float) -> np.ndarray:
        u = self.inner.value(t).copy()
        u[self.channel] = self.fn(np.asarray(u[self.channel]))
        return u

    def sample(self, t: np.ndarray) -> np.ndarray:
        u = self.inner.sample(t).copy()
        u[:, self.channel] = self.fn(u[:, self.channel])
        return u


def play_operator(u: np.ndarray, width: float, y0: float = 0.0) -> np.ndarray:
    """Backlash / play operator with dead band ``width``: y_k = min(u_k + w/2, max(u_k − w/2, y_{k−1}))
    (Krasnosel'skii & Pokrovskii 1989; the output moves only when the input pushes it at an edge)."""
    h = 0.5 * width
    y = np.empty_like(u)
    prev = y0
    for k, uk in enumerate(u):
        prev = min(uk + h, max(uk - h, prev))
        y[k] = prev
    return y


@dataclass
class Play(Signal):
    """Backlash on channel ``channel``: the play operator applied along time.

    For a piecewise-constant inner signal the operator is applied level by level (exact). For a smooth
    inner signal it is evaluated on a grid of ``fine`` points per sample interval and linearly
    interpolated (the play output of a continuous input is continuous and piecewise monotone, so the
    interpolation error is O(grid step²))."""

    inner: Signal
    width: float
    t_end: float
    dt: float
    channel: int = 0
    fine: int = 40
    _grid: np.ndarray = field(init=False, repr=False)
    _vals: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.n_inputs = self.inner.n_inputs
        self.breakpoints = self.inner.breakpoints
        if isinstance(self.inner, Held):
            self._grid = self.inner.switch
            u = self.inner.levels
        else:
            self._grid = np.linspace(0.0, self.t_end, int(round(self.t_end / self.dt * self.fine)) + 1)
            u = self.inner.sample(self._grid)[:, self.channel]
        self._vals = play_operator(u, self.width, y0=float(np.clip(0.0, u[0] - self.width / 2,
                                                                   u[0] + self.width / 2)))

    def _eval(self, t: np.ndarray) -> np.ndarray:
        if isinstance(self.inner, Held):
            i = np.clip(np.searchsorted(self._grid, t, side="right") - 1, 0, len(self._vals) - 1)
            return self._vals[i]
        return np.interp(t, self._grid, self._vals)

    def value(self, t: float) -> np.ndarray:
        u = self.inner.value(t).copy()
        u[self.channel] = float(self._eval(np.asarray(t, float)))
        return u

    def sample(self, t: np.ndarray) -> np.ndarray:
        u = self.inner.sample(t).copy()
        u[:, self.channel] = self._eval(np.asarray(t, float))
        return u
