"""Estimator benchmark (issue 3): LS, WLS and IV fit time against a bare ``numpy.linalg.lstsq``
on N = 10⁶ samples × 50 regressors (target: each within 3× of lstsq), and emcee effective samples
per second on a 5-parameter model through ``ESTIMATORS["mcmc"]``.

Timings are best-of-N wall-clock times (other work may share the machine); the repetitions of
all methods are interleaved so that a load spike hits them alike.  An estimator slower than the
target is profiled (cProfile, one call) and the profile is put into the section.
"""

from __future__ import annotations

import cProfile
import os
import io
import pstats
import sys
import time
import warnings

import numpy as np
from scipy import linalg

from pipeline.estimators import ESTIMATORS
from pipeline.estimators.bayes import GaussianPrior

TARGET_RATIO = 3.0


def _log(msg: str) -> None:
    print(f"[bench estimators] {msg}", file=sys.stderr, flush=True)


def _loadavg() -> tuple[float, ...]:
    try:
        return os.getloadavg()
    except OSError:
        return (float("nan"),) * 3


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def _ls_r_only(phi: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Prototype of the suggested LS fix (not used by the pipeline): one R-only Householder QR of
    [Φ | y] (no explicit Q), rank / singular values from the SVD of the p×p factor R (Φ = QR has the
    singular values and right singular vectors of R), θ by back substitution, (ΦᵀΦ)⁻¹ = R⁻¹R⁻ᵀ and the
    residuals that the Estimate returns."""
    p = phi.shape[1]
    r = linalg.qr(np.column_stack([phi, y]), mode="r", overwrite_a=True, check_finite=False)[0]
    rp = r[:p, :p]
    np.linalg.svd(rp)  # rank, singular values, null space (V) as numerical_rank() reports them
    theta = linalg.solve_triangular(rp, r[:p, p])
    rinv = linalg.solve_triangular(rp, np.eye(p))
    _ = rinv @ rinv.T
    resid = y - phi @ theta
    return theta, resid


def _iv_cross(phi: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Prototype of the suggested IV fix (not used by the pipeline): cross-products only, θ and
    Cov θ = σ̂²A⁻¹ (ma_lags = 0) without any p×N matrix."""
    zz, zp, zy = z.T @ z, z.T @ phi, z.T @ y
    m = linalg.cho_solve(linalg.cho_factor(zz), zp).T  # M = ΦᵀZ(ZᵀZ)⁻¹
    a = m @ zp
    theta = np.linalg.solve(a, m @ zy)
    r = y - phi @ theta
    _ = float(r @ r) / (y.size - phi.shape[1]) * np.linalg.inv(a)
    return theta


def _profile(fn, top: int = 5) -> list[tuple[str, float, float]]:
    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    st = pstats.Stats(pr, stream=io.StringIO())
    rows = []
    for (fname, line, func), (cc, nc, tt, ct, callers) in st.stats.items():
        short = fname.replace("\\", "/")
        for key in ("site-packages/", "/work/main/"):
            if key in short:
                short = short.split(key, 1)[1]
        rows.append((f"{short}:{line}({func})", tt, ct))
    rows.sort(key=lambda r: -r[1])
    return rows[:top]


def _regression_bench(quick: bool) -> tuple[list[str], dict]:
    n, p = (20_000, 10) if quick else (1_000_000, 50)
    reps = 2 if quick else 3
    rng = np.random.default_rng(3)
    _log(f"data N = {n}, p = {p}")
    phi = rng.standard_normal((n, p))
    theta = rng.standard_normal(p)
    y = phi @ theta + 0.1 * rng.standard_normal(n)
    w = rng.uniform(0.5, 2.0, n)  # inverse variances
    z = phi + 0.5 * rng.standard_normal((n, p))  # q = p instruments correlated with Φ
    z2 = np.column_stack([z, phi + 0.5 * rng.standard_normal((n, p))])  # q = 2p (two-stage form)

    cases = {
        "numpy.linalg.lstsq (baseline)": lambda: np.linalg.lstsq(phi, y, rcond=None),
        "LS `ESTIMATORS['ls']`": lambda: ESTIMATORS["ls"](phi, y),
        "WLS `ESTIMATORS['wls']` (weights)": lambda: ESTIMATORS["wls"](phi, y, weights=w),
        "IV `ESTIMATORS['iv']` (q = p instruments)": lambda: ESTIMATORS["iv"](phi, y, instruments=z),
        "IV `ESTIMATORS['iv']` (q = 2p, two-stage form)": lambda: ESTIMATORS["iv"](phi, y, instruments=z2),
    }
    best = {k: np.inf for k in cases}
    for rep in range(reps):
        for name, fn in cases.items():
            t = _timed(fn)
            best[name] = min(best[name], t)
        _log(f"rep {rep + 1}/{reps}, best so far: " + ", ".join(f"{k.split()[0]} {v:.2f}s" for k, v in best.items()))
    # correctness spot check: every estimator agrees with lstsq on this well-conditioned problem
    ref = np.linalg.lstsq(phi, y, rcond=None)[0]
    dev_ls = float(np.max(np.abs(ESTIMATORS["ls"](phi, y).theta - ref)))
    base = best["numpy.linalg.lstsq (baseline)"]
    lines = [
        f"Load average at start (1/5/15 min): {', '.join(f'{v:.1f}' for v in _loadavg())} on "
        f"{os.cpu_count()} cores. "
        f"Data: N = {n:,} samples, p = {p} regressors (standard normal, seeded), float64, C order; "
        f"best of {reps} runs each, repetitions interleaved. WLS uses positive weights (N,), IV uses instruments "
        f"Z = Φ + noise. Baseline: `numpy.linalg.lstsq(Φ, y, rcond=None)` (LAPACK gelsd) on the same Φ, y. "
        f"Target: fit time ≤ {TARGET_RATIO:g}× lstsq.",
        "",
        "| method | best time (s) | × lstsq | target ≤ 3× | met |",
        "|---|---:|---:|---:|:---:|",
    ]
    slow = []
    for name, t in best.items():
        ratio = t / base
        if name.startswith("numpy"):
            lines.append(f"| {name} | {t:.3f} | 1.00 | – | – |")
            continue
        ok = ratio <= TARGET_RATIO
        if not ok:
            slow.append(name)
        lines.append(f"| {name} | {t:.3f} | {ratio:.2f} | ≤ {TARGET_RATIO:g} | {'yes' if ok else '**no**'} |")
    lines.append("")
    lines.append(f"LS θ agrees with lstsq to max |Δθ| = {dev_ls:.1e}.")

    if slow:
        lines += ["", "### Profile of the estimators slower than the target", ""]
        for name in slow:
            _log(f"profiling {name}")
            rows = _profile(cases[name])
            lines += [f"{name} (cProfile, one call, top functions by own time):", "",
                      "| function | own time (s) | cumulative (s) |", "|---|---:|---:|"]
            lines += [f"| `{f}` | {tt:.3f} | {ct:.3f} |" for f, tt, ct in rows]
            lines.append("")
        causes = []
        if any(k.startswith(("LS", "WLS")) for k in slow):
            causes.append(
                "**Cause (LS/WLS).** `ls.fit` factorises Φ twice: `numerical_rank()` (base.py) calls "
                "`np.linalg.svd(Φ, full_matrices=False)`, which also builds the N×p matrix U although only the "
                "singular values and V are used, and then `np.linalg.qr(Φ, mode='reduced')` does a Householder QR "
                "*and* forms the N×p matrix Q explicitly (geqrf + orgqr) only to compute Qᵀy. Each of the two "
                "calls costs about as much as the whole gelsd solve (see the profile: `svd` and `qr` own nearly "
                "all the time); `wls.fit` (`_solve_whitened`) repeats the same pair on the whitened Φ·√w, plus "
                "the whitening copy.")
        if any(k.startswith("IV") for k in slow):
            causes.append(
                "**Cause (IV).** The two-stage branch of `iv.fit` (q > p) forms the p×N matrix MZᵀ "
                "(M = ΦᵀZ(ZᵀZ)⁻¹) twice (`m @ z.T @ phi` and `m @ z.T`), then solves for the p×N matrix "
                "P = (MZᵀΦ)⁻¹MZᵀ with N right-hand sides, besides ZᵀZ and ΦᵀZ: several tall-skinny products "
                "with inner dimension N, each about as costly as the whole lstsq. Both branches also copy Φ, y "
                "and Z through the boolean row mask (`phi[keep]`...) even when every row is kept, and the q = p "
                "branch materialises P = (ZᵀΦ)⁻¹Zᵀ (p×N) as well. P is only needed for Cov θ = PΣPᵀ with "
                "ma_lags > 0. **Suggested fix:** form only the cross-products ZᵀZ, ZᵀΦ, Zᵀy once; "
                "A = ΦᵀZ(ZᵀZ)⁻¹ZᵀΦ, θ = A⁻¹ΦᵀZ(ZᵀZ)⁻¹Zᵀy and, for ma_lags = 0, Cov θ = σ̂²A⁻¹ (exactly PPᵀσ̂², "
                "since P = A⁻¹MZᵀ and MZᵀZMᵀ = A; for q = p, Cov θ = σ̂²(ZᵀΦ)⁻¹ZᵀZ(ZᵀΦ)⁻ᵀ); form P only when "
                "ma_lags > 0; skip the row mask when all rows are finite. Prototype timed below.")
        for c in causes:
            lines += [c, ""]
        if slow:
            # prototypes of the suggested fixes, timed the same way
            proto = {"LS prototype (R-only QR of [Φ y] + SVD of R)": lambda: _ls_r_only(phi, y)}
            sw = np.sqrt(w)
            proto["WLS prototype (Φ·√w, y·√w, then the same)"] = lambda: _ls_r_only(phi * sw[:, None], y * sw)
            proto["IV prototype, q = p (cross-products only)"] = lambda: _iv_cross(phi, y, z)
            proto["IV prototype, q = 2p (cross-products only)"] = lambda: _iv_cross(phi, y, z2)
            pbest = {k: np.inf for k in proto}
            lbest = np.inf
            for _ in range(reps):
                lbest = min(lbest, _timed(cases["numpy.linalg.lstsq (baseline)"]))
                for k, fn in proto.items():
                    pbest[k] = min(pbest[k], _timed(fn))
            pd = float(np.max(np.abs(_ls_r_only(phi, y)[0] - ref)))
            piv = float(np.max(np.abs(_iv_cross(phi, y, z2) - ESTIMATORS["iv"](phi, y, instruments=z2).theta)))
            if any(k.startswith(("LS", "WLS")) for k in slow):
                lines += [
                    "**Suggested fix (LS/WLS)** (estimator files not edited here): one R-only QR of the augmented "
                    "matrix [Φ | y] (`scipy.linalg.qr(np.column_stack([phi, y]), mode='r', overwrite_a=True)`), then "
                    "`numerical_rank` on the p×p factor R (Φ = QR has the same singular values and right singular "
                    "vectors, so rank, tolerance and null space are unchanged), θ = R⁻¹(Qᵀy) with Qᵀy = the last "
                    "column of the augmented R, SSE = R[p, p]², (ΦᵀΦ)⁻¹ = R⁻¹R⁻ᵀ as now; keep the SVD/pinv of Φ only "
                    "for the rank-deficient `min_norm` branch. Same in `wls._solve_whitened`.",
                    "",
                ]
            lines += [
                f"Prototypes of the suggested fixes (not used by the pipeline; same data, best of {reps}, interleaved "
                f"with lstsq; LS prototype max |Δθ| vs lstsq = {pd:.1e}, IV prototype vs `iv.fit` = {piv:.1e}):",
                "",
                "| prototype | best time (s) | × lstsq |", "|---|---:|---:|",
            ]
            lines += [f"| {k} | {t:.3f} | {t / lbest:.2f} |" for k, t in pbest.items()]
    return lines, best


def _mcmc_bench(quick: bool) -> list[str]:
    n, p = (200, 5) if quick else (1000, 5)
    nwalkers, nsteps = (16, 400) if quick else (32, 5000)
    reps = 1 if quick else 3
    rng = np.random.default_rng(5)
    phi = rng.standard_normal((n, p))
    theta = np.array([1.0, -0.5, 0.25, 2.0, -1.5])
    sigma = 0.3
    y = phi @ theta + sigma * rng.standard_normal(n)
    prior = GaussianPrior(mean=0.0, cov=10.0)
    best, est = np.inf, None
    for rep in range(reps):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = time.perf_counter()
            est = ESTIMATORS["mcmc"](phi, y, prior=prior, sigma=sigma, nwalkers=nwalkers, nsteps=nsteps, seed=0)
            best = min(best, time.perf_counter() - t)
        _log(f"mcmc rep {rep + 1}/{reps}: {best:.2f}s")
    tau = np.asarray(est.extra["tau"], dtype=float)
    burn, thin = est.extra["burn"], est.extra["thin"]
    ess_per_param = nwalkers * (nsteps - burn) / tau
    ess = float(np.min(ess_per_param))
    n_flat = est.extra["samples"].shape[0]
    return [
        "### emcee effective samples per second (`ESTIMATORS['mcmc']`)",
        "",
        f"Model: y = Φθ + z, p = {p} parameters, N = {n} samples, known σ = {sigma}, Gaussian prior N(0, 10·I); "
        f"{nwalkers} walkers × {nsteps} steps, seed 0; wall time of the whole `fit_mcmc` call (MAP start, "
        f"sampling, τ estimate), best of {reps}.",
        "",
        "ESS formula: τ_j = integrated autocorrelation time of parameter j in steps (`extra['tau']`, emcee "
        "`get_autocorr_time(tol=0)`); ESS_j = walkers × (nsteps − burn) / τ_j — equivalently (flat samples "
        "after burn and thin) × thin / τ_j; reported ESS = min_j ESS_j (slowest-mixing parameter).",
        "",
        "| quantity | value |",
        "|---|---:|",
        f"| wall time (s) | {best:.3f} |",
        f"| τ per parameter (steps) | {', '.join(f'{t:.1f}' for t in tau)} |",
        f"| burn-in / thin (steps) | {burn} / {thin} |",
        f"| flat samples after burn & thin | {n_flat:,} |",
        f"| acceptance fraction | {est.extra['acceptance_fraction']:.3f} |",
        f"| ESS (min over parameters) | {ess:,.0f} |",
        f"| **ESS per second** | **{ess / best:,.0f}** |",
        "",
        "No speed target was set for MCMC (reported only)."
        + (" Chain shorter than 50 τ in quick mode." if nsteps < 50 * float(np.max(tau)) else ""),
    ]


def run(quick: bool = False) -> str:
    head = ["## Estimators: LS / WLS / IV fit time vs numpy.linalg.lstsq, emcee ESS/s (issue 3)", ""]
    if quick:
        head += ["**Quick mode: tiny sizes, numbers not meaningful.**", ""]
    reg_lines, _ = _regression_bench(quick)
    mc_lines = _mcmc_bench(quick)
    return "\n".join(head + reg_lines + [""] + mc_lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
