"""Issue 8, two causes at once: both named within ``max_findings``.

Records made here with ``scipy.integrate.solve_ivp`` on a continuous-time input (a sum of sines),
sharing no code with the detector; a mass–spring–damper m x'' = F(u) − c x' − k x + effects:

* friction + offset, as on a real positioning stage: − Fc·sgn(x') + d (sgn smoothed over 1e-3 of
  the velocity range, as a real friction characteristic is);
* input saturation + cubic stiffness: F(u) = clip(u, −L, L) and − k3 x³;
* a dead zone + offset, and input saturation + offset: F(u) = sgn(u)·max(|u| − w, 0) or clip(u, −L, L),
  and + d. Each cause alone leaves the other's smooth misfit in the validation residual, so neither
  extension's gain has an interval above 0 on its own: both are named by the loop's look-ahead
  (``Diagnoser._lookahead``), and the offset must reach the refits at all (``engine._share``).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.integrate import solve_ivp

from pipeline.config import load_config
from pipeline.runs import analyse

M, C, K = 1.0, 0.6, 4.0


def _input(seed):
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.02, 0.6, 8)
    ph = rng.uniform(0, 2 * np.pi, 8)
    a = rng.uniform(0.5, 1.0, 8)
    return lambda s: np.sum(a * np.sin(2 * np.pi * f * np.asarray(s)[..., None] + ph), axis=-1) / 2.0


def _record(tmp: Path, name: str, seed: int, *, fc=0.0, d=0.0, L=None, k3=0.0, w=0.0, n=4000,
            dt=0.02) -> Path:
    t = np.arange(n) * dt
    u = _input(seed)
    vscale = 1.0

    def F(s):
        x = u(s)
        if w:
            x = np.sign(x) * np.maximum(np.abs(x) - w, 0.0)
        return np.clip(x, -L, L) if L is not None else x

    def f(s, z):
        x, v = z
        return [v, (F(s) - C * v - K * x - k3 * x ** 3 - fc * np.tanh(v / (1e-3 * vscale)) + d) / M]

    sol = solve_ivp(f, (0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-11, max_step=dt / 2, method="LSODA")
    x = sol.y[0]
    rng = np.random.default_rng(seed + 7)
    y = x + 0.02 * np.std(x) * rng.standard_normal(n)
    folder = tmp / name
    folder.mkdir()
    pd.DataFrame({"t": t, "u": u(t), "x": y}).to_csv(folder / "data.csv", index=False)
    cfg = {"name": name, "seed": seed,
           "data": {"path": "data.csv", "time": "t", "inputs": ["u"], "outputs": ["x"], "intersample": "foh",
                    "remove_mean": False},
           "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": M, "c": 0.5, "k": 3.5},
                     "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"},
                     "initial": {"x": 0.0, "v": 0.0}},
           "split": {"validation_fraction": 0.3},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (folder / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder / "config.yaml"


def _diagnosis(path: Path) -> dict:
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(path)).summary["diagnosis"]


def _families(path: Path) -> list[str]:
    return [f["family"] for f in _diagnosis(path)["findings"]]


@pytest.mark.parametrize("seed", [1002, 1003])
def test_friction_and_offset_both_named(tmp_path, seed):
    """In open loop a constant force d and a sensor offset d/k differ only in the start transient
    (x(0) = 0 is known): either offset form counts as the offset (seed 1003 names the sensor form)."""
    fams = _families(_record(tmp_path, f"friction-offset-{seed}", seed, fc=0.15, d=0.2))
    assert "coulomb_friction" in fams and ("offset" in fams or "output_offset" in fams)


@pytest.mark.parametrize("seed", [1002, 1003])
def test_saturation_and_cubic_stiffness_both_named(tmp_path, seed):
    fams = _families(_record(tmp_path, f"sat-cubic-{seed}", seed, L=0.6, k3=3.0))
    assert "input_saturation" in fams and "cubic_stiffness" in fams


@pytest.mark.parametrize("seed", [1002, 1003])
def test_dead_zone_and_offset_both_named(tmp_path, seed):
    """A dead zone of ±0.15 on the input and a force offset 0.2. The offset's added-term test is weak
    after its GLS filter (a near-constant sensitivity is nearly differenced away: 2 % of the residual on
    one record, where its refit removes 74 %), so the refit screen must use the unfiltered share; and
    whichever cause comes first, its gain alone is not bounded (−115 % to +88 % for a 49 % point gain
    on another seed), so both are named through the look-ahead, each with its gain given the other."""
    d = _diagnosis(_record(tmp_path, f"deadzone-offset-{seed}", seed, w=0.15, d=0.2))
    fams = [f["family"] for f in d["findings"]]
    assert "dead_zone" in fams and ("offset" in fams or "output_offset" in fams)
    dz = next(f for f in d["findings"] if f["family"] == "dead_zone")
    assert dz["width"] == pytest.approx(0.15, rel=0.2)
    first = d["history"][0]["candidates"]
    # the offset was refitted in the first round (not screened out on its GLS share)
    assert any(c["family"] == "offset" and c.get("gain") for c in first)


@pytest.mark.parametrize("seed", [1002, 1003, 2003, 2004])
def test_saturation_and_offset_both_named(tmp_path, seed):
    """Seeds 1002 and 1003 name both without the look-ahead; 2003 and 2004 are the records on which
    the need for it was found (input saturation first, +45.5 % alone with the interval −58 % to +81 %)."""
    fams = _families(_record(tmp_path, f"sat-offset-{seed}", seed, L=0.6, d=0.2))
    assert "input_saturation" in fams and ("offset" in fams or "output_offset" in fams)
