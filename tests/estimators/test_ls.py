"""Least squares, identifiability, exact determination (Wrocław Ch. 2; Johansson Ch. 5, 7, 11)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, ls
from tests.estimators.helpers import EXACT, frac
from tests.seedcases import case


def test_wro_ex2_1_mimo_exact_determination():
    c = case("wro_ex2_1_mimo_exact_determination")
    d, exp = c["data"], c["expected"]
    u = np.array([d["u1"], d["u2"]], dtype=float)  # columns = measurements n = 1..6
    y = np.array([d["y1"], d["y2"]], dtype=float)
    u14 = u[:, [0, 3]]
    np.testing.assert_array_equal(u14, np.array(exp["pair_1_4"]["U_N"], dtype=float))
    ok, det = ls.identifiability(u14)
    assert ok is exp["pair_1_4"]["identifiable"] and det == exp["pair_1_4"]["det"]
    with pytest.raises(EstimationError, match="not identifiable.*det"):
        ls.exact_determination(u14, y[:, [0, 3]])
    ok, det = ls.identifiability(u[:, [1, 4]])
    assert ok and abs(det - exp["pair_2_5"]["det"]) < EXACT
    theta = ls.exact_determination(u[:, [1, 4]], y[:, [1, 4]])
    np.testing.assert_allclose(theta, exp["Theta"], atol=EXACT)
    np.testing.assert_allclose(theta @ u[:, [0, 5]], exp["verify_n1_n6_Y"], atol=EXACT)
    # LS over all six measurements (one output at a time) gives the same Θ
    for row in range(2):
        est = ls.fit(u.T, y[row])
        np.testing.assert_allclose(est.theta, exp["Theta"][row], atol=1e-12)


def test_wro_ex2_2_quadratic_exact_determination():
    c = case("wro_ex2_2_quadratic_exact_determination")
    d, exp = c["data"], c["expected"]
    u = np.array(d["u"], dtype=float)
    fbar = np.vstack([np.ones_like(u), u, u ** 2])  # columns f̄(u_n)
    np.testing.assert_array_equal(fbar[:, :3], exp["fbar_U3"])
    ok, det = ls.identifiability(fbar[:, :3])
    assert ok and abs(det - exp["det"]) < 1e-9
    theta = ls.exact_determination(fbar[:, :3], np.array(d["y"][:3], dtype=float))[0]
    np.testing.assert_allclose(theta, exp["theta"], atol=EXACT)
    np.testing.assert_allclose(theta @ fbar[:, 3:], exp["verify_n4_6"], atol=1e-11)


def test_wro_exer2_1_mimo3():
    c = case("wro_exer2_1_mimo3")
    d, exp = c["data"], c["expected"]
    u = np.array([d["u1"], d["u2"], d["u3"]], dtype=float)
    y = np.array([d["y1"], d["y2"]], dtype=float)
    singular = []
    for tri in itertools.combinations(range(6), 3):
        ok, _ = ls.identifiability(u[:, tri])
        if not ok:
            singular.append([i + 1 for i in tri])
            continue
        theta = ls.exact_determination(u[:, tri], y[:, tri])
        np.testing.assert_allclose(theta, [exp["theta_row1"], exp["theta_row2"]], atol=1e-11)
    assert singular == exp["non_identifiable_triples_1based"]


def test_wro_exer2_2_quadratic_mimo():
    c = case("wro_exer2_2_quadratic_mimo")
    d, exp = c["data"], c["expected"]
    u1, u2 = np.array(d["u1"], float), np.array(d["u2"], float)
    phi = np.column_stack([np.ones(6), u1, u2 ** 2])  # corrected reading (misprint 13)
    for yk, row in (("y1", "theta_row1"), ("y2", "theta_row2")):
        est = ls.fit(phi, d[yk])
        np.testing.assert_allclose(est.theta, exp[row], atol=1e-12)
        assert np.max(np.abs(est.residuals)) < 1e-12  # all six rows fit exactly
    # the printed reading (1, u2, u1²) leaves residuals > 2 (note in the case)
    bad = ls.fit(np.column_stack([np.ones(6), u2, u1 ** 2]), d["y1"])
    assert np.max(np.abs(bad.residuals)) > 2


def test_wro_ex2_3_ls_scalar():
    c = case("wro_ex2_3_ls_scalar")
    d = c["data"]
    est = ls.fit(d["u"], d["y"])
    assert abs(est.theta[0] - c["expected"]["theta_star"]) < EXACT
    # Q(θ) = 13θ² − 26θ + 14 (with the corrected residual (−2 + 2θ)², misprint 7); Q(1) = 1 = SSE
    assert abs(est.extra["sse"] - 1.0) < EXACT
    u, y = np.array(d["u"], float), np.array(d["y"], float)
    for th in (-1.0, 0.5, 2.0):
        assert abs(np.sum((y - th * u) ** 2) - (13 * th ** 2 - 26 * th + 14)) < 1e-12


def test_wro_ex2_4_ls_affine_formula():
    c = case("wro_ex2_4_ls_affine_formula")
    exp = c["expected"]
    for (u, y), key in ((([-2, 0, 3], [-2, 1, 3]), "table2_5_affine"), (([-1, 1, 3], [-2, 1, 2]), "table2_6_affine")):
        assert f"{{u:{u}".replace(" ", "") in c["data"].replace(" ", "")
        est = ESTIMATORS["ls"](np.column_stack([u, np.ones(3)]), y)
        assert abs(est.theta[0] - float(frac(exp[key]["th1"]))) < EXACT
        assert abs(est.theta[1] - float(frac(exp[key]["th0"]))) < EXACT


def test_wro_exer2_3_ls_scalar():
    c = case("wro_exer2_3_ls_scalar")
    est = ls.fit(c["data"]["u"], c["data"]["y"])
    assert abs(est.theta[0] - float(frac(c["expected"]["theta"]))) < EXACT


def test_wro_ex2_6_ls_vector():
    c = case("wro_ex2_6_ls_vector")
    d2 = case("wro_ex2_2_quadratic_exact_determination")["data"]
    u = np.array(d2["u"], float)
    est = ls.fit(np.column_stack([np.ones_like(u), u, u ** 2]), d2["y"])
    np.testing.assert_allclose(est.theta, c["expected"]["table2_2_theta"], atol=1e-12)
    # noisy data: QR solution equals the normal equations (Σφφᵀ)⁻¹Σwφ (corrected (2.81)) to 1e-12
    rng = np.random.default_rng(26)
    w = np.array(d2["y"], float) + rng.normal(0, 0.5, u.size)
    phi = np.column_stack([np.ones_like(u), u, u ** 2])
    ne = np.linalg.solve(sum(np.outer(f, f) for f in phi), sum(wn * f for wn, f in zip(w, phi)))
    np.testing.assert_allclose(ls.fit(phi, w).theta, ne, atol=1e-12)


def test_joh_5_2_min_norm_ls():
    c = case("joh_5_2_min_norm_ls")
    d, exp = c["data"], c["expected"]
    phi, y = np.array(d["Phi"], float), np.array(d["Y"], float)
    np.testing.assert_array_equal(phi.T @ phi, exp["PhiTPhi"])
    with pytest.raises(EstimationError, match=r"rank 2 < 3.*direction.*min_norm=True"):
        ls.fit(phi, y)
    est = ls.fit(phi, y, min_norm=True)
    exact = np.array([8 / 7, 25 / 14, 43 / 14])
    np.testing.assert_allclose(est.theta, exact, atol=1e-12)
    np.testing.assert_allclose(est.theta, exp["theta_hat"], atol=1e-4)
    assert abs(np.linalg.norm(est.theta) - exp["norm"]) < 1e-4
    psi1, psi0 = np.array([2.0, -3.0, 1.0]), np.array([1.0, 2.0, 3.0])
    lam = float(frac(exp["lambda_star"]))
    np.testing.assert_allclose(est.theta, psi0 + lam * psi1, atol=1e-12)
    assert abs(np.linalg.norm(psi0) - exp["true_norm"]) < 1e-4
    null = est.extra["null_space"]
    assert null.shape == (3, 1)
    np.testing.assert_allclose(np.abs(null[:, 0]), np.abs(psi1) / np.linalg.norm(psi1), atol=1e-12)
    np.testing.assert_allclose(est.extra["pinv_gram"], exp["pinv_PhiTPhi"], atol=1e-4)
    assert est.extra["rank"] == 2 and est.cov is None  # N − rank = 0: no variance estimate


def test_joh_5_6_residual_expectation():
    rng = np.random.default_rng(56)
    n, p, r = 20, 3, 2.0
    phi = rng.normal(size=(n, p))
    theta = np.array([1.0, -2.0, 0.5])
    v = np.array([0.5 * np.sum(ls.fit(phi, phi @ theta + rng.normal(0, np.sqrt(r), n)).residuals ** 2)
                  for _ in range(1000)])
    se = v.std(ddof=1) / np.sqrt(v.size)
    assert abs(v.mean() - 0.5 * (n - p) * r) < 3 * se


def test_joh_5_8_augmented_inverse():
    rng = np.random.default_rng(58)
    phi = rng.normal(size=(6, 2))
    inv = ls.augmented_inverse(phi)
    m = np.block([[np.eye(6), phi], [phi.T, np.zeros((2, 2))]])
    np.testing.assert_allclose(m @ inv, np.eye(8), atol=1e-12)
    # cov(ε, θ̃) = (I − P) σ² Φ(ΦᵀΦ)⁻¹ = 0 for white noise
    assert np.max(np.abs(inv[:6, :6] @ inv[:6, 6:])) < 1e-10
    # the augmented solve reproduces the LS residuals and estimate
    y = rng.normal(size=6)
    sol = inv @ np.concatenate([y, np.zeros(2)])
    est = ls.fit(phi, y)
    np.testing.assert_allclose(sol[:6], est.residuals, atol=1e-12)
    np.testing.assert_allclose(sol[6:], est.theta, atol=1e-12)


def test_joh_5_12c_exp_loglinear():
    c = case("joh_5_12c_exp_loglinear")
    d, exp = c["data"], c["expected"]
    t = np.array(d["t"], float)
    est = ls.fit(np.column_stack([np.ones_like(t), -t]), d["log_h"])
    np.testing.assert_allclose(est.theta, exp["theta"], atol=1e-4)
    # from the unrounded log h of the 5.12a data: the re-run's values
    h = np.array(case("joh_5_12a_exp_nls")["data"]["h"], float)
    exact = ls.fit(np.column_stack([np.ones_like(t), -t]), np.log(h))
    np.testing.assert_allclose(exact.theta, c["recomputed"]["theta"], atol=1e-6)
    assert abs(np.exp(est.theta[0]) / exp["K"] - 1) < 1e-4
    assert abs((1 / est.theta[1]) / exp["tau"] - 1) < 1e-4


def test_joh_7_4_tank_drain():
    c = case("joh_7_4_tank_drain")
    d = c["data"]
    t, h = np.array(d["t"], float), np.array(d["h"], float)
    y = 1.0 / (1.0 - np.sqrt(h / d["h0"]))
    np.testing.assert_allclose(y[[0, 2, 3]], np.array(d["y_doc"])[[0, 2, 3]], atol=0.005)  # printed to 2 decimals
    assert abs(y[1] - 7.155) < 1e-3  # y(2) = 7.155, printed 7.16 (misprint 34)
    est = ls.fit(1.0 / t, y)
    assert abs(est.theta[0] - 16.74) < 0.05 and abs(est.theta[0] - c["expected"]["T_hat"]) < 0.05
    # the other linearisation 1 − sqrt(h/h0) = t/T weights the samples differently: T = 15.09
    alt = ls.fit(t, 1.0 - np.sqrt(h / d["h0"]))
    assert abs(1.0 / alt.theta[0] - c["recomputed"]["alt_regression_1-sqrt(h/h0)=t/T"]) < 0.01


def test_joh_7_2_pharmacokinetic_compartments():
    """Data are not in the document: internal consistency only (case tolerance). Log-linear LS with
    Y = log x1 − log m, Φ = [−1, −t] recovers (log V, r1); V = exp(3.2754) = 26.45 (not 56.64)."""
    c = case("joh_7_2_pharmacokinetic_compartments")
    exp = c["expected"]
    t = np.linspace(0.5, 12, 12)
    m = 100.0
    x1 = m / np.exp(exp["logV"]) * np.exp(-exp["r1_loglin"] * t)
    est = ls.fit(np.column_stack([-np.ones_like(t), -t]), np.log(x1) - np.log(m))
    np.testing.assert_allclose(est.theta, [exp["logV"], exp["r1_loglin"]], atol=1e-12)
    assert abs(np.exp(est.theta[0]) - 26.45) < 0.01 and abs(np.exp(est.theta[0]) - exp["V_l"]) > 30
    # NLS J3 with the sign-corrected model K(e^{-r1 t} − e^{-r2 t}) (the printed form is negative)
    from pipeline.estimators import nls

    k, r1, r2 = exp["NLS"]["K"], exp["NLS"]["r1"], exp["NLS"]["r2"]
    assert np.all(k * (np.exp(-r2 * t) - np.exp(-r1 * t)) < 0)
    data = k * (np.exp(-r1 * t) - np.exp(-r2 * t))
    fit = nls.fit(t, data, model=lambda tt, th: th[0] * (np.exp(-th[1] * tt) - np.exp(-th[2] * tt)),
                  theta0=[0.003, 0.2, 2.0])
    np.testing.assert_allclose(fit.theta, [k, r1, r2], rtol=1e-6)
    assert abs(fit.theta[2] / fit.theta[1] - 9.56) < 0.01


def test_joh_11_1_3_ls_energy_identity():
    rng = np.random.default_rng(113)
    n, p, sigma = 50, 3, 0.7
    phi = rng.normal(size=(n, p))
    theta = np.array([0.3, -1.0, 2.0])
    vs, s2 = [], []
    for _ in range(1000):
        v = rng.normal(0, sigma, n)
        est = ls.fit(phi, phi @ theta + v)
        big_v = 0.5 * est.residuals @ est.residuals
        tt = est.theta - theta
        q = 0.5 * tt @ phi.T @ phi @ tt
        assert abs(big_v + q - 0.5 * v @ v) < 1e-10  # corrected identity V + Q = vᵀv/2 (misprint 41)
        vs.append(big_v)
        s2.append(est.extra["sigma2"])
    vs, s2 = np.array(vs), np.array(s2)
    assert abs(vs.mean() - 0.5 * (n - p) * sigma ** 2) < 3 * vs.std(ddof=1) / np.sqrt(vs.size)
    np.testing.assert_allclose(s2, 2 * vs / (n - p), rtol=1e-12)  # σ̂² = 2V/(N − p)
    assert abs(s2.mean() - sigma ** 2) < 3 * s2.std(ddof=1) / np.sqrt(s2.size)
    doc = vs / (n - p)  # the document's V/(N − p) is biased by a factor 1/2
    assert abs(doc.mean() - sigma ** 2) > 10 * doc.std(ddof=1) / np.sqrt(doc.size)


def test_ls_covariance_matches_monte_carlo_spread_and_coverage():
    rng = np.random.default_rng(2024)
    n, reps = 40, 1500
    phi = np.column_stack([np.ones(n), rng.uniform(-1, 1, n)])
    theta = np.array([0.5, -1.5])
    ests, covs, cover = [], [], []
    for _ in range(reps):
        est = ls.fit(phi, phi @ theta + rng.normal(0, 0.3, n))
        ests.append(est.theta)
        covs.append(est.cov)
        ci = est.conf_int(0.95)
        cover.append((ci[:, 0] <= theta) & (theta <= ci[:, 1]))
    emp = np.var(np.array(ests), axis=0, ddof=1)
    pred = np.mean(np.array(covs), axis=0).diagonal()
    np.testing.assert_allclose(pred, emp, rtol=0.15)
    rate = np.mean(np.array(cover), axis=0)
    assert np.all((rate >= 0.90) & (rate <= 0.99)), rate


def test_ls_singular_regressors_error_names_direction():
    u = np.arange(10.0)
    phi = np.column_stack([u, 2 * u, np.ones(10)])
    with pytest.raises(EstimationError) as err:
        ls.fit(phi, u)
    msg = str(err.value)
    assert "singular regressors" in msg and "rank 2 < 3" in msg and "direction(s) [1, -0.5, 0]" in msg
    assert "expected full column rank" in msg
