"""A saturating static law tanh(z/s) is named with its own knee, not as a sum of other families' terms.

The record is made with scipy's ``solve_ivp`` (code the detector does not share; ``tests/records.py``): two coupled
thermal nodes, each driven by its own held input, and the node T1 losing heat through an extra
saturating path −0.6·tanh(2·T1) (knee s = 0.5; the state's spread on the record is about 0.27). The
nominal model is linear. A hostile user's probe found that with the scale held at the state's spread
the loop named quadratic damping ``T1*abs(T1)`` and then Coulomb friction ``sign(T1)`` in the same
equation: two families approximating one saturating term. With the scale estimated in the refit, one
``static_nonlinearity`` finding names ``tanh(T1/s)`` with s and the coefficient near the truth."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.config import load_config
from pipeline.runs import analyse
from tests.records import thermal_tanh

DT, N = 0.05, 2000


def _record(path) -> None:
    t, U, X = thermal_tanh(N, DT, noise=0.003)
    pd.DataFrame({"t": t, "q1": U[:, 0], "q2": U[:, 1], "T1": X[:, 0], "T2": X[:, 1]}).to_csv(path, index=False)


@pytest.mark.slow
def test_a_saturating_heat_loss_is_one_tanh_finding_with_its_knee(tmp_path):
    _record(tmp_path / "thermal.csv")
    cfg = {"name": "thermal", "seed": 0,
           "data": {"path": "thermal.csv", "time": "t", "inputs": {"q1": "u1", "q2": "u2"},
                    "outputs": {"T1": "T1", "T2": "T2"}, "intersample": "zoh"},
           "model": {"states": ["T1", "T2"], "inputs": ["u1", "u2"], "params": {"a1": 1.0, "a2": 0.5, "b": 0.4},
                     "free": ["a1", "a2", "b"],
                     "equations": {"T1": "u1 - a1*T1 - b*(T1-T2)", "T2": "u2 - a2*T2 - b*(T2-T1)"},
                     "initial": {"T1": 0.0, "T2": 0.0}},
           "split": {"validation_fraction": 0.3},
           "diagnose": {"families": "all", "max_findings": 2}}
    (tmp_path / "thermal.yaml").write_text(yaml.safe_dump(cfg))
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(tmp_path / "thermal.yaml")).summary["diagnosis"]
    physical = [f for f in d["findings"] if not f["family"].endswith("_noise")]
    assert [f["family"] for f in physical] == ["static_nonlinearity"], [f.get("description") for f in physical]
    f = physical[0]
    assert f["equation"] == "T1" and f["term"].startswith("tanh(T1/"), f
    assert f["scale"] == pytest.approx(0.5, rel=0.1) and f["coefficient"] == pytest.approx(-0.6, rel=0.1), f
    # the term names the fitted knee, and the form test reads one state from it
    assert float(f["term"][len("tanh(T1/"):-1]) == pytest.approx(f["scale"], rel=1e-3)
    assert d["verdict"] == "discrepancy"


def test_the_knee_is_searched_between_a_smoothed_sign_and_the_records_reach(linear_msd):
    """On a linear mass–spring–damper record (scipy.signal.lsim), the tanh(x/s) hypothesis is tested at
    the spread of x and refitted with s between a tenth of the spread and the 99th percentile of |x|;
    a knee at either end is said so, without a standard deviation (an interior optimum's)."""
    from types import SimpleNamespace

    from pipeline.diagnostics.families import REGISTRY

    _, fit, ctx = linear_msd
    fam = REGISTRY["static_nonlinearity"]
    h = next(h for h in fam.hypotheses(ctx) if h.term.startswith("tanh(x/"))
    x = ctx.state("x")[slice(*ctx.est)]
    s = h.info["scale_name"]
    assert float(h.term[len("tanh(x/"):-1]) == pytest.approx(np.std(x), rel=1e-5)
    assert s in h.fixed and fam.extend(fit.model, h).free == fit.model.free + (h.coefs[0],)   # held in the test
    mr = fam.refit_model(fit.model, h, {h.coefs[0]: 0.0})
    assert s in mr.free
    lo, hi = mr.bounds[s]
    assert lo == pytest.approx(0.1 * np.std(x), rel=1e-5) and hi == pytest.approx(np.quantile(np.abs(x), 0.99))
    c = h.coefs[0]
    for value, end in ((lo, "lower"), (hi, "upper"), (0.5 * (lo + hi), None)):
        key, sentence = fam.describe(h, SimpleNamespace(model=mr), {c: -0.3, s: value}, {c: 0.01, s: 0.02})
        assert key["scale_at_bound"] == end and key["scale"] == value
        assert (key["scale_std"] is None) == (end is not None)
        assert (f"at the {end} end of the range searched" in sentence) == (end is not None)
