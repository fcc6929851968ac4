"""Which parameter jumped: a first-order thermal plant T' = −a T + b u whose loss coefficient a jumps
from 0.5 to 0.8 at 120 s, on records computed here in closed form (the exact step response of each
held input level; no pipeline code; the independent probe's ``th_jump_lo``, its input and noise
streams reproduced).

A jump of a changes both the time constant and the static gain b/a; a jump of b the gain alone. On the
slow steps of this record their added-term tests are nearly collinear, and the family's representative
(the largest linearised share, b) was the only one refitted: the finding was "b jumps from 1.02 to 0.66
at 119.8 s" with a colored-noise finding after it for the misfit left. Every significant parameter's
jump is now refitted beside the representative (``Family.refit_alternates``) and the refits' ΔBIC
decides (here about −8 160 for a against −5 790 for b).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.config import load_config
from pipeline.runs import analyse

DT, N, TJ = 0.1, 2000, 120.0


def _record(path: Path, seed: int, probe_streams: bool = False, tj: float = TJ, a1: float = 0.8) -> None:
    """Held levels U(0, 2) for 20–80 samples, the exact zero-order-hold response of T' = −a T + u with a
    jumping 0.5 → ``a1`` at ``tj`` (a sample time), white noise of 2 % of std(T). ``probe_streams``: the
    probe's draws (each level before its hold; the noise from its own stream seed + 1000), which
    reproduce its record ``th_jump_lo`` for seed 112; otherwise hold first and one stream."""
    rng = np.random.default_rng(seed)
    u = np.empty(N)
    k = 0
    while k < N:
        if probe_streams:
            level = rng.uniform(0.0, 2.0)
            h = int(rng.integers(20, 81))
        else:
            h = int(rng.integers(20, 81))
            level = rng.uniform(0.0, 2.0)
        u[k:k + h] = level
        k += h
    t = np.arange(N) * DT
    T = np.zeros(N)
    for k in range(N - 1):   # exact over a sample interval with u held and a constant
        a = 0.5 if t[k] < tj else a1
        e = np.exp(-a * DT)
        T[k + 1] = T[k] * e + (u[k] / a) * (1.0 - e)
    noise = np.random.default_rng(seed + 1000) if probe_streams else rng
    y = T + 0.02 * T.std() * noise.standard_normal(N)
    pd.DataFrame({"t": t, "u": u, "T": y}).to_csv(path, index=False)


def _findings(tmp_path: Path, start: dict[str, float]) -> list[dict]:
    """The findings of a diagnosis of ``th.csv`` with the user's linear model from ``start``."""
    cfg = {"name": "thermal", "seed": 0,
           "data": {"path": "th.csv", "time": "t", "inputs": ["u"], "outputs": ["T"], "intersample": "zoh"},
           "model": {"states": ["T"], "inputs": ["u"], "params": start, "free": ["a", "b"],
                     "equations": {"T": "-a*T + b*u"}, "initial": {"T": 0.0}},
           "diagnose": {"families": "all", "alpha": 0.01, "max_findings": 3}}
    (tmp_path / "th.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(tmp_path / "th.yaml")).summary
    f = s["diagnosis"]["findings"]
    assert f, s["diagnosis"]["verdict"]
    return f


def _first_finding(tmp_path: Path, start: dict[str, float]) -> dict:
    return _findings(tmp_path, start)[0]


@pytest.mark.parametrize("seed", [112])
def test_a_jump_of_the_loss_coefficient_is_not_named_a_jump_of_the_input_gain(tmp_path, seed):
    _record(tmp_path / "th.csv", seed, probe_streams=True)
    f = _first_finding(tmp_path, {"a": 0.55, "b": 1.1})
    assert f["family"] == "parameter_jump", f["description"]
    assert f["parameter"] == "a", f["description"]
    assert abs(f["time_s"] - TJ) <= 0.05 * N * DT
    assert f["before"] == pytest.approx(0.5, rel=0.2) and f["after"] == pytest.approx(0.8, rel=0.2)


@pytest.mark.parametrize("seed", [7, 9, 11])
def test_a_late_jump_is_detected_by_the_sup_likelihood_ratio(tmp_path, seed):
    """The jump at 120 s is 20 s before the estimation part ends (140 s). Its added-term Wald test,
    with a HAC variance from the residual that carries the jump, was not significant on 9 of 14 such
    records (seeds 1–14; these three among them: colored noise or nothing was named). With the
    likelihood-ratio screen maximised over the date (engine._lr_screen, stats.sup_lr_break_p) all 14
    name the jump of a within 0.1 s."""
    _record(tmp_path / "th.csv", seed)
    f = _first_finding(tmp_path, {"a": 0.4, "b": 0.9})
    assert (f["family"], f.get("parameter")) == ("parameter_jump", "a"), f["description"]
    assert abs(f["time_s"] - TJ) <= 0.05 * N * DT
    assert any(e["test"].startswith("likelihood_ratio_neff") and "sup-LR" in e["detail"] for e in f["evidence"])


def test_the_jump_date_is_resolved_to_the_simulations_own_resolution(tmp_path):
    """The kernel sees step(t − t_j) at the RK4 stage times (every half sample here), so the fit is
    constant in t_j between them and the golden-section search can stop on a plateau next to the best.
    Seed 12 of the late-jump records: the date came out 119.91 s, and the half-sample transient left at
    the jump (kurtosis 4.1) was named heavy-tailed noise, on Gaussian noise. With the last scan over the
    plateaus within a sample (ParameterJump._sample_scan) the date is within half a sample of the truth
    on all 14 seeds and the jump is the only finding."""
    _record(tmp_path / "th.csv", 12)
    f = _findings(tmp_path, {"a": 0.4, "b": 0.9})
    assert [(x["family"], x.get("parameter")) for x in f] == [("parameter_jump", "a")], [x["description"] for x in f]
    assert abs(f[0]["time_s"] - TJ) <= DT / 2


@pytest.mark.parametrize("seed", [2, 5])
def test_a_jump_is_screened_when_the_significant_family_is_rejected(tmp_path, seed):
    """a 0.5 -> 0.9 at 80 s (the independent probe's ``th_jumpA``): on these seeds a drift of a was the
    only significant family (the jump's Wald test was not) and was rejected (LR p 0.13 with N_eff 2.5;
    on seed 5 an unbounded gain interval), so the lazy likelihood-ratio screen, which runs when nothing
    is significant, never ran and the verdict was "unexplained" with no finding. When nothing of a
    first round is accepted, the screen runs after all (``Diagnoser.second_chance``)."""
    _record(tmp_path / "th.csv", seed, tj=80.0, a1=0.9)
    f = _findings(tmp_path, {"a": 0.55, "b": 1.1})
    assert (f[0]["family"], f[0].get("parameter")) == ("parameter_jump", "a"), f[0]["description"]
    assert abs(f[0]["time_s"] - 80.0) <= DT / 2
    assert f[0]["after"] == pytest.approx(0.9, rel=0.05)
    assert any("sup-LR" in e.get("detail", "") for e in f[0]["evidence"])
