"""Two causes at once (issue 8): are both named within ``max_findings``?

Records made here with ``scipy.integrate.solve_ivp`` (LSODA, rtol 1e-9) on a continuous-time input (a
sum of eight sines between 0.02 and 0.6 Hz), sharing no code with the detector: a mass–spring–damper

    m x'' = F(u) − c x' − k x − k3 x³ − cq x'|x'| − Fc·tanh(x'/1e-3) + d + a·sin(2π f t),

with F(u) the input through a dead zone sgn(u)·max(|u| − w, 0), a saturation clip(u, −L, L), a dead
time u(t − τ) or a first-order lag u_a' = (u − u_a)/τ_a, a jump of k at t_j, and a sensor offset on x;
2 % white measurement noise (of the clean output's standard deviation). The user's nominal model is
the linear one, with c and k free; 30 % of the record is held out for validation, ``max_findings: 3``.

A record counts as right when a finding of each cause's family is among the findings (either offset
form counts for an offset: in open loop a constant force d and a sensor offset d/k differ only in the
start transient). ``python -m pipeline.bench.two_causes [--seeds 2005,2006,2007,2008] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.integrate import solve_ivp

from .diagnosis import write_section

M, C, K = 1.0, 0.6, 4.0
OFFSETS = {"offset", "output_offset"}
# name: (the record's effects, the families that name the first cause, those that name the second)
COMBOS: dict[str, tuple[dict, set, set]] = {
    "friction+offset": (dict(fc=0.15, d=0.2), {"coulomb_friction"}, OFFSETS),
    "saturation+cubic": (dict(L=0.6, k3=3.0), {"input_saturation"}, {"cubic_stiffness"}),
    "deadzone+cubic": (dict(w=0.15, k3=3.0), {"dead_zone"}, {"cubic_stiffness"}),
    "delay+offset": (dict(tau=0.1, d=0.2), {"input_delay"}, OFFSETS),
    "jump+offset": (dict(jump=(50.0, 0.3), d=0.2), {"parameter_jump"}, OFFSETS),
    "saturation+offset": (dict(L=0.6, d=0.2), {"input_saturation"}, OFFSETS),
    "quaddamping+friction": (dict(cq=1.0, fc=0.15), {"quadratic_damping"}, {"coulomb_friction"}),
    "deadzone+offset": (dict(w=0.15, d=0.2), {"dead_zone"}, OFFSETS),
    "delay+cubic": (dict(tau=0.1, k3=3.0), {"input_delay"}, {"cubic_stiffness"}),
    "quaddamping+sensoroffset": (dict(cq=1.0, yoff=0.05), {"quadratic_damping"}, OFFSETS),
    "jump+friction": (dict(jump=(50.0, 0.3), fc=0.15), {"parameter_jump"}, {"coulomb_friction"}),
    "saturation+quaddamping": (dict(L=0.6, cq=1.0), {"input_saturation"}, {"quadratic_damping"}),
    "lag+cubic": (dict(lag=0.3, k3=3.0), {"unmodeled_dynamics"}, {"cubic_stiffness"}),
    "periodic+friction": (dict(per=(0.15, 1.3), fc=0.15), {"periodic_disturbance"}, {"coulomb_friction"}),
}
SEEDS = (2005, 2006, 2007, 2008)
START, END = "<!-- bench-two-causes:start -->", "<!-- bench-two-causes:end -->"


def sines(seed: int):
    """The input u(t): eight sines, frequencies U(0.02, 0.6) Hz, amplitudes U(0.5, 1)/2, phases U(0, 2π)."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.02, 0.6, 8)
    ph = rng.uniform(0, 2 * np.pi, 8)
    a = rng.uniform(0.5, 1.0, 8)
    return lambda s: np.sum(a * np.sin(2 * np.pi * f * np.asarray(s)[..., None] + ph), axis=-1) / 2.0


def record(folder: Path, name: str, seed: int, *, fc=0.0, d=0.0, L=None, k3=0.0, w=0.0, tau=0.0, cq=0.0,
           yoff=0.0, jump=None, lag=0.0, per=None, n=4000, dt=0.02) -> Path:
    """Write ``folder/name/{data.csv, config.yaml}`` (module docstring) and return the config's path."""
    t = np.arange(n) * dt
    u = sines(seed)

    def F(s, ua=None):
        x = u(s - tau) if ua is None else ua
        if w:
            x = np.sign(x) * np.maximum(np.abs(x) - w, 0.0)
        return np.clip(x, -L, L) if L is not None else x

    def f(s, z):
        x, v = z[0], z[1]
        Fu = F(s, z[2]) if lag else F(s)
        k = K * (1 + jump[1]) if (jump and s >= jump[0]) else K
        dv = (Fu - C * v - k * x - k3 * x ** 3 - fc * np.tanh(v / 1e-3) - cq * v * abs(v) + d
              + (per[0] * np.sin(2 * np.pi * per[1] * s) if per else 0.0)) / M
        return [v, dv] + ([(u(s) - z[2]) / lag] if lag else [])

    z0 = [0.0, 0.0] + ([float(u(0.0))] if lag else [])
    sol = solve_ivp(f, (0, t[-1]), z0, t_eval=t, rtol=1e-9, atol=1e-11, max_step=dt / 2, method="LSODA")
    x = sol.y[0] + yoff
    y = x + 0.02 * np.std(x) * np.random.default_rng(seed + 7).standard_normal(n)
    out = folder / name
    out.mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"t": t, "u": u(t), "x": y}).to_csv(out / "data.csv", index=False)
    cfg = {"name": name.replace("+", "_"), "seed": seed,
           "data": {"path": "data.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh",
                    "remove_mean": False},
           "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": M, "c": 0.5, "k": 3.5},
                     "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"},
                     "initial": {"x": 0.0, "v": 0.0}},
           "split": {"validation_fraction": 0.3},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (out / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return out / "config.yaml"


def run_one(combo: str, seed: int) -> dict:
    """One record: generate, diagnose, score."""
    from ..config import load_config
    from ..runs import analyse
    kw, first, second = COMBOS[combo]
    with tempfile.TemporaryDirectory(prefix="two-causes-") as tmp:
        path = record(Path(tmp), f"{combo}-{seed}", seed, **kw)
        t0 = time.perf_counter()
        with contextlib.redirect_stderr(io.StringIO()):
            d = analyse(load_config(path)).summary["diagnosis"]
        sec = time.perf_counter() - t0
    fams = [f["family"] for f in d["findings"]]
    return {"combo": combo, "seed": seed, "verdict": d["verdict"], "findings": fams,
            "look_ahead": any("gain_given" in f for f in d["findings"]),
            "right": bool(first & set(fams)) and bool(second & set(fams)), "seconds": sec}


def render(results: list[dict], seeds: tuple[int, ...], wall: float) -> str:
    rows = {}
    for r in results:
        rows.setdefault(r["combo"], []).append(r)
    right = sum(r["right"] for r in results)
    L = [START, "## Two causes at once (issue 8)", "",
         f"`python -m pipeline.bench.two_causes --seeds {','.join(map(str, seeds))}` "
         f"({time.strftime('%Y-%m-%d')}; {len(results)} records, {wall:.0f} s wall with 2 workers). Records made "
         "by `scipy.integrate.solve_ivp` on a sum of sines, sharing no code with the detector "
         "(`pipeline/bench/two_causes.py`): a mass–spring–damper with two hidden causes, 2 % white noise, the "
         "linear nominal model. Right: both causes' families among the findings.", "",
         f"**Both named: {right}/{len(results)}.**", "",
         "| causes | both named | findings (per seed) |", "|---|---:|---|"]
    for combo, rs in rows.items():
        cells = "; ".join(("✓ " if r["right"] else "✗ ") + (", ".join(r["findings"]) or r["verdict"])
                          + (" (look-ahead)" if r["look_ahead"] else "") for r in rs)
        L.append(f"| {combo} | {sum(r['right'] for r in rs)}/{len(rs)} | {cells} |")
    L += ["", END]
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Two hidden causes at once, on records the detector did not make.")
    ap.add_argument("--seeds", default=",".join(map(str, SEEDS)), help="comma-separated input/noise seeds")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="BENCHMARKS.md", help="the file whose section is written")
    ap.add_argument("--json", default=None, help="also write every record's result here")
    a = ap.parse_args(argv)
    try:
        seeds = tuple(int(s) for s in a.seeds.split(","))
    except ValueError:
        ap.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    if a.workers < 1:
        ap.error(f"--workers: expected a positive integer, got {a.workers}")
    for opt, path in (("--out", a.out), ("--json", a.json)):
        if path and not Path(path).resolve().parent.is_dir():
            ap.error(f"{opt}: the folder of {path} does not exist")
    os.environ.setdefault("MPLBACKEND", "Agg")
    jobs = [(c, s) for c in COMBOS for s in seeds]
    t0 = time.perf_counter()
    results = []
    with ProcessPoolExecutor(max_workers=a.workers, mp_context=get_context("spawn")) as pool:
        futs = [pool.submit(run_one, c, s) for c, s in jobs]
        for i, fu in enumerate(futs):
            r = fu.result()
            results.append(r)
            print(f"[bench-two-causes] {i + 1}/{len(jobs)} {r['combo']} {r['seed']}: "
                  f"{'both named' if r['right'] else 'MISS'} {r['findings']}", file=sys.stderr, flush=True)
    section = render(results, seeds, time.perf_counter() - t0)
    print(section)
    write_section(Path(a.out), section, START, END)
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
