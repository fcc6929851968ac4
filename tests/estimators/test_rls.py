"""RLS with forgetting and covariance resetting; normalised gradient (Johansson 11.2, 11.4)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, ls, wls
from pipeline.estimators.rls import normalized_gradient, rls
from tests.seedcases import case


def _data(n=500, seed=112, noise=0.1):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=n + 1)
    phi = np.column_stack([u[1:], u[:-1]])  # φ_k = [u_k, u_{k−1}]
    y = phi @ np.array([1.0, -0.5]) + rng.normal(0, noise, n)
    return phi, y


def test_joh_11_2_rls_forgetting():
    c = case("joh_11_2_rls_forgetting")
    assert "theta = [1, -0.5], phi_k = [u_k, u_{k-1}]" in c["data"] and "P0 = 1e6 I" in c["data"]
    phi, y = _data()
    est = rls(phi, y, lam=1.0, p0=1e6)
    np.testing.assert_allclose(est.theta, ls.fit(phi, y).theta, atol=1e-5)  # case tolerance
    traj = est.extra["theta_trajectory"]
    assert traj.shape == (500, 2) and np.array_equal(traj[-1], est.theta)
    np.testing.assert_allclose(est.extra["P"], np.linalg.inv(phi.T @ phi + np.eye(2) / 1e6), rtol=1e-8)
    # λ < 1 is weighted LS with weights λ^{N−k} (+ the λ^N P0⁻¹ regularisation, negligible here)
    lam = 0.98
    est_l = ESTIMATORS["rls"](phi, y, lam=lam, p0=1e6)
    wts = lam ** (len(y) - 1 - np.arange(len(y)))
    np.testing.assert_allclose(est_l.theta, wls.fit(phi, y, weights=wts).theta, atol=1e-5)


def test_rls_total_weight_uses_corrected_sum():
    """Σ_{i=1}^N λ^{N−i} = (1 − λ^N)/(1 − λ) (misprint 40: not (1 − λ^{N+1})/(1 − λ))."""
    n, lam, p0 = 60, 0.9, 1e8
    est = rls(np.ones(n), np.ones(n), lam=lam, p0=p0)
    info = 1.0 / est.extra["P"][0, 0]  # = Σ λ^{N−i} φ_i² + λ^N/p0 with φ = 1
    assert abs(info - ((1 - lam ** n) / (1 - lam) + lam ** n / p0)) < 1e-9
    assert abs(info - (1 - lam ** (n + 1)) / (1 - lam)) > 1e-4
    assert info < 1 / (1 - lam)


def test_rls_forgetting_and_reset_track_a_parameter_jump():
    rng = np.random.default_rng(7)
    n = 600
    phi = rng.normal(size=(n, 2))
    theta = np.where(np.arange(n)[:, None] < 300, [1.0, -0.5], [2.0, 0.5])
    y = np.sum(phi * theta, axis=1) + rng.normal(0, 0.05, n)
    plain = rls(phi, y, lam=1.0, p0=1e4)
    forget = rls(phi, y, lam=0.95, p0=1e4)
    reset = rls(phi, y, lam=1.0, p0=1e4, reset_every=100)
    err = lambda e: np.max(np.abs(e.theta - [2.0, 0.5]))  # noqa: E731
    assert err(plain) > 0.3
    assert err(forget) < 0.05 and err(reset) < 0.05
    # the last reset (k = 500) leaves P ≈ (Σ_{last 100} φφᵀ)⁻¹, far larger than after 600 samples
    assert np.trace(reset.extra["P"]) > 3 * np.trace(plain.extra["P"])


def test_rls_rejects_bad_options():
    phi, y = _data(50)
    with pytest.raises(EstimationError, match=r"forgetting factor lam must be in \(0, 1\]"):
        rls(phi, y, lam=1.2)
    with pytest.raises(EstimationError, match="p0 must be a positive"):
        rls(phi, y, p0=-1.0)


def test_joh_11_4_normalized_gradient():
    case("joh_11_4_normalized_gradient")
    rng = np.random.default_rng(114)
    phi = rng.normal(size=(300, 3))
    theta = np.array([0.5, -1.0, 2.0])
    y = phi @ theta  # noise-free
    for q in (np.eye(3), np.diag([2.0, 0.5, 1.0])):
        est = normalized_gradient(phi, y, Q=q, r0=1.0)
        err = est.extra["theta_trajectory"] - theta
        qi = np.linalg.inv(q)
        norm = np.einsum("ki,ij,kj->k", err, qi, err)
        norm = np.concatenate([[theta @ qi @ theta], norm])
        assert np.all(np.diff(norm) <= 1e-12)  # non-increasing (case tolerance)
        assert norm[-1] < norm[0]
