"""Integration of a continuous-time plant on a continuous-time input, then sampling.

``scipy.integrate.solve_ivp`` (LSODA by default — 2–3× fewer right-hand-side calls than RK45 here,
and safe on the stiff cases such as a smoothed Coulomb friction; RK45 on request; rtol 1e-8) runs segment by
segment between the input's discontinuities (and any other breakpoint, e.g. a parameter jump), so
the solver never steps over a jump: inside each segment the right-hand side is smooth. The state is
sampled at the record's instants from the solver's dense output.

A state limit (an end stop or an overflow) is a hybrid system handled with events: in free motion
the event ``x_s − L`` (crossing upward) stops the segment; the state is set to the limit (and the
velocity of a second-order state to zero: an inelastic stop); the clamped mode holds the state
constant until the free-motion derivative that pushes against the stop, evaluated at the clamped
state, changes sign (event, crossing downward), and free motion resumes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp

RTOL = 1e-8


@dataclass(frozen=True)
class StateLimit:
    """x[index] ≤ limit; ``velocity`` is the index zeroed on impact (second-order states) or None;
    the push is f(t, x)[velocity if given else index] at the clamped state."""

    index: int
    limit: float
    velocity: int | None = None


def _clamped(x: np.ndarray, lim: StateLimit) -> np.ndarray:
    xc = np.array(x, float)
    xc[lim.index] = lim.limit
    if lim.velocity is not None:
        xc[lim.velocity] = 0.0
    return xc


def integrate(rhs: Callable[[float, np.ndarray], np.ndarray], x0: np.ndarray, t: np.ndarray,
              breakpoints: np.ndarray, *, method: str = "LSODA", limit: StateLimit | None = None,
              atol: float = 1e-10, max_events: int = 100000) -> np.ndarray:
    """States at the sample instants ``t`` (increasing, t[0] the initial time), shape (len(t), nx)."""
    t = np.asarray(t, float)
    t0, t1 = float(t[0]), float(t[-1])
    bps = np.asarray(breakpoints, float)
    edges = np.unique(np.concatenate([[t0], bps[(bps > t0) & (bps < t1)], [t1]]))
    X = np.empty((len(t), len(x0)))
    x = np.array(x0, float)
    X[0] = x
    clamped = limit is not None and x[limit.index] >= limit.limit
    events = 0
    # no step longer than a sample interval: a plant at rest (e.g. an input inside a dead zone) must not
    # let the solver step over the input's later excursions; the clamped mode looks for release as often
    h = float(t[1] - t[0]) if len(t) > 1 else t1 - t0
    for a, b in zip(edges[:-1], edges[1:]):
        tc = a
        while tc < b:
            mask = (t > tc) & (t <= b)
            if b - tc < 1e-9 * h:            # a remnant of round-off: nothing happens in it
                X[mask] = _clamped(x, limit) if (limit is not None and clamped) else x
                tc = b
                continue
            if limit is None:
                sol = solve_ivp(rhs, (tc, b), x, method=method, rtol=RTOL, atol=atol, max_step=h,
                                dense_output=True)
                if not sol.success:
                    raise RuntimeError(f"solve_ivp failed at t={tc}: {sol.message}")
                if mask.any():
                    X[mask] = sol.sol(t[mask]).T
                x, tc = sol.y[:, -1], b
                continue
            events += 1
            if events > max_events:
                raise RuntimeError("too many limit events (chattering)")
            if clamped:
                xc = _clamped(x, limit)
                k = limit.velocity if limit.velocity is not None else limit.index

                p0 = rhs(tc, xc)[k]
                # release when the push is below −δ (not at 0: a root found at push ≈ +0 would re-hit
                # the stop at once and chatter); δ is 1e-9 of the push at clamping
                delta = 1e-9 * (1.0 + abs(p0))

                def push(s, _y, xc=xc, k=k, delta=delta):
                    return rhs(s, xc)[k] + delta
                push.terminal, push.direction = True, -1
                if p0 <= 0:                      # the input changed at a breakpoint: released at once
                    clamped = False
                    x = xc
                    continue
                sol = solve_ivp(lambda s, y: np.zeros_like(y), (tc, b), xc, method="RK45", rtol=RTOL,
                                atol=atol, events=push, max_step=h, dense_output=True)
                te = sol.t_events[0][0] if len(sol.t_events[0]) else b
                m = mask & (t <= te)
                X[m] = xc
                x, tc = xc, te
                if te < b:
                    clamped = False
                continue

            def hit(s, y, lim=limit):
                return y[lim.index] - lim.limit
            hit.terminal, hit.direction = True, 1
            sol = solve_ivp(rhs, (tc, b), x, method=method, rtol=RTOL, atol=atol, events=hit, max_step=h,
                            dense_output=True)
            if not sol.success:
                raise RuntimeError(f"solve_ivp failed at t={tc}: {sol.message}")
            te = sol.t_events[0][0] if len(sol.t_events[0]) else b
            m = mask & (t <= te)
            if m.any():
                X[m] = sol.sol(t[m]).T
            if te < b:
                x = _clamped(sol.y_events[0][0], limit)
                k = limit.velocity if limit.velocity is not None else limit.index
                clamped = rhs(te, x)[k] > 0      # pushed into the stop: stays; else it rebounds freely
            else:
                x = sol.y[:, -1]
            tc = te
    return X
