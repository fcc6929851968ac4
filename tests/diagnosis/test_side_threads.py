"""Work the engine runs beside the loop changes no number (issue 8, Silverbox speed).

* The nominal model's adequacy rows (``Diagnosis.adequacy_nominal``) are computed in a side thread from
  the nominal fit on, while the loop tests and refits the extensions in its own threads
  (``Diagnoser._run``). They must be the rows computed alone, afterwards, on the same fit.
* ``Diagnoser._basis`` keeps the Jacobian bases of several fits (the side thread's nominal and the
  loop's current fit), each computed once.

Data: ``scipy.integrate.solve_ivp`` of a mass–spring–damper with a cubic spring on a continuous-time
input (no code of the detector); the belief is linear, so the loop has findings to make."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from pipeline.data import Split
from pipeline.diagnostics import stats
from pipeline.diagnostics.adequacy import adequacy_tests
from pipeline.diagnostics.engine import Diagnoser
from pipeline.expressions import parse
from pipeline.fit import Problem, fit_output_error
from pipeline.model import Model


def _record(n: int = 3000, dt: float = 0.02):
    t = np.arange(n) * dt
    f = np.array([0.13, 0.37, 0.71, 1.09, 1.53])
    ph = np.random.default_rng(5).uniform(0, 2 * np.pi, f.size)

    def u(tt):
        return 3.0 * np.sum(np.sin(2 * np.pi * f[:, None] * np.atleast_1d(tt) + ph[:, None]), axis=0)

    def rhs(tt, s):
        x, v = s
        return [v, u(tt)[0] - 0.6 * v - 4.0 * x - 2.0 * x ** 3]

    sol = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-12)
    y = sol.y[0] + 0.01 * np.random.default_rng(6).normal(size=n)
    return t, u(t), y


def _model():
    allowed = {"x", "v", "u", "c", "k", "t"}
    return Model(("x", "v"), ("u",), {"x": parse("v", allowed), "v": parse("u - c*v - k*x", allowed)}, {},
                 {"c": 0.5, "k": 3.5}, ("c", "k"), {"x": 0.0, "v": 0.0}, intersample="foh",
                 nominal_params=("c", "k"))


def _rows(tests):
    return [(r.name, r.statistic, r.p_value, r.passed, r.detail) for r in tests]


def test_the_nominal_adequacy_from_the_side_thread_is_the_one_computed_alone():
    t, u, y = _record()
    prob = Problem(t, u[:, None], y[:, None], ["x"], Split((0, 2000), (2000, 3000)), bound=1e6)
    dg = Diagnoser(prob, alpha=0.01, families=["cubic_stiffness", "offset", "quadratic_damping"],
                   max_findings=2, seed=0, dt=0.02)
    diag = dg.run(_model())
    assert diag.findings and diag.findings[0]["family"] == "cubic_stiffness"   # the loop ran meanwhile
    alone = adequacy_tests(diag.nominal, prob, dg.alpha) + dg.state_probe(diag.nominal)
    assert len(alone) >= 3 and any(not r.passed for r in alone)          # the linear belief fails them
    assert _rows(diag.adequacy_nominal) == _rows(alone)


def test_the_bases_of_two_fits_are_each_computed_once_and_kept():
    t, u, y = _record(1500)
    prob = Problem(t, u[:, None], y[:, None], ["x"], Split((0, 1000), (1000, 1500)), bound=1e6)
    dg = Diagnoser(prob, alpha=0.01, families=["cubic_stiffness"], max_findings=1, seed=0, dt=0.02)
    a = fit_output_error(_model(), prob)
    allowed = {"x", "v", "u", "c", "k", "k3", "t"}
    cubic = Model(("x", "v"), ("u",), {"x": parse("v", allowed), "v": parse("u - c*v - k*x - k3*x**3", allowed)},
                  {}, {"c": 0.5, "k": 3.5, "k3": 1.0}, ("c", "k", "k3"), {"x": 0.0, "v": 0.0}, intersample="foh",
                  nominal_params=("c", "k", "k3"))
    b = fit_output_error(cubic, prob)
    ba = dg._basis(a)
    bb = dg._basis(b)
    assert dg._basis(a) is ba and dg._basis(b) is bb     # alternating fits do not evict each other
    np.testing.assert_array_equal(ba, stats.column_basis(a.jac))
    np.testing.assert_array_equal(bb, stats.column_basis(b.jac))
