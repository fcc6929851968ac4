"""Hidden effects, one function per family id (diagnosis contract §2), plus the out-of-vocabulary
kinds and the null record.

Each function gets a :class:`Ctx` (the base, a seeded Generator, the magnitude index 0/1/2 for
small/medium/large and a *pilot*: the base system simulated without any effect on the same input) and
returns an :class:`Effect`: its truth (key parameters named as in contract §2), where it acts, how it
changes the plant (``apply``) or the input (``wrap_input``), what the nominal config must say, and
noise settings. Sizes are relative to the pilot, so a "medium" effect is comparably hard on every
base: an additive term's standard deviation over the pilot is ``FRAC[m]`` × the standard deviation of
the derivative of the equation it enters.

Coefficients are those of ``d(state)/dt = nominal + coefficient * term`` (contract §2), i.e. the
terms below are added to dx/dt directly, in derivative units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .integrate import StateLimit
from .plant import Plant
from .signals import Delayed, Mapped, Play, Signal
from .systems import BASES, TANK_LINEAR, Base

MAGNITUDES = ("small", "medium", "large")
FRAC = (0.05, 0.15, 0.4)          # additive term std / derivative std


@dataclass
class Pilot:
    """The base system without effects on the case's input: scales for sizing the effects."""

    t: np.ndarray
    U: np.ndarray
    X: np.ndarray
    dX: np.ndarray
    Y: np.ndarray


@dataclass
class Ctx:
    base: Base
    rng: np.random.Generator
    mag: int
    pilot: Pilot
    input_kind: str

    def x(self, s: str) -> np.ndarray:
        return self.pilot.X[:, self.base.index(s)]

    def dstd(self, s: str) -> float:
        return float(np.std(self.pilot.dX[:, self.base.index(s)]))

    @property
    def duration(self) -> float:
        return float(self.pilot.t[-1] - self.pilot.t[0] + self.base.dt)


@dataclass
class Effect:
    family: str
    kind: str = "effect"                        # effect | null | out_of_vocabulary
    acts_on: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)  # key parameters, contract §2 names
    apply: Callable[[Plant], None] | None = None
    wrap_input: Callable[[list[Signal], float], list[Signal]] | None = None  # (parts, t_end)
    nominal: dict = field(default_factory=dict)  # overrides: equations, params, intersample
    noise: dict = field(default_factory=dict)    # overrides: phi, dist, hetero
    accept: tuple[str, ...] = ()                 # answers counted correct (family ids / verdicts)


def _add(index: int, n: int, fn: Callable) -> Callable:
    """An additive term fn(t, x, z, u, p) entering equation ``index`` of an n-state base."""
    def term(t, x, z, u, p):
        d = np.zeros(n)
        d[index] = fn(t, x, z, u, p)
        return d
    return term


def _scaled(ctx: Ctx, eq: str, values: np.ndarray) -> float:
    """Coefficient c with std(c · values) = FRAC[mag] · std(d eq/dt) over the pilot."""
    return FRAC[ctx.mag] * ctx.dstd(eq) / float(np.std(values))


def _term_effect(ctx: Ctx, family: str, term: str, fn: Callable[[np.ndarray, np.ndarray, float], float],
                 values: np.ndarray, sign: float) -> Effect:
    b = ctx.base
    eq = b.force_eq
    c = sign * _scaled(ctx, eq, values)
    i, n = b.index(eq), len(b.states)
    return Effect(family, acts_on={"equation": eq},
                  params={"equation": eq, "term": term, "coefficient": c},
                  apply=lambda pl: pl.additive.append(_add(i, n, lambda t, x, z, u, p: c * fn(x, u, t))))


# ------------------------------------------------------------------ families with a term in an equation
def offset(ctx: Ctx) -> Effect:
    b = ctx.base
    eq = b.force_eq
    c = float(ctx.rng.choice([-1.0, 1.0])) * FRAC[ctx.mag] * ctx.dstd(eq)
    i, n = b.index(eq), len(b.states)
    return Effect("offset", acts_on={"equation": eq}, params={"equation": eq, "coefficient": c},
                  apply=lambda pl: pl.additive.append(_add(i, n, lambda t, x, z, u, p: c)))


def cubic_stiffness(ctx: Ctx) -> Effect:
    j = ctx.base.index(ctx.base.pos)
    return _term_effect(ctx, "cubic_stiffness", f"{ctx.base.pos}**3", lambda x, u, t: x[j] ** 3,
                        ctx.x(ctx.base.pos) ** 3, -1.0)


def quadratic_damping(ctx: Ctx) -> Effect:
    v = ctx.base.vel
    j = ctx.base.index(v)
    return _term_effect(ctx, "quadratic_damping", f"{v}*abs({v})", lambda x, u, t: x[j] * abs(x[j]),
                        ctx.x(v) * np.abs(ctx.x(v)), -1.0)


def coulomb_friction(ctx: Ctx) -> Effect:
    """−F tanh(v/ε), ε = 1 % of std(v) (a smoothed sign(v), contract §2 allows it)."""
    v = ctx.base.vel
    j = ctx.base.index(v)
    eps = 0.01 * float(np.std(ctx.x(v)))
    e = _term_effect(ctx, "coulomb_friction", f"sign({v})", lambda x, u, t: math.tanh(x[j] / eps),
                     np.tanh(ctx.x(v) / eps), -1.0)
    e.params["smoothing_eps"] = eps
    return e


def static_nonlinearity(ctx: Ctx) -> Effect:
    """Tank: the truth has sqrt outflow, the nominal a linear one. Others: a missing u² input term."""
    b = ctx.base
    if b.name == "tank":
        a = b.params["a"]
        h0 = b.x0["h"]
        return Effect("static_nonlinearity", acts_on={"equation": "h"},
                      params={"equation": "h", "term": "sqrt(h)", "coefficient": -a,
                              "note": "the nominal's linear outflow a*h is absent from the truth (a = 0)"},
                      nominal={"equations": dict(TANK_LINEAR["equations"]),
                               "params": {"a": TANK_LINEAR["a_of"](a, h0)}})
    u = b.inputs[0]
    return _term_effect(ctx, "static_nonlinearity", f"{u}**2", lambda x, uu, t: uu[0] ** 2,
                        ctx.pilot.U[:, 0] ** 2, 1.0)


def periodic_disturbance(ctx: Ctx) -> Effect:
    """A sin(2π f t + φ) in the force equation; f near the plant's band, ≥ 10 cycles per record, and
    half-way between two lines of the multisine grid (never on an excited input frequency)."""
    b = ctx.base
    eq = b.force_eq
    T = ctx.duration
    f0 = ctx.rng.uniform(0.5, 1.5) / (2 * math.pi * b.tc)
    f0 = min(max(f0, 10.0 / T), 0.2 / b.dt)
    f = (math.floor(f0 * T) + 0.5) / T
    amp = FRAC[ctx.mag] * ctx.dstd(eq) * math.sqrt(2.0)
    ph = float(ctx.rng.uniform(0, 2 * math.pi))
    i, n = b.index(eq), len(b.states)
    w = 2 * math.pi * f
    return Effect("periodic_disturbance", acts_on={"equation": eq},
                  params={"equation": eq, "frequency_hz": f, "amplitude": amp, "phase_rad": ph},
                  apply=lambda pl: pl.additive.append(_add(i, n, lambda t, x, z, u, p: amp * math.sin(w * t + ph))))


# ------------------------------------------------------------------ input path
DELAY_SAMPLES = (1.4, 3.6, 8.3)


def input_delay(ctx: Ctx) -> Effect:
    d = DELAY_SAMPLES[ctx.mag] * ctx.base.dt
    return Effect("input_delay", acts_on={"input": "all"}, params={"delay_s": d, "delay_samples": d / ctx.base.dt},
                  wrap_input=lambda parts, t_end: [Delayed(s, d) for s in parts])


SAT_QUANTILE = (0.95, 0.85, 0.7)


def input_saturation(ctx: Ctx) -> Effect:
    """clip(u, −L, L) for a zero-mean input, minimum(u, L) for a positive one (a pump's maximum)."""
    b = ctx.base
    u0 = ctx.pilot.U[:, 0]
    if b.u_mean == 0.0:
        L = float(np.quantile(np.abs(u0), SAT_QUANTILE[ctx.mag]))
        fn, lower, frac = (lambda u: np.clip(u, -L, L)), -L, float(np.mean(np.abs(u0) > L))
    else:
        L = float(np.quantile(u0, SAT_QUANTILE[ctx.mag]))
        fn, lower, frac = (lambda u: np.minimum(u, L)), None, float(np.mean(u0 > L))
    return Effect("input_saturation", acts_on={"input": b.inputs[0]},
                  params={"limit": L, "lower": lower, "fraction_clipped": frac, "input": b.inputs[0]},
                  wrap_input=lambda parts, t_end: [Mapped(parts[0], fn)] + parts[1:])


DZ_WIDTH = (0.1, 0.25, 0.5)   # × std(u)


def dead_zone(ctx: Ctx) -> Effect:
    """sign(u)·max(|u| − w, 0): the input does nothing inside ±w."""
    b = ctx.base
    w = DZ_WIDTH[ctx.mag] * float(np.std(ctx.pilot.U[:, 0]))

    def fn(u):
        return np.sign(u) * np.maximum(np.abs(u) - w, 0.0)
    return Effect("dead_zone", acts_on={"input": b.inputs[0]}, params={"width": w, "input": b.inputs[0]},
                  wrap_input=lambda parts, t_end: [Mapped(parts[0], fn)] + parts[1:])


LAG_TAU = (0.15, 0.4, 1.0)     # × the base's fastest time constant


def unmodeled_dynamics(ctx: Ctx) -> Effect:
    """A first-order actuator lag on input 0: u_a' = (u − u_a)/τ, the plant sees u_a."""
    b = ctx.base
    tau = LAG_TAU[ctx.mag] * b.tc

    def apply(pl: Plant) -> None:
        pl.extra_x0 = [float(pl.signal.value(0.0)[0])]
        pl.actuator_state = 0
        pl.extra = lambda t, x, z, u_raw, p: np.array([(u_raw[0] - z[0]) / tau])
    return Effect("unmodeled_dynamics", acts_on={"input": b.inputs[0]},
                  params={"time_constant_s": tau, "added_order": 1, "input": b.inputs[0],
                          "what": "first-order actuator lag"}, apply=apply)


NODE_TAU = (0.5, 3.0)         # × the base's fastest time constant: the range a second storage's τ is drawn from


def unmodeled_state(ctx: Ctx) -> Effect:
    """A second storage coupled to the state s of the force equation (a second thermal mass, a
    compliant mount): z' = (s − z)/τ, s' gains c·(z − s). τ drawn log-uniformly from ``NODE_TAU`` × tc;
    c sized on the pilot like the additive families, with (z − s) from the pilot's s through the lag
    (exact for s held between samples), and positive (a passive exchange: s is pulled towards z)."""
    b = ctx.base
    s = b.force_eq
    i, n = b.index(s), len(b.states)
    tau = float(b.tc * math.exp(ctx.rng.uniform(math.log(NODE_TAU[0]), math.log(NODE_TAU[1]))))
    xs = ctx.x(s)
    g = 1.0 - math.exp(-b.dt / tau)
    zp = np.empty_like(xs)
    zp[0] = xs[0]
    for k in range(1, len(xs)):
        zp[k] = zp[k - 1] + g * (xs[k - 1] - zp[k - 1])
    c = _scaled(ctx, s, zp - xs)

    def apply(pl: Plant) -> None:
        pl.extra_x0 = [float(b.initial()[i])]
        pl.extra = lambda t, x, z, u_raw, p: np.array([(x[i] - z[0]) / tau])
        pl.additive.append(_add(i, n, lambda t, x, z, u, p: c * (z[0] - x[i])))
    return Effect("unmodeled_dynamics", acts_on={"equation": s},
                  params={"time_constant_s": tau, "added_order": 1, "equation": s, "coupling": c,
                          "what": "a second storage coupled to the state of the force equation"}, apply=apply)


# ------------------------------------------------------------------ parameters in time
JUMP_FACTOR = (1.15, 1.35, 1.8)
DRIFT_CHANGE = (0.1, 0.25, 0.6)   # relative change over the record


def parameter_jump(ctx: Ctx) -> Effect:
    b = ctx.base
    name = b.jump_param
    before = b.params[name]
    f = JUMP_FACTOR[ctx.mag]
    after = before * (f if ctx.rng.random() < 0.5 else 1.0 / f)
    tj = float(ctx.rng.uniform(0.25, 0.5) * ctx.duration)
    p_after = dict(b.params, **{name: after})

    def apply(pl: Plant) -> None:
        pl.params_of_t = lambda t: pl.params if t < tj else p_after
        pl.breakpoints.append(tj)
    return Effect("parameter_jump", acts_on={"parameter": name},
                  params={"parameter": name, "time_s": tj, "before": before, "after": after}, apply=apply)


def parameter_drift(ctx: Ctx) -> Effect:
    """p(t) = p0 (1 + r t): ``rate_per_s`` = r (relative), ``absolute_rate_per_s`` = p0 r."""
    b = ctx.base
    name = b.jump_param
    p0 = b.params[name]
    r = float(ctx.rng.choice([-1.0, 1.0])) * DRIFT_CHANGE[ctx.mag] / ctx.duration

    def apply(pl: Plant) -> None:
        pl.params_of_t = lambda t: dict(pl.params, **{name: p0 * (1.0 + r * t)})
    return Effect("parameter_drift", acts_on={"parameter": name},
                  params={"parameter": name, "rate_per_s": r, "absolute_rate_per_s": p0 * r,
                          "form": f"{name}*(1 + rate_per_s*t)"}, apply=apply)


# ------------------------------------------------------------------ state limit
LIMIT_QUANTILE = (0.97, 0.9, 0.8)


def state_saturation(ctx: Ctx) -> Effect:
    """Tank: overflow at h = L; mass–spring–damper: an inelastic end stop at x = L."""
    b = ctx.base
    s = b.pos if b.pos is not None else b.force_eq
    L = float(np.quantile(ctx.x(s), LIMIT_QUANTILE[ctx.mag]))
    vel = b.index(b.vel) if b.pos is not None else None
    lim = StateLimit(b.index(s), L, vel)

    def apply(pl: Plant) -> None:
        pl.limit = lim
    return Effect("state_saturation", acts_on={"state": s},
                  params={"state": s, "limit": L, "side": "upper"}, apply=apply)


# ------------------------------------------------------------------ noise families
def colored_noise(ctx: Ctx) -> Effect:
    phi = (0.5, 0.8, 0.95)[ctx.mag]
    return Effect("colored_noise", acts_on={"output": "all"},
                  params={"phi": phi, "correlation_time_s": -ctx.base.dt / math.log(phi),
                          "noise_model": "AR(1) on the output"}, noise={"phi": phi})


def heavy_tailed_noise(ctx: Ctx) -> Effect:
    return Effect("heavy_tailed_noise", acts_on={"output": "all"},
                  params={"df": 3.0, "noise_model": "Student t, nu = 3, scaled to the noise std"},
                  noise={"dist": "student_t", "df": 3.0})


def heteroscedastic_noise(ctx: Ctx) -> Effect:
    beta = (0.5, 0.8, 1.0)[ctx.mag]
    return Effect("heteroscedastic_noise", acts_on={"output": "all"},
                  params={"beta": beta, "formula": "sigma_k = a + b*|y_k - ybar| (per output)"},
                  noise={"hetero": beta})


def intersample(ctx: Ctx) -> Effect:
    """The config states the wrong intersample behaviour: zoh for a smooth input, foh for held steps.
    The smooth input is a multisine below the Nyquist frequency, exactly band-limited, so ``bandlimited``
    (the band-limited signal through the samples) is as right a choice as ``foh``, and closer
    (``also_right``)."""
    right = "foh" if ctx.input_kind == "band" else "zoh"
    wrong = "zoh" if right == "foh" else "foh"
    also = ["bandlimited"] if ctx.input_kind == "band" else []
    return Effect("intersample", acts_on={"simulation": "intersample"},
                  params={"chosen": right, "configured": wrong, "also_right": also}, nominal={"intersample": wrong})


def none(ctx: Ctx) -> Effect:
    return Effect("none", kind="null", accept=("no_significant_discrepancy",))


# ------------------------------------------------------------------ out of vocabulary
def backlash(ctx: Ctx) -> Effect:
    """Play operator on the input (gear backlash between actuator and plant), dead band w."""
    w = (0.1, 0.25, 0.5)[ctx.mag] * 2.0 * float(np.std(ctx.pilot.U[:, 0]))
    dt = ctx.base.dt
    return Effect("backlash", kind="out_of_vocabulary", acts_on={"input": ctx.base.inputs[0]},
                  params={"width": w},
                  wrap_input=lambda parts, t_end: [Play(parts[0], w, t_end, dt)] + parts[1:])


def hysteresis(ctx: Ctx) -> Effect:
    """Bouc–Wen restoring force (Wen 1976), n = 1: F = α k x + (1 − α) k z,
    z' = A v − β |v| z − γ v |z|, z bounded by A/(β + γ) = z_max."""
    b = ctx.base
    k = b.params["k"] if "k" in b.params else b.params["k1"]
    m = b.params.get("m", b.params.get("m1", 1.0))
    zmax = (2.0, 1.0, 0.5)[ctx.mag] * float(np.std(ctx.x(b.pos)))
    alpha, A = 0.5, 1.0
    beta = gamma = A / (2 * zmax)
    ix, iv = b.index(b.pos), b.index(b.vel)
    n = len(b.states)

    def apply(pl: Plant) -> None:
        pl.extra_x0 = [0.0]
        # truth −αk x − (1−α)k z = nominal −k x + (1−α) k (x − z)
        pl.additive.append(_add(iv, n, lambda t, x, z, u, p: (1 - alpha) * k * (x[ix] - z[0]) / m))
        pl.extra = lambda t, x, z, u_raw, p: np.array(
            [A * x[iv] - beta * abs(x[iv]) * z[0] - gamma * x[iv] * abs(z[0])])
    return Effect("hysteresis", kind="out_of_vocabulary", acts_on={"equation": b.vel},
                  params={"model": "Bouc-Wen n=1", "alpha": alpha, "A": A, "beta": beta, "gamma": gamma,
                          "z_max": zmax}, apply=apply)


def wrong_order(ctx: Ctx) -> Effect:
    """An extra lightly damped mode in parallel (modal form): q'' = −ω² q − 2ζω q' + g u, and the first
    measured output is the base's plus q; ω = 3/tc, ζ = 0.05, g so that std(q) = FRAC[m]·std(y)."""
    from scipy import signal as sps
    b = ctx.base
    om, zeta = 3.0 / b.tc, 0.05
    sysm = sps.lti([1.0], [1.0, 2 * zeta * om, om ** 2])
    _, q1, _ = sps.lsim(sysm, ctx.pilot.U[:, 0], ctx.pilot.t)
    g = (0.1, 0.25, 0.6)[ctx.mag] * float(np.std(ctx.pilot.Y[:, 0])) / float(np.std(q1))
    nb = len(b.states)

    def apply(pl: Plant) -> None:
        pl.extra_x0 = [0.0, 0.0]
        pl.extra = lambda t, x, z, u_raw, p: np.array([z[1], -om * om * z[0] - 2 * zeta * om * z[1] + g * u_raw[0]])

        def out(t, X):
            add = np.zeros((len(X), len(b.measured)))
            add[:, 0] = X[:, nb]
            return add
        pl.output_add = out
    return Effect("wrong_order", kind="out_of_vocabulary", acts_on={"output": b.measured[0]},
                  params={"extra_mode_rad_s": om, "zeta": zeta, "gain": g},
                  accept=("unexplained_discrepancy", "unmodeled_dynamics"), apply=apply)


def xexp(ctx: Ctx) -> Effect:
    """g·x·exp(−(x/x0)²) in the force equation (x0 = std(x)): a form no term library holds."""
    b = ctx.base
    j = b.index(b.pos)
    x0 = float(np.std(ctx.x(b.pos)))
    vals = ctx.x(b.pos) * np.exp(-(ctx.x(b.pos) / x0) ** 2)
    e = _term_effect(ctx, "xexp", f"{b.pos}*exp(-({b.pos}/{x0:.6g})**2)",
                     lambda x, u, t: x[j] * math.exp(-(x[j] / x0) ** 2), vals, 1.0)
    e.kind, e.family = "out_of_vocabulary", "xexp"
    e.params["x0"] = x0
    return e


def sensor_law(ctx: Ctx) -> Effect:
    """A static law in the sensor of the first measured output: y = z + c·(z − z̄)³ (z̄ the pilot's mean),
    std(c·(z − z̄)³) = FRAC[m]·std(y) over the pilot. No family holds it (the families act on the
    dynamics, an output offset is a constant)."""
    b = ctx.base
    y0 = ctx.pilot.Y[:, 0]
    zbar = float(np.mean(y0))
    c = FRAC[ctx.mag] * float(np.std(y0)) / float(np.std((y0 - zbar) ** 3))
    j = b.index(b.measured[0])

    def apply(pl: Plant) -> None:
        def out(t, X):
            add = np.zeros((len(X), len(b.measured)))
            add[:, 0] = c * (X[:, j] - zbar) ** 3
            return add
        pl.output_add = out
    return Effect("sensor_law", kind="out_of_vocabulary", acts_on={"output": b.measured[0]},
                  params={"law": "y = z + c*(z - centre)**3", "c": c, "centre": zbar}, apply=apply)


def modulated_stiffness(ctx: Ctx) -> Effect:
    """The restoring coefficient breathes: −k·x becomes −k·(1 + a·sin(ωt))·x, three cycles per record
    (a temperature or supply ripple), i.e. −a·k·sin(ωt)·x added to the force equation, sized as the
    additive families (std over the pilot = FRAC[m]·std(derivative)). Neither a step
    (``parameter_jump``) nor a straight line (``parameter_drift``), nor a forcing independent of the
    state (``periodic_disturbance``)."""
    b = ctx.base
    eq = b.force_eq
    i, n = b.index(eq), len(b.states)
    j = b.index(b.pos)
    om = 2 * math.pi * 3.0 / ctx.duration
    vals = np.sin(om * ctx.pilot.t) * ctx.x(b.pos)
    a = _scaled(ctx, eq, vals)
    return Effect("modulated_stiffness", kind="out_of_vocabulary", acts_on={"equation": eq},
                  params={"form": "-a*sin(2*pi*f*t)*x", "a": a, "f_hz": om / (2 * math.pi)},
                  apply=lambda pl: pl.additive.append(_add(i, n, lambda t, x, z, u, p: -a * math.sin(om * t) * x[j])))


def rate_limit(ctx: Ctx) -> Effect:
    """A slew-rate limit in the actuator of input 0: u_a' = R·tanh((u − u_a)/(R·τ_f)), the plant sees u_a
    (τ_f = dt/50: a rate limiter |u_a'| ≤ R, smoothed so the integrator can follow it); R = 0.6, 0.35,
    0.15 × the input's largest rate over the pilot. Not a lag (its ramps last longer for larger steps)
    nor a delay."""
    b = ctx.base
    u = ctx.pilot.U[:, 0]
    R = (0.6, 0.35, 0.15)[ctx.mag] * float(np.max(np.abs(np.diff(u)))) / b.dt
    tf = 0.02 * b.dt

    def apply(pl: Plant) -> None:
        pl.extra_x0 = [float(pl.signal.value(0.0)[0])]
        pl.actuator_state = 0
        pl.extra = lambda t, x, z, u_raw, p: np.array([R * math.tanh((u_raw[0] - z[0]) / (R * tf))])
    return Effect("rate_limit", kind="out_of_vocabulary", acts_on={"input": b.inputs[0]},
                  params={"rate": R, "smoothing_s": tf}, apply=apply)


FAMILIES: dict[str, Callable[[Ctx], Effect]] = {
    "none": none, "offset": offset, "output_offset": None, "cubic_stiffness": cubic_stiffness,
    "quadratic_damping": quadratic_damping, "coulomb_friction": coulomb_friction,
    "static_nonlinearity": static_nonlinearity, "periodic_disturbance": periodic_disturbance,
    "input_delay": input_delay, "input_saturation": input_saturation, "dead_zone": dead_zone,
    "parameter_jump": parameter_jump, "parameter_drift": parameter_drift,
    "unmodeled_dynamics": unmodeled_dynamics, "state_saturation": state_saturation,
    "colored_noise": colored_noise, "heavy_tailed_noise": heavy_tailed_noise,
    "heteroscedastic_noise": heteroscedastic_noise, "intersample": intersample,
}
OUT_OF_VOCABULARY: dict[str, Callable[[Ctx], Effect]] = {
    "backlash": backlash, "hysteresis": hysteresis, "wrong_order": wrong_order, "xexp": xexp,
    "sensor_law": sensor_law, "modulated_stiffness": modulated_stiffness, "rate_limit": rate_limit}


def output_offset(ctx: Ctx) -> Effect:
    b = ctx.base
    y = b.measured[0]
    val = float(ctx.rng.choice([-1.0, 1.0])) * (0.1, 0.3, 0.8)[ctx.mag] * float(np.std(ctx.pilot.Y[:, 0]))

    def apply(pl: Plant) -> None:
        def out(t, X):
            add = np.zeros((len(X), len(b.measured)))
            add[:, 0] = val
            return add
        pl.output_add = out
    return Effect("output_offset", acts_on={"output": y}, params={"output": y, "value": val}, apply=apply)


FAMILIES["output_offset"] = output_offset
# a second form of unmodeled_dynamics (a missing state coupled to a state, not an input lag), last in
# the menu so that the bench grid's rotation of the earlier records is unchanged
FAMILIES["unmodeled_state"] = unmodeled_state

# which bases each kind is physically sensible on
ZERO_MEAN = tuple(n for n, b in BASES.items() if b.u_mean == 0.0)
MECH2 = ("msd", "pendulum", "twomode")
WITH_VEL = ("msd", "pendulum", "dcmotor", "dcmotor2", "twomode")
ALL = tuple(BASES)
SUPPORTED: dict[str, tuple[str, ...]] = {
    "none": ALL, "offset": ALL, "output_offset": ALL, "cubic_stiffness": MECH2,
    "quadratic_damping": WITH_VEL, "coulomb_friction": WITH_VEL,
    "static_nonlinearity": ("tank", "msd", "dcmotor", "mimo"), "periodic_disturbance": ALL,
    "input_delay": ALL, "input_saturation": ALL, "dead_zone": ZERO_MEAN, "parameter_jump": ALL,
    "parameter_drift": ALL, "unmodeled_dynamics": ALL, "unmodeled_state": ALL, "state_saturation": ("tank", "msd"),
    "colored_noise": ALL, "heavy_tailed_noise": ALL, "heteroscedastic_noise": ALL, "intersample": ALL,
    "backlash": ("msd", "pendulum", "dcmotor"), "hysteresis": ("msd",), "wrong_order": ("msd", "dcmotor", "tank"),
    "xexp": ("msd", "pendulum"), "sensor_law": ("msd", "pendulum", "tank"),
    "modulated_stiffness": ("msd", "pendulum"), "rate_limit": ("msd", "dcmotor", "tank"),
}
# inputs that make a family unidentifiable: a clipped or dead-banded two-level PRBS is a gain change;
# so is a two-level PRBS through a backlash (play operator of width w: after every switch of ±a the
# output is ±(a − w/2), exactly a dead zone's or a gain's output, so no record can tell them apart;
# the bench of 2026-12-02 named dead_zone on 4 of 6 such records, each to the noise floor)
# ... and a slew limit R on a two-level PRBS (levels ±a) makes every switch the same ramp of length 2a/R:
# the input convolved with a box of that width, a linear input filter, which no record can tell from one
UNIDENTIFIABLE = {("input_saturation", "prbs"), ("dead_zone", "prbs"), ("backlash", "prbs"), ("rate_limit", "prbs")}
# ... and on some bases only: the static nonlinearity off the tank is u**2, a constant (an offset) when u
# is a two-level PRBS (the full bench grid of 2026-12-02 failed there with a division by its zero std)
UNIDENTIFIABLE_ON = {("static_nonlinearity", "prbs"): tuple(b for b in ALL if b != "tank")}


def identifiable(family: str, input_kind: str, base: str) -> bool:
    """Can the family's effect be told apart from the nominal model with this input on this base?"""
    return ((family, input_kind) not in UNIDENTIFIABLE
            and base not in UNIDENTIFIABLE_ON.get((family, input_kind), ()))
# what the input must look like for the family (before the pilot): scale of std, of the cutoff
# (the tank's square-root outflow is the base itself: its size is the operating range)
INPUT_OPTIONS: dict[str, Callable[[int, str], dict]] = {
    "static_nonlinearity": lambda m, base: {"std_scale": (0.6, 1.0, 1.3)[m]} if base == "tank" else {},
    "intersample": lambda m, base: {"cutoff_scale": (1.5, 3.0, 5.0)[m]},
}
