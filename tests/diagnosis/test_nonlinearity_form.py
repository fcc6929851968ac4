"""The ``nonlinearity_form`` adequacy row (:mod:`pipeline.diagnostics.form`): a library term followed by
another static term in the same state and equation means the data rejected the first form; the verdict
is then ``unexplained_discrepancy`` with the terms as partial findings.

End to end on records of the independent bench (solve_ivp, the effect written out without the
detector's classes; test seeds): a spring force g·x·exp(−(x/x₀)²), which no library term holds, on a
pendulum with held-step input was named "static_nonlinearity tanh(th/0.51)" then "cubic_stiffness th³"
with the verdict ``discrepancy`` before this row existed (bench of 2026-12-04, test seeds); a hidden
cubic stiffness, which one term does explain, keeps the verdict ``discrepancy``.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.diagnostics.adequacy import MATERIAL_R2, material
from pipeline.diagnostics.form import Accepted, form_test, variables
from pipeline.runs import analyse


def _a(family, term, eq="v", p=1e-6, before=100.0, after=50.0):
    return Accepted(family, eq, term, p, 30.0, before, after)


def test_variables_leave_functions_and_constants_out():
    assert variables("tanh(x/0.626843)") == ("x",)
    assert variables("x*abs(x)") == ("x",)
    assert variables("sign(v)") == ("v",)
    assert variables("x*v") == ("v", "x")
    assert variables(None) == ()


def test_a_library_term_then_a_second_form_in_the_same_state_and_equation_fails():
    row = form_test([_a("static_nonlinearity", "tanh(x/0.6)", before=100.0, after=40.0),
                     _a("cubic_stiffness", "x**3", p=3e-4, before=40.0, after=30.0)])
    assert row is not None and row.name == "nonlinearity_form" and not row.passed
    assert row.p_value == 3e-4                         # the later term's likelihood-ratio p
    assert row.r2 == pytest.approx(1 - 30.0 / 40.0)    # share of the residual the later term removed
    assert material(row)
    assert "x" in row.detail and "tanh(x/0.6)" in row.detail and "x**3" in row.detail


def test_three_terms_count_the_share_removed_by_both_later_ones():
    row = form_test([_a("static_nonlinearity", "tanh(x/0.6)", before=100.0, after=40.0),
                     _a("cubic_stiffness", "x**3", p=1e-3, before=40.0, after=30.0),
                     _a("static_nonlinearity", "x*abs(x)", p=1e-4, before=30.0, after=20.0)])
    assert row.r2 == pytest.approx(1 - 20.0 / 40.0)
    assert row.p_value == 1e-3


def test_a_small_second_term_is_not_material():
    row = form_test([_a("static_nonlinearity", "x**2", before=100.0, after=40.0),
                     _a("cubic_stiffness", "x**3", before=40.0, after=40.0 * (1 - MATERIAL_R2 / 2))])
    assert row is not None and not material(row)


@pytest.mark.parametrize("steps", [
    # Coulomb friction and quadratic damping on one velocity: two named physical causes, no library form
    [("coulomb_friction", "sign(v)", "v"), ("quadratic_damping", "v*abs(v)", "v")],
    # the same state in two different equations
    [("static_nonlinearity", "tanh(x/0.6)", "v"), ("cubic_stiffness", "x**3", "w")],
    # two states in one equation
    [("static_nonlinearity", "tanh(x/0.6)", "v"), ("quadratic_damping", "v*abs(v)", "v")],
    # one static form and a cause of another kind
    [("static_nonlinearity", "tanh(x/0.6)", "v"), ("offset", None, "v")],
    # a single finding
    [("static_nonlinearity", "tanh(x/0.6)", "v")],
])
def test_no_row_without_two_forms_of_one_state_in_one_equation(steps):
    assert form_test([_a(f, t, eq) for f, t, eq in steps]) is None


def _summary(tmp_path: Path, family: str, base: str, seed: int, **kw) -> dict:
    case = make_case(family, base, seed, out_dir=tmp_path, **kw)
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(Path(case.dir) / "config.yaml")).summary


@pytest.mark.slow
def test_a_nonlinearity_no_library_holds_is_unexplained_with_partial_findings(tmp_path):
    """x·exp(−(x/x₀)²) in the msd's force equation at 2 % noise: one library form is not enough, the loop
    needs a second static term in x, and the verdict says that the nonlinearity is of another form.
    (Until the tanh's knee was fitted, the pendulum record below served here.)"""
    s = _summary(tmp_path, "xexp", "msd", 1001, magnitude="medium", noise=0.02, input_kind="held")
    d = s["diagnosis"]
    assert d["verdict"] == "unexplained_discrepancy"
    statics = [f for f in d["findings"] if f["family"] in ("static_nonlinearity", "cubic_stiffness")]
    assert len(statics) >= 2 and {f["equation"] for f in statics} == {"v"}
    assert any(t.startswith("nonlinearity_form") and "in x " in t for t in d["unexplained"]["failed_tests"])


@pytest.mark.slow
@pytest.mark.parametrize("input_kind,magnitude,seed,above", [("held", "medium", 1001, 3.0), ("band", "small", 2003, 1.2)])
def test_a_form_the_noise_cannot_tell_from_a_library_term_is_named_only_at_the_noise_level(
        tmp_path, input_kind, magnitude, seed, above):
    """The same kind of law on the pendulum at 10 % noise: with its knee fitted, one tanh(th/s) brings the
    validation free-run RMSE from 3.2 (1.27) times the noise's standard deviation to within 3 % of it, and
    every adequacy test passes; on data it never saw, the record cannot tell the two forms apart, so the
    finding is named (verdict ``discrepancy``), which the bench scores as a miss of "unexplained" (both
    records were ``unexplained_discrepancy`` with the knee held at the state's spread). Named only because
    it explains the discrepancy: the final validation error is at the noise level."""
    case = make_case("xexp", "pendulum", seed, out_dir=tmp_path, magnitude=magnitude, noise=0.1, colour="white",
                     input_kind=input_kind)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    d = s["diagnosis"]
    sigma = case.truth["noise"]["sigma"][0]
    assert s["nominal"]["validation"]["rmse_sim"] > above * sigma
    assert [(f["family"], f["term"][:8]) for f in d["findings"]] == [("static_nonlinearity", "tanh(th/")]
    assert d["verdict"] == "discrepancy" and s["final"]["validation"]["rmse_sim"] < 1.05 * sigma


@pytest.mark.slow
def test_a_hidden_cubic_stiffness_is_still_a_named_cause(tmp_path):
    s = _summary(tmp_path, "cubic_stiffness", "msd", 1002, magnitude="medium", noise=0.02, input_kind="band")
    d = s["diagnosis"]
    assert d["findings"][0]["family"] == "cubic_stiffness"
    assert d["verdict"] == "discrepancy"
    assert not any("nonlinearity_form" in t for t in (d.get("unexplained") or {}).get("failed_tests", []))


def test_variables_read_numbers_in_exponent_notation_as_numbers():
    # a regex over the text took the "e" of 1e-05 for a second state, so tanh(x/1e-05) then x³ got no row
    assert variables("tanh(x/1e-05)") == ("x",)
    row = form_test([_a("static_nonlinearity", "tanh(x/1e-05)"), _a("cubic_stiffness", "x**3")])
    assert row is not None and not row.passed
