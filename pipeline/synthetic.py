"""Synthetic records with one hidden effect, deterministic from a seed.

Base systems (the nominal model a user would believe; parameters are the truth):

* ``msd``       mass–spring–damper   x' = v,  v' = (u − c v − k x)/m
* ``pendulum``  damped pendulum      θ' = ω,  ω' = −g_l sin θ − b ω + u
* ``tank``      first-order tank     h' = b u − a h
* ``dcmotor``   DC motor speed       w' = K u − a w

Hidden effects (contract §2 family ids): ``none``, ``offset``, ``output_offset``, ``cubic_stiffness``,
``quadratic_damping``, ``coulomb_friction``, ``periodic_disturbance``, ``input_delay``.

The record is integrated with the same RK4 kernel at 8 sub-steps per sample (the kernel is checked
against closed-form responses in tests/test_simulate.py), the input is band-limited noise held between
samples (zoh), and white Gaussian measurement noise of ``noise`` × std(y) is added.
Usage: ``python -m pipeline.synthetic msd cubic_stiffness --seed 0 --csv data/demo.csv``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
from scipy import signal

from .expressions import parse
from .model import Model, Term

BASE = {
    "msd": dict(states=["x", "v"], inputs=["u"], params={"m": 1.0, "c": 0.6, "k": 4.0}, free=["c", "k"],
                equations={"x": "v", "v": "(u - c*v - k*x)/m"}, measured="x", vel="v", pos="x",
                u_mean=0.0, u_std=2.0, band_hz=1.0, dt=0.02),
    "pendulum": dict(states=["th", "w"], inputs=["u"], params={"g_l": 9.81, "b": 0.5}, free=["g_l", "b"],
                     equations={"th": "w", "w": "-g_l*sin(th) - b*w + u"}, measured="th", vel="w", pos="th",
                     u_mean=0.0, u_std=1.5, band_hz=1.0, dt=0.02),
    "tank": dict(states=["h"], inputs=["u"], params={"a": 0.5, "b": 1.0}, free=["a", "b"],
                 equations={"h": "b*u - a*h"}, measured="h", vel="h", pos="h",
                 u_mean=1.0, u_std=0.5, band_hz=0.5, dt=0.05),
    "dcmotor": dict(states=["w"], inputs=["u"], params={"K": 4.0, "a": 2.0}, free=["K", "a"],
                    equations={"w": "K*u - a*w"}, measured="w", vel="w", pos="w",
                    u_mean=0.0, u_std=1.0, band_hz=1.0, dt=0.02),
}

# effect -> (term kind, target state role, coefficient as a multiple of a typical scale)
EFFECTS = ("none", "offset", "output_offset", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
           "periodic_disturbance", "input_delay")


@dataclass
class Synthetic:
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    system: str
    effect: str
    truth: dict           # family, equation, key parameters
    config: dict          # the nominal config (data section without path)

    def to_frame(self):
        import pandas as pd
        out = BASE[self.system]["measured"]
        return pd.DataFrame({"t": self.t, "u": self.u, out: self.y})


def _nominal(system: str) -> Model:
    b = BASE[system]
    allowed = set(b["states"]) | set(b["inputs"]) | set(b["params"]) | {"t"}
    return Model(states=tuple(b["states"]), inputs=tuple(b["inputs"]),
                 equations={s: parse(e, allowed) for s, e in b["equations"].items()}, output_exprs={},
                 params=dict(b["params"]), free=tuple(b["free"]), initial={s: 0.0 for s in b["states"]},
                 substeps=8, intersample="zoh", nominal_params=tuple(b["params"]))


def _input(rng: np.random.Generator, n: int, dt: float, mean: float, std: float, band: float) -> np.ndarray:
    sos = signal.butter(4, band, fs=1.0 / dt, output="sos")
    w = signal.sosfiltfilt(sos, rng.standard_normal(n + 400))[200:-200]
    return mean + std * w / np.std(w)


NOISE_KINDS = ("white", "ar1", "student_t", "hetero")


def measurement_noise(rng: np.random.Generator, y: np.ndarray, level: float, kind: str = "white",
                      param: float | None = None) -> np.ndarray:
    """Output noise with std ``level`` (absolute): white Gaussian; ``ar1`` (coefficient ``param``,
    default 0.9, scaled to the same std); ``student_t`` (ν = ``param``, default 3, scaled to the same
    std); ``hetero`` (std ∝ (0.2 + |y − ȳ|/std(y)), normalised to the same average variance)."""
    n = len(y)
    if kind == "white":
        return level * rng.standard_normal(n)
    if kind == "ar1":
        phi = 0.9 if param is None else param
        e = signal.lfilter([1.0], [1.0, -phi], rng.standard_normal(n + 500))[500:]
        return level * e * np.sqrt(1 - phi ** 2)
    if kind == "student_t":
        nu = 3.0 if param is None else param
        return level * rng.standard_t(nu, n) / np.sqrt(nu / (nu - 2))
    if kind == "hetero":
        s = 0.2 + np.abs(y - y.mean()) / (np.std(y) or 1.0)
        s = s / np.sqrt(np.mean(s ** 2))
        return level * s * rng.standard_normal(n)
    raise ValueError(f"unknown noise kind {kind!r}; known: {', '.join(NOISE_KINDS)}")


def generate(system: str, effect: str, seed: int, *, n: int = 3000, noise: float = 0.02,
             strength: float = 1.0, noise_kind: str = "white", noise_param: float | None = None) -> Synthetic:
    """A record of ``system`` with ``effect`` hidden in it; ``strength`` scales the effect;
    ``noise`` × std(y) is the measurement-noise level, of kind ``noise_kind`` (see measurement_noise)."""
    if system not in BASE:
        raise ValueError(f"unknown system {system!r}; known: {', '.join(BASE)}")
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
    b = BASE[system]
    rng = np.random.default_rng(seed)
    dt = b["dt"]
    t = np.arange(n) * dt
    u = _input(rng, n, dt, b["u_mean"], b["u_std"], b["band_hz"])
    m = _nominal(system)
    eq = b["states"][-1]          # the dynamic (force/flow) equation
    pos, vel = b["pos"], b["vel"]
    # effect sizes chosen relative to the nominal signal levels (strength = 1: clearly visible)
    y_lin = _simulate(m, t, u)
    ystd = float(np.std(y_lin))
    dstd = float(np.std(np.gradient(_simulate(m, t, u, state=eq), dt))) if len(b["states"]) > 1 else \
        float(np.std(np.gradient(y_lin, dt)))
    truth: dict = {"family": effect, "equation": eq}
    out_offset = 0.0
    if effect == "offset":
        c = 0.3 * dstd * strength
        m = m.extend([Term(effect, "const", eq, "h_off")], {"h_off": c})
        truth.update(coefficient=c)
    elif effect == "cubic_stiffness":
        xs = float(np.std(_simulate(m, t, u, state=pos)))
        c = -0.3 * dstd / xs ** 3 * strength
        m = m.extend([Term(effect, "pow", eq, "h_c3", var=pos, power=3)], {"h_c3": c})
        truth.update(coefficient=c, term=f"{pos}**3")
    elif effect == "quadratic_damping":
        vs = float(np.std(_simulate(m, t, u, state=vel)))
        c = -0.3 * dstd / vs ** 2 * strength
        m = m.extend([Term(effect, "absprod", eq, "h_qd", var=vel)], {"h_qd": c})
        truth.update(coefficient=c, term=f"{vel}*abs({vel})")
    elif effect == "coulomb_friction":
        c = -0.25 * dstd * strength
        m = m.extend([Term(effect, "sign", eq, "h_cf", var=vel)], {"h_cf": c})
        truth.update(coefficient=c, term=f"sign({vel})")
    elif effect == "periodic_disturbance":
        f = 0.8 if system != "tank" else 0.3
        a = 0.3 * dstd * strength
        m = m.extend([Term(effect, "sin", eq, "h_a", freq="h_f")], {"h_a": a, "h_f": f})
        truth.update(frequency_hz=f, amplitude=a)
    elif effect == "input_delay":
        d = 5 * dt * strength                       # strength 1: five samples of dead time
        m = m.extend([], {"h_d": d}, delay="h_d")
        truth.update(delay_s=d, equation=None)
    elif effect == "output_offset":
        out_offset = 0.3 * ystd * strength
        truth.update(value=out_offset, output=b["measured"], equation=None)
    y = _simulate(m, t, u) + out_offset
    y = y + measurement_noise(rng, y, noise * ystd, noise_kind, noise_param)
    truth["noise"] = {"kind": noise_kind, "param": noise_param, "std": noise * ystd}
    cfg = {"states": b["states"], "inputs": b["inputs"], "params": dict(b["params"]), "free": list(b["free"]),
           "equations": dict(b["equations"]), "initial": {s: 0.0 for s in b["states"]}}
    return Synthetic(t, u, y, system, effect, truth, cfg)


def _simulate(m: Model, t: np.ndarray, u: np.ndarray, state: str | None = None) -> np.ndarray:
    from .simulate import simulate_states
    res = simulate_states(m, t, u[:, None], np.zeros(len(m.states)))
    if res.diverged_at is not None:
        raise RuntimeError("synthetic system diverged")
    return res.X[:, m.states.index(state or _measured_state(m))]


def _measured_state(m: Model) -> str:
    for b in BASE.values():
        if tuple(b["states"]) == m.states:
            return b["measured"]
    return m.states[0]


def config_for(syn: Synthetic, data_path: str, *, name: str | None = None, seed: int = 0,
               max_findings: int = 3) -> dict:
    """A complete pipeline config (contract §1) for a synthetic record written to ``data_path``."""
    out = BASE[syn.system]["measured"]
    return {"name": name or f"{syn.system}-{syn.effect}", "seed": seed,
            "data": {"path": data_path, "time": "t", "inputs": ["u"], "outputs": [out], "intersample": "zoh"},
            "model": syn.config, "split": {"validation_fraction": 0.3},
            "diagnose": {"families": "all", "alpha": 0.01, "max_findings": max_findings}}


def siso_narx(n: int, sigma: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """SysIdentPy's documented ``get_siso_data`` system, seeded: x ~ U(−1, 1), e ~ N(0, σ²),
    y[k] = 0.2 y[k−1] + 0.1 y[k−1] x[k−1] + 0.9 x[k−2] + e[k]. Returns (x, y)."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, sigma, n)
    x = rng.uniform(-1.0, 1.0, n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.2 * y[k - 1] + 0.1 * y[k - 1] * x[k - 1] + 0.9 * x[k - 2] + e[k]
    return x, y


def course_project(dt: float = 0.05, duration: float = 100.0):
    """The course project's Problem 2 system (seed 000): x' = −x³ + 0.8 tanh x + 1.2/(1 + x²) + u,
    u = 2.5 sin t + 0.1 sin 0.2t + 0.5 sin 0.3t, x(0) = 0, integrated with solve_ivp (rtol 1e-10)."""
    import pandas as pd
    from scipy.integrate import solve_ivp
    t = np.arange(0.0, duration + dt / 2, dt)

    def u(tt):
        return 2.5 * np.sin(tt) + 0.1 * np.sin(0.2 * tt) + 0.5 * np.sin(0.3 * tt)

    sol = solve_ivp(lambda tt, x: -x ** 3 + 0.8 * np.tanh(x) + 1.2 / (1 + x ** 2) + u(tt), (0.0, t[-1]), [0.0],
                    t_eval=t, rtol=1e-10, atol=1e-12, max_step=dt)
    return pd.DataFrame({"t": t, "u": u(t), "x": sol.y[0]})


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("system", choices=list(BASE) + ["course_project"])
    ap.add_argument("effect", choices=list(EFFECTS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--n", type=int, default=3000)
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--csv", required=True)
    a = ap.parse_args(argv)
    if a.system == "course_project":
        course_project().to_csv(a.csv, index=False, float_format="%.10g")
        print(f"wrote {a.csv}: course project Problem 2 (x' = -x^3 + 0.8 tanh x + 1.2/(1+x^2) + u)")
        return
    syn = generate(a.system, a.effect, a.seed, n=a.n, noise=a.noise)
    syn.to_frame().to_csv(a.csv, index=False, float_format="%.10g")
    print(f"wrote {a.csv}: {a.system} with hidden {a.effect} {syn.truth}")


if __name__ == "__main__":
    main()
