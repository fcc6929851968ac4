"""Bayesian estimation for y = Φθ + z, z ~ N(0, σ²I) with known σ: MAP and posterior sampling.

* MAP with a Gaussian prior N(m, Σ_θ), closed form θ̂ = (Σ_θ⁻¹ + ΦᵀΦ/σ²)⁻¹(Σ_θ⁻¹m + ΦᵀY/σ²), posterior
  covariance (Σ_θ⁻¹ + ΦᵀΦ/σ²)⁻¹. Scalar case: θ_N = (m_θ + (σ_θ/σ_z)² Σ w_n u_n)/(1 + (σ_θ/σ_z)² Σ u_n²)
  (Wrocław Example 2.8, (2.116)); limits σ_z ≫ σ_θ → m_θ, σ_z ≪ σ_θ or N → ∞ → LS.
* MAP with any proper prior by optimisation of the log posterior on the prior's support (Wrocław
  Exercise 2.6, exponential prior: θ = max(0, v̄ − λσ²/N)).
* Posterior sampling with emcee's affine-invariant ensemble sampler (``fit_mcmc``): seeded walkers
  started around the MAP, burn-in = 2·max τ and thinning = max(1, ⌊min τ / 2⌋) from the integrated
  autocorrelation time τ (``get_autocorr_time(tol=0)``), warning when the chain is shorter than 50 τ.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from .. import progress
from ..runfolder import deferred_interrupts, raise_if_interrupted
from .base import Estimate, EstimationError, as_regressors, as_target, numerical_hessian

# ---------------------------------------------------------------- priors


@dataclass(frozen=True)
class GaussianPrior:
    """θ ~ N(mean, cov); a scalar/1-D cov means a diagonal covariance."""

    mean: object
    cov: object

    def arrays(self, p):
        m, c = np.asarray(self.mean, dtype=float), np.asarray(self.cov, dtype=float)
        for what, v in (("mean", m), ("variance", c)):
            if v.ndim == 1 and v.size not in (1, p):
                raise EstimationError(f"prior {what}: {v.size} values for {p} parameters; expected one value "
                                      f"or {p} (one per parameter, in the order of the structure's terms)")
        m = np.broadcast_to(m, (p,)).copy()
        c = np.diag(np.broadcast_to(c, (p,))) if c.ndim <= 1 else c
        if c.shape != (p, p) or not np.all(np.isfinite(c)) or not np.all(np.isfinite(m)):
            raise EstimationError(f"improper prior: Gaussian prior needs a finite mean and a finite ({p}, {p}) "
                                  f"covariance, got cov shape {c.shape} (an infinite variance is a flat, improper prior)")
        try:
            np.linalg.cholesky(c)
        except np.linalg.LinAlgError:
            raise EstimationError("improper prior: Gaussian prior covariance is not positive definite; "
                                  "expected a symmetric positive-definite covariance") from None
        return m, c

    def bounds(self, p):
        return [(None, None)] * p

    def logpdf(self, th):
        th = np.atleast_2d(th)
        m, c = self.arrays(th.shape[-1])
        ci = np.linalg.inv(c)
        d = th - m
        _, logdet = np.linalg.slogdet(c)
        return -0.5 * np.einsum("ij,jk,ik->i", d, ci, d) - 0.5 * (logdet + th.shape[-1] * math.log(2 * math.pi))

    def grad(self, th):
        m, c = self.arrays(np.size(th))
        return -np.linalg.solve(c, np.asarray(th, dtype=float) - m)

    def hess(self, th):
        return np.linalg.inv(self.arrays(np.size(th))[1])


@dataclass(frozen=True)
class ExponentialPrior:
    """Independent θ_j ~ Exp(rate_j) on θ_j >= 0 (Wrocław Exercise 2.6)."""

    rate: object

    def _rate(self, p):
        r = np.broadcast_to(np.asarray(self.rate, dtype=float), (p,))
        if not np.all(np.isfinite(r)) or np.any(r <= 0):
            raise EstimationError(f"improper prior: exponential prior rate must be positive and finite, got {self.rate}")
        return r

    def bounds(self, p):
        self._rate(p)
        return [(0.0, None)] * p

    def logpdf(self, th):
        th = np.atleast_2d(th)
        r = self._rate(th.shape[-1])
        out = np.sum(np.log(r) - r * th, axis=-1)
        return np.where(np.all(th >= 0, axis=-1), out, -np.inf)

    def grad(self, th):
        return -self._rate(np.size(th)).copy()

    def hess(self, th):
        return np.zeros((np.size(th), np.size(th)))


@dataclass(frozen=True)
class UniformPrior:
    """θ_j ~ U[low_j, high_j] with finite bounds."""

    low: object
    high: object

    def _lh(self, p):
        lo = np.broadcast_to(np.asarray(self.low, dtype=float), (p,))
        hi = np.broadcast_to(np.asarray(self.high, dtype=float), (p,))
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
            raise EstimationError(f"improper prior: uniform prior needs finite bounds low < high, got low={self.low}, "
                                  f"high={self.high} (an unbounded uniform prior cannot be normalised)")
        return lo, hi

    def bounds(self, p):
        lo, hi = self._lh(p)
        return list(zip(lo, hi))

    def logpdf(self, th):
        th = np.atleast_2d(th)
        lo, hi = self._lh(th.shape[-1])
        inside = np.all((th >= lo) & (th <= hi), axis=-1)
        return np.where(inside, -np.sum(np.log(hi - lo)), -np.inf)

    def grad(self, th):
        return np.zeros(np.size(th))

    def hess(self, th):
        return np.zeros((np.size(th), np.size(th)))


@dataclass(frozen=True)
class CallablePrior:
    """User log-density (must be proper: the caller is responsible for normalisability), optional bounds."""

    log_density: object
    support: object = None

    def bounds(self, p):
        return list(self.support) if self.support is not None else [(None, None)] * p

    def logpdf(self, th):
        th = np.atleast_2d(th)
        return np.array([float(self.log_density(t)) for t in th])

    grad = None
    hess = None


def _check_prior(prior, p):
    if prior is None:
        raise EstimationError("improper prior: no prior given (a flat prior over R^p is improper); expected a "
                              "GaussianPrior, ExponentialPrior, UniformPrior or CallablePrior")
    if not hasattr(prior, "logpdf"):
        raise EstimationError(f"prior must be a prior object with logpdf(), got {type(prior).__name__}")
    prior.bounds(p)  # validates properness
    if isinstance(prior, GaussianPrior):
        prior.arrays(p)


def _check_sigma(sigma):
    if sigma is None or not np.isfinite(sigma) or sigma <= 0:
        raise EstimationError(f"noise standard deviation sigma must be known, positive and finite, got {sigma}")


# ---------------------------------------------------------------- MAP


def fit_map(regressors, target, *, prior=None, sigma: float | None = None, theta0=None) -> Estimate:
    """MAP estimate: closed form for a Gaussian prior (Wrocław (2.116)), numerical optimisation for other
    proper priors (Wrocław Exercise 2.6); ``cov`` is the inverse Hessian of −log posterior."""
    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    _check_prior(prior, p)
    _check_sigma(sigma)
    s2 = sigma ** 2
    info_lik = phi.T @ phi / s2
    if isinstance(prior, GaussianPrior):
        m, c = prior.arrays(p)
        ci = np.linalg.inv(c)
        post_cov = np.linalg.inv(ci + info_lik)
        theta = post_cov @ (ci @ m + phi.T @ y / s2)
        post_cov = 0.5 * (post_cov + post_cov.T)
        method = "closed form (Wrocław (2.116))"
    else:
        bounds = prior.bounds(p)

        def nlp(th):
            r = y - phi @ th
            lp = float(prior.logpdf(th)[0])
            return 0.5 * float(r @ r) / s2 - lp if np.isfinite(lp) else 1e300

        def grad(th):
            r = y - phi @ th
            g = -phi.T @ r / s2
            if prior.grad is not None:
                return g - prior.grad(th)
            h = 1e-7 * np.maximum(np.abs(th), 1.0)
            for j in range(p):  # prior gradient by central difference (one-sided at a bound)
                e = np.zeros(p)
                e[j] = h[j]
                lo = bounds[j][0]
                if lo is not None and th[j] - h[j] < lo:
                    g[j] -= (float(prior.logpdf(th + e)[0]) - float(prior.logpdf(th)[0])) / h[j]
                else:
                    g[j] -= (float(prior.logpdf(th + e)[0]) - float(prior.logpdf(th - e)[0])) / (2 * h[j])
            return g

        x0 = np.asarray(theta0, dtype=float) if theta0 is not None else np.linalg.lstsq(phi, y, rcond=None)[0]
        x0 = np.array([min(max(v, b[0] if b[0] is not None else -np.inf), b[1] if b[1] is not None else np.inf)
                       for v, b in zip(x0, bounds)])
        res = optimize.minimize(nlp, x0, jac=grad, method="L-BFGS-B", bounds=bounds,
                                options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 1000})
        theta = res.x
        # Newton polish on the coordinates not held at a bound (exact for quadratic + linear log posterior)
        if prior.hess is not None:
            for _ in range(5):
                free = np.array([not ((b[0] is not None and abs(t - b[0]) < 1e-10) or
                                      (b[1] is not None and abs(t - b[1]) < 1e-10)) for t, b in zip(theta, bounds)])
                if not np.any(free):
                    break
                hmat = info_lik + prior.hess(theta)
                g = grad(theta)
                step = np.zeros(p)
                step[free] = np.linalg.solve(hmat[np.ix_(free, free)], g[free])
                cand = theta - step
                cand = np.array([min(max(v, b[0] if b[0] is not None else -np.inf), b[1] if b[1] is not None else np.inf)
                                 for v, b in zip(cand, bounds)])
                if nlp(cand) <= nlp(theta):
                    theta = cand
                else:
                    break
        hmat = numerical_hessian(nlp, theta) if prior.hess is None else info_lik + prior.hess(theta)
        try:
            post_cov = np.linalg.inv(hmat)
        except np.linalg.LinAlgError:
            post_cov = None
        method = "numerical optimisation"
    resid = y - phi @ theta
    loglik = -0.5 * n * math.log(2 * math.pi * s2) - 0.5 * float(resid @ resid) / s2
    logpost = loglik + float(prior.logpdf(theta)[0])
    return Estimate(theta, post_cov, resid, loglik, p, "map",
                    {"log_posterior": logpost, "method": method, "prior": prior})


# ---------------------------------------------------------------- MCMC


def fit_mcmc(regressors, target, *, prior=None, sigma: float | None = None, nwalkers: int = 32,
             nsteps: int = 3000, seed: int = 0, init_scale: float = 0.1, min_tau_multiple: float = 50.0) -> Estimate:
    """Posterior sampling with emcee (EnsembleSampler, vectorised log posterior).

    Reproducible: initial walkers from ``np.random.default_rng(seed)`` around the MAP (spread
    ``init_scale`` × Laplace standard deviations) and the sampler's RandomState seeded with ``seed``.
    Burn-in 2·max τ, thinning max(1, ⌊min τ/2⌋); a warning (``extra['warnings']`` and
    ``warnings.warn``) when nsteps < ``min_tau_multiple`` · max τ. ``theta``/``cov`` are the posterior
    mean/covariance; ``extra['percentiles']`` rows are the 2.5, 50, 97.5 % quantiles.
    """
    import emcee

    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    _check_prior(prior, p)
    _check_sigma(sigma)
    if nwalkers < 2 * p:
        raise EstimationError(f"emcee needs nwalkers >= 2·p = {2 * p}, got {nwalkers}")
    s2 = sigma ** 2
    map_est = fit_map(phi, y, prior=prior, sigma=sigma)

    def log_prob(ths):
        ths = np.atleast_2d(ths)
        lp = prior.logpdf(ths)
        r = y[None, :] - ths @ phi.T
        ll = -0.5 * np.sum(r * r, axis=1) / s2
        return np.where(np.isfinite(lp), lp + ll, -np.inf)

    rng = np.random.default_rng(seed)
    scale = np.sqrt(np.diag(map_est.cov)) if map_est.cov is not None else np.maximum(np.abs(map_est.theta), 1.0) * 1e-2
    p0 = map_est.theta + init_scale * scale * rng.standard_normal((nwalkers, p))
    for _ in range(100):  # keep initial walkers inside the prior support
        bad = ~np.isfinite(log_prob(p0))
        if not np.any(bad):
            break
        p0[bad] = map_est.theta + init_scale * scale * np.abs(rng.standard_normal((int(bad.sum()), p)))
    else:
        raise EstimationError("could not place the initial walkers inside the prior support")
    sampler = emcee.EnsembleSampler(nwalkers, p, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(seed).get_state()
    with deferred_interrupts():    # a Ctrl-C stops the chain between steps, not inside emcee's wrapper
        for _ in progress.bar(sampler.sample(p0, iterations=nsteps), nsteps, "MCMC steps", always_final=False):
            raise_if_interrupted()   # = sampler.run_mcmc(p0, nsteps), with a progress bar
    tau = np.asarray(sampler.get_autocorr_time(tol=0), dtype=float)
    tmax = float(np.max(tau))
    burn = int(math.ceil(2 * tmax))
    thin = max(1, int(0.5 * float(np.min(tau))))
    warns = []
    if nsteps < min_tau_multiple * tmax:
        msg = (f"MCMC chain may not have converged: {nsteps} steps < {min_tau_multiple:g} × integrated "
               f"autocorrelation time ({tmax:.1f}); run a longer chain")
        warns.append(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    if burn >= nsteps:
        raise EstimationError(f"chain too short: burn-in {burn} >= nsteps {nsteps}")
    samples = sampler.get_chain(discard=burn, thin=thin, flat=True)
    mean = samples.mean(axis=0)
    cov = np.atleast_2d(np.cov(samples.T))
    resid = y - phi @ mean
    loglik = -0.5 * n * math.log(2 * math.pi * s2) - 0.5 * float(resid @ resid) / s2
    extra = {
        "chain": sampler.get_chain(),
        "samples": samples,
        "tau": tau,
        "burn": burn,
        "thin": thin,
        "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
        "percentiles": np.percentile(samples, [2.5, 50.0, 97.5], axis=0),
        "map": map_est.theta,
        "warnings": warns,
        "seed": seed,
    }
    return Estimate(mean, cov, resid, loglik, p, "mcmc", extra)
