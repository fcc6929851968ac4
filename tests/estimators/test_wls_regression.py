"""Weighted / generalised LS and the continuous criteria (Wrocław 2.4–2.5, 2.10–2.11; Johansson 5.7)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import EstimationError
from pipeline.estimators import ls, regression, wls
from tests.estimators.helpers import frac
from tests.seedcases import case

QUAD = 1e-10  # case tolerance 'exact (symbolic or quadrature 1e-10)'


def test_wro_ex2_5_weighted_continuous_approx():
    c = case("wro_ex2_5_weighted_continuous_approx")
    # F(u) = u² (misprint 9: printed θu²), Φ = θu, weight g(u) = 2u on [0, 1]
    est = wls.continuous_fit(lambda u: u ** 2, [lambda u: u], lambda u: 2 * u, (0.0, 1.0))
    assert abs(est.theta[0] - float(frac(c["expected"]["theta_star"]))) < QUAD
    uni = wls.continuous_fit(lambda u: u ** 2, [lambda u: u], None, (0.0, 1.0))
    assert abs(uni.theta[0] - 0.75) < QUAD  # recomputed: uniform weight gives 3/4


def test_wro_exer2_4_2_5_weight_figures():
    """Weights only in figures: the case gives the unweighted references 3/4 and (1, −1/6)."""
    case("wro_exer2_4_2_5_weight_figures")
    est = wls.continuous_fit(lambda u: u ** 2, [lambda u: u], None, (0.0, 1.0))
    assert abs(est.theta[0] - 0.75) < QUAD
    est = wls.continuous_fit(lambda u: u ** 2, [lambda u: u, lambda u: 1.0], None, (0.0, 1.0))
    np.testing.assert_allclose(est.theta, [1.0, -1.0 / 6.0], atol=QUAD)


def test_wro_ex2_10_regression_type1():
    c = case("wro_ex2_10_regression_type1")
    pdf, yb = (lambda u, y: y / u ** 2), (lambda u: (0.0, u))
    for u in (0.3, 1.0, 1.7):
        assert abs(regression.marginal_u(pdf, yb, u) - float(frac(c["expected"]["f_u"]))) < QUAD
        assert abs(regression.type1(pdf, yb, u) - 2.0 / 3.0 * u) < QUAD
        for y in (0.1 * u, 0.6 * u):  # f(y|u) = 2y/u²
            assert abs(pdf(u, y) / regression.marginal_u(pdf, yb, u) - 2 * y / u ** 2) < QUAD
    assert abs(regression.total_mass(pdf, (0.0, 2.0), yb) - 1.0) < QUAD


def test_wro_ex2_11_regression_type2():
    c = case("wro_ex2_11_regression_type2")
    exp = c["expected"]
    pdf, yb = (lambda u, y: y / u ** 3), (lambda u: (0.0, u ** 2))
    for u in (0.5, 1.5):
        assert abs(regression.marginal_u(pdf, yb, u) - u / 2) < QUAD
        assert abs(regression.type1(pdf, yb, u) - 2.0 / 3.0 * u ** 2) < QUAD
    est = regression.type2(pdf, (0.0, 2.0), yb, [lambda u: u, lambda u: 1.0])
    assert abs(est.theta[0] - float(frac(exp["th1"]))) < QUAD
    assert abs(est.theta[1] - float(frac(exp["th0"]))) < QUAD
    g, b = est.extra["gram"], est.extra["rhs"]
    # (2.155): θ0 = 4/3 − (4/3)θ1 is the θ0 normal equation: E u = 4/3, E Φ* = 4/3
    np.testing.assert_allclose([g[1, 0], g[1, 1], b[1]], [4 / 3, 1.0, 4 / 3], atol=QUAD)
    # (2.157): θ1 = 16/15 − (2/3)θ0, i.e. the θ1 normal equation divided by E u² = 2
    np.testing.assert_allclose([b[0] / g[0, 0], g[0, 1] / g[0, 0]], [16 / 15, 2 / 3], atol=QUAD)


def test_wro_exer2_9_regression_type1():
    case("wro_exer2_9_regression_type1")
    pdf, yb = (lambda u, y: 1.0), (lambda u: (u ** 2, u ** 2 + 1))
    # misprint 14: the printed density 1 integrates to 2 on its support (should be 1/2) ...
    assert abs(regression.total_mass(pdf, (0.0, 2.0), yb) - 2.0) < QUAD
    # ... which does not change the conditional mean ȳ = u² + 1/2
    for u in (0.2, 1.0, 1.9):
        assert abs(regression.type1(pdf, yb, u) - (u ** 2 + 0.5)) < QUAD
        assert abs(regression.type1(lambda uu, y: 0.5, yb, u) - (u ** 2 + 0.5)) < QUAD


def test_wro_exer2_10_regression_type2():
    c = case("wro_exer2_10_regression_type2")
    exp = c["expected"]
    pdf, yb = (lambda u, y: 2.0), (lambda u: (1 - u, 1.0))
    for u in (0.25, 0.8):
        assert abs(regression.marginal_u(pdf, yb, u) - 2 * u) < QUAD
        assert abs(regression.type1(pdf, yb, u) - (1 - u / 2)) < QUAD
    est = regression.type2(pdf, (0.0, 1.0), yb, [lambda u: u, lambda u: 1.0])
    np.testing.assert_allclose(est.theta, [float(frac(exp["th1"])), float(frac(exp["th0"]))], atol=QUAD)


def test_joh_5_7_markov_vs_ls():
    rng = np.random.default_rng(57)
    n = 30
    phi = np.column_stack([np.ones(n), rng.normal(size=n)])
    a = rng.normal(size=(n, n))
    r = a @ a.T / n + 0.1 * np.eye(n)  # R = Rᵀ > 0
    y = phi @ np.array([1.0, 2.0]) + np.linalg.cholesky(r) @ rng.normal(size=n)
    gls = wls.fit(phi, y, noise_cov=r)
    np.testing.assert_allclose(gls.cov, np.linalg.inv(phi.T @ np.linalg.solve(r, phi)), rtol=1e-10)
    g = np.linalg.inv(phi.T @ phi)
    cov_ls = g @ phi.T @ r @ phi @ g
    assert np.min(np.linalg.eigvalsh(cov_ls - gls.cov)) >= -1e-10  # (5.77): difference PSD
    ols = ls.fit(phi, y)
    assert np.sum(gls.residuals ** 2) >= np.sum(ols.residuals ** 2)  # larger (unweighted) residual
    ri = np.linalg.inv(r)
    assert ols.residuals @ ri @ ols.residuals >= gls.residuals @ ri @ gls.residuals  # (5.75)


def test_wls_known_weights_and_variance_model_match_whitened_ls():
    rng = np.random.default_rng(7)
    n = 200
    u = rng.uniform(0.5, 3.0, n)
    phi = np.column_stack([np.ones(n), u])
    sd = 0.2 * u
    y = phi @ np.array([1.0, -0.5]) + sd * rng.normal(size=n)
    a = wls.fit(phi, y, weights=1 / sd ** 2)
    b = wls.fit(phi, y, variance_model=lambda ph: (0.2 * ph[:, 1]) ** 2)
    ref = np.linalg.lstsq(phi / sd[:, None], y / sd, rcond=None)[0]
    np.testing.assert_allclose(a.theta, ref, atol=1e-12)
    np.testing.assert_allclose(b.theta, ref, atol=1e-12)
    # absolute variances from the model: Cov = (ΦᵀWΦ)⁻¹ without rescaling
    np.testing.assert_allclose(b.cov, np.linalg.inv(phi.T @ (phi / sd[:, None] ** 2)), rtol=1e-10)


def test_feasible_gls_recovers_variance_model_and_beats_ls():
    rng = np.random.default_rng(11)
    n, reps = 300, 120
    u = rng.uniform(0.2, 4.0, n)
    phi = np.column_stack([np.ones(n), u])
    z = np.column_stack([np.ones(n), np.log(u)])  # log σ² = γ0 + γ1 log u, true γ1 = 2
    sd = 0.1 * u
    th_ls, th_fg, gam = [], [], []
    for _ in range(reps):
        y = phi @ np.array([1.0, 0.5]) + sd * rng.normal(size=n)
        th_ls.append(ls.fit(phi, y).theta[1])
        est = wls.fit(phi, y, fgls=True, variance_regressors=z, n_iter=3)
        th_fg.append(est.theta[1])
        gam.append(est.extra["variance_params"][1])
    assert abs(np.mean(gam) - 2.0) < 0.1
    assert np.var(th_fg) < 0.7 * np.var(th_ls)


@pytest.mark.parametrize("bad, text", [([1.0, 0.0, 2.0, 1.0], "zero or negative"),
                                       ([1.0, -1.0, 2.0, 1.0], "zero or negative")])
def test_wls_rejects_non_positive_weights(bad, text):
    phi = np.column_stack([np.ones(4), np.arange(4.0)])
    with pytest.raises(EstimationError, match=f"weights must be strictly positive.*{text}.*index 1"):
        wls.fit(phi, np.arange(4.0), weights=bad)


def test_wls_rejects_indefinite_noise_covariance():
    phi = np.column_stack([np.ones(3), np.arange(3.0)])
    with pytest.raises(EstimationError, match="not positive definite"):
        wls.fit(phi, np.arange(3.0), noise_cov=-np.eye(3))
