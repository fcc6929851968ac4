"""Base systems of the independent bench: the true physics written out as plain Python, and the
nominal model a user would write for it in the project's config language (text only).

Each right-hand side ``f(x, u, p)`` takes the state vector, the input vector and a dict of parameter
values and returns dx/dt. The effects (see :mod:`.effects`) wrap these functions; nothing here knows
the project's model classes or kernel.

Bases (states; measured outputs; where the effects act):

=============  ===================================  ==========  =======================================
``msd``        mass–spring–damper (x, v)            x           forces in v' (÷ m), position x
``pendulum``   damped pendulum (th, w)              th          torques in w', angle th
``tank``       tank with square-root outflow (h)    h           inflow terms in h'
``dcmotor``    DC motor speed, first order (w)      w           torques in w'
``dcmotor2``   DC motor, speed and current (w, i)   w, i        torques in w'
``twomode``    two masses, two springs (x1 v1 x2 v2) x1, x2     forces in v1', position x1
``mimo``       two coupled thermal zones, 2 inputs  T1, T2      heat flows in T1', input u1
=============  ===================================  ==========  =======================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

Rhs = Callable[[np.ndarray, np.ndarray, dict], np.ndarray]


def _msd(x, u, p):
    return np.array([x[1], (u[0] - p["c"] * x[1] - p["k"] * x[0]) / p["m"]])


def _pendulum(x, u, p):
    return np.array([x[1], -p["g_l"] * math.sin(x[0]) - p["b"] * x[1] + u[0]])


def _tank(x, u, p):
    return np.array([p["b"] * u[0] - p["a"] * math.sqrt(max(x[0], 0.0))])


def _dcmotor(x, u, p):
    return np.array([p["K"] * u[0] - p["a"] * x[0]])


def _dcmotor2(x, u, p):
    w, i = x
    return np.array([(p["Kt"] * i - p["bm"] * w) / p["J"], (u[0] - p["R"] * i - p["Ke"] * w) / p["L"]])


def _twomode(x, u, p):
    x1, v1, x2, v2 = x
    f12 = p["k2"] * (x1 - x2) + p["c2"] * (v1 - v2)
    return np.array([v1, (u[0] - p["k1"] * x1 - p["c1"] * v1 - f12) / p["m1"], v2, f12 / p["m2"]])


def _mimo(x, u, p):
    T1, T2 = x
    q = p["g"] * (T2 - T1)
    return np.array([p["b1"] * u[0] - p["a1"] * T1 + q, p["b2"] * u[1] - p["a2"] * T2 - q])


@dataclass(frozen=True)
class Base:
    """One base system: truth, nominal config text, input design and the roles effects use."""

    name: str
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    params: dict[str, float]                 # true values
    free: tuple[str, ...]
    equations: dict[str, str]                # the nominal model (project's expression language)
    measured: tuple[str, ...]
    rhs: Rhs
    dt: float
    u_mean: float
    u_std: float
    band_hz: float
    hold: tuple[int, int]                    # held-step durations, samples
    clock: int                               # PRBS clock, samples
    tc: float                                # fastest time constant of the dynamics, s
    force_eq: str                            # equation where forces/torques/flows act
    jump_param: str                          # parameter that jumps or drifts
    pos: str | None = None                   # position state (stiffness terms)
    vel: str | None = None                   # velocity state (friction, damping)
    x0: dict[str, float] = field(default_factory=dict)   # initial state (0 unless given)
    u_low: float | None = None               # lowest physical input level (held steps)

    def initial(self) -> np.ndarray:
        return np.array([self.x0.get(s, 0.0) for s in self.states])

    def index(self, state: str) -> int:
        return self.states.index(state)


BASES: dict[str, Base] = {b.name: b for b in [
    Base("msd", ("x", "v"), ("u",), {"m": 1.0, "c": 0.6, "k": 4.0}, ("c", "k"),
         {"x": "v", "v": "(u - c*v - k*x)/m"}, ("x",), _msd, 0.02, 0.0, 2.0, 1.0, (10, 60), 5, 0.5,
         "v", "k", pos="x", vel="v"),
    Base("pendulum", ("th", "w"), ("u",), {"g_l": 9.81, "b": 0.5}, ("g_l", "b"),
         {"th": "w", "w": "-g_l*sin(th) - b*w + u"}, ("th",), _pendulum, 0.02, 0.0, 1.5, 1.0, (10, 60), 5,
         0.32, "w", "b", pos="th", vel="w"),
    Base("tank", ("h",), ("u",), {"a": 0.5, "b": 1.0}, ("a", "b"),
         {"h": "b*u - a*sqrt(h)"}, ("h",), _tank, 0.1, 1.0, 0.3, 0.1, (20, 100), 20, 8.0, "h", "a",
         x0={"h": 4.0}, u_low=0.2),
    Base("dcmotor", ("w",), ("u",), {"K": 4.0, "a": 2.0}, ("K", "a"),
         {"w": "K*u - a*w"}, ("w",), _dcmotor, 0.02, 0.0, 1.0, 1.0, (10, 60), 5, 0.5, "w", "a", vel="w"),
    Base("dcmotor2", ("w", "i"), ("u",), {"J": 0.02, "bm": 0.02, "Kt": 0.2, "Ke": 0.2, "R": 2.0, "L": 0.1},
         ("bm", "Kt", "R"), {"w": "(Kt*i - bm*w)/J", "i": "(u - R*i - Ke*w)/L"}, ("w", "i"), _dcmotor2,
         0.01, 0.0, 2.0, 2.0, (10, 60), 5, 0.05, "w", "R", vel="w"),
    Base("twomode", ("x1", "v1", "x2", "v2"), ("u",),
         {"m1": 1.0, "m2": 0.5, "k1": 4.0, "k2": 10.0, "c1": 0.3, "c2": 0.2}, ("k1", "c1", "k2", "c2"),
         {"x1": "v1", "v1": "(u - k1*x1 - c1*v1 - k2*(x1 - x2) - c2*(v1 - v2))/m1", "x2": "v2",
          "v2": "(k2*(x1 - x2) + c2*(v1 - v2))/m2"}, ("x1", "x2"), _twomode, 0.02, 0.0, 2.0, 1.5, (10, 60), 5,
         0.16, "v1", "k1", pos="x1", vel="v1"),
    Base("mimo", ("T1", "T2"), ("u1", "u2"), {"a1": 0.5, "a2": 0.3, "g": 0.2, "b1": 1.0, "b2": 0.8},
         ("a1", "a2", "g"), {"T1": "b1*u1 - a1*T1 + g*(T2 - T1)", "T2": "b2*u2 - a2*T2 - g*(T2 - T1)"},
         ("T1", "T2"), _mimo, 0.05, 0.0, 1.0, 0.3, (10, 60), 5, 1.4, "T1", "a1"),
]}

# the tank's linear-outflow nominal (the user's belief for the static_nonlinearity case), with the
# outflow coefficient that gives the same steady state at the mean input: a_lin = a / sqrt(h0)
TANK_LINEAR = {"equations": {"h": "b*u - a*h"}, "a_of": lambda a, h0: a / math.sqrt(h0)}
