"""The noise families run only when no structural test on the final model is significant (issue 9:
"input cross-correlation passes, no structural Wald test significant"), not merely when none is
material: a misfit too small to fail adequacy still colours the residual, and an AR noise model would
take that colour for the noise's.

The record is made here (exact zoh of a first-order system by scipy.signal.lfilter, AR(1) φ = 0.9 output
noise): with the true structure the coloured noise is named; the same record with one significant but
immaterial adequacy row (p = 1e-4, 0.5 % of the residual) injected gets its noise families "not tested"
with the reason, and the verdict says the discrepancy is unexplained, never "colored_noise".

Nor when the final residual is unstable: a CUSUM of recursive residuals outside its bounds (HAC-scaled,
so it keeps its size under AR noise) contradicts stationary coloured noise; a CUSUM of *squares* outside
its bounds does not (a changing noise level is heteroscedastic_noise's own evidence). On correct
structures with AR(1) noise up to φ = 0.95 the CUSUM gate lets the noise families run.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from scipy.signal import lfilter

from pipeline.diagnostics import engine, stats
from pipeline.diagnostics.adequacy import MATERIAL_R2
from pipeline.diagnostics.engine import Diagnoser
from tests.diagnosis.first_order import held_steps, problem
from tests.diagnosis.test_hausman import _record


def _inject_immaterial_row(monkeypatch) -> None:
    """Every adequacy battery gains a significant (p = 1e-4) but immaterial (0.5 % of the residual) row."""
    real = engine.adequacy_tests

    def with_row(fit, prob_, alpha):
        row = stats.TestResult("model_error_model", 30.0, 1e-4, None, False, "injected")
        row.r2 = 0.005
        return real(fit, prob_, alpha) + [row]
    monkeypatch.setattr(engine, "adequacy_tests", with_row)


def _inject_battery_rejection(monkeypatch, name: str) -> None:
    """The final residual battery's row ``name`` rejects (p = 1e-6), as a slow departure would make it."""
    real = engine.residual_tests

    def rejecting(fit, prob_, alpha):
        tests, f_cyc = real(fit, prob_, alpha)
        out = [stats.TestResult(t.name, 9.0, 1e-6, t.bound, False, "injected") if t.name == name else t
               for t in tests]
        return out, f_cyc
    monkeypatch.setattr(engine, "residual_tests", rejecting)


def _diagnose(tmp_path, monkeypatch, inject: bool | str, phi: float = 0.9, seed: int = 11):
    rng = np.random.default_rng(seed)
    prob, model = _record(tmp_path, 0, rng, phi, False)
    if inject is True:
        _inject_immaterial_row(monkeypatch)
    elif inject:
        _inject_battery_rejection(monkeypatch, inject)
    dg = Diagnoser(prob, alpha=0.01, families=["colored_noise"], max_findings=2, seed=0, dt=0.1)
    with contextlib.redirect_stderr(io.StringIO()):
        return dg.run(model)


def test_coloured_noise_is_named_on_a_correct_structure(tmp_path, monkeypatch):
    d = _diagnose(tmp_path, monkeypatch, inject=False)
    assert [f["family"] for f in d.findings] == ["colored_noise"]
    assert d.verdict == "discrepancy"


def test_a_significant_immaterial_structural_test_keeps_the_noise_families_out(tmp_path, monkeypatch):
    d = _diagnose(tmp_path, monkeypatch, inject=True)
    assert 0.005 < MATERIAL_R2                       # the row alone does not fail adequacy
    assert not d.findings
    row = next(t for t in d.noise_tests if t.name == "colored_noise")
    assert row.detail.startswith("not tested: structure inadequate") and "model_error_model" in row.detail
    assert d.verdict == "unexplained_discrepancy"    # the residual is coloured and nothing explains it


def _record_with_offset(tmp, rng):
    """y' = −a y + b u + 0.3 (an input-side offset the nominal model lacks), exact zoh by lfilter,
    AR(1) φ = 0.9 output noise at 5 % of std(y)."""
    n, dt = 800, 0.1
    u = held_steps(rng, n)
    a, b = 0.8, 1.0
    e1 = np.exp(-a * dt)
    x = lfilter([0.0, (1 - e1) / a], [1.0, -e1], b * u + 0.3)
    noise = lfilter([1.0], [1.0, -0.9], rng.standard_normal(n + 300))[300:]
    y = x + 0.05 * np.std(x) / np.std(noise) * noise
    return problem(tmp / "r", dt, u, y, "g")


@pytest.mark.parametrize("inject", [False, True])
def test_a_finding_does_not_make_an_ungated_colour_explained(tmp_path, monkeypatch, inject):
    """With a physical finding (the offset) and AR(1) noise: without a significant structural test the
    noise families name the colour and the verdict is "discrepancy"; with one (injected, immaterial)
    the noise families are kept out, the coloured residual is unexplained, and the verdict says so,
    with the offset listed as a partial finding."""
    prob, model = _record_with_offset(tmp_path, np.random.default_rng(13))
    if inject:
        _inject_immaterial_row(monkeypatch)
    dg = Diagnoser(prob, alpha=0.01, families=["offset", "colored_noise"], max_findings=3, seed=0, dt=0.1)
    with contextlib.redirect_stderr(io.StringIO()):
        d = dg.run(model)
    fams = [f["family"] for f in d.findings]
    if inject:
        assert fams == ["offset"]
        assert d.verdict == "unexplained_discrepancy"
    else:
        assert fams == ["offset", "colored_noise"]
        assert d.verdict == "discrepancy"


def test_an_unstable_residual_keeps_the_noise_families_out(tmp_path, monkeypatch):
    d = _diagnose(tmp_path, monkeypatch, inject="cusum")
    assert not d.findings
    row = next(t for t in d.noise_tests if t.name == "colored_noise")
    assert row.detail.startswith("not tested: structure inadequate") and "CUSUM" in row.detail
    assert d.verdict == "unexplained_discrepancy"


def test_a_changing_noise_level_does_not_keep_them_out(tmp_path, monkeypatch):
    """cusum_squares rejecting is what heteroscedastic noise does: the noise families still run."""
    d = _diagnose(tmp_path, monkeypatch, inject="cusum_squares")
    assert [f["family"] for f in d.findings] == ["colored_noise"]


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.9, 0.95])
def test_the_cusum_gate_keeps_coloured_noise_in_on_correct_structures(tmp_path, monkeypatch, phi):
    """12 correct-structure records per φ (fresh seeds): the CUSUM gate keeps the noise families out of at
    most one (the CUSUM is a 1 % test in the battery's Holm family; a gate that fired on AR noise would
    call coloured noise "unexplained")."""
    gated = 0
    for seed in range(100, 112):
        (tmp_path / f"s{seed}").mkdir()
        d = _diagnose(tmp_path / f"s{seed}", monkeypatch, inject=False, phi=phi, seed=seed)
        gated += any("CUSUM" in (t.detail or "") for t in d.noise_tests)
    assert gated <= 1
