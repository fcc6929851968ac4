"""The ``input_direction`` adequacy test (pipeline.diagnostics.adequacy), issue 9.

Records are made here with the exact zero-order-hold discretisation of a first-order system
(closed form, scipy.signal.lfilter), a play operator (backlash) written out in this file, and AR(1)
output noise from lfilter; they share nothing with the simulator or the detector.

* The direction signal d_t (sign of the input's last change) on hand-worked inputs.
* Size: a correct structure with AR(1) noise φ = 0.5 and 0.9 on held-step inputs: the test rejects at
  most 1.5 α at α = 5 % and 1 %, and the adequacy rule (p < α and a share ≥ MATERIAL_R2) fires at most
  α of the time.
* Power: the same system behind a play of width 0.3 (input range ±1) with white noise, whose residual
  the linear input cross-correlation and model-error model miss on most records: the direction test
  fails adequacy on at least 90 %.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from pipeline.diagnostics.adequacy import (MATERIAL_R2, adequacy_tests, direction_signal,
                                           input_direction_sensitivity, input_direction_test, material)
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model
from tests.diagnosis.first_order import (ar1, assert_sized, fitted_row, held_steps, p_and_share, problem,
                                         with_noise, zoh_first_order)

DT, N = 0.1, 800


def test_direction_signal_on_hand_worked_inputs():
    assert direction_signal(np.array([0, 0, 1, 1, 1, 0.5, 0.5, 2, 2.0])).tolist() == [0, 0, 1, 1, 1, -1, -1, 1, 1]
    assert direction_signal(np.array([3, 3, 3, 1.0])).tolist() == [0, 0, 0, -1]
    # a change of 1e-12 of the range is no change
    assert direction_signal(np.array([0, 1, 1 - 1e-12, 1, 0.0])).tolist() == [0, 1, 1, 1, -1]


def _play(u: np.ndarray, w: float) -> np.ndarray:
    """Backlash (play operator) of total width w on a sampled input, started engaged at u[0]:
    v_k = min(max(v_{k−1}, u_k − w/2), u_k + w/2)."""
    v = np.empty_like(u)
    v[0] = u[0]
    for k in range(1, len(u)):
        v[k] = min(max(v[k - 1], u[k] - w / 2), u[k] + w / 2)
    return v


def _problem(tmp, k: int, rng: np.random.Generator, phi: float, width: float) -> tuple[Problem, Model]:
    """y' = −a y + b·play(u), u held for 8–40 samples at uniform levels in ±1, exact zoh, output noise
    AR(1) φ at 5 % of std(y)."""
    u = held_steps(rng, N)
    ua = _play(u, width) if width > 0 else u
    a, b = 0.8, 1.0
    y = with_noise(zoh_first_order(ua, DT, a, b), ar1(rng, N, phi))
    return problem(tmp / f"r{k}", DT, u, y, "d")


def _direction_row(tmp, k, rng, phi, width):
    prob, model = _problem(tmp, k, rng, phi, width)
    return fitted_row(prob, model, input_direction_sensitivity, input_direction_test)


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.5, 0.9])
def test_input_direction_size_on_correct_structure_with_ar_noise(tmp_path, phi):
    rng = np.random.default_rng([47, int(10 * phi)])
    p, share = p_and_share(150, lambda k: _direction_row(tmp_path, k, rng, phi, 0.0)[0])
    assert_sized(p, share, phi)


@pytest.mark.slow
def test_input_direction_finds_a_backlash_the_linear_tests_miss(tmp_path):
    rng = np.random.default_rng(53)
    found, linear = 0, 0
    reps = 30
    for k in range(reps):
        row, fit, prob = _direction_row(tmp_path, k, rng, 0.0, 0.3)
        found += row.p_value < 0.01 and row.r2 >= MATERIAL_R2
        rows = adequacy_tests(fit, prob, 0.01)
        linear += any(material(t) for t in rows if t.name in ("input_crosscorrelation", "model_error_model"))
        assert any(t.name == "input_direction" for t in rows)
    assert found >= 0.9 * reps
    assert linear < found          # the reason the test exists


def test_input_direction_is_skipped_for_a_two_level_input(tmp_path):
    """On a two-level input the direction of the last change is the input's own sign: nothing to test."""
    rng = np.random.default_rng(3)
    prob, model = _problem(tmp_path, 0, rng, 0.0, 0.0)
    prob.U[:, 0] = np.sign(prob.U[:, 0] + 1e-9)
    with contextlib.redirect_stderr(io.StringIO()):
        fit = fit_output_error(model, prob)
    assert input_direction_sensitivity(fit, prob, 0) is None
    assert not any(t.name.startswith("input_direction") for t in adequacy_tests(fit, prob, 0.01))
