"""A finer integration step chosen on a model with a jump in time says so (an auditor's record: k jumped
between two samples, the parameter_jump was found, then "the integration step is too coarse" was
named with nothing about the jump, although RK4 at that step is accurate to 1e-7 on the smooth
dynamics; the finer step resolves the discontinuity)."""

from pipeline.diagnostics.families.intersample import Intersample, time_steps
from pipeline.expressions import parse
from pipeline.model import Model, Rewrite


def _msd():
    params = {"m": 1.0, "c": 0.6, "k": 4.0}
    allowed = {"x", "v", "u", "t", *params}
    return Model(states=("x", "v"), inputs=("u",), equations={"x": parse("v", allowed),
                                                              "v": parse("(u - c*v - k*x)/m", allowed)},
                 output_exprs={}, params=params, free=(), initial={"x": 0.0, "v": 0.0}, substeps=1,
                 intersample="zoh", nominal_params=tuple(params))


def test_a_substeps_choice_on_a_model_with_a_jump_names_the_jump():
    base = _msd()
    jumped = base.extend([], {"dk": 1.5, "tj": 29.975},
                         param_rewrites=(Rewrite("parameter_jump", "k", "k + dk*step(t - tj)"),))
    assert time_steps(base) == [] and time_steps(jumped) == [29.975]
    key, text = Intersample().describe_choice(jumped, "substeps=4")
    assert key["at_jumps_s"] == [29.975] and "jump in time (t = 29.975 s)" in text
    key0, text0 = Intersample().describe_choice(base, "substeps=4")
    assert "at_jumps_s" not in key0 and text0.startswith("The integration step is too coarse: with 4")
    # a constant date is read too
    lit = base.extend([], {"dk": 1.5}, param_rewrites=(Rewrite("parameter_jump", "k", "k + dk*step(t - 12)"),))
    assert time_steps(lit) == [12.0]
