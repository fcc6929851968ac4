"""``make_case``: one record with one hidden effect (or none), its nominal config and its truth.

A case folder holds ``data.csv`` (t, the commanded inputs, the noisy measured outputs),
``config.yaml`` (the nominal model the user believes, in the project's config format, contract §1:
it names no effect) and ``truth.json`` (family, what it acts on, key parameters named as in contract
§2, magnitude, noise, input kind, seed, the answers counted correct).

Randomness: one ``numpy.random.SeedSequence`` per case from (seed, CRC-32 of the case's settings),
spawned into independent streams for the input, the effect, the noise and the nominal parameter
guesses, so the same arguments give byte-identical files and changing one stream leaves the others.
"""

from __future__ import annotations

import json
import math
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from . import effects as fx
from .noise import add_noise
from .plant import Plant
from .signals import BandLimited, Held, Signal, Stack, prbs
from .systems import BASES, Base

INPUT_KINDS = ("band", "held", "prbs")
COLOURS = {"white": 0.0, "ar0.5": 0.5, "ar0.9": 0.9}
NOISE_LEVELS = (0.01, 0.02, 0.05, 0.10)
MARKER = "pipeline.bench.independent"
FILES = ("data.csv", "config.yaml", "truth.json")


@dataclass
class Case:
    name: str
    truth: dict
    config: dict
    t: np.ndarray
    U: np.ndarray          # (N, nu) commanded input, sampled
    Y: np.ndarray          # (N, ny) measured (noisy)
    Y_clean: np.ndarray
    X: np.ndarray          # (N, nx) true states (base + extra)
    dir: Path | None = None

    @property
    def config_path(self) -> Path | None:
        return None if self.dir is None else self.dir / "config.yaml"


def case_name(family: str, base: str, seed: int, magnitude: str, noise: float, colour: str, input_kind: str) -> str:
    return f"{family}-{base}-{input_kind}-{magnitude}-n{noise:g}-{colour}-s{seed}"


def _inputs(base: Base, kind: str, rng: np.random.Generator, n: int, *, std_scale: float = 1.0,
            cutoff_scale: float = 1.0) -> list[Signal]:
    dt, T = base.dt, n * base.dt
    parts: list[Signal] = []
    for _ in base.inputs:
        std = base.u_std * std_scale
        if kind == "band":
            cutoff = min(base.band_hz * cutoff_scale, 0.2 / dt)
            parts.append(BandLimited.make(rng, duration=T, cutoff=cutoff, std=std, mean=base.u_mean))
        elif kind == "held":
            parts.append(Held.make(rng, dt=dt, n=n, min_samples=base.hold[0], max_samples=base.hold[1],
                                   std=std, mean=base.u_mean, low=base.u_low))
        elif kind == "prbs":
            parts.append(prbs(rng, dt=dt, n=n, clock=base.clock, std=std, mean=base.u_mean))
        else:
            raise ValueError(f"unknown input kind {kind!r} (known: {', '.join(INPUT_KINDS)})")
    return parts


def _pilot(base: Base, parts: list[Signal], t: np.ndarray) -> fx.Pilot:
    pl = Plant(base, Stack(parts), dict(base.params))
    X = pl.simulate(t)
    U = Stack(parts).sample(t)
    dX = np.array([base.rhs(x, u, base.params) for x, u in zip(X, U)])
    return fx.Pilot(t, U, X, dX, pl.measure(t, X))


def _colour_phi(colour: str) -> float:
    if colour not in COLOURS:
        raise ValueError(f"unknown colour {colour!r} (known: {', '.join(COLOURS)})")
    return COLOURS[colour]


def _effect_fn(family: str):
    if family in fx.FAMILIES:
        return fx.FAMILIES[family]
    if family in fx.OUT_OF_VOCABULARY:
        return fx.OUT_OF_VOCABULARY[family]
    raise ValueError(f"unknown family {family!r}; see menu()")


def make_case(family: str, base: str, seed: int, *, magnitude: str = "medium", noise: float = 0.02,
              colour: str = "white", input_kind: str = "band", n: int = 2000, out_dir: str | Path | None = None,
              fresh_seed: int | None = None, fresh_n: int | None = None, fresh_input: bool = True) -> Case:
    """Generate one case (and write it under ``out_dir/<name>/`` when given).

    ``fresh_seed``: the same truth (effect parameters sized on the original record) driven by a fresh
    input and fresh noise of ``fresh_n`` samples — for checking a gain measured on the original; with
    ``fresh_input=False`` only the noise is fresh (the original input, the same length).
    """
    fn = _effect_fn(family)
    if base not in BASES:
        raise ValueError(f"unknown base {base!r} (known: {', '.join(BASES)})")
    if base not in fx.SUPPORTED[family]:
        raise ValueError(f"{family} is not defined on {base} (supported: {', '.join(fx.SUPPORTED[family])})")
    if magnitude not in fx.MAGNITUDES:
        raise ValueError(f"unknown magnitude {magnitude!r} (known: {', '.join(fx.MAGNITUDES)})")
    phi = _colour_phi(colour)
    b = BASES[base]
    mag = fx.MAGNITUDES.index(magnitude)
    name = case_name(family, base, seed, magnitude, noise, colour, input_kind)
    key = zlib.crc32(f"{family}|{base}|{magnitude}|{noise!r}|{colour}|{input_kind}|{n}".encode())
    s_input, s_effect, s_noise, s_nominal = np.random.SeedSequence([int(seed), key]).spawn(4)
    opts = fx.INPUT_OPTIONS.get(family, lambda m, bb: {})(mag, base)
    t = np.arange(n) * b.dt
    parts = _inputs(b, input_kind, np.random.default_rng(s_input), n, **opts)
    pilot = _pilot(b, parts, t)
    eff = fn(fx.Ctx(b, np.random.default_rng(s_effect), mag, pilot, input_kind))
    rng_noise = np.random.default_rng(s_noise)
    if fresh_seed is not None:
        fs = np.random.SeedSequence([int(seed), key, int(fresh_seed)]).spawn(2)
        if fresh_input:
            n = int(fresh_n or n)
            t = np.arange(n) * b.dt
            parts = _inputs(b, input_kind, np.random.default_rng(fs[0]), n, **opts)
        rng_noise = np.random.default_rng(fs[1])
    plant_parts = eff.wrap_input(parts, float(t[-1] + b.dt)) if eff.wrap_input else parts
    plant = Plant(b, Stack(plant_parts), dict(b.params))
    if eff.apply is not None:
        eff.apply(plant)
    X = plant.simulate(t)
    Yc = plant.measure(t, X)
    nz = {"phi": phi, **eff.noise}
    phi_used = nz.get("phi", phi)
    Y, ninfo = add_noise(rng_noise, Yc, noise, phi=phi_used, dist=nz.get("dist", "normal"),
                         df=nz.get("df", 3.0), hetero=nz.get("hetero"))
    U = Stack(parts).sample(t)
    right = "foh" if input_kind == "band" else "zoh"
    config = _config(b, name, seed, eff, right, np.random.default_rng(s_nominal))
    truth = {
        "generator": MARKER, "case": name, "family": eff.family, "kind": eff.kind, "base": base,
        "acts_on": eff.acts_on, "params": eff.params, "magnitude": magnitude,
        "noise": {"level": noise, "colour": colour if "phi" not in eff.noise else f"ar{phi_used:g}",
                  **ninfo},
        "input_kind": input_kind, "seed": int(seed), "n": n, "dt": b.dt,
        "intersample_correct": right, "intersample_configured": config["data"]["intersample"],
        "identifiable": fx.identifiable(family, input_kind, base),
        "accept": list(eff.accept or ((eff.family,) if eff.kind == "effect" else ("unexplained_discrepancy",))),
        "true_base_params": dict(b.params),
        "fresh": None if fresh_seed is None else {"seed": int(fresh_seed), "n": n, "input": bool(fresh_input)},
    }
    case = Case(name, truth, config, t, U, Y, Yc, X)
    if out_dir is not None:
        case.dir = write_case(case, Path(out_dir))
    return case


def _config(b: Base, name: str, seed: int, eff: fx.Effect, right: str, rng: np.random.Generator) -> dict:
    """The nominal config: the base's equations, free parameters started 5–20 % off the truth."""
    params = dict(b.params)
    params.update(eff.nominal.get("params", {}))
    for p in b.free:
        f = float(rng.uniform(0.05, 0.2)) * float(rng.choice([-1.0, 1.0]))
        params[p] = float(params[p] * (1.0 + f))
    return {
        "name": f"case-{zlib.crc32(name.encode()):08x}",   # opaque: the name must not reveal the effect
        "seed": int(seed),
        "data": {"path": "data.csv", "time": "t", "inputs": list(b.inputs), "outputs": list(b.measured),
                 "intersample": eff.nominal.get("intersample", right), "remove_mean": False},
        "model": {"states": list(b.states), "inputs": list(b.inputs), "params": params, "free": list(b.free),
                  "equations": dict(eff.nominal.get("equations", b.equations)),
                  "initial": {s: float(v) for s, v in zip(b.states, b.initial())}},
        "split": {"validation_fraction": 0.3},
        "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3},
    }


def _owned(d: Path) -> bool:
    """True when the folder is empty or was written by this generator (only its files, its marker)."""
    if not d.exists():
        return True
    names = {p.name for p in d.iterdir()}
    if not names:
        return True
    if not names <= set(FILES) or "truth.json" not in names:
        return False
    try:
        return json.loads((d / "truth.json").read_text()).get("generator") == MARKER
    except (OSError, ValueError):
        return False


def write_case(case: Case, out_dir: Path) -> Path:
    d = out_dir / case.name
    if not _owned(d):
        raise FileExistsError(f"{d} exists and was not written by {MARKER}; not overwriting it")
    d.mkdir(parents=True, exist_ok=True)
    cols = {"t": case.t}
    cols.update({u: case.U[:, j] for j, u in enumerate(case.config["model"]["inputs"])})
    cols.update({y: case.Y[:, j] for j, y in enumerate(case.config["data"]["outputs"])})
    pd.DataFrame(cols).to_csv(d / "data.csv", index=False, float_format="%.12g")
    (d / "config.yaml").write_text(yaml.safe_dump(case.config, sort_keys=False))
    (d / "truth.json").write_text(json.dumps(_jsonable(case.truth), indent=1, sort_keys=True) + "\n")
    return d


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return None if not math.isfinite(v) else v
    if isinstance(o, np.integer):
        return int(o)
    return o


def menu() -> dict:
    """What the generator supports: per kind, the bases, and the grid axes."""
    kinds = {}
    for fam in list(fx.FAMILIES) + list(fx.OUT_OF_VOCABULARY):
        kinds[fam] = {"kind": "null" if fam == "none" else ("out_of_vocabulary" if fam in fx.OUT_OF_VOCABULARY
                                                             else "effect"),
                      "bases": list(fx.SUPPORTED[fam]),
                      "not_identifiable_with": [k for (f, k) in fx.UNIDENTIFIABLE if f == fam]}
    return {"families": kinds, "bases": list(BASES), "magnitudes": list(fx.MAGNITUDES),
            "input_kinds": list(INPUT_KINDS), "colours": list(COLOURS), "noise_levels": list(NOISE_LEVELS)}
