"""The choice among accepted causes on coloured residuals (independent bench generator, solve_ivp; seeds
outside the bench's sets): ΔBIC with the effective sample size (:func:`engine.effective_bic`) and the
validation part between near-equals (:meth:`engine.Diagnoser.separate`).

On 20 fresh seeds of each setting (2200-2219), before -> after these two rules: quadratic damping in a DC
motor at AR(1) φ = 0.9, 2 % noise, 8 -> 11 named (the rest: a library term 6 -> 3, cubic 3, unexplained 3);
a stiffness drift at φ = 0.9, 10 % noise, 14 -> 16 (a jump 4 -> 2). No seed went the other way."""

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse


def _diagnose(tmp_path, family, base, seed, magnitude, noise, colour, kind):
    case = make_case(family, base, seed, magnitude=magnitude, noise=noise, colour=colour, input_kind=kind,
                     n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    return case.truth, s["diagnosis"]


def test_quadratic_damping_is_not_given_to_a_library_term_fitting_coloured_noise(tmp_path):
    """Seed 2208: tanh(w/0.54) fits the estimation part 21 BIC units better than w·|w|, enough to beat the
    library's 2 ln 4 prior by raw ΔBIC; with N_eff (ρ̂ ≈ 0.9) it is 1.3 units better and the prior decides.
    The validation gains are equal (34.9 % vs 34.3 %): the data cannot prefer the library term."""
    truth, d = _diagnose(tmp_path, "quadratic_damping", "dcmotor", 2208, "small", 0.02, "ar0.9", "prbs")
    first = d["findings"][0]
    assert (first["family"], first["equation"], first["term"]) == ("quadratic_damping", "w", "w*abs(w)")
    assert first["coefficient"] == pytest.approx(truth["params"]["coefficient"], rel=0.2)
    lib = next(r for r in first["runners_up"] if r["hypothesis"].startswith("static_nonlinearity:w:tanh"))
    # by raw ΔBIC and the prior the library term would have been named ...
    assert lib["delta_bic"] + lib["prior_penalty"] < first["delta_bic"] + first["prior_penalty"]
    # ... with the effective sample size it is not, and the runner-up says so with the right signs
    assert lib["delta_bic_eff"] + lib["prior_penalty"] > first["delta_bic_eff"] + first["prior_penalty"]
    assert "lower than the finding's" in lib["separation"] and "effective sample size" in lib["separation"]


def test_a_drift_is_not_named_a_jump_when_the_validation_part_separates_them(tmp_path):
    """Seed 2203: k·(1 + r·t), r = 0.625 %/s. A jump of k at 16.5 s fits the estimation part 80 BIC units
    better (1.6 effective units); the drift's validation error is half the jump's, so the drift is named,
    with the reason, and the jump is its runner-up."""
    import html
    import json

    from pipeline.cli import main
    case = make_case("parameter_drift", "msd", 2203, magnitude="medium", noise=0.1, colour="ar0.9",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", str(Path(case.dir) / "config.yaml"), "--out", str(tmp_path / "run")]) == 0
    truth = case.truth
    d = json.loads((tmp_path / "run" / "summary.json").read_text())["diagnosis"]
    first = d["findings"][0]
    assert (first["family"], first["parameter"]) == ("parameter_drift", "k")
    assert first["rate_per_s"] == pytest.approx(truth["params"]["rate_per_s"], rel=0.2)
    assert first["selection"].startswith("preferred to parameter_jump:k@")
    assert "tied_with" not in first                  # the validation part separated them
    jump = next(r for r in first["runners_up"] if r["family"] == "parameter_jump")
    assert jump["delta_bic"] < first["delta_bic"] and jump["gain"]["relative"] < first["gain"]["relative"]
    # the report shows why the drift was chosen and what came second
    page = html.unescape((tmp_path / "run" / "report.html").read_text(encoding="utf-8"))
    assert "chosen over a near-equal" in page and first["selection"] in page
    assert "runners-up" in page and jump["separation"] in page


def test_a_refitted_alternative_that_was_not_accepted_is_listed_with_the_reason(tmp_path):
    """The issue's example of runners-up: an offset in the force equation vs a sensor offset. On this
    record (the bench's tuning seed 1: a force offset, msd, held input, 10 % AR(0.9) noise) the force
    offset fits the estimation part better, but its validation gain's interval reaches below 0 and the
    sensor offset's does not: the sensor offset is the finding, and the force offset is listed beside it,
    not accepted, with why (it was missing from the runners-up, which held accepted extensions only)."""
    _, d = _diagnose(tmp_path, "offset", "msd", 1, "medium", 0.1, "ar0.9", "held")
    first = d["findings"][0]
    assert first["family"] == "output_offset"
    force = next(r for r in first["runners_up"] if r["hypothesis"] == "offset:v")
    assert force["accepted"] is False and force["gain"]["ci95"][0] <= 0 < first["gain"]["ci95"][0]
    assert force["separation"].startswith("not accepted (validation error not lower with 95 % confidence)")
    assert force["delta_bic"] < first["delta_bic"] and "lower than the finding's" in force["separation"]


def test_a_tie_neither_part_separates_is_stated_not_hidden(tmp_path):
    """Bench tuning seed 0: a 1.4-sample input delay in a pendulum, held input, 10 % AR(0.5) noise. A
    first-order lag of 1.2 samples and the delay fit the estimation part within 0.1 criterion units, and
    their validation errors differ by 0.1 % with an interval around 0: the record cannot tell them
    apart. Whichever is named, the finding carries the other in ``tied_with``, its sentence says so, and
    the report's first screen names both."""
    import html

    from pipeline.cli import main
    case = make_case("input_delay", "pendulum", 0, magnitude="small", noise=0.1, colour="ar0.5",
                     input_kind="held", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", str(Path(case.dir) / "config.yaml"), "--out", str(tmp_path / "run")]) == 0
    import json
    first = json.loads((tmp_path / "run" / "summary.json").read_text())["diagnosis"]["findings"][0]
    pair = {"input_delay", "unmodeled_dynamics"}
    assert first["family"] in pair
    other = (pair - {first["family"]}).pop()
    tie = next(t for t in first["tied_with"] if t["family"] == other)
    assert abs(tie["criterion_gap"]) < 2.0 and tie["ci95"][0] < 0 < tie["ci95"][1]
    assert "cannot tell it from" in first["description"]
    page = html.unescape((tmp_path / "run" / "report.html").read_text(encoding="utf-8"))
    assert f"or {tie['hypothesis']}: these data cannot tell them apart" in page


def test_a_clear_finding_carries_no_tie(tmp_path):
    """The other side: cubic stiffness in a mass–spring–damper at 2 % white noise (tuning seed 0); every
    other family's refit is far behind or clearly worse on validation, so nothing is stated as tied."""
    truth, d = _diagnose(tmp_path, "cubic_stiffness", "msd", 0, "medium", 0.02, "white", "band")
    first = d["findings"][0]
    assert first["family"] == "cubic_stiffness" and "tied_with" not in first
    assert "cannot tell" not in first["description"]
