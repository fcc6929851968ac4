"""The output-error vs prediction-error Hausman test (pipeline.diagnostics.hausman), issue 9.

Records are made here with the exact zero-order-hold discretisation of the true system (closed form,
scipy.signal.lfilter) and AR(1) output noise from lfilter; they share nothing with the simulator.

* Size: a correct first-order structure with AR(1) noise (φ = 0.5 and 0.9): the test rejects at most
  1.5 α at α = 5 % and 1 %, and the rule that calls a coloured-noise record a structural misfit
  (p < α and a share ≥ adequacy.MATERIAL_R2) fires at most as often.
* Power: a second-order system fitted with the first-order structure and the same noise, whose
  misfit the AR filter would otherwise take as "coloured noise".
* The closed form of Var(θ̂_PEM − θ̂_OE) equals its explicit matrix form (AR Toeplitz Σ, filter F).
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from scipy.linalg import toeplitz
from scipy.signal import lfilter

from pipeline.diagnostics.adequacy import MATERIAL_R2
from pipeline.diagnostics.hausman import NAME, covariance_of_difference
from pipeline.diagnostics.noise import diagnose_noise
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model
from tests.diagnosis.first_order import ar1, held_steps, p_and_share, problem, with_noise, zoh_first_order

DT, N = 0.1, 800


def _record(tmp, k: int, rng: np.random.Generator, phi: float, second_order: bool) -> tuple[Problem, Model]:
    """y' = −a y + b u (or that in series with a lag of 0.6 s), u held for 8–40 samples, exact zoh."""
    u = held_steps(rng, N)
    a, b = 0.8, 1.0
    x = zoh_first_order(u, DT, a, b)
    if second_order:
        e2 = np.exp(-DT / 0.6)
        x = lfilter([0.0, 1 - e2], [1.0, -e2], x)
    y = with_noise(x, ar1(rng, N, phi))
    return problem(tmp / f"r{k}", DT, u, y, "h", {"families": ["colored_noise"]})


def _hausman(tmp, k, rng, phi, second_order):
    prob, model = _record(tmp, k, rng, phi, second_order)
    with contextlib.redirect_stderr(io.StringIO()):
        fit = fit_output_error(model, prob)
        findings, tests = diagnose_noise(fit, prob, alpha=0.01, seed=0)
    row = next((t for t in tests if t.name == NAME), None)
    return row, findings


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.5, 0.9])
def test_hausman_size_on_correct_structure_with_ar_noise(tmp_path, phi):
    rng = np.random.default_rng([31, int(10 * phi)])

    def row_of(k):
        row, _ = _hausman(tmp_path, k, rng, phi, False)
        assert row is not None                  # AR(1) noise of this strength: Ljung-Box always fires
        return row
    p, share = p_and_share(120, row_of)
    assert np.mean(p < 0.05) <= 1.5 * 0.05
    assert np.mean(p < 0.01) <= 1.5 * 0.01 + 1 / 120     # at most 2 of 120 (binomial resolution)
    # the rule that turns a coloured-noise record into a structural misfit: significant and material
    flagged = (p < 0.01) & (share >= MATERIAL_R2)
    assert np.mean(flagged) <= 1.5 * 0.01 + 1 / 120


@pytest.mark.slow
def test_hausman_detects_a_missing_lag_that_ar_noise_would_absorb(tmp_path):
    rng = np.random.default_rng(77)
    rej, named = 0, 0
    for k in range(20):
        row, findings = _hausman(tmp_path, k, rng, 0.5, True)
        rej += row is not None and row.p_value < 0.01 and row.r2 >= MATERIAL_R2
        named += any(f["family"] == "colored_noise" for f in findings)
    assert rej >= 16
    assert named <= 20 - rej                  # a rejected structure gets no noise finding


def test_covariance_of_the_difference_matches_the_explicit_matrix_form():
    """Var(θ̂_PEM − θ̂_OE) = P Σ Pᵀ with P = (J̃ᵀJ̃)⁻¹J̃ᵀF − (JᵀJ)⁻¹Jᵀ, F the (N−p)×N AR prediction-error
    filter matrix, J̃ = FJ and Σ = σ²HHᵀ (H the lower-triangular Toeplitz impulse response of 1/A),
    every matrix built explicitly here."""
    rng = np.random.default_rng(3)
    n, a, s2 = 300, np.array([0.7, -0.2]), 0.3
    p = len(a)
    J = rng.standard_normal((n, 3)).cumsum(axis=0) / 10
    h = lfilter([1.0], np.r_[1.0, -a], np.r_[1.0, np.zeros(n - 1)])      # impulse response of 1/A
    H = toeplitz(h, np.zeros(n))                                          # lower triangular
    F = np.zeros((n - p, n))
    for r, t in enumerate(range(p, n)):
        F[r, t] = 1.0
        F[r, t - 1 - np.arange(p)] = -a
    Jt = F @ J
    P = np.linalg.inv(Jt.T @ Jt) @ Jt.T @ F - np.linalg.inv(J.T @ J) @ J.T
    np.testing.assert_allclose(covariance_of_difference(J, a, s2), P @ (s2 * H @ H.T) @ P.T,
                               rtol=1e-8, atol=1e-14)
