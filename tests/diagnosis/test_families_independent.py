"""Issue 8, hidden effects on records made by code that shares nothing with the detector
(``pipeline.bench.independent``: solve_ivp on continuous-time inputs, effects written out per family).

Every family × two base systems × three seeds (1002–1004; seeds 0–2 tune the bench, 1000–1001 were
looked at while the families were written): the first finding names the family, where it acts (the
equation, input, parameter, state or output) and its key parameter within the issue's tolerance
(20 %; delay 1.5 samples; jump time 5 % of the record; frequency 5 %), scored by the bench's own
``parameter_error`` against the generator's truth. Known failures are marked ``xfail(strict=True)``
with the reason, so a fix shows up as an unexpected pass.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.diagnosis import parameter_error
from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse

PAIRS = {
    "offset": ["msd", "dcmotor"],
    "output_offset": ["msd", "dcmotor"],
    "cubic_stiffness": ["msd", "pendulum"],
    "quadratic_damping": ["msd", "dcmotor"],
    "coulomb_friction": ["msd", "dcmotor"],
    "static_nonlinearity": ["tank", "dcmotor"],
    "periodic_disturbance": ["msd", "dcmotor"],
    "input_delay": ["tank", "dcmotor"],
    "input_saturation": ["msd", "dcmotor"],
    "dead_zone": ["msd", "dcmotor"],
    "parameter_jump": ["msd", "pendulum"],
    "parameter_drift": ["msd", "tank"],
    "unmodeled_dynamics": ["msd", "dcmotor"],
    "unmodeled_state": ["msd", "dcmotor"],      # unmodeled_dynamics as a second storage coupled to a state
    "state_saturation": ["tank", "msd"],
    "intersample": ["msd", "tank"],
}
SEEDS = (1002, 1003, 1004)
# Cases that were strict xfails here, and what fixed them:
# * end stops and overflows (state_saturation): the linearised added-term test had no power (family
#   p = 1.0 on the msd end stop); the hard limit at the measured maximum is now refitted and LR-tested
#   (engine._lr_screen);
# * square-root outflow on the tank (static_nonlinearity): the family was represented by its largest
#   statistic (h*u), whose refit lost to an offset; it is now the significant hypothesis explaining the
#   largest share of the residual (sqrt(h)), whose refit wins.
KNOWN: dict = {}


def _diagnose(tmp_path: Path, family: str, base: str, seed: int):
    case = make_case(family, base, seed, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(Path(case.dir) / "config.yaml"))
    return case, ctx.summary


CASES = [(f, b, s) for f, bases in PAIRS.items() for b in bases for s in SEEDS]


def _param(case):
    f, b, s = case
    marks = [pytest.mark.xfail(strict=True, reason=KNOWN[case])] if case in KNOWN else []
    return pytest.param(f, b, s, id=f"{f}-{b}-{s}", marks=marks)


@pytest.mark.slow
@pytest.mark.parametrize("family,base,seed", [_param(c) for c in CASES])
def test_hidden_effect_named_placed_and_sized(tmp_path, family, base, seed):
    case, s = _diagnose(tmp_path, family, base, seed)
    findings = s["diagnosis"]["findings"]
    assert findings, s["diagnosis"]["verdict"]
    top = findings[0]
    truth = dict(case.truth)
    assert top["family"] == truth["family"], [f["family"] for f in findings]
    errs = parameter_error(truth, top)
    assert all(v["ok"] for v in errs.values()), errs
    acts = truth.get("acts_on") or {}
    if "input" in acts and family in ("input_saturation", "dead_zone", "unmodeled_dynamics"):
        assert top["input"] == acts["input"]
    if "equation" in acts:
        assert top["equation"] == acts["equation"]
    g = top["gain"]
    assert g["ci95"][0] <= g["relative"] <= g["ci95"][1] and g["ci95"][0] > 0


NULLS = [(b, s) for b in ("msd", "tank", "dcmotor", "pendulum") for s in SEEDS]


@pytest.mark.slow
@pytest.mark.parametrize("base,seed", NULLS, ids=[f"{b}-{s}" for b, s in NULLS])
def test_band_limited_null_records_under_zoh_and_foh_give_no_physical_finding(tmp_path, base, seed):
    """A band-limited input, configured with the right foh (the `none` case) and with the wrong zoh (the
    `intersample` case): no physical family is named in either; the wrong zoh is named as intersample."""
    _, right = _diagnose(tmp_path / "foh", "none", base, seed)
    assert right["diagnosis"]["findings"] == [] and right["diagnosis"]["verdict"] == "no_significant_discrepancy"
    _, wrong = _diagnose(tmp_path / "zoh", "intersample", base, seed)
    fams = [f["family"] for f in wrong["diagnosis"]["findings"]]
    physical = [f for f in fams if f not in ("intersample", "colored_noise", "heavy_tailed_noise",
                                             "heteroscedastic_noise")]
    assert physical == [], fams


@pytest.mark.parametrize("base", ["pendulum", "tank", "twomode"])
def test_an_offset_under_a_prbs_input_is_named_offset_not_an_input_nonlinearity(tmp_path, base):
    """Under a two-level PRBS every static g(u) (u**2, abs(u), sqrt(u)) is affine in u: an offset plus
    an input gain. The bench named 4 hidden offsets on PRBS records ``static_nonlinearity u**2`` (a tie
    with ``offset`` broken by chance); such terms are no longer hypotheses on such inputs."""
    case = make_case("offset", base, 1003, magnitude="large", input_kind="prbs", out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    first = s["diagnosis"]["findings"][0]
    assert first["family"] == "offset", first
    assert first["equation"] == case.truth["params"]["equation"]


@pytest.mark.parametrize("base,seed,kind", [("dcmotor", 1003, "prbs"), ("dcmotor2", 1004, "held")])
def test_a_long_input_delay_is_refitted_although_its_linearised_test_explains_little(tmp_path, base, seed, kind):
    """A delay of 8.3 samples at 10 % noise: the added-term test linearises at d = 0, where it explains
    7–11 % of the residual, and the refit screen left it out while an unmodeled lag was refitted and
    named first (the delay came second, or not at all on dcmotor2). Input delay is now always refitted
    (``Family.screened``): one finding, the delay, within 1.5 samples."""
    case = make_case("input_delay", base, seed, magnitude="large", noise=0.1, input_kind=kind, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    fams = [f["family"] for f in s["diagnosis"]["findings"]]
    assert fams and fams[0] == "input_delay", fams
    assert "unmodeled_dynamics" not in fams, fams
    first = s["diagnosis"]["findings"][0]
    assert abs(first["delay_samples"] - case.truth["params"]["delay_samples"]) <= 1.5


def test_velocity_drag_at_10_percent_noise_is_quadratic_damping_not_a_tanh_of_the_velocity(tmp_path):
    """v·|v| drag on the msd under a PRBS at 10 % noise was named ``static_nonlinearity tanh(v/s)``
    (ΔBIC 1 lower, a tie): an odd saturating function of a velocity in its own force equation is a
    friction law, which coulomb_friction and quadratic_damping own, so it is no longer in the static
    library."""
    case = make_case("quadratic_damping", "msd", 1004, magnitude="medium", noise=0.1, input_kind="prbs",
                     out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    first = s["diagnosis"]["findings"][0]
    assert (first["family"], first["term"]) == ("quadratic_damping", "v*abs(v)"), first
    tried = {c["hypothesis"] for it in s["diagnosis"]["history"] for c in it["candidates"]}
    assert not any("tanh(v/" in str(h) for h in tried), sorted(map(str, tried))


SMOOTH_AR = [("periodic_disturbance", "dcmotor", "prbs", s) for s in (1001, 1002, 1003)] + \
            [("static_nonlinearity", "tank", "band", s) for s in (1001, 1002, 1003)] + \
            [("input_saturation", "tank", "band", s) for s in (1000, 1001, 1002)]


@pytest.mark.slow
@pytest.mark.parametrize("family,base,kind,seed", SMOOTH_AR, ids=[f"{f}-{b}-{s}" for f, b, _, s in SMOOTH_AR])
def test_a_large_smooth_effect_under_ar_noise_is_accepted_not_left_unexplained(tmp_path, family, base, kind, seed):
    """Large effects with AR(1) 0.9 output noise at 2 %: the nominal residual is the effect itself (lag-1
    autocorrelation near 1). With N_eff of the likelihood-ratio test taken from that residual, all nine
    ended ``unexplained_discrepancy`` with no finding although their refits cut the validation RMSE;
    with N_eff from the refit's residual (``refit_criteria.lr_against``) the first finding is the hidden
    family, where it acts and with its key parameter within the issue's tolerance."""
    case = make_case(family, base, seed, magnitude="large", noise=0.02, colour="ar0.9", input_kind=kind,
                     out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        summary = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    findings = summary["diagnosis"]["findings"]
    assert findings and findings[0]["family"] == family, summary["diagnosis"]["verdict"]
    f = findings[0]
    assert f["gain"]["ci95"][0] > 0
    errors = parameter_error(case.truth, f)
    assert all(v["ok"] for v in errors.values()), errors


def test_a_biased_equation_error_start_does_not_stop_the_run(tmp_path):
    """A 3.6-sample dead time on the two-tank (2-input 2-output) base biases the equation-error start
    into an unstable model (a1 = −0.09, a2 = −1.18); the output-error fit stayed in that basin and the
    whole run stopped with "the fitted model fails on this record" (exit 2 on valid data; bench record
    input_delay-mimo-prbs-medium-n0.1-white-s1). The nominal fit now also starts from the config's own
    values and keeps the better fit: the run completes and names the dead time."""
    case = make_case("input_delay", "mimo", 1, magnitude="medium", noise=0.1, colour="white",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    f = s["diagnosis"]["findings"][0]
    assert f["family"] == "input_delay"
    assert abs(f["delay_s"] - case.truth["params"]["delay_s"]) < 1.5 * case.truth["dt"]
    assert s["nominal"]["params"]["a1"] > 0 and s["nominal"]["params"]["a2"] > 0


@pytest.mark.parametrize("seed", [1013, 1023])
def test_a_drift_is_not_named_a_jump_at_a_searched_time(tmp_path, seed):
    """A small drift of the DC motor's damping at 10 % noise: a jump at a searched time and the drift
    both explain it, within ln N in BIC. The jump's time is estimated by a search and held fixed in
    its refit; counted as a parameter (``Hypothesis.searched``), the drift wins. Uncounted, both
    records were named parameter_jump (ΔBIC −29.8 vs −25.0 and −18.1 vs −14.5)."""
    case = make_case("parameter_drift", "dcmotor", seed, magnitude="small", noise=0.1, colour="white",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    f = s["diagnosis"]["findings"][0]
    assert f["family"] == "parameter_drift"
    assert f["parameter"] == case.truth["acts_on"]["parameter"]


@pytest.mark.parametrize("family,kind,noise,seed,key,want", [
    ("static_nonlinearity", "held", 0.1, 1012, "term", "sqrt(h)"),
    ("static_nonlinearity", "held", 0.1, 1016, "term", "sqrt(h)"),
    ("parameter_jump", "band", 0.02, 1012, "parameter", "a"),
    ("parameter_jump", "band", 0.02, 1014, "parameter", "a"),
])
def test_a_near_tie_inside_a_family_is_settled_by_the_refit(tmp_path, family, kind, noise, seed, key, want):
    """Tank records (medium effect, white noise): the family's representative was the hypothesis with
    the largest linearised share, and only it was refitted. sqrt(h) explains 0.58 against h**2's 0.69
    of the residual (and h**2's refit loses to an offset), a jump in b nearly as much as the true jump
    in a. A runner-up acting elsewhere with at least 0.8 of the share is now refitted too
    (``Diagnoser._near_tie``): the first finding is the hidden term or parameter. Before: offset or
    sqrt(u), and a jump in b (seed scan 1005-1016; no scanned record changed for the worse)."""
    case = make_case(family, "tank", seed, magnitude="medium", noise=noise, colour="white",
                     input_kind=kind, n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(Path(case.dir) / "config.yaml")).summary
    f = s["diagnosis"]["findings"][0]
    assert (f["family"], f[key]) == (family, want)
