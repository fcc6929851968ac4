"""The ``parameter_stability`` adequacy row (pipeline.diagnostics.stability): a parameter that varies
during the record, which no family holds unless it is a step or a straight line.

Records are made here: held steps, the first-order plant y' = −A y + b(t) u with a gain that ripples,
b(t) = B (1 + r sin(2π t / P)), integrated by ``scipy.signal.lsim`` for the forcing b(t)·u(t) on a grid
100 times finer than the samples (the plant is linear in the forcing), sampled, and AR(1) noise from
lfilter. They share nothing with the simulator or the detector.

* Size: a correct structure (r = 0) with AR(1) noise φ = 0.5 and 0.9: the row rejects at most 1.5 α at
  α = 5 % and 1 %, and the adequacy rule (p < α and a share ≥ MATERIAL_R2) fires at most α of the time.
* Power and the number it reports: a 30 % ripple with two periods in the estimation part, 5 % white
  noise: the row fails adequacy on at least 90 % of records, names b, at 2 cycles, and its amplitude
  is within 15 % of r·B in the median (the first-order approximation e ≈ J δ(t) holds when the ripple
  is slow beside the time constant: P = 28 s, 1/A = 1.25 s).
* The whole run on the independent bench's stiffness-ripple records (solve_ivp) that had been called
  coloured noise: now unexplained, with the row failing.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.diagnostics.adequacy import MATERIAL_R2, adequacy_tests
from pipeline.diagnostics.stability import K_MAX, parameter_stability_test
from pipeline.fit import fit_output_error
from pipeline.runs import analyse
from tests.diagnosis.first_order import (ar1, assert_sized, held_steps, p_and_share, problem, with_noise,
                                         zoh_first_order)

DT, N, FINE = 0.1, 800, 100
A, B = 0.8, 1.0
PERIOD = 28.0          # the estimation part (70 % of 80 s) holds two periods


def _rippled_response(u: np.ndarray, r: float) -> np.ndarray:
    """y' = −A y + B (1 + r sin(2π t/PERIOD)) u from rest, u held between samples, sampled every DT."""
    h = DT / FINE
    tf = h * np.arange(len(u) * FINE)
    f = B * (1 + r * np.sin(2 * np.pi * tf / PERIOD)) * np.repeat(u, FINE)
    _, y, _ = signal.lsim(signal.lti([1.0], [1.0, A]), f, tf)
    return y[::FINE]


def _row(tmp: Path, k: int, rng: np.random.Generator, phi: float, r: float):
    u = held_steps(rng, N)
    y0 = _rippled_response(u, r) if r else zoh_first_order(u, DT, A, B)
    prob, model = problem(tmp / f"r{k}", DT, u, with_noise(y0, ar1(rng, N, phi)), "ripple")
    with contextlib.redirect_stderr(io.StringIO()):
        fit = fit_output_error(model, prob)
    return parameter_stability_test(fit, 0, float(prob.weights[0]), 0.01), fit, prob


def test_the_ripple_is_integrated_right():
    """The record maker itself: with r = 0 the fine-grid lsim equals the exact zero-order-hold response."""
    u = held_steps(np.random.default_rng(0), 200)
    assert np.allclose(_rippled_response(u, 0.0), zoh_first_order(u, DT, A, B), atol=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.5, 0.9])
def test_parameter_stability_size_on_correct_structure_with_ar_noise(tmp_path, phi):
    rng = np.random.default_rng([71, int(10 * phi)])
    p, share = p_and_share(300, lambda k: _row(tmp_path, k, rng, phi, 0.0)[0])
    # Bonferroni over K_MAX frequencies, each a fixed-b test that is itself conservative here (1–2 %
    # rejections at 5 % with white noise, 200 records): the row rejects far less than α
    assert_sized(p, share, phi, k=K_MAX)


@pytest.mark.slow
def test_parameter_stability_finds_a_rippling_gain_and_its_size(tmp_path):
    rng = np.random.default_rng(73)
    reps, r = 30, 0.3
    rows = [_row(tmp_path, k, rng, 0.0, r)[0] for k in range(reps)]
    assert sum(t.p_value < 0.01 and t.r2 >= MATERIAL_R2 for t in rows) >= 0.9 * reps
    assert sum("strongest at 2 cycles" in t.detail and "most of it in b," in t.detail for t in rows) >= 0.9 * reps
    amp = [float(t.detail.split("swings by ±")[1].split(" ")[0]) for t in rows]
    assert abs(np.median(amp) / (r * B) - 1) <= 0.15


def test_the_row_joins_the_adequacy_battery(tmp_path):
    """adequacy_tests carries one parameter_stability row per output, at the battery's Bonferroni level."""
    row, fit, prob = _row(tmp_path, 0, np.random.default_rng(5), 0.0, 0.3)
    rows = adequacy_tests(fit, prob, 0.01)
    st = [t for t in rows if t.name.startswith("parameter_stability")]
    assert len(st) == 1 and st[0].p_value == row.p_value and not st[0].passed


# the independent bench's stiffness-ripple records (2 % white noise) that the whole run had called
# coloured noise (verdict ``discrepancy``) before the row
@pytest.mark.parametrize("base,kind,magnitude,seed,restoring", [
    ("msd", "band", "medium", 0, "k"), ("msd", "band", "medium", 1, "k"), ("msd", "prbs", "medium", 1, "k"),
    ("pendulum", "band", "medium", 2, "g_l"), ("pendulum", "prbs", "medium", 0, "g_l")])
def test_a_rippling_stiffness_is_unexplained_not_coloured_noise(tmp_path, base, kind, magnitude, seed, restoring):
    """The whole run: no family and no noise model is named, the stability row fails, and it puts the
    variation in the restoring coefficient (k·x, or g/l·sin x for the pendulum), not in the damping."""
    case = make_case("modulated_stiffness", base, seed, magnitude=magnitude, noise=0.02, colour="white",
                     input_kind=kind, n=2000, out_dir=tmp_path)
    assert case.truth["kind"] == "out_of_vocabulary"
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy" and d["findings"] == []
    row = next(t for t in d["adequacy"] if t["name"] == "parameter_stability")
    assert not row["passed"] and row["explained_share"] >= MATERIAL_R2
    assert f"most of it in {restoring}," in row["detail"]
    assert d["unexplained"]["why"]["sentence"].startswith("The fitted parameters do not stay constant")


def test_one_row_per_output_on_two_outputs(tmp_path):
    """Two measured outputs (the bench's two thermal zones, solve_ivp, no effect): a row for each,
    named by its output, and neither fails on the correct structure."""
    case = make_case("none", "mimo", 0, noise=0.02, colour="white", input_kind="held", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    rows = {t["name"]: t for t in d["adequacy"] if t["name"].startswith("parameter_stability")}
    assert sorted(rows) == ["parameter_stability[T1]", "parameter_stability[T2]"]
    assert all(t["passed"] for t in rows.values())
