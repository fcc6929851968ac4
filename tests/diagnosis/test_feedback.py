"""Closed-loop data: the input responds to the measured output, so the residual leads the input
(negative-lag correlation). The record is made here by an explicit Euler loop with a proportional
controller on the noisy measurement (no project code), and an open-loop record with the same plant."""

import numpy as np

from pipeline.data import Split
from pipeline.diagnostics.adequacy import feedback_test
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
    fb = feedback_test(f, prob, 0.01)
    assert not fb.passed and "closed loop" in fb.detail and fb.p_value < 1e-6
    f, prob = _fit(*_record(False))
    assert feedback_test(f, prob, 0.01).passed
