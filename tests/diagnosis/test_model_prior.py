"""The finding among accepted extensions is chosen by ΔBIC plus the model prior's 2 ln(places)
(:func:`pipeline.diagnostics.engine.choose`; Kass & Raftery 1995 §4.1, Scott & Berger 2010)."""

import math

from pipeline.diagnostics.engine import Candidate, choose
from pipeline.diagnostics.families import Hypothesis


def _acc(family: str, key: str, dbic: float, places: int) -> Candidate:
    c = Candidate(Hypothesis(family, key), None, 0.0, [], places=places)
    c.delta_bic, c.accepted = dbic, True
    return c


def test_a_library_term_must_beat_a_one_place_cause_by_its_prior_penalty():
    """The numbers of an independent-bench record (quadratic damping hidden in a DC motor, 10 % noise):
    a static term from a 6-term library was 1.3 BIC units better; the prior's 2 ln 6 = 3.58 reverses it."""
    qd = _acc("quadratic_damping", "quadratic_damping:w:w", -256.48, 1)
    sn = _acc("static_nonlinearity", "static_nonlinearity:w:tanh(w/1.1)", -257.76, 6)
    assert math.isclose(sn.prior_penalty, 2 * math.log(6))
    assert qd.prior_penalty == 0.0
    assert choose([sn, qd]) is qd
    # a library term that explains clearly more still wins: 2 ln 6 is a prior, not a veto
    sn.delta_bic = qd.delta_bic - 2 * math.log(6) - 0.1
    assert choose([qd, sn]) is sn


def test_equal_places_leave_the_lowest_delta_bic():
    a = _acc("offset", "offset:v", -431.2, 1)
    b = _acc("output_offset", "output_offset:y", -433.3, 1)
    assert choose([a, b]) is b
    assert choose([]) is None


def test_a_tie_in_bic_goes_to_the_cause_with_fewer_places_whatever_the_order():
    """w*abs(w) of the library and quadratic damping of w are the same column on a DC motor: the same
    ΔBIC; the choice must not depend on the order the families were tested in."""
    qd = _acc("quadratic_damping", "quadratic_damping:w:w", -90.1, 1)
    sn = _acc("static_nonlinearity", "static_nonlinearity:w:w*abs(w)", -90.1, 6)
    assert choose([sn, qd]) is qd and choose([qd, sn]) is qd


def test_a_hidden_cubic_spring_is_not_given_to_the_library(tmp_path):
    """An independent-bench record (solve_ivp, the spring force written out there; seed outside the bench's
    sets): a cubic spring in the first mode of a two-mode structure at 10 % noise. x1*abs(x1) from the
    22-place library fits the estimation part 3.8 BIC units better than x1**3 and was the finding; on
    seeds 2011-2039 of this setting the prior changed this record only, and all 29 name the cubic spring."""
    import contextlib
    import io
    from pathlib import Path

    from pipeline.bench.independent.case import make_case
    from pipeline.config import load_config
    from pipeline.runs import analyse

    case = make_case("cubic_stiffness", "twomode", 2015, magnitude="medium", noise=0.1, colour="white",
                     input_kind="band", n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    first = d["findings"][0]
    assert first["family"] == "cubic_stiffness" and first["equation"] == "v1"
    lib = next(r for r in first["runners_up"] if r["family"] == "static_nonlinearity")
    # the runner-up fits better by BIC alone, and loses by the prior's 2 ln(22) − 2 ln(2)
    assert lib["delta_bic"] < first["delta_bic"]
    assert lib["delta_bic"] + lib["prior_penalty"] > first["delta_bic"] + first["prior_penalty"]
    assert "model prior" in lib["separation"]
