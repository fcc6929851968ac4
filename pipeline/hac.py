"""Long-run (HAC) covariance of a vector series that stays honest when the series is smooth.

Output-error residuals of a slightly wrong model have lag-1 autocorrelation 0.9–0.98, and so do the
score rows g_t = x_t e_t built from them. A Newey–West/Bartlett estimate with a bandwidth of a few dozen
lags then misses most of the long-run variance and tests over-reject. Two published remedies are
combined here:

* **Prewhitening** (Andrews & Monahan 1992, Econometrica 60(4), 953–966): fit a VAR(1)
  g_t = A g_{t−1} + v_t by least squares, estimate the long-run covariance Ω_v of the whitened rows
  v_t, recolour Ω = (I − A)⁻¹ Ω_v (I − A)⁻ᵀ. Andrews & Monahan shrink A by its singular values so
  (I − A) stays invertible; the cap here is :data:`A_CAP`. The least-squares A is biased towards 0 by
  about −(1 + 3ρ)/T for an AR(1) (Kendall 1954; Marriott & Pope 1954); that first-order bias is added
  back to each singular value before the cap, because at ρ ≈ 0.95 and T = 1000 it alone shrinks
  (1 − ρ)⁻² by a fifth.
* **Fixed-b / equal-weighted cosine (EWC) estimator** on the whitened rows (Lazarus, Lewis, Stock &
  Watson 2018, "HAR inference: recommendations for practice", JBES 36(4) 541–559, eq. (8) and §4):
  Ω_v = (1/B) Σ_{j=1}^{B} Λ_j Λ_jᵀ, Λ_j = √(2/T) Σ_t v_t cos(π j (t − ½)/T), with B =
  ⌈0.4 T^{2/3}⌉ cosines. With this estimator a Wald statistic W over q restrictions is referred to
  F(q, ν − q + 1) after scaling W·(ν − q + 1)/(ν q) (their eq. (11)), a t statistic to Student's t_ν;
  the χ² limit would ignore the estimator's own variance. ν is B corrected by Satterthwaite (1946) for
  the variance the estimated prewhitening factor adds (:func:`satterthwaite_dof`); without it,
  prewhitened tests still rejected 2–2.5 % at nominal 1 % on AR(1) residuals with φ = 0.9–0.97.

All covariances are returned on the *sum* scale (≈ gᵀg for white rows, T × the long-run covariance),
like :func:`pipeline.diagnostics.stats.long_run_variance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.fft import dct, next_fast_len
from scipy.linalg import qr
from scipy.stats import chi2
from scipy.stats import f as f_dist

A_CAP = 0.99   # largest singular value allowed for the prewhitening VAR(1) matrix


@dataclass
class LongRun:
    """A long-run covariance estimate with the degrees of freedom of its fixed-b reference law."""

    omega: np.ndarray      # (q, q), sum scale
    dof: float             # ν of the reference law (Student t_ν / F(q, ν − q + 1) critical values)
    a: np.ndarray          # the (bias-corrected, capped) prewhitening VAR(1) matrix


def ewc_dof(n: int) -> int:
    """ν = B = ⌈0.4 T^{2/3}⌉ cosines (Lazarus et al. 2018, rule (9) for the EWC estimator), 2 ≤ B ≤ T/2."""
    return int(max(2, min(n // 2, math.ceil(0.4 * n ** (2.0 / 3.0)))))


def satterthwaite_dof(b: float, rho: np.ndarray, var_rho: np.ndarray) -> float:
    """Degrees of freedom of the reference law of a prewhitened EWC estimate.

    Ω̂ = (1 − ρ̂)⁻² Ω̂_v has two sources of error: Ω̂_v ~ Ω_v χ²_B/B (relative variance 2/B; Lazarus et
    al. 2018 §2), and the recolouring factor, whose log has variance 4 var(ρ̂)/(1 − ρ)² by the delta
    method. Matching var(ln Ω̂) ≈ 2/B + 4 var(ρ̂)/(1 − ρ)² to that of a scaled χ²_ν/ν, 2/ν
    (Satterthwaite 1946), gives ν. var(ρ̂) is the Eicker–White (HC0) variance of the AR(1) slope,
    Σ x_{t−1}² v_t² / (Σ x_{t−1}²)² (White 1980), not the Gaussian (1 − ρ²)/T (Bartlett 1946): squared
    residuals (the gain's loss rows) are conditionally heteroscedastic, and the Gaussian value made ν
    twice too large at φ = 0.98. With several columns the largest term is used (conservative)."""
    rho = np.minimum(np.maximum(np.asarray(rho, float), 0.0), A_CAP)
    extra = float(np.max(4.0 * np.asarray(var_rho, float) / (1.0 - rho) ** 2)) if rho.size else 0.0
    return float(2.0 / (2.0 / b + extra))


def dof_with_base(dof: float, base_used: float, base: np.ndarray) -> np.ndarray:
    """The degrees of freedom :func:`satterthwaite_dof` gives the same prewhitened estimate when its EWC
    part has ``base`` degrees of freedom instead of ``base_used``: its recolouring term
    2/ν − 2/b_used is kept, ν' = 2/(2/b' + that term). Used for each parameter's own ν beside the
    smallest one (:func:`pipeline.fit.scaled_covariance`)."""
    extra = max(2.0 / float(dof) - 2.0 / float(base_used), 0.0)
    return 2.0 / (2.0 / np.asarray(base, float) + extra)


def var1(g: np.ndarray, cap: float = A_CAP) -> np.ndarray:
    """Least-squares VAR(1) matrix of the rows of g (N×q, centred by the caller), each singular value
    raised by the AR(1) first-order bias (1 + 3σ)/N (Kendall 1954) and capped at ``cap``
    (Andrews & Monahan 1992, §3: singular-value truncation keeps I − A invertible)."""
    x0, x1 = g[:-1], g[1:]
    n = g.shape[0]
    xx = x0.T @ x0
    if not np.all(np.isfinite(xx)) or np.linalg.matrix_rank(xx) < g.shape[1]:
        return np.zeros((g.shape[1], g.shape[1]))
    a = np.linalg.solve(xx, x0.T @ x1).T          # g_t ≈ a g_{t−1}
    u, s, vt = np.linalg.svd(a)
    s = np.minimum(s + (1.0 + 3.0 * s) / n, cap)
    return (u * s) @ vt


def cosine_transform(x: np.ndarray, b: int) -> np.ndarray:
    """(B, q) Λ_j = √(2/N) Σ_t x_t cos(π j (t + ½)/N), j = 1..B (Lazarus et al. 2018, eq. (8)), from
    scipy's DCT-II y_j = 2 Σ_t x_t cos(π j (t + ½)/N) in O(N log N): Λ_j = √(2/N) y_j / 2."""
    n = x.shape[0]
    y = dct(np.asarray(x, float), type=2, axis=0)
    return y[1:b + 1] * (math.sqrt(2.0 / n) / 2.0)


def design_terms(x: np.ndarray, s: np.ndarray, b: int | None = None, *, ny: int = 1,
                 var: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per column a of s: bias factor κ_a and Satterthwaite degrees of freedom ν_a of the EWC estimate
    of the long-run variance of scores s_{t,a} ε_t when ε is white and replaced by its least-squares
    residual on the columns of x (N×k), given the design (Bell & McCaffrey 2002, bias-reduced
    linearisation and its Satterthwaite df, applied to the EWC estimator of Lazarus et al. 2018).

    With W = [cos_j ⊙ s_a]_j (N×B) and M = I − x x⁺, the cosine transforms Λ = WᵀMε have covariance
    σ²C, C = WᵀMW, so E Σ_j Λ_j² = σ² tr C (the unprojected, stationary value is σ² tr WᵀW: κ is their
    ratio) and var Σ_j Λ_j² = 2σ⁴ tr C², i.e. ν = (tr C)²/tr C². Two effects of smooth regressors are
    in it: the projection removes the lowest frequencies, where the estimate lives (κ < 1), and a
    slowly varying s_t² makes the Λ_j correlated, so B cosines carry fewer than B degrees of freedom.

    ``ny`` > 1: the rows of x and s are N samples × ny outputs, sample-major, and the score of sample t
    sums its outputs, g_{t,a} = Σ_o s_{(t,o),a} ε_{t,o} (an output-error fit of several outputs,
    :func:`pipeline.fit.score_rows`); ``var`` (ny,) are the outputs' residual variances (ε_{t,o} white
    with variance var_o; ones when omitted). See :func:`_design_terms_outputs`."""
    if ny > 1 or var is not None:
        return _design_terms_outputs(x, s, b, ny, np.ones(ny) if var is None else np.asarray(var, float))
    x, s = _fast_rows(x), _fast_rows(s)
    n = x.shape[0]
    b = int(min(ewc_dof(n) if b is None else b, n // 2))
    # scipy's economic Householder QR of a Fortran-ordered copy that it may overwrite: the same
    # factorisation as numpy's default, 4× faster on a Silverbox-length design (92 000 × 9: 4.8 ms vs
    # 20 ms, one thread; without overwrite_a scipy copies again, 12.6 ms)
    q = qr(np.array(x, order="F"), mode="economic", check_finite=False, overwrite_a=True)[0]
    qt = np.ascontiguousarray(q.T)       # (k, N): the DCTs below run along contiguous rows
    kap, nus = np.ones(s.shape[1]), np.full(s.shape[1], float(b))
    for a in range(s.shape[1]):
        sa = s[:, a]
        # WᵀW_jk = (2/N) Σ s² cos_j cos_k = (1/N) Σ s² (cos_{j−k} + cos_{j+k}) from one DCT-II of s²:
        # a Toeplitz plus a Hankel matrix in y (y[|j−k|] + y[j+k+2] with the index shift, gathered)
        y = np.concatenate([dct(sa * sa, type=2), [0.0]]) / 2.0       # index N: cos(π N(t+½)/N) = 0
        if b < TRACE_FFT_FROM:
            it, ih = _toeplitz_hankel_index(b)
            wtw = (y[it] + y[ih]) / n
            tot = float(np.trace(wtw))
        else:
            y = y / n
            tot = b * float(y[0]) + float(np.sum(y[2:2 * b + 1:2]))    # tr WᵀW = Σ_j (y_0 + y_{2j+2})
        if tot <= 0:
            continue
        wq = (dct(qt * sa, type=2, axis=-1)[:, 1:b + 1] * (math.sqrt(2.0 / n) / 2.0)).T   # (B, k) = Wᵀq
        if b < TRACE_FFT_FROM:                                         # small B: C = WᵀMW formed
            c = wtw - wq @ wq.T
            tr, tc2 = float(np.trace(c)), float(np.sum(c * c))
        else:                                                          # large B: no B×B matrix
            tr = tot - float(np.sum(wq * wq))                          # tr WᵀMW = tr WᵀW − ‖Wᵀq‖²
            tc2 = _trace_c2(y, b, wq)
        if tr > 0:
            kap[a], nus[a] = tr / tot, tr * tr / tc2
    return kap, nus


def _design_terms_outputs(x: np.ndarray, s: np.ndarray, b: int | None, ny: int,
                          var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`design_terms` for rows of N samples × ny outputs (sample-major) whose white errors have
    per-output variances Σ = diag(var_o) (the weighted outputs of one fit are not equally well fitted).

    The cosine weights act on the sample index: W_a = [cos_j(t) s_{(t,o),a}] (Nny×B), Λ = W_aᵀMε with
    M = I − QQᵀ (Q an orthonormal basis of x over all Nny rows), so
    C = cov Λ = W_aᵀMΣMW_a = W_aᵀΣW_a − A Pᵀ − P Aᵀ + A (QᵀΣQ) Aᵀ with A = W_aᵀQ and P = W_aᵀΣQ;
    κ_a = tr C / tr W_aᵀΣW_a and ν_a = (tr C)²/tr C² as for one output. Every term is a sum over samples
    of per-sample sums over the outputs, so it is the one-output computation on those sums: W_aᵀΣW_a is
    the Toeplitz-plus-Hankel matrix of the DCT of Σ_o var_o s², A and P the DCTs of Σ_o s Q and
    Σ_o var_o s Q. For ny = 1 and var = 1 it equals :func:`design_terms` (checked in
    ``tests/diagnosis/test_mc_calibration.py`` against C formed from its definition). C is formed (B×B); beyond
    ``OUTPUTS_MAX_B`` cosines (records of about 240 000 samples) the classic (Nny − k)/(Nny) and ν = B are
    returned instead."""
    x, s = np.asarray(x, float), np.asarray(s, float)
    n = x.shape[0] // ny
    m = _fast_len(n)
    x, s = x[(n - m) * ny:], s[(n - m) * ny:]
    n = m
    b = int(min(ewc_dof(n) if b is None else b, n // 2))
    p = s.shape[1]
    if b > OUTPUTS_MAX_B or b < 1:
        k = x.shape[1]
        return np.full(p, max(n * ny - k, 1) / (n * ny)), np.full(p, float(max(b, 1)))
    q = qr(np.array(x, order="F"), mode="economic", check_finite=False, overwrite_a=True)[0]   # (Nny, k)
    k = q.shape[1]
    sig = np.tile(var, n)
    g = q.T @ (q * sig[:, None])                                                   # QᵀΣQ
    it, ih = _toeplitz_hankel_index(b)
    scale = math.sqrt(2.0 / n) / 2.0
    kap, nus = np.ones(p), np.full(p, float(b))
    for a in range(p):
        sa = s[:, a]
        y = np.concatenate([dct((sig * sa * sa).reshape(n, ny).sum(axis=1), type=2), [0.0]]) / 2.0
        wsw = (y[it] + y[ih]) / n                                                  # W_aᵀΣW_a
        tot = float(np.trace(wsw))
        if tot <= 0:
            continue
        qs = (q * sa[:, None]).reshape(n, ny, k).sum(axis=1).T                     # (k, N): Σ_o s Q
        qss = (q * (sig * sa)[:, None]).reshape(n, ny, k).sum(axis=1).T            # Σ_o var s Q
        A = (dct(qs, type=2, axis=-1)[:, 1:b + 1] * scale).T
        P = (dct(qss, type=2, axis=-1)[:, 1:b + 1] * scale).T
        c = wsw - A @ P.T - P @ A.T + A @ g @ A.T
        tr = float(np.trace(c))
        if tr > 0:
            kap[a], nus[a] = tr / tot, tr * tr / float(np.sum(c * c))
    return kap, nus


OUTPUTS_MAX_B = 1500    # _design_terms_outputs forms B×B matrices up to this many cosines


def _trace_c2(y: np.ndarray, b: int, wq: np.ndarray) -> float:
    """tr C² for C = WᵀW − (Wᵀq)(Wᵀq)ᵀ, WᵀW_jk = y_{|j−k|} + y_{j+k+2} (j, k < B), without forming a
    B×B matrix: tr C² = ‖WᵀW‖²_F − 2 tr(qᵀW WᵀW Wᵀq) + ‖qᵀWWᵀq‖²_F.

    * ‖WᵀW‖²_F in O(B): the Toeplitz part Σ_d (multiplicity of d) y_d², the Hankel part
      Σ_m (multiplicity of m) y_{m+2}², and the cross term Σ_{jk} y_{|j−k|} y_{j+k+2}: for a fixed
      d = |j − k| the sum j + k = m runs over d, d + 2, …, 2B − 2 − d, a prefix-sum difference over one
      parity of m.
    * the quadratic forms by FFT in O(kB log B): Σ_c w_cᵀ T w_c = Σ_d y_{|d|} r(d) with r the columns'
      summed autocorrelation, Σ_c w_cᵀ H w_c = Σ_m y_{m+2} (w_c ∗ w_c)(m) their summed self-convolution.

    The difference cancels when the projection removes nearly all of WᵀW; below 10⁻⁶ of ‖WᵀW‖² the
    explicit B×B form is used instead; :func:`design_terms` forms C itself for B < ``TRACE_FFT_FROM``
    (faster there: 47 µs against 104 µs at B = 100, 0.90 ms against 0.16 ms at B = 300, k = 8). Both
    agree to 4·10⁻¹⁵ relative on 300 random designs (N = 50–20 000)."""
    d = np.arange(b)
    yd, z = y[:b], y[2:2 * b + 1]                        # z[m] = y_{m+2}, m = 0 … 2B − 2
    m = np.arange(2 * b - 1)
    t2 = float(np.sum(np.where(d == 0, b, 2 * (b - d)) * yd * yd))
    h2 = float(np.sum(np.minimum(m + 1, 2 * b - 1 - m) * z * z))
    cross = 0.0
    for par in (0, 1):
        zp = np.concatenate([[0.0], np.cumsum(z[par::2])])   # zp[i] = Σ_{i' < i} z[par + 2i']
        dd = d[par::2]                                       # m from dd to 2B − 2 − dd, step 2
        lo, hi = (dd - par) // 2, (2 * b - 2 - dd - par) // 2 + 1
        cross += float(np.sum(np.where(dd == 0, 1.0, 2.0) * yd[dd] * (zp[hi] - zp[lo])))
    ww = t2 + h2 + 2.0 * cross
    L = next_fast_len(2 * b - 1, real=True)
    f = np.fft.rfft(wq, L, axis=0)
    r = np.fft.irfft(np.sum(f.real ** 2 + f.imag ** 2, axis=1), L)[:b]      # Σ_c autocorrelation, lags 0…B−1
    cv = np.fft.irfft(np.sum(f * f, axis=1), L)[:2 * b - 1]                # Σ_c self-convolution
    quad = float(yd[0] * r[0] + 2.0 * np.dot(yd[1:], r[1:]) + np.dot(z, cv))
    g = wq.T @ wq
    tc2 = ww - 2.0 * quad + float(np.sum(g * g))
    return tc2 if tc2 > TRACE_CANCEL * ww else _trace_c2_explicit(y, b, wq)


TRACE_FFT_FROM = 160    # B from which _trace_c2 avoids the B×B matrix (N ≳ 8 000 samples)
TRACE_CANCEL = 1e-6     # below this fraction of ‖WᵀW‖² the FFT form of tr C² has cancelled: C is formed


def _trace_c2_explicit(y: np.ndarray, b: int, wq: np.ndarray) -> float:
    """tr C² from C formed explicitly (the Toeplitz-plus-Hankel WᵀW gathered, minus (Wᵀq)(Wᵀq)ᵀ)."""
    it, ih = _toeplitz_hankel_index(b)
    c = y[it] + y[ih] - wq @ wq.T
    return float(np.sum(c * c))


_TH_INDEX: dict = {}


def _toeplitz_hankel_index(b: int) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays |j − k| and j + k + 2 (j, k < b): y[it] + y[ih] is toeplitz(y[:b]) +
    hankel(y[2:b + 2], y[b + 1:2b + 1]) element for element, gathered without scipy's strided copies
    (1.4 ms instead of 2.8 ms at b = 804, Silverbox's number of cosines)."""
    if b not in _TH_INDEX:
        if len(_TH_INDEX) > 16:
            _TH_INDEX.clear()
        i = np.arange(b)
        _TH_INDEX[b] = (np.abs(i[:, None] - i[None, :]), i[:, None] + i[None, :] + 2)
    return _TH_INDEX[b]


FAST_FROM = 4096     # design_terms trims longer series to a length the FFT handles fast (see _fast_rows)
_FAST_M: dict[int, int] = {}


def _fast_rows(a: np.ndarray) -> np.ndarray:
    """The last m rows of a, m the largest length ≤ N whose prime factors are at most 11 (pocketfft's
    fast lengths), when N ≥ FAST_FROM. A DCT of a length with a large prime factor (Silverbox: N =
    90 422 = 2·29·1559) runs by Bluestein's algorithm, 8–10× slower; the gap to the next such length
    is under 0.5 % of N above 4096, and κ, ν are smooth averages over the sample (they change by
    O(gap/N); checked against the untrimmed values in tests/diagnosis/test_mc_calibration.py)."""
    n = a.shape[0]
    return a if n < FAST_FROM else a[n - _fast_len(n):]


def _fast_len(n: int) -> int:
    """The largest 11-smooth length ≤ n from ``FAST_FROM`` on (n itself below it); see :func:`_fast_rows`."""
    if n < FAST_FROM:
        return n
    m = _FAST_M.get(n)
    if m is None:
        m = n
        while next_fast_len(m, real=False) != m:
            m -= 1
        if len(_FAST_M) > 4096:
            _FAST_M.clear()
        _FAST_M[n] = m
    return m


def design_correction(x: np.ndarray, s: np.ndarray, b: int | None = None) -> tuple[float, float]:
    """κ of :func:`design_terms` for the column of s with the fewest degrees of freedom, and the degrees
    of freedom of the reference law: that column's ν for one column, the joint η of
    :func:`joint_design_dof` for several.

    Why not the smallest column's ν for several columns: Hotelling's reference F(q, ν − q + 1)·νq/(ν − q + 1)
    treats the q×q estimate as one Wishart matrix with ν degrees of freedom, and the columns' cosine
    sums are not that dependent. With that ν, added-term tests of q smooth columns (a regressor times sin
    and cos) rejected 0–2.7 % at nominal 5 % for q = 4 and 6 (N = 1000, ν ≈ 12–16; white and AR(1) 0.9
    residuals; mean p-value 0.605 where an exact test has 0.5); with η, 0.3–3.7 % (mean p 0.565): still
    conservative, less so, and never above the nominal size (``tests/diagnosis/test_mc_calibration.py``).
    For q ≤ 2 the two are nearly the same.

    η is not computed where it cannot matter or would cost too much: when the level-5 % critical value
    with ν is within ``JOINT_MIN_EFFECT`` of the χ² limit (η ≥ ν moves it less than that), and when q²B²,
    the size of its sum, exceeds ``JOINT_MAX_WORK`` (it also takes q(q + 1)/2 cosine transforms of the
    record: the FIR(15) row on Silverbox's 90 000 rows, B = 806, took 20 s for a critical value 1.5 %
    lower, ν = 495 against η = 746). There the smallest column's ν stays: conservative."""
    kap, nus = design_terms(x, s, b)
    if not len(nus):
        return 1.0, float(b or ewc_dof(x.shape[0]))
    i = int(np.argmin(nus))
    q, nu = len(nus), float(nus[i])
    bb = int(min(ewc_dof(x.shape[0]) if b is None else b, x.shape[0] // 2))
    if q == 1 or q * q * bb * bb > JOINT_MAX_WORK or \
            hotelling_critical(nu, q) < (1.0 + JOINT_MIN_EFFECT) * float(chi2.isf(0.05, q)):
        return float(kap[i]), nu
    return float(kap[i]), joint_design_dof(x, s, b)


JOINT_MIN_EFFECT = 0.03     # η is computed only when ν's critical value is this much above the χ² limit
JOINT_MAX_WORK = 20_000_000  # and q²B², its sum's size, is at most this (a FIR(15) on Silverbox: 1.5e8, 20 s)
JOINT_BLOCK = 4_000_000     # entries of the q×q×r×B slab :func:`joint_design_dof` holds at once


def hotelling_critical(nu: float, q: int, alpha: float = 0.05) -> float:
    """The level-α critical value of W under the fixed-b law W·(ν − q + 1)/(νq) ~ F(q, ν − q + 1), with
    ν floored at q as :func:`pipeline.diagnostics.stats.added_terms_test` floors it (the law needs
    ν − q + 1 > 0; a smaller ν used to be clipped to 10⁻³ denominator degrees of freedom, whose critical
    value overflowed to inf with a RuntimeWarning)."""
    nu = max(float(nu), float(q))
    return float(q * nu / (nu - q + 1.0) * f_dist.isf(alpha, q, nu - q + 1.0))


def joint_design_dof(x: np.ndarray, s: np.ndarray, b: int | None = None) -> float:
    """Degrees of freedom η of the q×q EWC estimate Ω̂ of the scores s_{t,a} ε_t (ε white, replaced by
    its least-squares residual on x) taken as one Wishart matrix: the "HTZ" approximation of Hotelling's
    T² (Zhang 2012; Tipton & Pustejovsky 2015, J. Educ. Behav. Stat. 40(6) 604–634;
    Pustejovsky & Tipton 2018, JBES 36(4) 672–683, §3.2; R's clubSandwich ``Wald_test(test = "HTZ")``
    computes it for cluster-robust covariances, here it is for the cosine estimate).

    With W_a = [cos_j ⊙ s_a]_j (N×B), M = I − x x⁺ and C^{ac} = W_aᵀ M W_c, the cosine transforms
    Λ_{ja} = (W_aᵀMε)_j are jointly Gaussian with cov(Λ_{ja}, Λ_{kc}) = σ² C^{ac}_{jk}. Standardise by
    L = E^{−1/2}, E_{ac} = tr C^{ac} (so that D = L (Σ_j Λ_j Λ_jᵀ) Lᵀ/σ² has mean I) and write
    C̃^{st} = Σ_{ac} L_{sa} L_{tc} C^{ac} (C̃^{ts} = C̃^{stᵀ}). By Isserlis' theorem var D_{st} =
    Σ_{jk} (C̃^{ss}_{jk} C̃^{tt}_{jk} + C̃^{st}_{jk} C̃^{ts}_{jk}), and a Wishart matrix with η degrees of
    freedom and mean I has Σ_{st} var D_{st} = q(q + 1)/η, so
    η = q(q + 1) / (‖Σ_s C̃^{ss}‖²_F + Σ_{st} ⟨C̃^{st}, C̃^{ts}⟩_F). For one column it is
    (tr C)²/tr C², the ν of :func:`design_terms`. Columns whose E is singular (collinear after the
    projection) count once: q is the rank of E."""
    x, s = _fast_rows(x), _fast_rows(s)
    n, q = s.shape
    b = int(min(ewc_dof(n) if b is None else b, n // 2))
    qx = qr(np.array(x, order="F"), mode="economic", check_finite=False, overwrite_a=True)[0]
    qt = np.ascontiguousarray(qx.T)
    scale = math.sqrt(2.0 / n) / 2.0
    wq = [(dct(qt * s[:, a], type=2, axis=-1)[:, 1:b + 1] * scale).T for a in range(q)]     # (B, k) each
    it, ih = _toeplitz_hankel_index(b)
    y = {}
    for a in range(q):
        for c in range(a, q):
            y[a, c] = np.concatenate([dct(s[:, a] * s[:, c], type=2), [0.0]]) / (2.0 * n)

    def block(a: int, c: int, j0: int, j1: int) -> np.ndarray:
        """Rows j0:j1 of C^{ac} = W_aᵀW_c − (W_aᵀq)(W_cᵀq)ᵀ (the Toeplitz-plus-Hankel form of design_terms)."""
        yy = y[min(a, c), max(a, c)]
        return yy[it[j0:j1]] + yy[ih[j0:j1]] - wq[a][j0:j1] @ wq[c].T

    E = np.array([[float(np.trace(block(a, c, 0, b))) for c in range(q)] for a in range(q)])
    lam, V = np.linalg.eigh(0.5 * (E + E.T))
    keep = lam > 1e-10 * max(float(lam.max()), 1e-300)
    r = int(keep.sum())
    if r == 0:
        return float(b)
    L = (V[:, keep] / np.sqrt(lam[keep])).T                     # (r, q): L E Lᵀ = I_r
    rows = max(1, JOINT_BLOCK // (q * q * b))
    s1 = s2 = 0.0
    for j0 in range(0, b, rows):
        j1 = min(b, j0 + rows)
        T = np.stack([np.stack([block(a, c, j0, j1) for c in range(q)]) for a in range(q)])   # (q, q, r', B)
        Ct = np.einsum("sa,acjk,tc->stjk", L, T, L, optimize=True)
        s1 += float(np.sum(Ct * Ct.transpose(1, 0, 2, 3)))
        d = np.einsum("ssjk->jk", Ct)
        s2 += float(np.sum(d * d))
    return float(r * (r + 1) / (s1 + s2)) if s1 + s2 > 0 else float(b)


def ewc(v: np.ndarray, dof: int) -> np.ndarray:
    """EWC long-run covariance of the rows of v (N×q) with B = ``dof`` cosines, sum scale
    (Lazarus et al. 2018, eq. (8)): N·(1/B) Σ_j Λ_j Λ_jᵀ.

    From ``FAST_FROM`` rows the cosine transforms are taken over the last m rows, m the largest
    11-smooth length ≤ N (:func:`_fast_rows`; less than 0.5 % fewer rows): (1/B) Σ Λ_j Λ_jᵀ estimates
    the per-sample long-run covariance from any stretch of a stationary series, and N times it is the
    sum scale of all N rows. A DCT of a length with a large prime factor runs by Bluestein's algorithm,
    10–15× slower: on Silverbox every added-term test's scores have such a length (N − p − 1 after an
    AR(p) filter and the prewhitening): 7.5–9.4 ms per transform against 0.65 ms at the fast length, on
    a test of about 36–40 ms. Shorter series use every row, as before."""
    n = v.shape[0]
    lam = cosine_transform(_fast_rows(v), dof)                                                      # (B, q)
    return n * (lam.T @ lam) / dof


def long_run(g: np.ndarray, prewhiten: bool = True, dof: int | None = None,
             base_dof: float | None = None) -> LongRun:
    """Prewhitened EWC long-run covariance of the rows g_t (N×q) (module docstring), with the
    Satterthwaite degrees of freedom of its reference law (:func:`satterthwaite_dof`). The rows are
    used as given (scores have mean zero at the estimate; they are not centred again). ``dof``: the
    number of cosines B (default :func:`ewc_dof`); ``base_dof``: the degrees of freedom of the EWC part
    when they are known to be fewer than B (:func:`design_correction`)."""
    g = np.atleast_2d(np.asarray(g, float).T).T
    n, q = g.shape
    b = ewc_dof(n) if dof is None else int(dof)
    if n < 8:
        return LongRun(g.T @ g, float(max(1, n - 1)), np.zeros((q, q)))
    a = var1(g) if prewhiten else np.zeros((q, q))
    v = g[1:] - g[:-1] @ a.T
    om_v = ewc(v, b) * n / (n - 1)
    binv = np.linalg.inv(np.eye(q) - a)
    if not prewhiten:
        return LongRun(binv @ om_v @ binv.T, float(b), a)
    x0 = g[:-1]
    xx = np.sum(x0 * x0, axis=0)
    var_rho = np.where(xx > 0, np.sum((x0 * v) ** 2, axis=0) / np.where(xx > 0, xx, 1.0) ** 2, 0.0)
    return LongRun(binv @ om_v @ binv.T, satterthwaite_dof(base_dof or b, np.diag(a), var_rho), a)
