"""A true plant: a base system's right-hand side wrapped with the effects of one case.

The composed right-hand side, for the full state X = (base states x, extra states z):

    u_raw = u(t)                       (the input as the plant sees it: delayed, clipped, ... signal)
    u     = u_raw, with channel 0 replaced by an actuator state when there is a lag
    p     = params(t)                  (constant, or a jump / drift)
    dx    = f_base(x, u, p) + Σ additive terms(t, x, z, u, p)
    dz    = extra(t, x, z, u_raw, p)

Every piece is a plain Python closure written in :mod:`.effects`; sampling and integration are in
:mod:`.integrate`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .integrate import StateLimit, integrate
from .signals import Signal
from .systems import Base


@dataclass
class Plant:
    base: Base
    signal: Signal
    params: dict[str, float]
    params_of_t: Callable[[float], dict] | None = None
    additive: list[Callable] = field(default_factory=list)      # (t, x, z, u, p) -> dx contribution
    extra_x0: list[float] = field(default_factory=list)
    extra: Callable | None = None                               # (t, x, z, u_raw, p) -> dz
    actuator_state: int | None = None                           # index in z replacing u[0]
    output_add: Callable | None = None                          # (t, Xfull) -> (N, n_meas) added
    limit: StateLimit | None = None
    breakpoints: list[float] = field(default_factory=list)
    method: str = "LSODA"

    def rhs(self, t: float, X: np.ndarray) -> np.ndarray:
        nb = len(self.base.states)
        x, z = X[:nb], X[nb:]
        u_raw = self.signal.value(t)
        u = u_raw
        if self.actuator_state is not None:
            u = u_raw.copy()
            u[0] = z[self.actuator_state]
        p = self.params_of_t(t) if self.params_of_t is not None else self.params
        dx = self.base.rhs(x, u, p)
        for term in self.additive:
            dx = dx + term(t, x, z, u, p)
        if self.extra is None:
            return dx
        return np.concatenate([dx, self.extra(t, x, z, u_raw, p)])

    def x0(self) -> np.ndarray:
        return np.concatenate([self.base.initial(), np.asarray(self.extra_x0, float)])

    def simulate(self, t: np.ndarray) -> np.ndarray:
        """Full state at the sample instants, integrated segment by segment."""
        bps = np.concatenate([self.signal.breakpoints, np.asarray(self.breakpoints, float)])
        return integrate(self.rhs, self.x0(), t, bps, method=self.method, limit=self.limit)

    def measure(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Noise-free measured outputs (N, n_measured)."""
        Y = np.column_stack([X[:, self.base.index(s)] for s in self.base.measured])
        if self.output_add is not None:
            Y = Y + self.output_add(t, X)
        return Y
