"""Residual statistics against closed forms, published values and Monte Carlo."""

import math

import numpy as np
import pytest
from scipy import stats as sps

from pipeline.diagnostics import stats


def test_fisher_g_pvalue_closed_form_small_q():
    """q = 2: P(g > x) = 2(1 − x) for x ≥ 1/2 (Fisher 1929 with only the j = 1 term non-zero)."""
    assert stats.fisher_g_pvalue(0.7, 2) == pytest.approx(2 * 0.3)
    # q = 3, x = 0.4: 3·0.6² − 3·0.2² = 0.96
    assert stats.fisher_g_pvalue(0.4, 3) == pytest.approx(3 * 0.6 ** 2 - 3 * 0.2 ** 2)


def test_fisher_g_size_under_white_noise_and_detects_sinusoid():
    rng = np.random.default_rng(1)
    rej = sum(stats.fisher_g(rng.standard_normal(512), 0.05)[0].p_value < 0.05 for _ in range(400))
    assert 8 <= rej <= 35  # 5 % of 400 = 20
    n = 1000
    x = rng.standard_normal(n) + 0.3 * np.sin(2 * np.pi * 0.123 * np.arange(n))
    res, f = stats.fisher_g(x, 0.01)
    assert not res.passed and res.p_value < 1e-4  # expected ≈ 5e-6 for A = 0.3, n = 1000
    assert f == pytest.approx(0.123, abs=0.5 / n)


def test_ljung_box_matches_formula():
    rng = np.random.default_rng(2)
    e = rng.standard_normal(300)
    r, _ = stats.autocorr(e, 10)
    ec = e - e.mean()
    rk = [np.dot(ec[k:], ec[:len(ec) - k]) / np.dot(ec, ec) for k in range(11)]
    np.testing.assert_allclose(r, rk, atol=1e-12)
    q = 300 * 302 * sum(rk[k] ** 2 / (300 - k) for k in range(1, 11))
    res = stats.ljung_box(e, 10)
    assert res.statistic == pytest.approx(q)
    assert res.p_value == pytest.approx(sps.chi2.sf(q, 10))


def test_autocorr_bound_is_2_58_over_sqrt_n():
    _, b = stats.autocorr(np.random.default_rng(0).standard_normal(400), 5, 0.99)
    assert b == pytest.approx(2.5758 / 20, rel=1e-4)


def test_resid_crosscorr_bound_white_input_reduces_to_2_58_over_sqrt_n_and_grows_for_coloured():
    rng = np.random.default_rng(3)
    e, u = rng.standard_normal(4000), rng.standard_normal(4000)
    _, _, b_white = stats.crosscorr(e, u, 10, 0.99)
    assert b_white == pytest.approx(2.5758 / math.sqrt(4000), rel=0.15)
    # coloured e and u (AR(1), 0.9): Σ r_e r_u = (1 + 0.81)/(1 − 0.81) ≈ 9.5 → bound ≈ √9.5 × larger
    from scipy.signal import lfilter
    ec, uc = lfilter([1], [1, -0.9], e), lfilter([1], [1, -0.9], u)
    _, _, b_col = stats.crosscorr(ec, uc, 10, 0.99)
    assert b_col / b_white == pytest.approx(math.sqrt(1.81 / 0.19), rel=0.2)


def test_mean_test_hac_keeps_size_for_autocorrelated_noise():
    from scipy.signal import lfilter
    rng = np.random.default_rng(4)
    rej = 0
    for _ in range(300):
        e = lfilter([1], [1, -0.8], rng.standard_normal(2000))
        rej += stats.mean_test(e, 0.05).p_value < 0.05
    assert rej <= 30  # a naive t-test rejects ~60 % here; HAC with Andrews' bandwidth stays near 5 % (≤ 10 %)


def test_added_terms_wald_size_and_power():
    rng = np.random.default_rng(5)
    n = 1500
    J = rng.standard_normal((n, 2))
    S = rng.standard_normal((n, 1)) + 0.5 * J[:, :1]
    rej = 0
    for _ in range(300):
        e = rng.standard_normal(n)
        e = e - J @ np.linalg.lstsq(J, e, rcond=None)[0]
        rej += stats.added_terms_test(e, J, S).p_value < 0.01
    assert rej <= 9  # 1 % of 300 = 3
    e = rng.standard_normal(n) + 0.2 * (S[:, 0] - 0.5 * J[:, 0])
    w = stats.added_terms_test(e, J, S)
    assert w.p_value < 1e-6 and w.beta[0] == pytest.approx(0.2, abs=0.06)


def test_added_terms_share_is_the_unfiltered_projection():
    """``share``: the residual sum of squares a least-squares step on the added columns removes, before the
    GLS filter (the linearised refit's SSE drop). For a constant column and no current parameters it is
    N·ē²/Σe² in closed form. A smooth residual around a constant offset (AR(1), φ = 0.98) is where the
    GLS ``r2`` nearly differences the constant away and understates it."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(11)
    n = 2000
    e = 0.3 + lfilter([1], [1, -0.98], 0.05 * rng.standard_normal(n))
    S = np.ones((n, 1))
    w = stats.added_terms_test(e, np.zeros((n, 0)), S)
    assert w.share == pytest.approx(n * e.mean() ** 2 / (e @ e), rel=1e-9)
    assert w.share > 0.5 and w.r2 < 0.2 * w.share


def test_holm_step_down():
    out = stats.holm({"a": 0.001, "b": 0.015, "c": 0.03, "d": 0.5}, 0.05)
    # 0.001 ≤ .05/4; 0.015 ≤ .05/3; 0.03 > .05/2 → stop
    assert out == {"a": True, "b": True, "c": False, "d": False}


def test_hac_fft_path_equals_the_lag_loop():
    from scipy.signal import lfilter
    rng = np.random.default_rng(0)
    g = lfilter([1], [1, -0.95], rng.standard_normal((5000, 2)), axis=0)
    L = 40
    ref = g.T @ g
    for lag in range(1, L + 1):
        gam = g[lag:].T @ g[:-lag]
        ref += (1 - lag / (L + 1)) * (gam + gam.T)
    np.testing.assert_allclose(stats.long_run_variance(g, L), ref, rtol=1e-12)


def test_crosscorr_equals_direct_sum_at_negative_and_positive_lags():
    rng = np.random.default_rng(1)
    e, u = rng.standard_normal(1001), rng.standard_normal(1001)
    lags, c, _ = stats.crosscorr(e, u, 10)
    ec, uc = e - e.mean(), u - u.mean()
    ref = [np.dot(ec[k:], uc[:len(uc) - k]) if k >= 0 else np.dot(ec[:k], uc[-k:]) for k in lags]
    np.testing.assert_allclose(c, np.array(ref) / 1001 / np.sqrt(np.var(e) * np.var(u)), atol=1e-14)


def test_passed_follows_the_p_value_and_white_records_pass_at_the_nominal_rate():
    """`passed` is p ≥ α for every residual test, and under white residuals (and a white input) the
    autocorrelation and cross-correlation tests reject about α of the time (Monte Carlo, 600 records;
    the old lag-count rule rejected 21.7 % and 42 %)."""
    from pipeline.diagnostics.stats import input_crosscorr, whiteness
    rng = np.random.default_rng(7)
    rej_a = rej_x = 0
    for _ in range(600):
        e, u = rng.normal(size=500), rng.normal(size=500)
        a, x = whiteness(e, 25, 0.01), input_crosscorr(e, u, 25, 0.01)
        for r in (a, x):
            assert r.passed == (r.p_value >= 0.01)
            assert r.passed == (r.statistic <= r.bound)
        rej_a += not a.passed
        rej_x += not x.passed
    # Bonferroni is conservative: at most 1.5 α, and not absurdly conservative either
    assert rej_a / 600 <= 0.015 and rej_x / 600 <= 0.015
    assert rej_a + rej_x >= 1


def test_column_basis_projects_like_lstsq_and_the_test_is_unchanged():
    """stats.column_basis(J) is computed once per fit and replaces each test's lstsq(J, S): U_r U_rᵀ S
    must equal J lstsq(J, S) (J J⁺ = U_r U_rᵀ), and the added-term test with the basis must give the
    same statistic and p-value as without it; a collinear J keeps only its rank's directions."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(3)
    n = 3000
    J = lfilter([1], [1, -0.9], rng.standard_normal((n, 4)), axis=0)
    S = lfilter([1], [1, -0.9], rng.standard_normal((n, 2)), axis=0) + 0.3 * J[:, :2]
    e = lfilter([1], [1, -0.95], rng.standard_normal(n)) + 0.05 * S[:, 0]
    B = stats.column_basis(J)
    assert B.shape == (n, 4)
    np.testing.assert_allclose(B @ (B.T @ S), J @ np.linalg.lstsq(J, S, rcond=None)[0], rtol=0, atol=1e-10 * np.abs(S).max())
    a, b = stats.added_terms_test(e, J, S), stats.added_terms_test(e, J, S, basis=B)
    assert b.statistic == pytest.approx(a.statistic, rel=1e-9) and b.p_value == pytest.approx(a.p_value, rel=1e-9)
    Jc = np.column_stack([J, J[:, 0] - 2.0 * J[:, 1]])          # rank 4 of 5
    assert stats.column_basis(Jc).shape == (n, 4)
    c, d = stats.added_terms_test(e, Jc, S, basis=stats.column_basis(Jc)), stats.added_terms_test(e, Jc, S)
    assert c.statistic == pytest.approx(d.statistic, rel=1e-6) and c.p_value == pytest.approx(d.p_value, rel=1e-6)


def test_sup_lr_break_p_matches_andrews_table_and_a_brownian_bridge():
    """Andrews (1993, Econometrica 61(4), Table 1, p = 1, π₀ = 0.15): sup-LR critical values 7.17 / 8.85 /
    12.35 at 10 / 5 / 1 %. And a Monte Carlo of sup B(π)²/(π(1 − π)) over [π₀, 1 − π₀] for the
    trimming the jump family uses, 20 000 bridges of 2 000 steps (discretisation makes the simulated
    tail slightly thinner than the continuous one: the approximation errs on the conservative side)."""
    from pipeline.diagnostics.stats import sup_lr_break_p
    for c, p in ((7.17, 0.10), (8.85, 0.05), (12.35, 0.01)):
        assert sup_lr_break_p(c, 0.15) == pytest.approx(p, rel=0.06)
    rng = np.random.default_rng(1)
    n, trim = 2000, 0.5 / 17
    t = np.arange(1, n + 1) / n
    m = (t >= trim) & (t <= 1 - trim)
    sups = []
    for _ in range(10):
        W = np.cumsum(rng.standard_normal((2000, n)), axis=1) / np.sqrt(n)
        B = W - t * W[:, -1:]
        sups.append(np.max(B[:, m] ** 2 / (t[m] * (1 - t[m])), axis=1))
    s = np.concatenate(sups)
    for c in (10.0, 12.0, 14.0):
        mc = float(np.mean(s > c))
        approx = sup_lr_break_p(c, trim)
        assert mc <= approx <= 1.3 * mc + 0.002, (c, mc, approx)
    assert sup_lr_break_p(0.5, trim) == 1.0 and sup_lr_break_p(float("inf"), trim) == 0.0


def test_ar_prediction_error_filter_matches_scipy_lfilter():
    """v_t = x_t − Σ a_i x_{t−i} (the GLS prewhitening of the added-terms test), computed by the compiled
    kernel four samples at a time, equals scipy's FIR filter [1, −a_1, …, −a_p] from sample p on, for one
    and several columns, lengths that are not a multiple of 4, a record shorter than p and no lag at all;
    and it is, to the last bit, the whole-array numpy loop over the lags in the order i = 1..p (the
    arithmetic the added-term tests' p-values were calibrated with), also for a Fortran-ordered and a
    strided input."""
    from scipy.signal import lfilter
    from pipeline.diagnostics.stats import _ar_filter
    rng = np.random.default_rng(3)
    for shape, p in (((10_001,), 3), ((9_000, 4), 10), ((257, 2), 2), ((50, 3), 0), ((13, 2), 10), ((7,), 10)):
        x = rng.standard_normal(shape).cumsum(axis=0)
        a = rng.uniform(-0.4, 0.4, p)
        ref = lfilter(np.concatenate([[1.0], -a]), [1.0], x, axis=0)[p:]
        got = _ar_filter(x, a)
        assert got.shape == ref.shape
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(x).max())
        loop = x[p:].copy()
        for i in range(p if len(x) > p else 0):
            loop -= a[i] * x[p - 1 - i:len(x) - 1 - i]
        assert np.array_equal(got, loop)
    x = rng.standard_normal((3001, 6))
    a = rng.uniform(-0.4, 0.4, 7)
    for view in (np.asfortranarray(x), x[:, ::2], x[::-1]):
        loop = view[7:].copy()
        for i in range(7):
            loop -= a[i] * view[6 - i:len(view) - 1 - i]
        assert np.array_equal(_ar_filter(view, a), loop)
