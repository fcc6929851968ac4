"""MAP (Wrocław Example 2.8, Exercise 2.6) and emcee posterior sampling."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, bayes, ls
from tests.estimators.helpers import EXACT, frac
from tests.seedcases import case

U, W = [1.0, 2.0, 3.0], [1.1, 1.9, 3.2]


def test_wro_ex2_8_bayes_map_gaussian():
    c = case("wro_ex2_8_bayes_map_gaussian")
    assert "u = [1,2,3], w = [1.1,1.9,3.2], m_theta = 0.5, sigma_theta = 1, sigma_z = 0.5" in c["data"]
    exp = c["expected"]
    prior = bayes.GaussianPrior(0.5, 1.0 ** 2)
    est = ESTIMATORS["map"](U, W, prior=prior, sigma=0.5)
    assert abs(est.theta[0] - float(frac(exp["instance_MAP"]))) < EXACT
    assert abs(ls.fit(U, W).theta[0] - float(frac(exp["instance_LS"]))) < EXACT
    # posterior variance (1/σ_θ² + Σu²/σ_z²)⁻¹
    assert abs(est.cov[0, 0] - 1 / (1 + 14 / 0.25)) < EXACT
    # limits of (2.116): σ_z ≫ σ_θ -> m_θ ; σ_z ≪ σ_θ -> LS ; N large -> LS
    assert abs(bayes.fit_map(U, W, prior=prior, sigma=1e6).theta[0] - 0.5) < 1e-9
    assert abs(bayes.fit_map(U, W, prior=prior, sigma=1e-6).theta[0] - 14.5 / 14) < 1e-9
    big_u, big_w = np.tile(U, 10_000), np.tile(W, 10_000)
    assert abs(bayes.fit_map(big_u, big_w, prior=prior, sigma=0.5).theta[0] - 14.5 / 14) < 1e-5
    # the general optimiser agrees with the closed form (same Gaussian prior as a callable)
    gen = bayes.fit_map(U, W, prior=bayes.CallablePrior(lambda t: -0.5 * (t[0] - 0.5) ** 2), sigma=0.5)
    assert abs(gen.theta[0] - est.theta[0]) < 1e-8


def test_wro_exer2_6_map_exponential_prior():
    c = case("wro_exer2_6_map_exponential_prior")
    assert "v = [1.2,0.8,1.0], s = 0.5, lambda = 2" in c["data"]
    v, s, lam = np.array([1.2, 0.8, 1.0]), 0.5, 2.0
    est = bayes.fit_map(np.ones(3), v, prior=bayes.ExponentialPrior(lam), sigma=s)
    assert abs(est.theta[0] - float(c["expected"]["instance"])) < 1e-7  # printed to 7 decimals
    assert abs(est.theta[0] - max(0.0, v.mean() - lam * s ** 2 / 3)) < EXACT  # = 5/6
    # formula's truncation at 0: mean(v) − λs²/N < 0 gives θ = 0 on the prior's support
    v2 = np.array([0.05, -0.1, 0.0])
    est2 = bayes.fit_map(np.ones(3), v2, prior=bayes.ExponentialPrior(lam), sigma=s)
    assert est2.theta[0] == 0.0


def _linear_gaussian():
    rng = np.random.default_rng(99)
    n, sigma = 30, 0.5
    phi = np.column_stack([np.ones(n), rng.uniform(-1, 2, n)])
    y = phi @ np.array([1.0, -0.7]) + rng.normal(0, sigma, n)
    m0, c0 = np.array([0.0, 0.0]), np.diag([4.0, 4.0])
    post_cov = np.linalg.inv(np.linalg.inv(c0) + phi.T @ phi / sigma ** 2)
    post_mean = post_cov @ (np.linalg.inv(c0) @ m0 + phi.T @ y / sigma ** 2)
    return phi, y, sigma, bayes.GaussianPrior(m0, c0), post_mean, post_cov


def test_mcmc_matches_closed_form_posterior():
    phi, y, sigma, prior, mean, cov = _linear_gaussian()
    est = ESTIMATORS["mcmc"](phi, y, prior=prior, sigma=sigma, nwalkers=32, nsteps=6000, seed=1)
    assert est.extra["warnings"] == []
    np.testing.assert_allclose(est.theta, mean, rtol=0.05)
    sd = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(est.cov, cov, rtol=0.05)  # every element, off-diagonal included
    q = est.extra["percentiles"]
    np.testing.assert_allclose(q[0], mean - 1.96 * sd, atol=0.1 * sd.max())
    np.testing.assert_allclose(q[1], mean, atol=0.05 * sd.max())
    np.testing.assert_allclose(q[2], mean + 1.96 * sd, atol=0.1 * sd.max())
    tau = est.extra["tau"]
    assert est.extra["burn"] == int(np.ceil(2 * tau.max())) and est.extra["thin"] == max(1, int(0.5 * tau.min()))


def test_mcmc_same_seed_same_chain_and_short_chain_warning():
    phi, y, sigma, prior, _, _ = _linear_gaussian()
    with pytest.warns(RuntimeWarning, match="50 × integrated autocorrelation time"):
        a = bayes.fit_mcmc(phi, y, prior=prior, sigma=sigma, nwalkers=8, nsteps=300, seed=7)
    assert a.extra["warnings"] and "not have converged" in a.extra["warnings"][0]
    with pytest.warns(RuntimeWarning):
        b = bayes.fit_mcmc(phi, y, prior=prior, sigma=sigma, nwalkers=8, nsteps=300, seed=7)
        d = bayes.fit_mcmc(phi, y, prior=prior, sigma=sigma, nwalkers=8, nsteps=300, seed=8)
    assert np.array_equal(a.extra["chain"], b.extra["chain"])
    assert not np.array_equal(a.extra["chain"], d.extra["chain"])


def test_mcmc_respects_bounded_prior_support():
    rng = np.random.default_rng(4)
    v = 0.1 + rng.normal(0, 0.5, 5)
    est = bayes.fit_mcmc(np.ones(5), v, prior=bayes.ExponentialPrior(2.0), sigma=0.5, nwalkers=16, nsteps=3000,
                         seed=3)
    assert np.all(est.extra["samples"] >= 0)


@pytest.mark.parametrize("prior, text", [
    (None, "no prior given"),
    (bayes.GaussianPrior(0.0, np.inf), "infinite variance is a flat, improper prior"),
    (bayes.GaussianPrior([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]]), "not positive definite"),
    (bayes.UniformPrior(0.0, np.inf), "unbounded uniform prior cannot be normalised"),
    (bayes.ExponentialPrior(0.0), "rate must be positive"),
])
def test_improper_prior_raises(prior, text):
    phi = np.column_stack([np.ones(4), np.arange(4.0)])
    for fn in (bayes.fit_map, bayes.fit_mcmc):
        with pytest.raises(EstimationError, match="improper prior") as err:
            fn(phi, np.arange(4.0), prior=prior, sigma=1.0)
        assert text in str(err.value)


def test_ctrl_c_during_mcmc_stops_between_steps_without_a_traceback(capsys):
    """An auditor's Ctrl-C during the structure stage's MCMC: the KeyboardInterrupt was raised inside
    emcee's likelihood wrapper, which printed its traceback before the CLI's "interrupted" line. Under
    the CLI's SIGINT handler the sampling loop now only marks the process and raises between steps."""
    import signal

    from pipeline import runfolder as rf
    from pipeline.cli import _remember_interrupts
    prev = _remember_interrupts(rf)
    fired = []

    def log_density(t):
        if rf.DEFERRING.is_set() and not fired:         # inside the chain: Ctrl-C arrives
            fired.append(True)
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        return -0.5 * (t[0] - 0.5) ** 2

    try:
        with pytest.raises(KeyboardInterrupt):
            bayes.fit_mcmc(U, W, prior=bayes.CallablePrior(log_density), sigma=0.5, nwalkers=8, nsteps=500)
        out = capsys.readouterr()
        assert fired and rf.INTERRUPTED.is_set() and not rf.DEFERRING.is_set()
        assert "Traceback" not in out.err + out.out and "emcee" not in out.err + out.out
    finally:
        signal.signal(signal.SIGINT, prev)
        rf.INTERRUPTED.clear()
