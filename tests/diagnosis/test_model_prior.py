"""The finding among accepted extensions is chosen by ΔBIC plus the model prior's 2 ln(places)
(:func:`pipeline.diagnostics.engine.choose`; Kass & Raftery 1995 §4.1, Scott & Berger 2010)."""

import math

import pytest

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


# ------------------------------------------------------------------ ΔBIC with the effective sample size
def _ar1(phi: float, n: int, seed: int):
    """AR(1) noise by scipy's filter (not the project's code), unit innovation variance."""
    import numpy as np
    from scipy.signal import lfilter
    return lfilter([1.0], [1.0, -phi], np.random.default_rng(seed).standard_normal(n))


def _refit(resid, n_params: int):
    import numpy as np
    from types import SimpleNamespace
    r = np.asarray(resid, float).reshape(-1, 1)
    return SimpleNamespace(resid_est=r, sse_w=float(r[:, 0] @ r[:, 0]), n_params=n_params)


def test_effective_bic_is_jones_formula_with_the_best_refits_lag1_autocorrelation():
    """ΔBIC_eff = (N_eff/N)·(ΔBIC − Δk ln N) + Δk ln N_eff, N_eff = N(1 − ρ)/(1 + ρ) with ρ the lag-1
    autocorrelation (statsmodels' acf here) of the residual of the refit that fits best (Jones 2011)."""
    from statsmodels.tsa.stattools import acf
    from pipeline.diagnostics.engine import effective_bic
    n = 2000
    e_best, e_other = _ar1(0.9, n, 1), 1.5 * _ar1(0.9, n, 2)
    current = _refit(3 * _ar1(0.9, n, 3), 2)
    a = _acc("input_delay", "input_delay", -4071.85, 1)
    b = _acc("unmodeled_dynamics", "unmodeled_dynamics:u@2.5dt", -4077.73, 1)
    a.fit, b.fit = _refit(e_best, 3), _refit(e_other, 3)
    n_eff = effective_bic([a, b], current)
    rho = acf(e_best, nlags=1, fft=False)[1]
    assert 0.85 < rho < 0.95
    assert n_eff == pytest.approx(n * (1 - rho) / (1 + rho), rel=1e-9)
    for c, raw in ((a, -4071.85), (b, -4077.73)):
        assert c.delta_bic_eff == pytest.approx((raw - math.log(n)) * n_eff / n + math.log(n_eff), rel=1e-12)
    # the 5.9 raw BIC units the lag had over the delay are 0.3 effective units: a prior over two places
    # for the lag now decides, where raw ΔBIC would have named the lag whatever the prior
    assert abs(a.delta_bic_eff - b.delta_bic_eff) < 0.5
    b.places = 2
    assert choose([b, a]) is a
    a.delta_bic_eff = b.delta_bic_eff = None
    assert choose([b, a]) is b


def test_effective_bic_leaves_white_residuals_nearly_as_they_are():
    """White residuals: ρ ≈ 0, N_eff ≈ N, and a 2-unit ΔBIC lead survives."""
    from pipeline.diagnostics.engine import effective_bic
    import numpy as np
    n = 2000
    rng = np.random.default_rng(7)
    current = _refit(rng.standard_normal(n), 2)
    a, b = _acc("offset", "offset:v", -433.3, 1), _acc("output_offset", "output_offset:y", -431.2, 1)
    a.fit, b.fit = _refit(rng.standard_normal(n), 3), _refit(rng.standard_normal(n), 3)
    n_eff = effective_bic([a, b], current)
    assert 0.9 * n < n_eff <= 1.1 * n
    assert choose([b, a]) is a and b.delta_bic_eff - a.delta_bic_eff > 1.5
    assert effective_bic([], current) is None


# ------------------------------------------------------------------ near-equals separated by validation
def _separate(best, others, y, yhats):
    """naming.separate on a one-output problem whose validation part is the whole record."""
    import numpy as np
    from types import SimpleNamespace
    from pipeline.data import Split
    from pipeline.diagnostics import naming
    y = np.asarray(y, float).reshape(-1, 1)
    prob = SimpleNamespace(Y=y, split=Split((0, 0), (0, len(y))))
    for c, yh in zip([best] + others, yhats):
        c.fit = SimpleNamespace(Yhat=np.asarray(yh, float).reshape(-1, 1))
        c.gain = {"relative": 0.5}
    return naming.separate(prob, best, [best] + others)


def test_a_near_equal_clearly_better_on_validation_is_the_finding():
    """Within 2 criterion units the estimation part cannot separate two causes; the other one replaces
    the chosen one when its validation error is lower with the 95 % interval above 0 and by ≥ 1 %."""
    import numpy as np
    n = 1000
    t = np.arange(n)
    e = 0.1 * np.random.default_rng(3).standard_normal(n)
    misfit = 0.2 * np.sin(2 * np.pi * t / 50)
    y = np.sin(2 * np.pi * t / 200) + e
    truth = y - e                                    # the other model leaves only the noise
    best = _acc("parameter_jump", "parameter_jump:k@18.1", -700.0, 1)
    other = _acc("parameter_drift", "parameter_drift:k", -698.6, 1)
    got = _separate(best, [other], y, [truth + misfit, truth])
    assert got is other and "parameter_jump:k@18.1" in other.separation and "lower" in other.separation
    assert "could not separate" in other.separation
    # beyond a tie, up to "positive" evidence (6 units), the validation part still decides on a clear
    # difference, and says by how much the estimation part preferred the other
    best2, pos = _acc("parameter_jump", "j", -700.0, 1), _acc("parameter_drift", "d", -695.9, 1)
    assert _separate(best2, [pos], y, [truth + misfit, truth]) is pos
    assert "preferred by 4.1 criterion units, below 6" in pos.separation
    # from "strong" evidence on (6 units) the estimation part decides, however much better the other is
    best3, far = _acc("parameter_jump", "j", -700.0, 1), _acc("parameter_drift", "d", -693.9, 1)
    assert _separate(best3, [far], y, [truth + misfit, truth]) is best3


def test_a_near_equal_better_by_less_than_one_percent_does_not_replace_the_finding():
    """A deterministic difference of 0.3 % of the validation RMSE is significant on a low-noise record
    (its interval is above 0), and is no evidence of the cause: the estimation choice stands."""
    import numpy as np
    n = 1000
    e = 0.1 * np.random.default_rng(4).standard_normal(n)
    y = e.copy()
    small = 0.003 * e                              # the other's residual is 0.997 e: 0.3 % lower
    best = _acc("unmodeled_dynamics", "unmodeled_dynamics:u@2.5dt", -90.0, 1)
    other = _acc("input_delay", "input_delay", -89.0, 1)
    from pipeline.diagnostics.gain import gain_ci
    g = gain_ci(y.reshape(-1, 1), (y - small).reshape(-1, 1))
    assert g["ci95"][0] > 0 and g["relative"] < 0.01      # significant and immaterial
    assert _separate(best, [other], y, [np.zeros(n), small]) is best and not other.separation
