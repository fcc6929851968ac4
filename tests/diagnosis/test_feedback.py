"""Closed-loop data: the input responds to the measured output, so the residual leads the input
(negative-lag correlation). The record is made here by an explicit Euler loop with a proportional
controller on the noisy measurement (no project code), and an open-loop record with the same plant."""

import numpy as np

from pipeline.data import Split
from pipeline.diagnostics.adequacy import feedback_tests
from pipeline.expressions import parse
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model


def _record(closed: bool, seed: int = 0, n: int = 3000, dt: float = 0.01):
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.normal(size=n // 50), 50)
    x, y, u = 0.0, np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = x + 0.05 * rng.normal()
        # a digital controller acts on the last measurement it has (one sample old)
        u[k] = (r[k] - 3.0 * (y[k - 1] if k else 0.0)) if closed else r[k]
        for _ in range(10):                      # x' = -x + u, fine Euler steps within the sample
            x += dt / 10 * (-x + u[k])
    return np.arange(n) * dt, u, y


def _fit(t, u, y):
    allowed = {"x", "u", "a", "t"}
    m = Model(("x",), ("u",), {"x": parse("-a*x + u", allowed)}, {}, {"a": 2.0}, ("a",), {"x": 0.0},
              nominal_params=("a",))
    prob = Problem(t, u[:, None], y[:, None], ["x"], Split((0, 2000), (2000, len(t))), bound=1e6)
    return fit_output_error(m, prob), prob


def test_negative_lag_correlation_flags_closed_loop_data_and_not_open_loop():
    f, prob = _fit(*_record(True))
    [fb] = feedback_tests(f, prob, 0.01)
    assert fb.name == "feedback_crosscorrelation"
    assert not fb.passed and "closed loop" in fb.detail and fb.p_value < 1e-6
    f, prob = _fit(*_record(False))
    assert [t.passed for t in feedback_tests(f, prob, 0.01)] == [True]


def _record_two(seed: int = 0, n: int = 3000, dt: float = 0.01):
    """Two first-order plants side by side: x1 driven open loop by u1, x2 by u2 = r2 − 3·y2 (the
    loop closes through the second output and the second input only)."""
    rng = np.random.default_rng(seed)
    r1, r2 = (np.repeat(rng.normal(size=n // 50), 50) for _ in range(2))
    x, y, u = np.zeros(2), np.zeros((n, 2)), np.zeros((n, 2))
    for k in range(n):
        y[k] = x + 0.05 * rng.normal(size=2)
        u[k] = r1[k], r2[k] - 3.0 * (y[k - 1, 1] if k else 0.0)
        for _ in range(10):
            x += dt / 10 * (-x + u[k])
    return np.arange(n) * dt, u, y


def test_every_output_and_input_pair_is_checked_and_only_the_closed_pair_fails():
    """Issue 8 (every output and input): the loop closes from y2 to u2, so only the [u2->x2] row fails;
    with only the first pair checked (as before) the feedback went unreported."""
    t, u, y = _record_two()
    allowed = {"x1", "x2", "u1", "u2", "a1", "a2", "t"}
    m = Model(("x1", "x2"), ("u1", "u2"), {"x1": parse("-a1*x1 + u1", allowed), "x2": parse("-a2*x2 + u2", allowed)},
              {}, {"a1": 2.0, "a2": 2.0}, ("a1", "a2"), {"x1": 0.0, "x2": 0.0}, nominal_params=("a1", "a2"))
    prob = Problem(t, u, y, ["x1", "x2"], Split((0, 2000), (2000, len(t))), bound=1e6)
    rows = {r.name: r for r in feedback_tests(fit_output_error(m, prob), prob, 0.01)}
    assert sorted(rows) == ["feedback_crosscorrelation", "feedback_crosscorrelation[u1->x2]",
                            "feedback_crosscorrelation[u2->x1]", "feedback_crosscorrelation[u2->x2]"]
    failed = [k for k, r in rows.items() if not r.passed]
    assert failed == ["feedback_crosscorrelation[u2->x2]"] and rows[failed[0]].p_value < 1e-6
