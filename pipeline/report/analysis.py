"""Numbers the report draws that the diagnosis does not keep: display decimation, higher-order
residual correlations, the model-error model, the response band and the emcee posterior of the final
grey-box model. All seeded from the config's seed; nothing here changes ``summary.json``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.signal import welch

from .. import progress


# ------------------------------------------------------------------ display decimation

def envelope(t: np.ndarray, y: np.ndarray, max_points: int = 4000, bins: int = 600):
    """Min/max envelope for drawing a long trace: ``None`` when ``len(y) <= max_points`` (draw it
    as is), else ``(t_bin, lo, hi)`` over ``bins`` bins of consecutive samples, so every sample's value
    lies inside the drawn band (no aliasing, unlike taking every k-th sample). ``bins`` ≈ the axes'
    width in pixels: narrower bins would be thinner than a pixel and vanish under antialiasing."""
    n = len(y)
    if n <= max_points:
        return None
    nb = max(1, min(bins, n))
    edges = np.linspace(0, n, nb + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1])
    hi = np.maximum.reduceat(y, edges[:-1])
    tb = 0.5 * (t[edges[:-1]] + t[np.maximum(edges[1:] - 1, edges[:-1])])
    return tb, lo, hi


def zoom_window(err: np.ndarray, width: int) -> tuple[int, int]:
    """[a, b) of ``width`` samples centred on the largest |error| (where the model is worst)."""
    n = len(err)
    width = min(width, n)
    k = int(np.nanargmax(np.abs(err))) if n and np.any(np.isfinite(err)) else 0
    a = max(0, min(n - width, k - width // 2))
    return a, a + width


# ------------------------------------------------------------------ higher-order correlation tests

def _ncorr(a: np.ndarray, b: np.ndarray, nlags: int) -> np.ndarray:
    """φ_ab(τ) = Σ_k a_k b_{k+τ} / √(Σa² Σb²), τ = 0..nlags (a, b mean-removed)."""
    a = a - a.mean()
    b = b - b.mean()
    den = math.sqrt(float(a @ a) * float(b @ b)) or 1.0
    n = len(a)
    return np.array([float(a[:n - k] @ b[k:]) / den for k in range(nlags + 1)])


@dataclass
class HigherOrder:
    lags: np.ndarray
    curves: dict[str, np.ndarray]
    bound: float


def billings_voon(e: np.ndarray, u: np.ndarray | None, nlags: int = 20) -> HigherOrder:
    """Billings & Voon (1986) nonlinear correlation tests of a residual e against input u:
    φ_{u²'e}(τ), φ_{u²'e²}(τ) (u²' = u² − mean) and φ_{e(eu)}(τ) = corr(e_k, e_{k−1−τ} u_{k−1−τ});
    each ≈ 0 for an adequate model, bounds ±1.96/√N (95 %)."""
    n = len(e)
    curves: dict[str, np.ndarray] = {}
    if u is not None and np.ptp(u) > 0:
        u2 = u ** 2
        curves["φ u²′e"] = _ncorr(u2, e, nlags)
        curves["φ u²′e²"] = _ncorr(u2, e ** 2, nlags)
        eu = e * u
        curves["φ e(eu)"] = np.concatenate([[np.nan], _ncorr(eu[:-1], e[1:], nlags - 1)])  # τ ≥ 1 ↔ lag 1+τ
    else:
        curves["φ e²′e²"] = _ncorr(e ** 2, e ** 2, nlags)
        curves["φ e²′e²"][0] = np.nan
    return HigherOrder(np.arange(nlags + 1), curves, 1.96 / math.sqrt(n))


# ------------------------------------------------------------------ model-error model

@dataclass
class ErrorModel:
    f_hz: np.ndarray
    mag: np.ndarray
    band: np.ndarray     # 99 % half-width of |G| (delta method)
    order: int


def error_model(e: np.ndarray, u: np.ndarray, dt: float, order: int | None = None, n_freq: int = 256) -> ErrorModel | None:
    """Model-error model (Ljung 1999, *System Identification*, §16.6 "model error models"): an FIR
    model e_k = Σ_{j=0}^{n−1} b_j u_{k−j} + v_k of the residual on the input, on the input lags'
    well-determined directions, by the added-term test's FGLS; its frequency response
    G(f) = Σ b_j e^{−i2πf j Δt} with a pointwise 99 % band (the test's HAC covariance of b̂, delta method
    for |G|). A band that contains 0 at every frequency says the residual holds no more input
    dynamics. ``order`` defaults to the adequacy row's FIR length (``adequacy.FIR_ORDER``, 15 taps), so
    the figure draws the model that row tests (30 taps cost 2.25 s per model on Silverbox's rows with
    the HAC test, 15 taps 0.75 s)."""
    if order is None:
        from ..diagnostics.adequacy import FIR_ORDER
        order = FIR_ORDER
    n = len(e)
    if n <= 4 * order or np.ptp(u) == 0:
        return None
    Phi = np.column_stack([u[order - 1 - j:n - j] for j in range(order)])
    y = e[order - 1:]
    # a smooth input makes its lags nearly collinear: the coefficients and their covariance on the
    # same well-determined directions (σ_i > 10⁻⁶ σ_max, as adequacy.model_error_model tests them).
    # Before, lstsq kept every direction while pinv(ΦᵀΦ) dropped the weak ones, so on a band-limited
    # input |G| reached 10⁵ above the band with a 99 % band of width 0 there.
    # The coefficients and their covariance are those of the adequacy row's test (FGLS with the HAC
    # long-run covariance, :func:`pipeline.diagnostics.stats.added_terms_test`): σ̂²(ΦᵀΦ)⁻¹ assumed a
    # white residual, and an output-error residual is smooth (the heating system's lag-1 correlation
    # is 0.99), so its band was far too narrow.
    Uo, sv, Vt = np.linalg.svd(Phi, full_matrices=False)
    keep = sv > 1e-6 * sv[0]
    Vk = Vt[keep].T / sv[keep]
    from ..diagnostics.stats import added_terms_test
    w = added_terms_test(y - y.mean(), np.zeros((len(y), 0)), Uo[:, keep])
    b = Vk @ w.beta
    C = Vk @ w.cov @ Vk.T
    # only where the input has power: within 30 dB of its Welch spectrum's peak (Hann, 50 % overlap);
    # beyond, the FIR response is not identifiable (the cumulative-power rule used before reached
    # twice the band edge of a band-limited input through the periodogram's leakage)
    seg = int(min(256, max(16, n // 4)))
    fw, pw = welch(u - u.mean(), fs=1.0 / dt, nperseg=seg)
    f_max = max(float(fw[pw >= 1e-3 * float(pw.max())].max()) if pw.max() > 0 else 0.0, 2.0 / (n * dt))
    f = np.linspace(0, min(f_max, 0.5 / dt), n_freq)
    E = np.exp(-2j * np.pi * f[:, None] * dt * np.arange(order)[None, :])
    G = E @ b
    mag = np.abs(G)
    re, im = E.real, E.imag  # Re G = re·b, Im G = im·b
    var_re = np.einsum("fi,ij,fj->f", re, C, re)
    var_im = np.einsum("fi,ij,fj->f", im, C, im)
    cov_ri = np.einsum("fi,ij,fj->f", re, C, im)
    safe = np.where(mag > 0, mag, 1.0)
    var_mag = (G.real ** 2 * var_re + G.imag ** 2 * var_im + 2 * G.real * G.imag * cov_ri) / safe ** 2
    z = float(stats.norm.ppf(0.995))
    return ErrorModel(f, mag, z * np.sqrt(np.clip(var_mag, 0, None)), order)


# ------------------------------------------------------------------ parameters → simulation

def unpack(fit, theta: np.ndarray):
    """(model, x0) of a fit's estimated vector (free params, then "x0.<state>"), as in fit.py."""
    nfree = sum(1 for n in fit.names if not n.startswith("x0."))
    m = fit.model.with_params(dict(zip(fit.names[:nfree], theta[:nfree])))
    x0 = np.array(fit.x0, dtype=float).copy()
    for n, v in zip(fit.names[nfree:], theta[nfree:]):
        x0[list(fit.model.states).index(n[3:])] = v
    return m, x0


def response_band(fit, prob, samples: np.ndarray, level: float = 0.95) -> np.ndarray | None:
    """Pointwise ``level`` band (2, N, ny) of the free-run output over parameter draws ``samples``
    (:func:`parameter_draws` or posterior draws); draws that diverge are left out."""
    from ..errors import SimulationError
    from ..fit import simulate_full
    sims = []
    for th in progress.bar(samples, len(samples), "response band"):
        m, x0 = unpack(fit, th)
        try:
            sims.append(simulate_full(m, prob, x0))
        except SimulationError:
            continue
    if len(sims) < 5:
        return None
    arr = np.stack(sims)
    q = 100 * (1 - level) / 2
    return np.percentile(arr, [q, 100 - q], axis=0)


def parameter_draws(fit, n: int, seed: int) -> tuple[np.ndarray, str] | None:
    """``n`` draws of the parameters from the law their intervals use, and its name: with the sandwich
    covariance's degrees of freedom ν (``fit.identifiability.cov_dof``, floored at 1 as the intervals'
    t quantile floors it) the multivariate t, θ̂ + z·√(ν/w), z ~ N(0, P), w ~ χ²_ν (Kotz & Nadarajah 2004,
    "Multivariate t distributions", eq. 1.1), whose marginals are the t_ν of the θ̂ ± t·σ intervals
    (:func:`pipeline.fit.param_intervals`) of the parameter with the fewest degrees of freedom (one ν
    for the whole vector: the smallest, so the band is conservative for parameters whose own ν is
    larger); without ν (the classic covariance) Gauss N(θ̂, P). Gauss
    draws with ν = 2 put 95 % of a parameter within ±1.96σ where its interval is ±4.3σ: the band
    understated the parameters' own uncertainty. None without a finite covariance."""
    if not len(fit.theta) or not np.all(np.isfinite(fit.cov)):
        return None
    rng = np.random.default_rng([seed, 10])
    z = rng.multivariate_normal(np.zeros(len(fit.theta)), fit.cov, size=n, method="eigh")
    nu = None if fit.identifiability is None else fit.identifiability.cov_dof
    if nu is None or not math.isfinite(nu):
        return fit.theta + z, "Gauss N(θ̂, P) draws"
    nu = max(float(nu), 1.0)
    w = rng.chisquare(nu, size=n)
    return fit.theta + z * np.sqrt(nu / w)[:, None], f"multivariate t draws (ν = {nu:.2g}, scale P)"


THIN_CORR = 0.99   # pairs correlated beyond this get the caption's warning (:func:`thin_pairs`)


def thin_pairs(fit) -> list[str]:
    """"a–b" for every pair of estimated quantities whose correlation exceeds ±``THIN_CORR``. Their
    ellipse is a thin sliver, and a linearised region cannot follow the curved law of such estimates:
    on two thermal nodes with a near-collinear triple (a1·T1 beside c·tanh(T1/s), correlations
    0.993–0.999; 400 solve_ivp draws) the 95 % ellipses of the pairs (a1, c) and (c, s) held the truth
    85–86 % of the time, and even the Monte Carlo's own covariance with χ²₂ only 91–92 % (BENCHMARKS,
    thirty-third session); the other pairs 91–97 %."""
    cov = np.asarray(fit.cov, float)
    names = list(getattr(fit, "names", []) or [])
    if cov.ndim != 2 or len(names) != cov.shape[0]:
        return []
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if sd[i] > 0 and sd[j] > 0 and np.isfinite(cov[i, j]) and abs(cov[i, j]) > THIN_CORR * sd[i] * sd[j]:
                out.append(f"{names[i]}–{names[j]}")
    return out


# ------------------------------------------------------------------ emcee posterior of the final model

@dataclass
class Posterior:
    samples: np.ndarray        # (n, p) after burn-in and thinning
    names: list[str]
    tau: np.ndarray
    acceptance: float
    walkers: int
    steps: int
    burn: int
    thin: int
    warnings: list[str]


def mcmc_posterior(fit, prob, seed: int, walkers: int | None = None, steps: int = 800) -> Posterior | None:
    """emcee posterior of the final grey-box model's estimated quantities under the output-error
    likelihood with σ² fixed at its estimate: log p(θ | y) = −SSE_w(θ)/(2σ̂²) + const, flat prior on
    a box of ±50 Laplace standard deviations (the model is nonlinear in θ, so the posterior need not be
    the Gauss ellipse). Walkers start on N(θ̂, (0.1 P)) from ``default_rng(seed)``; the sampler's
    RandomState is seeded too. Burn-in 2·max τ, thinning ⌊min τ/2⌋ (emcee's guidance)."""
    import emcee

    from ..fit import simulate_until
    p = len(fit.theta)
    if p == 0 or not np.all(np.isfinite(fit.cov)):
        return None
    walkers = walkers or max(2 * p + 2, 12)
    est = prob.split.est
    stop = est[1]
    w = prob.weights
    yobs = prob.Y[est[0]:stop]
    dof = max(yobs.size - p, 1)
    s2 = fit.sse_w / dof
    sd = np.sqrt(np.clip(np.diag(fit.cov), 1e-300, None))
    lo, hi = fit.theta - 50 * sd, fit.theta + 50 * sd

    def log_prob(th):
        if np.any(th < lo) or np.any(th > hi):
            return -np.inf
        m, x0 = unpack(fit, th)
        Yh = simulate_until(m, prob, x0, stop)
        if Yh is None:
            return -np.inf
        r = ((yobs - Yh[est[0]:stop]) * w).ravel()
        if not np.all(np.isfinite(r)):
            return -np.inf
        return -0.5 * float(r @ r) / s2

    rng = np.random.default_rng([seed, 11])
    L = np.linalg.cholesky(fit.cov + 1e-30 * np.eye(p)) if np.all(np.linalg.eigvalsh(fit.cov) > 0) else np.diag(sd)
    p0 = fit.theta + 0.1 * rng.standard_normal((walkers, p)) @ L.T
    sampler = emcee.EnsembleSampler(walkers, p, log_prob)
    sampler.random_state = np.random.RandomState(seed).get_state()
    for _ in progress.bar(sampler.sample(p0, iterations=steps), steps, "MCMC steps"):
        pass
    tau = np.asarray(sampler.get_autocorr_time(tol=0), float)
    tmax = float(np.nanmax(tau)) if np.all(np.isfinite(tau)) else float(steps)
    burn = min(int(math.ceil(2 * tmax)), steps // 2)
    thin = max(1, int(0.5 * float(np.nanmin(tau)))) if np.all(np.isfinite(tau)) else 1
    warns = []
    if steps < 50 * tmax:
        warns.append(f"{steps} steps < 50 × the integrated autocorrelation time ({tmax:.0f} steps): the "
                     "chain may not have converged; treat the posterior as indicative")
    samples = sampler.get_chain(discard=burn, thin=thin, flat=True)
    return Posterior(samples, list(fit.names), tau, float(np.mean(sampler.acceptance_fraction)), walkers, steps,
                     burn, thin, warns)
