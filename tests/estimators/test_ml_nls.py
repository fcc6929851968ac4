"""Maximum likelihood with several noise densities and nonlinear LS (Wrocław 2.7–2.9, Exercises 2.7–2.8;
Johansson 5.12, 6.4, 6.5, 6.10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, ls, ml, nls
from tests.estimators.helpers import EXACT, frac
from tests.seedcases import case


def test_wro_ex2_7_ml_gaussian_offset():
    c = case("wro_ex2_7_ml_gaussian_offset")
    assert "u = [1,2,3], w = [1.6,2.4,3.7], m_z = 0.5" in c["data"]
    est = ESTIMATORS["ml"]([1.0, 2.0, 3.0], [1.6, 2.4, 3.7], density="gaussian", loc=0.5, sigma=0.3)
    assert abs(est.theta[0] - float(frac(c["expected"]["instance_theta"]))) < EXACT
    np.testing.assert_allclose(est.cov, [[0.09 / 14]], rtol=1e-12)  # σ²(Σu²)⁻¹ with σ known


def test_wro_exer2_7_ml_gaussian_mean():
    case("wro_exer2_7_ml_gaussian_mean")  # expected: θ = mean(v) − m_z
    v = np.array([1.2, 0.8, 1.0, 1.4])
    est = ml.fit(np.ones(4), v, density="gaussian", loc=0.3)
    assert abs(est.theta[0] - (v.mean() - 0.3)) < EXACT
    assert abs(est.extra["sigma2"] - np.mean((v - v.mean()) ** 2)) < EXACT  # ML variance SSE/N


def test_wro_ex2_9_ml_triangular_noise():
    c = case("wro_ex2_9_ml_triangular_noise")
    exp = c["expected"]
    # f_z(z) = 1 + z/2 on [−2, 0]: triangular with low −2, mode 0, high 0
    dens = dict(low=-2.0, mode=0.0, high=0.0)
    total = integrate.quad(lambda z: math.exp(ml.triangular_logpdf(z, **dens)[0]), -2, 0)[0]
    mean = integrate.quad(lambda z: z * math.exp(ml.triangular_logpdf(z, **dens)[0]), -2, 0)[0]
    assert abs(total - 1) < 1e-10 and abs(mean - float(frac(exp["m_z"]))) < 1e-10
    est = ml.fit(np.ones(2), c["data"]["v"], density="triangular", **dens)
    assert abs(est.theta[0] - exp["theta_ML"]) < EXACT
    assert abs(est.extra["likelihood"] - exp["L_max"]) < EXACT
    np.testing.assert_allclose(est.extra["feasible_box"][0], exp["support"], atol=EXACT)
    assert est.extra["support_active"] and est.cov is None
    v = np.array(c["data"]["v"], float)
    for th in (2.0, 2.5, 3.0, 2.9):  # L(θ) = θ²/4 − 7θ/4 + 3 on [2, 3]
        lik = math.exp(np.sum(ml.triangular_logpdf(v - th, **dens)))
        assert abs(lik - (th ** 2 / 4 - 7 * th / 4 + 3)) < 1e-12
    assert exp["unconstrained_stationary"] > exp["support"][1]  # the stationary point 3.5 is infeasible


def test_wro_exer2_8_ml_uniform_noise():
    c = case("wro_exer2_8_ml_uniform_noise")
    assert "v = [0.3,0.9,0.5]" in c["data"]
    est = ml.fit(np.ones(3), [0.3, 0.9, 0.5], density="uniform", low=0.0, high=1.0)
    np.testing.assert_allclose(est.extra["feasible_box"][0], c["expected"]["instance"], atol=EXACT)
    assert not est.extra["unique"] and est.cov is None
    assert abs(est.loglik - 0.0) < EXACT  # likelihood 1 on the feasible set


def test_ml_uniform_polytope_for_two_parameters():
    u = np.array([0.0, 1.0, 2.0, 3.0])
    y = 1.0 + 0.5 * u + np.array([0.1, 0.9, 0.4, 0.6])
    est = ml.fit(np.column_stack([np.ones(4), u]), y, density="uniform", low=0.0, high=1.0)
    e = y - np.column_stack([np.ones(4), u]) @ est.theta
    assert np.all((e >= -1e-9) & (e <= 1 + 1e-9))
    lo, hi = est.extra["feasible_box"][0]
    assert lo <= 1.0 <= hi  # the true intercept is feasible


@pytest.mark.parametrize("density, opts", [("uniform", dict(low=0.0, high=1.0)),
                                           ("triangular", dict(low=-1.0, mode=0.0, high=0.0))])
def test_ml_support_excluding_data_raises(density, opts):
    with pytest.raises(EstimationError, match=rf"support of the {density} noise density .* excludes the data"):
        ml.fit(np.ones(3), [0.0, 5.0, 1.0], density=density, **opts)


def test_ml_exponential_support_excludes_data_raises():
    # y = θu + v with v >= 0 and u of both signs at the same level: no θ keeps all residuals >= 0
    u = np.array([1.0, -1.0, 1.0, -1.0])
    y = np.array([-1.0, -1.0, 0.0, 0.0])
    with pytest.raises(EstimationError, match=r"support of the exponential noise density \[0, inf\] excludes"):
        ml.fit(u, y, density="exponential")


def test_joh_6_4_ml_rayleigh_noise():
    case("joh_6_4_ml_rayleigh_noise")
    rng = np.random.default_rng(64)
    n, sigma = 2000, 0.5
    u = rng.normal(size=n)
    phi = np.column_stack([np.ones(n), u])
    theta = np.array([0.2, 1.5])
    y = phi @ theta + rng.rayleigh(sigma, n)
    est = ml.fit(phi, y, density="rayleigh")
    e = est.residuals
    assert np.all(e > 0)
    assert abs(est.extra["sigma2"] - e @ e / (2 * n)) < 1e-14  # σ̂² = εᵀε/(2N)
    assert abs(est.extra["sigma2"] / sigma ** 2 - 1) < 0.1
    assert np.all(np.abs(est.theta - theta) < 4 * est.stderr)

    def loglik(th):  # corrected (misprint 29): +Σ log ε − 2N log σ − Σε²/(2σ²), σ² profiled
        r = y - phi @ th
        s2 = r @ r / (2 * n)
        return np.sum(np.log(r)) - n * np.log(s2) - r @ r / (2 * s2) if np.all(r > 0) else -np.inf

    best = loglik(est.theta)
    for d in ([1e-3, 0], [-1e-3, 0], [0, 1e-3], [0, -1e-3]):
        assert loglik(est.theta + np.array(d)) < best


def test_joh_6_5_ml_scaled_input_noise():
    c = case("joh_6_5_ml_scaled_input_noise")
    tol = 0.06  # case: |θ_ML − 1| < 0.06 (3 sd)
    n, sigma = 1000, 1.0
    ml_est, ls_est = [], []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        u, w = rng.normal(size=n), rng.normal(0, sigma, n)
        y = 1.0 * (u + w)  # y_{k+1} = a(u_k + w_k), a = 1
        est = ml.fit(u, y, density="gaussian", sigma_fn=lambda th: abs(th[0]) * sigma)
        th = est.theta[0]
        # the maximised criterion is −N/2 log(θ²σ²) − Σ(y − uθ)²/(2θ²σ²) (− N/2 log 2π)
        ll = -n / 2 * math.log(th ** 2 * sigma ** 2) - np.sum((y - u * th) ** 2) / (2 * th ** 2 * sigma ** 2) \
            - n / 2 * math.log(2 * math.pi)
        assert abs(est.loglik - ll) < 1e-8
        assert est.loglik >= -n / 2 * math.log(2 * math.pi) - np.sum((y - u) ** 2) / 2  # >= value at θ = 1
        ml_est.append(th)
        ls_est.append(ls.fit(u, y).theta[0])
        if seed == 0:
            assert abs(th - 1.0) < tol
    assert abs(c["expected"]["theta_ML"] - 1.0) < tol  # the document's 0.987 is inside the band
    ml_est, ls_est = np.array(ml_est), np.array(ls_est)
    assert np.all(np.abs(ml_est - 1.0) < tol)
    assert np.std(ml_est) < np.std(ls_est)  # re-run: ML sd 0.019 vs LS sd 0.031


def test_joh_6_10_ml_exponential_noise():
    case("joh_6_10_ml_exponential_noise")
    rng = np.random.default_rng(610)
    n, a, b, mu = 500, -0.5, 1.0, 2.0
    u = rng.normal(size=n + 1)
    v = rng.exponential(1 / mu, n + 1)
    y = np.zeros(n + 1)
    for k in range(1, n + 1):
        y[k] = -a * y[k - 1] + b * u[k - 1] + v[k]
    phi = np.column_stack([-y[:-1], u[:-1]])
    est = ml.fit(phi, y[1:], density="exponential")
    e = est.residuals
    s = e.sum()
    assert np.all(e >= 0)  # support constraint ε_k >= 0 honoured
    assert abs(est.extra["mu"] - n / s) < 1e-12
    assert abs(est.loglik - (n * math.log(n) - n - n * math.log(s))) < 1e-9  # corrected (misprint 31)
    assert abs(est.extra["mu"] / mu - 1) < 0.15
    np.testing.assert_allclose(est.theta, [a, b], atol=0.02)  # super-consistent (rate 1/N)
    # any feasible perturbation has a smaller Σε-profile likelihood
    for d in rng.normal(0, 1e-3, (20, 2)):
        r = y[1:] - phi @ (est.theta + d)
        if np.all(r >= 0):
            assert n * math.log(n) - n - n * math.log(r.sum()) <= est.loglik + 1e-12
    assert est.cov is None and "non-regular" in est.extra["cov_note"]


def test_ml_student_t_beats_ls_under_student_t_noise():
    rng = np.random.default_rng(3)
    n, reps = 200, 40
    u = rng.uniform(-1, 1, n)
    phi = np.column_stack([np.ones(n), u])
    slopes_ml, slopes_ls, nus = [], [], []
    for _ in range(reps):
        y = phi @ np.array([1.0, 2.0]) + 0.5 * rng.standard_t(3, n)
        est = ml.fit(phi, y, density="student_t")
        slopes_ml.append(est.theta[1])
        nus.append(est.extra["nu"])
        slopes_ls.append(ls.fit(phi, y).theta[1])
        assert est.cov is not None and est.n_params == 4
    assert np.mean((np.array(slopes_ml) - 2) ** 2) < 0.8 * np.mean((np.array(slopes_ls) - 2) ** 2)
    assert 2.0 < np.median(nus) < 5.0


def test_ml_laplace_is_median_and_gaussian_cov_matches_observed_information():
    y = np.array([3.0, -1.0, 7.0, 2.0, 10.0])
    est = ml.fit(np.ones(5), y, density="laplace")
    assert abs(est.theta[0] - 3.0) < 1e-9 and abs(est.extra["scale"] - np.mean(np.abs(y - 3.0))) < 1e-9
    rng = np.random.default_rng(5)
    phi = np.column_stack([np.ones(30), rng.normal(size=30)])
    yy = phi @ [1.0, 2.0] + rng.normal(0, 0.4, 30)
    g = ml.fit(phi, yy, density="gaussian")
    from pipeline.estimators.base import numerical_hessian

    s2 = g.extra["sigma2"]
    nll = lambda th: 0.5 * np.sum((yy - phi @ th) ** 2) / s2  # noqa: E731
    np.testing.assert_allclose(g.cov, np.linalg.inv(numerical_hessian(nll, g.theta)), rtol=1e-5)


def test_joh_5_12a_exp_nls():
    c = case("joh_5_12a_exp_nls")
    d, rec = c["data"], c["recomputed"]
    t, h = np.array(d["t"], float), np.array(d["h"], float)
    est = nls.fit(t, h, model=lambda tt, th: th[0] * np.exp(-tt / th[1]), theta0=[3.0, 0.5])
    # corrected minimiser (misprint 28), not the printed K = 3.359, τ = 0.588
    assert abs(est.theta[0] / 3.35821 - 1) < 1e-4 and abs(est.theta[1] / 0.582935 - 1) < 1e-4
    assert abs(est.extra["cost"] - rec["J_min"]) < 1e-8
    assert abs(est.theta[1] / c["expected"]["tau"] - 1) > 1e-3  # the document's τ fails at 1e-3
    j_doc = 0.5 * np.sum((h - 3.359 * np.exp(-t / 0.588)) ** 2)
    assert abs(j_doc - rec["J_at_doc_point"]) < 1e-7 and j_doc > est.extra["cost"]


def test_joh_5_12b_exp_relative_error():
    c = case("joh_5_12b_exp_relative_error")
    assert c["data"] == "as 5.12a"
    d, exp = case("joh_5_12a_exp_nls")["data"], c["expected"]
    t, h = np.array(d["t"], float), np.array(d["h"], float)

    def resid(th):
        k, tau = th
        with np.errstate(divide="ignore", invalid="ignore"):
            r_tau = np.where(t == 0, 1.0, (tau - t / np.log(k / h)) / tau)  # t = 0 term is the constant 1
        r_k = (k - h / np.exp(-t / tau)) / k
        return np.concatenate([r_tau, r_k])

    est = nls.fit_residuals(resid, [3.0, 0.6])
    assert abs(est.theta[0] / exp["K"] - 1) < 1e-4 and abs(est.theta[1] / exp["tau"] - 1) < 1e-4
    assert abs(est.extra["cost"] - c["recomputed"]["J"]) < 1e-5
