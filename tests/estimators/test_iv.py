"""Coloured-noise bias of LS, instrumental variables, closed loop and Yule–Walker
(Johansson 5.11, 6.1, 6.3, 6.6–6.8, 8.8)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, iv, ls


def _armax(n, a, b, c, s_u, s_w, seed):
    """y_{k+1} = −a y_k + b u_k + w_{k+1} + c w_k, y_0 = 0 (seeded)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(0, s_u, n + 1)
    w = rng.normal(0, s_w, n + 1)
    y = lfilter([0.0, b], [1.0, a], u) + lfilter([1.0, c], [1.0, a], w)
    return u, y


def _rows(u, y):
    """target y_{k+1}, regressors [−y_k, u_k]."""
    return np.column_stack([-y[:-1], u[:-1]]), y[1:]


def test_joh_5_11_armax_ls_bias():
    from tests.seedcases import case

    c = case("joh_5_11_armax_ls_bias")
    assert "a = -0.5, b = 1, c = 0.5, sigma = 1" in c["data"]
    a, b, cc = -0.5, 1.0, 0.5
    u, y = _armax(400_000, a, b, cc, 1.0, 1.0, seed=511)
    phi, tgt = _rows(u, y)
    est = ls.fit(phi, tgt)
    ey2 = (b ** 2 - 2 * a * cc + 1 + cc ** 2) / (1 - a ** 2)
    assert abs(ey2 - 3.66667) < 1e-5
    assert abs(np.mean(y ** 2) / ey2 - 1) < 0.02
    a_inf = a - cc / ey2
    assert abs(a_inf - (-0.636364)) < 1e-6
    assert abs(est.theta[0] - a_inf) < 0.01 and abs(est.theta[1] - b) < 0.01  # case tolerance
    # LS has a lower prediction-error variance than the true parameters: 1.1818 < 1.25
    pe_ls = np.mean(est.residuals ** 2)
    pe_true = np.mean((tgt - phi @ np.array([a, b])) ** 2)
    assert abs(pe_ls - 1.181818) < 0.01 and abs(pe_true - 1.25) < 0.01 and pe_ls < pe_true
    # IV with delayed inputs z_k = [u_{k−1}, u_k] removes the bias (Johansson 6.6–6.8)
    est_iv = iv.fit(phi, tgt, inputs=u[:-1], delays=[1, 0], ma_lags=1)
    assert abs(est_iv.theta[0] - a) < 0.01 and abs(est_iv.theta[1] - b) < 0.01
    assert np.all(np.abs(est_iv.theta - [a, b]) < 4 * est_iv.stderr)
    assert abs(est.theta[0] - a) > 10 * est_iv.stderr[0]  # LS is clearly biased at this N


def test_joh_6_1_arx_colored_noise_general():
    a, b, cc, s_u, s_w = -0.5, 1.0, 0.5, 2.0, 1.0  # σ_u ≠ σ_w
    u, y = _armax(200_000, a, b, cc, s_u, s_w, seed=61)
    phi, tgt = _rows(u, y)
    est = ls.fit(phi, tgt)
    ey2 = (b ** 2 * s_u ** 2 + (1 + cc ** 2 - 2 * a * cc) * s_w ** 2) / (1 - a ** 2)
    a_inf = a - cc * s_w ** 2 / ey2
    assert abs(est.theta[0] - a_inf) < 0.01 and abs(est.theta[1] - b) < 0.01
    pe = (1 + cc ** 2) * s_w ** 2 - cc ** 2 * s_w ** 4 / ey2
    assert pe < (1 + cc ** 2) * s_w ** 2
    assert abs(np.mean(est.residuals ** 2) - pe) < 0.01
    est_iv = iv.fit(phi, tgt, inputs=u[:-1], delays=[1, 0], ma_lags=1)
    assert np.all(np.abs(est_iv.theta - [a, b]) < 4 * est_iv.stderr)


def test_joh_6_3_fir_consistency():
    rng = np.random.default_rng(63)
    n, b = 100_000, np.array([1.0, 0.5])
    v = lfilter([1.0], [1.0, -0.9], rng.normal(0, 0.5, n))  # AR(1) 0.9 coloured noise
    u = rng.normal(size=n)
    y = b[0] * u + b[1] * np.concatenate([[0.0], u[:-1]]) + v
    phi = np.column_stack([u[1:], u[:-1]])
    est = ls.fit(phi, y[1:])
    assert np.all(np.abs(est.theta - b) < 4 * est.stderr)  # consistent: E Φᵀv = 0
    # with output feedback u_k = r_k − K y_{k−1}, u is correlated with v and LS is inconsistent
    r = rng.normal(size=n)
    uf, yf = np.zeros(n), np.zeros(n)
    for k in range(1, n):
        uf[k] = r[k] - 0.5 * yf[k - 1]
        yf[k] = b[0] * uf[k] + b[1] * uf[k - 1] + v[k]
    phi_f = np.column_stack([uf[2:], uf[1:-1]])
    est_f = ls.fit(phi_f, yf[2:])
    assert np.max(np.abs(est_f.theta - b) / est_f.stderr) > 4
    # the reference r is a valid instrument
    est_r = iv.fit(phi_f, yf[2:], instruments=np.column_stack([r[2:], r[1:-1]]))
    assert np.all(np.abs(est_r.theta - b) < 4 * est_r.stderr)


def test_joh_6_6_8_instrumental_variables():
    """Cov θ̂_IV = P Σ Pᵀ (6.66) with banded Σ (MA(1) equation error) predicts the Monte-Carlo spread."""
    a, b, cc = -0.5, 1.0, 0.5
    ests, covs = [], []
    for seed in range(300):
        u, y = _armax(1000, a, b, cc, 1.0, 1.0, seed=10_000 + seed)
        phi, tgt = _rows(u, y)
        e = ESTIMATORS["iv"](phi, tgt, inputs=u[:-1], delays=[1, 0], ma_lags=1)
        ests.append(e.theta)
        covs.append(e.cov)
    ests = np.array(ests)
    assert np.all(np.abs(ests.mean(axis=0) - [a, b]) < 4 * ests.std(axis=0) / np.sqrt(len(ests)))
    ratio = np.mean(covs, axis=0).diagonal() / ests.var(axis=0, ddof=1)
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio  # 300 reps: sd of a variance ratio ≈ 8 %
    # more instruments than parameters (generalised IV) is also consistent
    u, y = _armax(50_000, a, b, cc, 1.0, 1.0, seed=68)
    phi, tgt = _rows(u, y)
    g = iv.fit(phi, tgt, inputs=u[:-1], delays=[0, 1, 2], ma_lags=1)
    assert np.all(np.abs(g.theta - [a, b]) < 4 * g.stderr)


def test_joh_8_8_closed_loop_bias_yule_walker():
    from tests.seedcases import case

    c = case("joh_8_8_closed_loop_bias_yule_walker")
    exp = c["expected"]
    a, b, k_fb, cc, sigma = 0.5, 1.0, 0.3, 0.5, 1.0
    n = 400_000
    rng = np.random.default_rng(88)
    w = rng.normal(0, sigma, n + 1)
    y = np.zeros(n + 1)
    u = np.zeros(n + 1)
    alpha = a + b * k_fb
    # closed loop u_k = −K y_k, explicitly: y_{k+1} = −a y_k + b u_k + w_{k+1} + c w_k
    for k in range(n):
        u[k] = -k_fb * y[k]
        y[k + 1] = -a * y[k] + b * u[k] + w[k + 1] + cc * w[k]
    # a and b are not separable: [−y_k, u_k] are collinear
    with pytest.raises(EstimationError, match="singular regressors"):
        ls.fit(np.column_stack([-y[:-1], u[:-1]]), y[1:])
    est = ls.fit(-y[:-1], y[1:])  # LS for a + bK
    ls_limit = float(exp["LS_limit"].split("=")[-1])
    assert abs(est.theta[0] - ls_limit) < 0.01  # case tolerance
    ey2 = sigma ** 2 * (1 + cc ** 2 - 2 * cc * alpha) / (1 - alpha ** 2)
    assert abs(ey2 - 1.25) < 1e-12 and abs(alpha - cc * sigma ** 2 / ey2 - 0.4) < 1e-12
    yw = iv.yule_walker_arma11(y)
    np.testing.assert_allclose(yw["C"], exp["C"], atol=0.02)
    assert abs(yw["alpha"] - exp["YW"]["a+bK"]) < 0.02  # case tolerance
    assert abs(yw["c_sigma2"] - exp["YW"]["c_sigma2"]) < 0.02
    # Yule–Walker = IV with the delayed output y_{k−1} as instrument
    est_iv = iv.fit(-y[1:-1], y[2:], instruments=y[:-2])
    assert abs(est_iv.theta[0] - yw["alpha"]) < 1e-3


def test_iv_rejects_uncorrelated_instruments():
    phi = np.column_stack([np.ones(5), np.arange(5.0)])
    with pytest.raises(EstimationError, match="singular instrument cross-moment"):
        iv.fit(phi, np.arange(5.0), instruments=np.zeros((5, 2)))
