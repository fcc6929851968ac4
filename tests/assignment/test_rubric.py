"""The rubric's formulas (pipeline/assignment/rubric.py docstring), the size of a cause in a model
written in the student's own way (closed form), and the summary page's escaping."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from pipeline.assignment import rubric
from pipeline.assignment.grade import COLUMNS, FORM_SHARE_MIN, KeyStudent, cause_projection, cause_size
from pipeline.assignment.summary import render_summary
from pipeline.assignment.template import Rubric
from pipeline.config import load_config
from pipeline.model import Model


def test_item_shares_follow_the_documented_formulas():
    r = Rubric()  # tolerance 0.25, target 0.8
    s = rubric.shares(r, cause_correct=True, parameter_error=0.25, validation=0.4, gain_reproduces=False)
    assert s == {"cause": 1.0, "parameter": 1.0, "validation": 0.5, "gain": 0.0}
    assert rubric.shares(r, cause_correct=True, parameter_error=0.375, validation=0.8,
                         gain_reproduces=True)["parameter"] == pytest.approx(0.5)
    assert rubric.shares(r, cause_correct=True, parameter_error=0.6, validation=1.2,
                         gain_reproduces=True) == {"cause": 1.0, "parameter": 0.0, "validation": 1.0, "gain": 1.0}
    # a right-sized term for the wrong cause earns no parameter marks
    assert rubric.shares(r, cause_correct=False, parameter_error=0.0, validation=1.0,
                         gain_reproduces=True)["parameter"] == 0.0
    assert rubric.shares(r, cause_correct=True, parameter_error=math.nan, validation=math.nan,
                         gain_reproduces=True)["validation"] == 0.0


def test_score_is_the_weighted_share_scaled_to_100_and_gated_by_the_data_hash():
    r = Rubric()  # weights 40 / 20 / 30 / 10
    s = {"cause": 1.0, "parameter": 0.5, "validation": 0.5, "gain": 0.0}
    assert rubric.score(r, s, data_issued=True) == pytest.approx(40 + 10 + 15)
    assert rubric.score(r, s, data_issued=False) == 0.0
    lax = Rubric(require_issued_data=False, weights={"cause": 1, "parameter": 0, "validation": 0, "gain": 1})
    assert rubric.score(lax, s, data_issued=False) == pytest.approx(50.0)


def test_validation_share_of_the_achievable_improvement():
    assert rubric.validation_share(0.10, 0.03, 0.02) == pytest.approx(0.875)
    assert rubric.validation_share(0.10, 0.12, 0.02) == pytest.approx(-0.25)
    assert rubric.validation_share(0.02, 0.02, 0.03) == 1.0     # starter already at the noise level
    assert rubric.validation_share(0.02, 0.05, 0.03) == 0.0
    assert rubric.validation_share(0.1, math.inf, 0.02) == 0.0


def _model(tmp_path, equations: dict, params: dict, outputs: dict | None = None) -> tuple[Model, dict]:
    cfg = {"name": "m", "data": {"path": "r.csv", "time": "t", "inputs": ["u"],
                                 "outputs": {"x": "x_meas"} if outputs else ["x"]},
           "model": {"states": ["x", "v"], "inputs": ["u"], "params": params, "free": list(params),
                     "equations": equations, **({"outputs": outputs} if outputs else {})}}
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cfg))
    lc = load_config(p)
    return Model.from_config(lc), lc.output_map


def _key(family: str, acts_on: str, **params) -> KeyStudent:
    main = {"periodic_disturbance": "amplitude", "output_offset": "value"}.get(family, "coefficient")
    return KeyStudent(id="s", name="n", family=family, acts_on=acts_on, parameters=params, main_parameter=main,
                      data_sha256="", issued_samples=1, heldout_samples=1, instructor_record="",
                      instructor_record_sha256="", starter_config="", heldout_rmse_truth=0.0)


@pytest.fixture
def traj():
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 0.02
    X = rng.normal(size=(2000, 2))
    U = rng.normal(size=(2000, 1))
    return t, U, X


def test_cause_size_whatever_the_sign_and_scaling_the_student_wrote(tmp_path, traj):
    t, U, X = traj
    # -q x^3 / m with m = 2: the additive coefficient of x**3 in dv/dt is -q/m = -1.5
    m, _ = _model(tmp_path, {"x": "v", "v": "(u - c*v - k*x - q*x**3)/mm"},
                  {"c": 0.6, "k": 4.0, "q": 3.0, "mm": 2.0})
    assert cause_size(m, "q", _key("cubic_stiffness", "v", coefficient=-1.5, term="x**3"), t, U, X, None) \
        == pytest.approx(-1.5, rel=1e-12)
    m, _ = _model(tmp_path, {"x": "v", "v": "u - c*v - k*x - 0.5*d*sign(v)"}, {"c": 0.6, "k": 4.0, "d": 0.8})
    assert cause_size(m, "d", _key("coulomb_friction", "v", coefficient=-0.4, term="sign(v)"), t, U, X, None) \
        == pytest.approx(-0.4, rel=1e-12)
    m, _ = _model(tmp_path, {"x": "v", "v": "u - c*v - k*x + h"}, {"c": 0.6, "k": 4.0, "h": 0.3})
    assert cause_size(m, "h", _key("offset", "v", coefficient=0.3), t, U, X, None) == pytest.approx(0.3)


def test_a_term_of_the_keys_form_is_told_from_one_that_only_correlates_with_it(tmp_path, traj):
    """The share of the parameter's change the key's term explains: all of it for the cause's term
    however written (scaled, negated, divided by a fixed mass), too little for the linear damping,
    whose change -c*v still projects on sign(v) with a size of the key's order."""
    t, U, X = traj
    key = _key("coulomb_friction", "v", coefficient=-0.4, term="sign(v)")
    m, _ = _model(tmp_path, {"x": "v", "v": "(u - c*v - k*x - 0.5*d*sign(v))/mm"},
                  {"c": 0.6, "k": 4.0, "d": 0.8, "mm": 2.0})
    size, share = cause_projection(m, "d", key, t, U, X, None)
    assert size == pytest.approx(-0.2, rel=1e-12) and share == pytest.approx(1.0, abs=1e-12)
    size, share = cause_projection(m, "c", key, t, U, X, None)
    # for Gaussian v the explained share of c*v by sign(v) is 2/pi (closed form)
    assert abs(size) > 0.1 and share == pytest.approx(2 / np.pi, abs=0.03) and share < FORM_SHARE_MIN
    m, omap = _model(tmp_path, {"x": "v", "v": "u - c*v - k*x"}, {"c": 0.6, "k": 4.0, "b": -0.2},
                     outputs={"x_meas": "x - b"})
    assert cause_projection(m, "b", _key("output_offset", "output x", value=0.2), t, U, X, omap["x"]) \
        == pytest.approx((0.2, 1.0))


def test_cause_size_periodic_amplitude_is_phase_free(tmp_path, traj):
    t, U, X = traj
    m, _ = _model(tmp_path, {"x": "v", "v": "u - c*v - k*x + a*sin(2*3.141592653589793*f*t + 0.7)"},
                  {"c": 0.6, "k": 4.0, "a": 0.4, "f": 0.8})
    key = _key("periodic_disturbance", "v", amplitude=0.4, frequency_hz=0.8)
    assert cause_size(m, "a", key, t, U, X, None) == pytest.approx(0.4, rel=1e-10)


def test_cause_size_output_offset(tmp_path, traj):
    t, U, X = traj
    m, omap = _model(tmp_path, {"x": "v", "v": "u - c*v - k*x"}, {"c": 0.6, "k": 4.0, "b": -0.2},
                     outputs={"x_meas": "x - b"})
    assert cause_size(m, "b", _key("output_offset", "output x", value=0.2), t, U, X, omap["x"]) == pytest.approx(0.2)


def test_summary_escapes_what_students_and_rosters_wrote(tmp_path):
    row = {c: "" for c in COLUMNS}
    row.update(student_id="s1", name="<script>alert(1)</script>", status="invalid", cause_key="offset",
               score="0.0", reason="answer.yaml: <b>bad</b>")
    html = render_summary("a&b", [row], tmp_path / "summary.html", tmp_path / "runs")
    assert "<script" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert "&lt;b&gt;bad&lt;/b&gt;" in html and "a&amp;b" in html
