"""Residual tests. Each returns a :class:`TestResult` with the statistic, p-value, the bound used and
whether the residual passed (no evidence against the null at the given level).

Sources: sample autocorrelation bound ±2.58/√N (99 %) and the input cross-correlation bound of MATLAB
``resid`` for coloured inputs, ±2.58·√(Σ_k R̂e(k)R̂u(k))/(√N·√(R̂e(0)R̂u(0))) (Ljung 1999 §16.6);
Ljung–Box Q = N(N+2) Σ_{k=1}^{m} r_k²/(N−k) ~ χ²_m (Ljung & Box 1978); Fisher's g = max I(f_j)/Σ I(f_j)
with P(g > x) = Σ_{j≥1} (−1)^{j−1} C(q, j)(1 − jx)_+^{q−1} (Fisher 1929); the mean t-test uses a
Newey–West long-run variance (Newey & West 1987) with Andrews' (1991) bandwidth so autocorrelated residuals do not inflate it;
the score/Wald test of added terms uses the same HAC covariance.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit
from scipy import stats
from scipy.fft import next_fast_len
from scipy.special import gammaln

from .. import hac


@dataclass
class TestResult:
    name: str
    statistic: float
    p_value: float
    bound: float | None
    passed: bool
    detail: str = ""
    r2: float | None = None     # effect size where it applies (adequacy): the share of the residual explained

    def as_dict(self) -> dict:
        return asdict(self)


def _fast_len(n: int) -> int:
    """FFT length >= n with small prime factors (a length with a large prime factor is slow)."""
    return next_fast_len(n, real=True)


def _acf(x: np.ndarray, nlags: int) -> np.ndarray:
    x = x - x.mean()
    n = len(x)
    m = _fast_len(2 * n)
    f = np.fft.rfft(x, m)
    r = np.fft.irfft(f * np.conj(f), m)[: nlags + 1] / n
    return r


def _acov(x: np.ndarray, nlags: int) -> np.ndarray:
    """Autocovariances r_k = Σ_t x̃_t x̃_{t+k} / N, k = 0..nlags (x̃ centred): the biased estimator of
    :func:`_acf`, by direct sums. For the few lags an AR fit needs this is cheaper than the FFT of
    twice the length (11 lags of 90 000 samples: 0.1 ms against 3 ms) and has no FFT rounding."""
    x = np.asarray(x, float)
    x = x - x.mean()
    n = len(x)
    return np.array([float(x[:n - k] @ x[k:]) / n for k in range(min(nlags, n - 1) + 1)])


def _lags(n: int, nlags: int) -> int:
    """At most N/4 lags (and at least 1): short records get fewer lags, never an error."""
    return max(1, min(nlags, n // 4))


def autocorr(e: np.ndarray, nlags: int = 25, level: float = 0.99) -> tuple[np.ndarray, float]:
    """Normalised autocorrelation r_k (k = 0..nlags) and the bound z/√N (2.58/√N at 99 %)."""
    r = _acf(e, _lags(len(e), nlags))
    z = stats.norm.ppf(0.5 + level / 2)
    return r / r[0], float(z / math.sqrt(len(e)))


def crosscorr(e: np.ndarray, u: np.ndarray, nlags: int = 25, level: float = 0.99):
    """Cross-correlation R̂eu(τ)/√(R̂e(0)R̂u(0)) for τ = −nlags..nlags and MATLAB resid's bound
    for a coloured input: z·√(Σ_k r_e(k) r_u(k))/√N with normalised autocorrelations."""
    n = len(e)
    nlags = _lags(n, nlags)
    e0, u0 = e - e.mean(), u - u.mean()
    mlen = _fast_len(2 * n)
    f = np.fft.irfft(np.fft.rfft(e0, mlen) * np.conj(np.fft.rfft(u0, mlen)), mlen)
    lags = np.arange(-nlags, nlags + 1)
    c = f[lags] / n  # negative lags wrap around (f is circular with zero padding >= n)
    c = c / math.sqrt(np.dot(e0, e0) / n * np.dot(u0, u0) / n)
    m = min(n - 1, 200)
    re, ru = _acf(e0, m), _acf(u0, m)
    re, ru = re / re[0], ru / ru[0]
    s = re[0] * ru[0] + 2.0 * float(np.dot(re[1:], ru[1:]))
    z = stats.norm.ppf(0.5 + level / 2)
    return lags, c, float(z * math.sqrt(max(s, 1e-12)) / math.sqrt(n))


def ljung_box(e: np.ndarray, nlags: int = 20, alpha: float = 0.01) -> TestResult:
    n = len(e)
    nlags = _lags(n, nlags)
    r, _ = autocorr(e, nlags)
    k = np.arange(1, nlags + 1)
    q = float(n * (n + 2) * np.sum(r[1:] ** 2 / (n - k)))
    p = float(stats.chi2.sf(q, nlags))
    return TestResult("ljung_box", q, p, float(stats.chi2.isf(alpha, nlags)), p >= alpha,
                      f"Q over lags 1..{nlags}, chi2({nlags})")


def whiteness(e: np.ndarray, nlags: int = 25, alpha: float = 0.01) -> TestResult:
    """Largest |r_k|, k = 1..m, against the Bonferroni bound z_{1−α/(2m)}/√N: ``passed`` is p ≥ α, and
    |r_k| ≤ bound for all k exactly when it passes (the pointwise 99 % band count is in the detail)."""
    nlags = _lags(len(e), nlags)
    r, band = autocorr(e, nlags, 1 - alpha)
    worst = float(np.max(np.abs(r[1:])))
    n_out = int(np.sum(np.abs(r[1:]) > band))
    # p-value of the largest |r_k| under whiteness (Bonferroni over lags)
    p = float(min(1.0, nlags * 2 * stats.norm.sf(worst * math.sqrt(len(e)))))
    bound = float(stats.norm.isf(alpha / (2 * nlags)) / math.sqrt(len(e)))
    lag = int(np.argmax(np.abs(r[1:]))) + 1
    return TestResult("autocorrelation", worst, p, bound, p >= alpha,
                      f"largest at lag {lag}; {n_out} of {nlags} lags outside the pointwise band ±{band:.3g}; "
                      f"test: largest |r_k| against the Bonferroni bound ±{bound:.3g}")


def input_crosscorr(e: np.ndarray, u: np.ndarray, nlags: int = 25, alpha: float = 0.01) -> TestResult:
    """Largest |r_eu(τ)|, τ = −m..m, against MATLAB resid's coloured-input standard deviation with a
    Bonferroni level over the 2m+1 lags: ``passed`` is p ≥ α (and |r| ≤ bound exactly then)."""
    lags, c, band = crosscorr(e, u, nlags, 1 - alpha)
    worst = float(np.max(np.abs(c)))
    sd = band / stats.norm.ppf(1 - alpha / 2)
    p = float(min(1.0, len(lags) * 2 * stats.norm.sf(worst / sd)))
    bound = float(sd * stats.norm.isf(alpha / (2 * len(lags))))
    lag = int(lags[int(np.argmax(np.abs(c)))])
    n_out = int(np.sum(np.abs(c) > band))
    return TestResult("input_crosscorrelation", worst, p, bound, p >= alpha,
                      f"largest at lag {lag}; {n_out} of {len(lags)} lags outside the pointwise band "
                      f"±{band:.3g} (MATLAB resid, coloured input); test against the Bonferroni bound")


def affine_in(x: np.ndarray, u: np.ndarray, rtol: float) -> bool:
    """Is x, to within ``rtol`` of its standard deviation, a + b·u? (Any function of a two-level input
    is: a test built on such an x has nothing beyond the input's own linear term to find.)"""
    X = np.column_stack([np.ones(len(u)), u])
    r = x - X @ np.linalg.lstsq(X, x, rcond=None)[0]
    return float(np.std(r)) <= rtol * (float(np.std(x)) or 1.0)


def billings_voon(e: np.ndarray, u: np.ndarray, nlags: int = 25, alpha: float = 0.01) -> TestResult | None:
    """Billings & Voon (1986, Int. J. Control 44(1), 235–244) higher-order correlation tests of a
    residual against an input, for nonlinearity the linear tests miss:

        φ_{u²′e}(τ) = corr(u²′_t, e_{t+τ}),   φ_{u²′e²}(τ) = corr(u²′_t, e²′_{t+τ}),   τ = −m..m,

    u²′ = (u − ū)² − mean, e²′ = e² − mean; both vanish at every lag when the residual is independent
    of the input. Billings & Voon bound them by ±1.96/√N, which assumes a white residual; an
    output-error residual is coloured, so each is referred to Bartlett's (1946) variance of the
    cross-correlation of two independent stationary series, Σ_k r_x(k) r_y(k)/N, as MATLAB ``resid``
    does for the input cross-correlation (:func:`crosscorr`). The test is the largest standardised
    |z| = |φ|/sd over the 2(2m+1) correlations, Bonferroni: p = min(1, 2(2m+1)·2Φ(−max|z|)). None when u² is
    affine in u (a two-level input: u² carries nothing). The statistic is max|z|, the bound the
    Bonferroni quantile z_{1−α/(2·2(2m+1))}."""
    u = np.asarray(u, float)
    u2 = (u - u.mean()) ** 2
    if affine_in(u2, u, 1e-6):
        return None   # two levels
    u2 = u2 - u2.mean()
    e = np.asarray(e, float)
    rows = []
    for label, x in (("u2'e", e), ("u2'e2", (e - e.mean()) ** 2)):
        lags, c, band = crosscorr(x, u2, nlags, 1 - alpha)
        sd = band / stats.norm.ppf(1 - alpha / 2)
        k = int(np.argmax(np.abs(c)))
        rows.append((label, float(abs(c[k])), float(abs(c[k]) / sd), int(lags[k]), sd, len(lags)))
    m = sum(r[5] for r in rows)
    label, worst, z, lag, sd, _ = max(rows, key=lambda r: r[2])
    p = float(min(1.0, m * 2 * stats.norm.sf(z)))
    bound = float(stats.norm.isf(alpha / (2 * m)))
    return TestResult("billings_voon", z, p, bound, p >= alpha,
                      f"largest standardised |phi| {z:.3g} (|phi| = {worst:.3g}) in phi_{label} at lag {lag} "
                      f"(lag > 0: the input leads); "
                      + "; ".join(f"phi_{r[0]}: largest {r[1]:.3g} ({r[2]:.2f} sd) at lag {r[3]}" for r in rows)
                      + "; Bartlett variance for a coloured residual, Bonferroni over lags")


def andrews_bandwidth(g: np.ndarray) -> int:
    """Andrews (1991, eq. 6.4) automatic bandwidth for the Bartlett kernel with AR(1) plug-in:
    α̂(1) = Σ 4ρ²σ⁴/((1−ρ)⁶(1+ρ)²) / Σ σ⁴/(1−ρ)⁴ over the columns, S = 1.1447 (α̂(1) N)^{1/3}."""
    g = np.atleast_2d(g.T).T
    n = g.shape[0]
    # the ratio is invariant to a common scale of the columns, but σ⁴ of squared residuals of order
    # 1e50 overflows a float: such input is rescaled (others are left bit for bit as they were)
    big = float(np.max(np.abs(g))) if g.size else 0.0
    if np.isfinite(big) and big > 1e50:
        g = g / big
    num = den = 0.0
    for a in range(g.shape[1]):
        x = g[:, a] - g[:, a].mean()
        xx = float(np.dot(x[:-1], x[:-1]))
        if xx <= 0:
            continue
        rho = float(np.clip(np.dot(x[1:], x[:-1]) / xx, -0.97, 0.97))
        s2 = float(np.mean((x[1:] - rho * x[:-1]) ** 2))
        num += 4 * rho ** 2 * s2 ** 2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += s2 ** 2 / (1 - rho) ** 4
    if den == 0:
        return 0
    return int(min(n // 4, math.floor(1.1447 * (num / den * n) ** (1.0 / 3.0))))


def long_run_variance(g: np.ndarray, lags: int | None = None) -> np.ndarray:
    """Newey–West HAC estimate Ω = Γ0 + Σ_{l=1}^{L} (1 − l/(L+1))(Γ_l + Γ_lᵀ) for rows g_t (N×q);
    L from Andrews' automatic rule unless given."""
    g = np.atleast_2d(g.T).T
    L = andrews_bandwidth(g) if lags is None else lags
    om = g.T @ g
    if L == 0:
        return om
    n, q = g.shape
    if L <= 8:
        for lag in range(1, L + 1):
            gam = g[lag:].T @ g[:-lag]
            om += (1 - lag / (L + 1)) * (gam + gam.T)
        return om
    # all lags at once: Γ_l[a, b] = Σ_t g[t+l, a] g[t, b] from FFT cross-correlations, O(q² N log N)
    m = _fast_len(2 * n)
    F = np.fft.rfft(g, m, axis=0)
    w = 1.0 - np.arange(1, L + 1) / (L + 1)
    for a in range(q):
        for b in range(q):
            c = np.fft.irfft(F[:, a] * np.conj(F[:, b]), m)[1:L + 1]
            v = float(np.dot(w, c))
            om[a, b] += v
            om[b, a] += v
    return om


def mean_test(e: np.ndarray, alpha: float = 0.01) -> TestResult:
    """t-test of a zero mean with a Newey–West long-run variance."""
    n = len(e)
    d = e - e.mean()
    lrv = float(long_run_variance(d[:, None])[0, 0]) / n
    t = float(e.mean() / math.sqrt(max(lrv, 1e-300) / n))
    p = float(2 * stats.norm.sf(abs(t)))
    return TestResult("mean_t", t, p, float(stats.norm.isf(alpha / 2)), p >= alpha, "HAC t-test of mean 0")


def levinson(r: np.ndarray, pmax: int) -> list[tuple[np.ndarray, float]]:
    """Yule–Walker AR(p) coefficients a (x_t = Σ a_i x_{t−i} + ε_t) and innovation variance for every
    p = 0..pmax from the autocovariances r₀..r_pmax, by the Levinson–Durbin recursion (Levinson 1947;
    Durbin 1960; Brockwell & Davis 1991 §5.2)."""
    out = [(np.zeros(0), float(r[0]))]
    a = np.zeros(0)
    v = float(r[0])
    for p in range(1, pmax + 1):
        if v <= 0:
            break
        k = (r[p] - float(a @ r[p - 1:0:-1])) / v if p > 1 else r[1] / v
        a = np.concatenate([a - k * a[::-1], [k]])
        v = v * (1.0 - k * k)
        out.append((a.copy(), float(v)))
    return out


def ar_coefficients(e: np.ndarray, pmax: int = 20) -> np.ndarray:
    """Coefficients a of an AR(p) fitted to the centred e by Yule–Walker (Levinson–Durbin on the biased
    autocovariances), p ≤ ``pmax`` (and ≤ N/10) chosen by AIC = N ln σ̂²_p + 2p (Akaike 1974); an empty
    array for p = 0. The filter of :func:`prewhiten_ar` without its residual (the added-term tests
    need only a: they filter e, J and S with it)."""
    x = np.asarray(e, float) - float(np.mean(e))
    n = len(x)
    pmax = int(max(0, min(pmax, n // 10)))
    if pmax == 0 or not np.any(x):
        return np.zeros(0)
    fits = levinson(_acov(x, pmax), pmax)
    aic = [n * math.log(max(v, 1e-300)) + 2 * len(a) for a, v in fits]
    return fits[int(np.argmin(aic))][0]


def prewhiten_ar(e: np.ndarray, pmax: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Residual of the AR(p) of :func:`ar_coefficients`: v_t = ẽ_t − Σ a_i ẽ_{t−i}, t = p..N−1 (ẽ
    centred). Returns (v, a); p = 0 gives v = ẽ."""
    x = np.asarray(e, float) - float(np.mean(e))
    n = len(x)
    a = ar_coefficients(e, pmax)
    p = len(a)
    if p == 0:
        return x, a
    v = x[p:] - sum(a[i] * x[p - 1 - i:n - 1 - i] for i in range(p))
    return v, a


def _line_free(x: np.ndarray, half: int = 8) -> tuple[np.ndarray, float]:
    """x with its most prominent sinusoid removed: the Fourier frequency where the periodogram most
    exceeds its running median over ±``half`` bins (a line-robust estimate of the continuous spectrum),
    refined to the least-squares frequency within ±1 bin (bounded scalar search; the periodogram peak
    is the LS frequency estimate, Walker 1971), then the least-squares sine and cosine at that
    frequency are subtracted (line removal before estimating the continuum: Percival & Walden 1993
    §10.11). An off-bin line left as leakage would be fitted by the AR model and notched out again.
    Also returns the peak's ratio to the background I(f_j)·ln 2/median: under a continuous spectrum
    each ratio is about Exp(1) (I(ω)/f(ω) ~ χ²₂/2, Priestley 1981 §6.1.3; the median of Exp(1) is ln 2)."""
    from scipy.ndimage import median_filter
    from scipy.optimize import minimize_scalar
    n = len(x)
    per = np.abs(np.fft.rfft(x)) ** 2
    per = per[1:(n - 1) // 2 + 1]
    if len(per) < 2 * half + 1:
        return x, 0.0
    bg = median_filter(per, size=2 * half + 1, mode="nearest") / math.log(2.0)
    ratio = per / np.maximum(bg, 1e-300)
    j = int(np.argmax(ratio)) + 1
    t = np.arange(n)

    def fit(f):
        X = np.column_stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)])
        return X @ np.linalg.lstsq(X, x, rcond=None)[0]

    res = minimize_scalar(lambda f: float(np.sum((x - fit(f)) ** 2)), bounds=((j - 1) / n, (j + 1) / n),
                          method="bounded", options={"xatol": 1e-4 / n})
    return x - fit(float(res.x)), float(ratio[j - 1])


def fisher_g(e: np.ndarray, alpha: float = 0.01) -> tuple[TestResult, float]:
    """Fisher's exact test for a hidden periodicity on the *prewhitened* residual; also returns the
    peak frequency (cycles/sample).

    Fisher (1929) assumes white noise under H0; a smooth (coloured) residual has a periodogram peak at
    low frequencies from its colour alone (the raw test rejected 100 % of AR(1) φ = 0.8 records). So e
    is first whitened by an AR(p), p ≤ 20 by AIC, fitted by Yule–Walker (:func:`prewhiten_ar`); the
    test is Fisher's g = max I(f_j)/Σ I(f_j) of the whitened series v. A strong line would be fitted by
    the AR model itself (a pole pair on the unit circle) and notched out of v, so when the most
    prominent line stands out of the background at level 0.001 (its Exp(1) ratio above
    ln(q/0.001), q Fourier frequencies: a Bonferroni pre-test) the AR model is fitted to e with that
    line removed (:func:`_line_free`) and then applied to e: the colour is whitened, the line is left
    in. Below that level the AR model is fitted to e itself (removing the largest ordinate of a null
    record would deepen the whitened peak and inflate the size). The reported frequency is the refined peak of v's
    periodogram (parabola on the log of a 4× zero-padded periodogram)."""
    x0 = np.asarray(e, float) - float(np.mean(e))
    clean, ratio = _line_free(x0)
    q_all = max(1, (len(x0) - 1) // 2)
    a = ar_coefficients(clean if ratio > math.log(q_all / 1e-3) else x0)
    p_ar = len(a)
    x = x0[p_ar:] - sum(a[i] * x0[p_ar - 1 - i:len(x0) - 1 - i] for i in range(p_ar)) if p_ar else x0
    n = len(x)
    x = x - x.mean()
    per = np.abs(np.fft.rfft(x)) ** 2
    per = per[1:(n - 1) // 2 + 1]  # exclude 0 and Nyquist
    q = len(per)
    j = int(np.argmax(per))
    g = float(per[j] / per.sum())
    p = fisher_g_pvalue(g, q)
    # refine the peak with a parabola on the log periodogram of a 4x zero-padded FFT
    pad = np.abs(np.fft.rfft(x, 4 * n)) ** 2
    k = int(np.argmax(pad[4:len(pad) - 1])) + 4
    y0, y1, y2 = np.log(pad[k - 1:k + 2] + 1e-300)
    den = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / den if den != 0 else 0.0
    f = (k + float(np.clip(shift, -0.5, 0.5))) / (4 * n)
    # critical value: solve P(g > x) = alpha with the first-term approximation
    crit = 1 - (alpha / q) ** (1 / (q - 1))
    return TestResult("fisher_g", g, p, float(crit), p >= alpha,
                      f"peak at {f:.6g} cycles/sample; on the AR({len(a)})-prewhitened residual (Yule-Walker, "
                      f"AIC)"), f


def fisher_g_pvalue(g: float, q: int) -> float:
    """P(G > g) for Fisher's g with q Fourier frequencies (exact alternating sum, log-space terms)."""
    total = 0.0
    for j in range(1, q + 1):
        base = 1 - j * g
        if base <= 0:
            break
        lt = gammaln(q + 1) - gammaln(j + 1) - gammaln(q - j + 1) + (q - 1) * math.log(base)
        total += (-1) ** (j - 1) * math.exp(lt)
    return float(min(max(total, 0.0), 1.0))


@dataclass
class WaldResult:
    beta: np.ndarray
    cov: np.ndarray
    statistic: float
    dof: int
    p_value: float
    r2: float = 0.0      # share of the residual's sum of squares the added columns explain (partial R²)
    share: float | None = None   # the same share before the GLS filter: the linearised refit's SSE drop


def column_basis(J: np.ndarray) -> np.ndarray:
    """Orthonormal basis U_r of the column space of J as ``np.linalg.lstsq`` sees it: the left singular
    vectors whose singular values exceed its default cutoff ε·max(N, k)·σ_max, so that
    S − U_r U_rᵀ S = S − J lstsq(J, S) (J J⁺ = U_r U_rᵀ; Golub & Van Loan 2013, §5.5.4). Computed once
    for a fit, it serves every hypothesis' test against that fit (:func:`added_terms_test`)."""
    J = np.asarray(J, float)
    if not J.size:
        return np.zeros((J.shape[0], 0))
    u, sv, _ = np.linalg.svd(J, full_matrices=False)
    keep = sv > np.finfo(float).eps * max(J.shape) * (sv[0] if len(sv) else 0.0)
    return np.ascontiguousarray(u[:, keep])


DETERMINED_RTOL = 1e-6    # a direction of S is determined when its singular value after the projection exceeds this × max ‖S_j‖


def determined(S: np.ndarray, basis: np.ndarray, rtol: float = DETERMINED_RTOL) -> np.ndarray:
    """The directions of S's column space that the current parameters cannot already produce and the
    record determines: S⊥ = S − U_r U_rᵀ S (``basis`` = :func:`column_basis` of J), then its left
    singular directions scaled by their singular values, σ_i·u_i, for σ_i > ``rtol``·max_j ‖S_j‖ (as
    ``adequacy.model_error_model`` keeps a smooth input's well-determined lags). A probe term collinear
    with a free parameter's sensitivity (an output gain beside an input gain) leaves a column of rounding
    noise after the projection, which a Wald test would treat as a regressor. When every direction is
    determined S itself is returned, so such a test is exactly the test on S (the kept directions span
    the same space, but the HAC estimate's design correction is not exactly invariant to the basis)."""
    S = np.atleast_2d(np.asarray(S, float).T).T
    scale = float(np.max(np.linalg.norm(S, axis=0))) if S.size else 0.0
    Sp = S - basis @ (basis.T @ S) if basis is not None and basis.size else S
    if not scale > 0:
        return Sp[:, :0]
    u, sv, _, keep = _kept_directions(S, Sp, rtol)
    return S if keep.all() else u[:, keep] * sv[keep]


def _kept_directions(S: np.ndarray, Sp: np.ndarray, rtol: float = DETERMINED_RTOL):
    """The SVD u, σ, vᵀ of the projected columns Sp and which directions are determined:
    σ_i > ``rtol``·max_j ‖S_j‖ (:func:`determined`)."""
    u, sv, vt = np.linalg.svd(Sp, full_matrices=False)
    return u, sv, vt, sv > rtol * float(np.max(np.linalg.norm(S, axis=0)))


def added_terms_test(e: np.ndarray, J: np.ndarray, S: np.ndarray, basis: np.ndarray | None = None) -> WaldResult:
    """Does adding the columns S (output sensitivities of new parameters) explain the residual e,
    beyond the current parameters' sensitivities J? Regress e on S⊥ = (I − J J⁺) S (Frisch–Waugh),
    Wald statistic W = βᵀ V⁻¹ β with V the sandwich A⁻¹ Ω A⁻¹, A = S⊥ᵀS⊥.

    Ω is the long-run covariance of the score rows S⊥_t e_t at the *restricted* residual e (the LM /
    score form: under H0 the sum Σ S⊥_t e_t is not forced to zero, so its low frequencies are not
    removed from the estimate), by the prewhitened equal-weighted-cosine estimator (:mod:`pipeline.hac`;
    Andrews & Monahan 1992; Lazarus, Lewis, Stock & Watson 2018). W is referred to the fixed-b law
    W·(ν − q + 1)/(ν q) ~ F(q, ν − q + 1) (Lazarus et al. 2018, eq. (11); Kiefer & Vogelsang 2005)
    with ν the Satterthwaite degrees of freedom of the estimate (:func:`pipeline.hac.satterthwaite_dof`),
    whose design part is, for several columns, the dof of the q×q estimate as one Wishart matrix
    (:func:`pipeline.hac.joint_design_dof`, the "HTZ" test of Tipton & Pustejovsky 2015). Plain Newey–West with a χ² reference
    rejected 2.8 % (φ = 0.9) and 6.2 % (φ = 0.97) at nominal 1 % on AR(1) residuals.

    Before that, with ``GLS`` (default), the regression is AR-filtered (feasible GLS, Cochrane &
    Orcutt 1949): an AR(p) fitted to the unrestricted OLS residual filters e, J and S. Without it the
    EWC estimate of very smooth scores keeps few degrees of freedom and the test lost its power on
    large misfits (an input saturation explaining 88 % of the validation error was not significant);
    the Monte Carlo size tests (``tests/diagnosis/test_mc_calibration.py``) hold with it.

    ``basis``: :func:`column_basis` of J, when many tests share J (the same projection, computed once)."""
    S = np.atleast_2d(S.T).T
    e = np.asarray(e, float)
    J = np.asarray(J, float).reshape(len(e), -1)
    share = None
    back = None          # (q × k) map from the determined directions' coefficients to S's columns

    def off_J(X: np.ndarray) -> np.ndarray:
        """X projected off J's columns (on ``basis`` when given)."""
        if basis is not None:
            return X - basis @ (basis.T @ X)
        return X - J @ np.linalg.lstsq(J, X, rcond=None)[0] if J.size else X

    S0 = None            # S projected off J's columns, computed once
    if J.size and S.size:
        # a direction of S that J already produces (an output gain beside a free input gain) leaves a
        # column of rounding noise after the projection, which the Wald statistic would take for a
        # regressor: with one such column among six, 40 of 100 null records rejected at 5 %. Only the
        # determined directions are tested (:func:`determined`), S itself when all of them are. Their
        # coefficients are mapped back to S's columns (S⊥V_k = U_kΣ_k, so β = V_k β_k, the minimum-norm
        # coefficients, and cov = V_k cov_k V_kᵀ), so callers read β and cov column by column as before
        S0 = off_J(S)
        u, sv, vt, keep = _kept_directions(S, S0)
        if not keep.all():
            q0 = S.shape[1]
            S, back, S0 = u[:, keep] * sv[keep], vt[keep].T, None
            if not S.shape[1]:
                return WaldResult(np.zeros(q0), np.zeros((q0, q0)), 0.0, 0, 1.0, 0.0, 0.0)
    if GLS:
        # feasible GLS (Cochrane & Orcutt 1949): an AR(p) (Yule–Walker, p ≤ GLS_PMAX by AIC) fitted to
        # the unrestricted OLS residual filters e, J and S alike, so the long-run variance below is that
        # of nearly white scores and keeps its degrees of freedom when the residual is very smooth
        if S0 is None:
            S0 = off_J(S)
        eu0 = e - S0 @ np.linalg.lstsq(S0, e, rcond=None)[0]
        e0 = float(e @ e)
        share = float(1.0 - float(eu0 @ eu0) / e0) if e0 > 0 else 0.0
        a = ar_coefficients(eu0, GLS_PMAX)
        if len(a) and len(e) > 4 * (len(a) + S.shape[1] + J.shape[1]):
            e, J, S = _ar_filter(e, a), _ar_filter(J, a), _ar_filter(S, a)
    if J.size:
        S = S - J @ np.linalg.lstsq(J, S, rcond=None)[0]
    beta = np.linalg.lstsq(S, e, rcond=None)[0]
    eu = e - S @ beta
    A_inv = np.linalg.pinv(S.T @ S)
    kappa, nu_c = hac.design_correction(np.column_stack([J, S]) if J.size else S, S)
    lr = hac.long_run(S * eu[:, None], base_dof=nu_c)
    V = A_inv @ lr.omega @ A_inv / max(kappa, 0.05)
    q = S.shape[1]
    try:
        stat = float(beta @ np.linalg.solve(V, beta))
    except np.linalg.LinAlgError:
        stat = 0.0
    if not math.isfinite(stat):
        stat = 0.0
    nu = max(float(lr.dof), float(q))
    p = float(stats.f.sf(stat * (nu - q + 1) / (nu * q), q, nu - q + 1))
    ee = float(e @ e)
    r2 = float(1.0 - float(eu @ eu) / ee) if ee > 0 else 0.0
    if back is not None:
        beta, V = back @ beta, back @ V @ back.T
    return WaldResult(beta, V, stat, q, p, r2, r2 if share is None else share)


GLS = True
GLS_PMAX = 10


def _ar_filter(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """v_t = x_t − Σ_i a_i x_{t−i}, t = p..N−1, column by column (the AR(p) prediction error filter).

    Each v_t is x_t minus the lag terms in the order i = 1..p, the arithmetic of a whole-array numpy
    loop over the lags (``x[p:] − a_1 x[p−1:−1] − …``), so the values are the same to the last bit
    (``tests/test_stats.py``). A compiled loop (:func:`_ar_filter_kernel`), four samples at a
    time: Silverbox's added-term tests filter about 90 000 × 6 values with p = 10, 6.1 ms in numpy
    (blocked to stay in cache), 2.4 ms compiled, one thread; the kernel releases the GIL."""
    x = np.asarray(x, float)
    a = np.ascontiguousarray(a, dtype=float)
    if x.ndim == 1:
        return _ar_filter_kernel(np.ascontiguousarray(x)[:, None], a)[:, 0]
    return _ar_filter_kernel(np.ascontiguousarray(x), a)


@njit(cache=True, nogil=True)
def _ar_filter_kernel(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """:func:`_ar_filter` of the columns of a C-ordered (N, k) array. Each output is one chain of
    subtractions in the lag order i = 1..p; four consecutive samples are computed side by side (four
    independent chains, so the processor overlaps their latencies; the values are unchanged)."""
    p = a.shape[0]
    n, k = x.shape
    m = max(n - p, 0)
    out = np.empty((m, k))
    col = np.empty(n)
    for c in range(k):
        for t in range(n):
            col[t] = x[t, c]
        t = 0
        while t + 4 <= m:
            v0, v1, v2, v3 = col[t + p], col[t + p + 1], col[t + p + 2], col[t + p + 3]
            for i in range(p):
                ai = a[i]
                s = t + p - 1 - i
                v0 -= ai * col[s]
                v1 -= ai * col[s + 1]
                v2 -= ai * col[s + 2]
                v3 -= ai * col[s + 3]
            out[t, c], out[t + 1, c], out[t + 2, c], out[t + 3, c] = v0, v1, v2, v3
            t += 4
        while t < m:
            v = col[t + p]
            for i in range(p):
                v -= a[i] * col[t + p - 1 - i]
            out[t, c] = v
            t += 1
    return out


def effective_n(n: int, rho: float) -> tuple[float, float]:
    """(ρ clipped to [0, 0.999], N_eff = N(1 − ρ)/(1 + ρ)): the number of independent samples a sum of
    squares of an AR(1) residual with lag-1 autocorrelation ρ carries (Bartlett 1946; Bayley &
    Hammersley 1946). A negatively correlated residual is not given more than N samples; a non-finite ρ
    counts as 0."""
    r = float(min(max(rho, 0.0), 0.999)) if math.isfinite(rho) else 0.0
    return r, n * (1.0 - r) / (1.0 + r)


def lr_test(rss0: float, rss1: float, n: int, q: int, rho: float, alpha: float = 0.01,
            break_trim: float | None = None) -> TestResult:
    """Likelihood-ratio test of a refit with q more parameters against the current model, with the
    effective sample size of an AR(1) residual.

    Gaussian LR = N ln(RSS₀/RSS₁) ~ χ²_q for independent errors (Wilks 1938). With residual lag-1
    autocorrelation ρ the sums of squares carry the information of N_eff = N(1 − ρ)/(1 + ρ)
    independent samples (the variance inflation (1 + ρ)/(1 − ρ) of a mean of an AR(1) series; Bartlett
    1946, Bayley & Hammersley 1946), so the statistic used is N_eff ln(RSS₀/RSS₁) ~ χ²_q. ρ is clipped
    to [0, 0.999]: a negatively correlated residual is not given more than N samples.

    ρ is that of the **alternative's** (refitted) residual. Under the null the two residuals nearly
    coincide, and the size stays ≤ 1.5 α (Monte Carlo in ``tests/diagnosis/test_mc_calibration.py``).
    Under the alternative the current model's residual carries the missing effect itself: a large,
    smooth misfit (a periodic disturbance of 190 samples per cycle) has lag-1 autocorrelation 0.9995,
    N_eff fell below one sample and a 98 % validation gain was rejected (p = 0.052).

    ``break_trim``: the refit adds one coefficient's jump at a date searched over [trim, 1 − trim] of
    the sample; the p-value is then :func:`sup_lr_break_p`'s (``q`` is not used)."""
    r, n_eff = effective_n(n, rho)
    if rss1 <= 0 or rss0 <= 0:
        stat = 0.0 if rss0 <= rss1 else float("inf")
    else:
        stat = float(max(0.0, n_eff * math.log(rss0 / rss1)))
    # q = 0 (an alternative with as many parameters, e.g. another input interpolation): no χ² law;
    # any fall of the RSS is the better fit (the ΔBIC < 0 rule for equal parameter counts)
    if break_trim is not None:   # one coefficient's jump, its date searched: the sup-LR law
        p = sup_lr_break_p(stat, break_trim)
        law = (f"maximised over the break date (sup-LR, trimming {break_trim:.3g}; James, James & "
               "Siegmund 1987)")
    else:
        p = float(stats.chi2.sf(stat, q)) if q > 0 else (0.0 if stat > 0 else 1.0)
        law = f"~ chi2({q})"
    return TestResult("likelihood_ratio_neff", stat, p, float(stats.chi2.isf(alpha, max(q, 1))), p >= alpha,
                      f"N_eff ln(RSS0/RSS1) {law}, N = {n}, lag-1 autocorrelation {r:.3g}, N_eff = {n_eff:.1f}")


def sup_lr_break_p(stat: float, trim: float) -> float:
    """p-value of a likelihood-ratio statistic maximised over the date of a break in one coefficient,
    the date searched over [trim, 1 − trim] of the sample (Andrews 1993, Econometrica 61(4): sup-LR,
    p = 1). Under the null the statistic is the supremum of B(π)²/(π(1 − π)), B a Brownian bridge,
    whose tail is (James, James & Siegmund 1987, Biometrika 74(1), eq. 3.6; b = √stat)

        P(sup > b²) ≈ b φ(b) [(1 − 1/b²) ln((1 − π₀)²/π₀²) + 4/b²],

    which gives 1.0 % at Andrews' tabulated 1 % value 12.35 for π₀ = 0.15 (checked by Monte Carlo of
    the bridge in ``tests/test_stats.py``). Never below the fixed-date χ²₁ p-value, at most 1."""
    if not math.isfinite(stat):
        return 0.0
    c = max(float(stat), 0.0)
    p_fixed = float(stats.chi2.sf(c, 1))
    if c <= 1.0:
        return 1.0
    b = math.sqrt(c)
    tail = b * math.exp(-0.5 * c) / math.sqrt(2.0 * math.pi) * (
        (1.0 - 1.0 / c) * math.log((1.0 - trim) ** 2 / trim ** 2) + 4.0 / c)
    return float(min(1.0, max(p_fixed, tail)))


def lag1(e: np.ndarray) -> float:
    """Lag-1 sample autocorrelation r₁ = Σ ẽ_t ẽ_{t−1}/Σ ẽ_t² (ẽ centred; Box & Jenkins 1976 eq. 2.1.12),
    the largest over the columns of a multi-output residual."""
    e = np.atleast_2d(np.asarray(e, float).T).T
    out = 0.0
    for a in range(e.shape[1]):
        x = e[:, a] - e[:, a].mean()
        den = float(x @ x)
        if den > 0 and len(x) > 2:
            out = max(out, float(x[1:] @ x[:-1]) / den)
    return out


def holm(pvalues: dict[str, float], alpha: float) -> dict[str, bool]:
    """Holm (1979) step-down: reject p_(i) while p_(i) <= alpha/(m − i + 1)."""
    order = sorted(pvalues, key=lambda k: pvalues[k])
    m = len(order)
    out = {k: False for k in pvalues}
    for i, k in enumerate(order):
        if pvalues[k] <= alpha / (m - i):
            out[k] = True
        else:
            break
    return out
