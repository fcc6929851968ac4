"""``pipeline.diagnostics.why``: the paragraph an unexplained verdict gets, from the diagnosis history.
Histories are written out here by hand (the engine's candidate records: family, hypothesis, accepted,
gain, reason), so each case checks one rule of the synthesis; the cascaded tanks' real record is checked
in ``tests/test_realdata.py``."""

from __future__ import annotations

from pipeline.diagnostics.why import why_unexplained
from pipeline.report.view import first_screen

LR = ("estimation fit not better by the likelihood-ratio test with the effective sample size "
      "(p = 0.0173; N_eff = 3.6)")


def _c(family, hyp, rel=None, ci=None, dof=None, accepted=False, reason="validation error not lower"):
    g = None if rel is None else {"relative": rel, "ci95": ci, "bootstrap": {"dof": dof}}
    return {"family": family, "hypothesis": hyp, "gain": g, "accepted": accepted, "reason": reason}


def test_unbounded_gains_of_different_causes_are_said_to_be_inseparable():
    hist = [{"iteration": 1, "candidates": [
        _c("offset", "offset:y", 0.470, [-99.0, 0.99], 0.15),
        _c("static_nonlinearity", "static_nonlinearity:y:sqrt(h1)", 0.465, [-99.0, 0.99], 0.17),
        _c("output_offset", "output_offset:y", 0.230, [0.124, 0.323], 37.8, reason=LR),
        _c("cubic_stiffness", "cubic_stiffness:y:y", reason="not significant after Holm correction"),
        _c("intersample", "foh", -0.007, [-99.0, 0.99], 0.19)]}]
    w = why_unexplained(hist)
    assert [r["hypothesis"] for r in w["refitted"]] == ["offset:y", "static_nonlinearity:y:sqrt(h1)",
                                                        "output_offset:y"]     # gain > 0 only, largest first
    assert [r["kind"] for r in w["refitted"]] == ["unbounded", "unbounded", "estimation"]
    s = w["sentence"]
    assert "cannot bound the gain of 2 of them (ν ≤ 0.17" in s
    assert "2 different causes (offset, static_nonlinearity)" in s and "(46.5 to 47.0 %): these data do not say" in s
    # the bounded gain is said with its interval and the estimation part's objection, made a clause
    assert "output_offset:y has a validation gain of +23.0 % (95 % interval +12.4 % to +32.3 %), " \
           "but its estimation fit is not better by the likelihood-ratio test" in s


def test_one_cause_alone_is_not_called_inseparable_and_a_bounded_null_gain_is_not_significant():
    hist = [{"iteration": 1, "candidates": [
        _c("coulomb_friction", "coulomb_friction:v:v", 0.037, [-0.207, 0.232], 12.0),
        _c("quadratic_damping", "quadratic_damping:v:v", 0.01, [-0.3, 0.2], 9.0)]}]
    s = why_unexplained(hist)["sentence"]
    assert "different causes" not in s            # 0.01 is not within 80 % of 0.037
    assert "cannot bound" not in s
    assert "The largest, coulomb_friction:v:v, has a 95 % interval of -20.7 % to +23.2 %" in s


def test_a_round_that_accepted_was_not_against_the_final_model():
    hist = [{"iteration": 3, "candidates": [
        _c("static_nonlinearity", "static_nonlinearity:v:x**2", 0.012, [0.009, 0.014], 40.0, accepted=True,
           reason="accepted"),
        _c("quadratic_damping", "quadratic_damping:v:v", 0.004, [-0.009, 0.009], 40.0)]}]
    w = why_unexplained(hist)
    assert w["refitted"] == [] and "max_findings" in w["sentence"]


def test_nothing_refitted_and_nothing_lower():
    none = [{"iteration": 1, "candidates": [_c("offset", "offset:v", reason="not significant after Holm correction")]}]
    assert "none of their added-term tests was significant" in why_unexplained(none)["sentence"]
    worse = [{"iteration": 1, "candidates": [_c("offset", "offset:v", -0.05, [-0.2, 0.1], 9.0)]}]
    assert why_unexplained(worse)["sentence"] == "No refitted extension lowered the validation error."


def test_causes_whose_gain_one_of_them_bounds_are_not_called_open():
    hist = [{"iteration": 1, "candidates": [
        _c("offset", "offset:v", 0.10, [0.06, 0.14], 30.0, reason=LR),
        _c("coulomb_friction", "coulomb_friction:v:v", 0.09, [-99.0, 0.99], 0.5)]}]
    s = why_unexplained(hist)["sentence"]
    assert "2 different causes (offset, coulomb_friction) lower the validation error by similar amounts " \
           "(9.0 to 10.0 %)." in s and "do not say which" not in s


def test_the_first_screen_says_why_after_where():
    hist = [{"iteration": 1, "candidates": [_c("offset", "offset:y", 0.47, [-99.0, 0.99], 0.15)]}]
    s = {"diagnosis": {"verdict": "unexplained_discrepancy", "findings": [],
                       "unexplained": {"failed_tests": ["ljung_box: Q over lags 1..20"],
                                       "why": why_unexplained(hist)}}}
    w = first_screen(s)["warnings"]
    i = next(i for i, x in enumerate(w) if x.startswith("Where the model fails"))
    assert w[i + 1].startswith("Why no cause is named: Refitted on the final model") and "offset:y +47.0 %" in w[i + 1]


def test_a_look_ahead_that_found_no_second_cause_is_said():
    reason = ("validation error not lower with 95 % confidence; looked ahead: with offset:v in the model no "
              "further extension was accepted")
    hist = [{"iteration": 1, "candidates": [
        _c("offset", "offset:v", 0.49, [-1.15, 0.88], 0.4, reason=reason),
        _c("dead_zone", "dead_zone:u", 0.09, [-1.8, 0.7], 0.5)]}]
    s = why_unexplained(hist)["sentence"]
    assert s.endswith("Taken as the model for one more round, to look for a second cause beside it, offset:v: "
                      "with offset:v in the model no further extension was accepted.")
    plain = [{"iteration": 1, "candidates": [_c("offset", "offset:v", 0.49, [-1.15, 0.88], 0.4)]}]
    assert "one more round" not in why_unexplained(plain)["sentence"]


def _stability(p, r2):
    from pipeline.diagnostics.stats import TestResult
    return TestResult("parameter_stability", 30.0, p, None, p >= 0.0017,
                      "trigonometric test of time-varying parameters (…, Bonferroni over k); strongest at 2 "
                      "cycles, where the terms explain 23 % of the residual; most of it in k, whose best "
                      "single-frequency variation swings by ±0.9 (±21 % of 4.3)", r2)


def test_parameters_that_vary_are_said_first_and_only_when_the_row_fails_materially():
    none = [{"iteration": 1, "candidates": [_c("offset", "offset:v", reason="not significant after Holm correction")]}]
    s = why_unexplained(none, [_stability(1e-6, 0.23)])["sentence"]
    assert s.startswith("The fitted parameters do not stay constant over the estimation record (strongest at 2 "
                        "cycles, where the terms explain 23 % of the residual; most of it in k,")
    assert s.endswith("none of their added-term tests was significant after Holm correction, so the misfit lies "
                      "in no family's direction.")
    assert why_unexplained(none, [_stability(0.5, 0.23)]) == why_unexplained(none)      # passed
    assert why_unexplained(none, [_stability(1e-6, 0.01)]) == why_unexplained(none)     # not material
