"""Maximum likelihood for y = Φθ + v with a chosen noise density.

Densities (``density=``):

* ``gaussian`` — σ known (``sigma``) or estimated (σ̂² = SSE/N), known mean ``loc`` m_z:
  θ̂ = (ΦᵀΦ)⁻¹Φᵀ(Y − m_z) (Wrocław Example 2.7, (2.82)–(2.98); Exercise 2.7: θ̂ = v̄ − m_z).
  With ``sigma_fn(θ)`` giving the noise standard deviation as a function of θ (noise entering through
  the input, y = a(u + w): σ_v = |a|σ, Johansson 6.5) the likelihood is maximised numerically.
* ``laplace`` — least absolute deviations (a linear program), b̂ = mean|ε|.
* ``student_t`` — location-scale t with ν estimated (or fixed ``nu``), numerical optimisation.
* ``exponential`` — f(v) = μe^{−μv}, v >= 0: μ̂ = N/Σε and log L = N log N − N − N log Σε
  (Johansson 6.10, (6.77)–(6.83), misprint 31 corrected) maximised subject to ε_k >= 0: a linear program.
* ``rayleigh`` — f(v) = (v/σ²)e^{−v²/2σ²}, v >= 0: σ̂² = εᵀε/(2N) (Johansson 6.4, (6.45)–(6.51), with
  +Σ log ε_k and −N/σ² as corrected in misprint 29); θ by numerical maximisation of the profile.
* ``uniform`` on [low, high] — likelihood constant on the feasible set {θ : low <= y − Φθ <= high}
  (Wrocław Exercise 2.8): the set is reported (``extra['feasible_box']``), θ̂ is its centre.
* ``triangular`` on [low, high] with ``mode`` — constrained ML on the support
  (Wrocław Example 2.9, (2.117)–(2.132): θ = 2, L = 1/2).

Covariance: closed form where it exists, otherwise the inverse of the numerical Hessian of −log L
(observed information). For densities whose support depends on θ (exponential, uniform, triangular at
an active support constraint) the regularity conditions fail and ``cov`` is None.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import optimize, special

from .base import Estimate, EstimationError, as_regressors, as_target, numerical_hessian, numerical_rank

DENSITIES = ("gaussian", "laplace", "student_t", "exponential", "rayleigh", "uniform", "triangular")
BOUNDED = {"exponential", "rayleigh", "uniform", "triangular"}


# ---------------------------------------------------------------- support / feasibility


def _support_error(density: str, low: float, high: float) -> EstimationError:
    return EstimationError(
        f"the support of the {density} noise density [{low:g}, {high:g}] excludes the data: no θ makes every "
        f"residual y − φᵀθ lie inside [{low:g}, {high:g}]; expected data compatible with the density's support "
        "(check the density, its bounds or an offset in the data)")


def feasible_interval(phi: np.ndarray, y: np.ndarray, low: float, high: float) -> tuple[float, float]:
    """Exact feasible set {θ : low <= y_k − φ_k θ <= high ∀k} for one parameter (p = 1)."""
    f = phi[:, 0]
    lo, hi = -np.inf, np.inf
    pos, neg, zero = f > 0, f < 0, f == 0
    if np.any(pos):
        hi = min(hi, np.min((y[pos] - low) / f[pos]))
        lo = max(lo, np.max((y[pos] - high) / f[pos]))
    if np.any(neg):
        lo = max(lo, np.max((y[neg] - low) / f[neg]))
        hi = min(hi, np.min((y[neg] - high) / f[neg]))
    if np.any(zero) and (np.any(y[zero] < low) or np.any(y[zero] > high)):
        return np.inf, -np.inf
    return float(lo), float(hi)


def _feasible_set(phi, y, low, high, density):
    """(interior point, per-parameter box [min, max] over the feasible polytope)."""
    n, p = phi.shape
    if p == 1:
        lo, hi = feasible_interval(phi, y, low, high)
        if lo > hi:
            raise _support_error(density, low, high)
        if np.isfinite(lo) and np.isfinite(hi):
            centre = 0.5 * (lo + hi)
        elif np.isfinite(lo):
            centre = lo + 1.0
        elif np.isfinite(hi):
            centre = hi - 1.0
        else:
            centre = 0.0
        return np.array([centre]), np.array([[lo, hi]])
    # p > 1: Chebyshev-type centre maximising the smallest margin t (bounded by 1 for unbounded supports)
    a_ub, b_ub = [], []
    if np.isfinite(high):  # y − Φθ <= high − t  ->  −Φθ + t <= high − y
        a_ub.append(np.hstack([-phi, np.ones((n, 1))]))
        b_ub.append(high - y)
    if np.isfinite(low):  # y − Φθ >= low + t  ->  Φθ + t <= y − low
        a_ub.append(np.hstack([phi, np.ones((n, 1))]))
        b_ub.append(y - low)
    a_ub = np.vstack(a_ub)
    b_ub = np.concatenate(b_ub)
    c = np.zeros(p + 1)
    c[-1] = -1.0
    res = optimize.linprog(c, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * p + [(None, 1.0)], method="highs")
    if res.status != 0 or res.x[-1] < -1e-12:
        raise _support_error(density, low, high)
    box = np.empty((p, 2))
    for j in range(p):
        for k, sgn in enumerate((1.0, -1.0)):  # k = 0: min θ_j, k = 1: max θ_j
            cj = np.zeros(p + 1)
            cj[j] = sgn
            r = optimize.linprog(cj, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * p + [(0.0, 0.0)], method="highs")
            box[j, k] = sgn * r.fun if r.status == 0 else -sgn * np.inf
    return res.x[:p], box


# ---------------------------------------------------------------- log densities


def triangular_logpdf(e, low: float, mode: float, high: float) -> np.ndarray:
    """log of the triangular density on [low, high] with the given mode (−inf outside the support)."""
    return _logpdf("triangular", np.atleast_1d(np.asarray(e, dtype=float)), {"low": low, "mode": mode, "high": high})


def _logpdf(density: str, e: np.ndarray, prm: dict) -> np.ndarray:
    if density == "triangular":
        lo, md, hi = prm["low"], prm["mode"], prm["high"]
        out = np.full(e.shape, -np.inf)
        with np.errstate(divide="ignore"):
            left = (e >= lo) & (e <= md) & (md > lo)
            out[left] = np.log(2 * (e[left] - lo) / ((hi - lo) * (md - lo)))
            right = (e > md) & (e <= hi) & (hi > md)
            out[right] = np.log(2 * (hi - e[right]) / ((hi - lo) * (hi - md)))
            if md == hi:
                out[e == hi] = math.log(2 / (hi - lo))
            if md == lo:
                out[e == lo] = math.log(2 / (hi - lo))
        return out
    raise KeyError(density)


def _minimise(nll, x0, bounds=None):
    with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore"):
        # −log L is +inf outside the support: finite differences there are expected to be inf/nan
        warnings.simplefilter("ignore", RuntimeWarning)
        res = optimize.minimize(nll, x0, method="L-BFGS-B" if bounds else "BFGS", bounds=bounds,
                                options={"maxiter": 2000})
    if not np.isfinite(res.fun):
        raise EstimationError("ML optimisation failed: the log-likelihood is not finite at the optimum")
    # polish with Nelder–Mead (robust to small non-smoothness)
    res2 = optimize.minimize(nll, res.x, method="Nelder-Mead",
                             options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 20000})
    return res2 if res2.fun <= res.fun else res


def _inv_info(nll, x):
    h = numerical_hessian(nll, x)
    try:
        cov = np.linalg.inv(h)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        return None
    return 0.5 * (cov + cov.T)


# ---------------------------------------------------------------- the estimator


def fit(regressors, target, *, density: str = "gaussian", sigma: float | None = None, loc: float = 0.0,
        sigma_fn=None, nu: float | None = None, low: float | None = None, high: float | None = None,
        mode: float | None = None, theta0=None) -> Estimate:
    """Maximum-likelihood estimate for the chosen noise density (see module docstring for sources:
    Wrocław Examples 2.7, 2.9, Exercises 2.7, 2.8; Johansson 6.4, 6.5, 6.10)."""
    y = as_target(target)
    phi = as_regressors(regressors, y.size)
    n, p = phi.shape
    if density not in DENSITIES:
        raise EstimationError(f"unknown density '{density}'; expected one of {', '.join(DENSITIES)}")
    if sigma is not None and not (np.isfinite(sigma) and sigma > 0):
        raise EstimationError(f"sigma must be a positive finite number, got {sigma}")
    if density not in BOUNDED and numerical_rank(phi)[0] < p:
        raise EstimationError(f"singular regressors: numerical rank {numerical_rank(phi)[0]} < {p} parameters; "
                              "expected full column rank")
    handler = globals()[f"_fit_{density}"]
    return handler(phi, y, sigma=sigma, loc=loc, sigma_fn=sigma_fn, nu=nu, low=low, high=high, mode=mode,
                   theta0=theta0)


def _fit_gaussian(phi, y, *, sigma, loc, sigma_fn, theta0, **_):
    n, p = phi.shape
    yc = y - loc
    theta_ls = np.linalg.lstsq(phi, yc, rcond=None)[0]
    if sigma_fn is None:
        e = yc - phi @ theta_ls
        sse = float(e @ e)
        s2 = sigma ** 2 if sigma is not None else sse / n
        if s2 <= 0:
            return Estimate(theta_ls, None, e, None, p, "ml", {"density": "gaussian", "sigma2": 0.0})
        cov = s2 * np.linalg.inv(phi.T @ phi)
        loglik = -0.5 * n * math.log(2 * math.pi * s2) - 0.5 * sse / s2
        k = p if sigma is not None else p + 1
        return Estimate(theta_ls, cov, e, float(loglik), k, "ml", {"density": "gaussian", "sigma2": s2, "loc": loc})

    def nll(th):
        s = np.broadcast_to(np.asarray(sigma_fn(th), dtype=float), (n,))
        if np.any(s <= 0) or not np.all(np.isfinite(s)):
            return np.inf
        r = yc - phi @ th
        return float(np.sum(np.log(s)) + 0.5 * np.sum((r / s) ** 2) + 0.5 * n * math.log(2 * math.pi))

    x0 = np.asarray(theta0, dtype=float) if theta0 is not None else theta_ls
    res = _minimise(nll, x0)
    th = res.x
    return Estimate(th, _inv_info(nll, th), yc - phi @ th, -float(res.fun), p, "ml",
                    {"density": "gaussian", "sigma_fn": True, "theta_ls": theta_ls})


def _lad(phi, y):
    """min Σ|y − Φθ| as a linear program (variables θ, t >= |ε|)."""
    n, p = phi.shape
    c = np.concatenate([np.zeros(p), np.ones(n)])
    a_ub = np.block([[phi, -np.eye(n)], [-phi, -np.eye(n)]])
    b_ub = np.concatenate([y, -y])
    res = optimize.linprog(c, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * p + [(0, None)] * n, method="highs")
    return res.x[:p]


def _fit_laplace(phi, y, *, sigma, **_):
    n, p = phi.shape
    th = _lad(phi, y)
    e = y - phi @ th
    b = float(np.mean(np.abs(e))) if sigma is None else sigma
    if b <= 0:
        return Estimate(th, None, e, None, p + 1, "ml", {"density": "laplace", "scale": 0.0})
    # asymptotic covariance of LAD: (2 f(0))⁻² (ΦᵀΦ)⁻¹ with f(0) = 1/(2b) -> b²(ΦᵀΦ)⁻¹
    cov = b ** 2 * np.linalg.inv(phi.T @ phi)
    loglik = -n * math.log(2 * b) - float(np.sum(np.abs(e))) / b
    return Estimate(th, cov, e, loglik, p + (sigma is None), "ml", {"density": "laplace", "scale": b})


def _fit_student_t(phi, y, *, nu, sigma, theta0, **_):
    """Student-t ML: ECM for (θ, s) at fixed ν and a bounded profile search over ν (no Nelder–Mead)."""
    n, p = phi.shape
    th0 = np.asarray(theta0, dtype=float) if theta0 is not None else np.linalg.lstsq(phi, y, rcond=None)[0]
    e0 = y - phi @ th0
    s0 = sigma if sigma is not None else max(1.4826 * float(np.median(np.abs(e0 - np.median(e0)))), 1e-8)
    est_nu, est_s = nu is None, sigma is None

    def unpack(x):
        th = x[:p]
        k = p
        ls = x[k] if est_s else math.log(sigma)
        k += est_s
        lnu = x[k] if est_nu else math.log(nu)
        return th, ls, lnu

    def nll(x):
        th, ls, lnu = unpack(x)
        if not (-30 < ls < 30 and math.log(0.2) <= lnu <= math.log(1e4)):
            return np.inf
        r = (y - phi @ th) / math.exp(ls)
        v = math.exp(lnu)
        ll = (special.gammaln((v + 1) / 2) - special.gammaln(v / 2) - 0.5 * math.log(v * math.pi) - ls) * n \
            - (v + 1) / 2 * np.sum(np.log1p(r * r / v))
        return -float(ll)

    def em(v, th, s, iters=200):
        """ECM for the t regression at fixed ν (Lange, Little & Taylor 1989): weights
        w = (ν+1)/(ν + r²/s²), θ by weighted LS, s² = Σ w r²/N; the likelihood never decreases."""
        for _ in range(iters):
            r = y - phi @ th
            w = (v + 1) / (v + (r / s) ** 2)
            sw = np.sqrt(w)
            th_new = np.linalg.lstsq(phi * sw[:, None], y * sw, rcond=None)[0]
            r = y - phi @ th_new
            s_new = math.sqrt(max(float(np.sum(w * r * r)) / n, 1e-300)) if est_s else s
            done = np.allclose(th_new, th, rtol=1e-10, atol=1e-13) and abs(s_new - s) <= 1e-10 * s
            th, s = th_new, s_new
            if done:
                break
        return th, s

    def pack(th, s, v):
        return np.array(list(th) + ([math.log(s)] if est_s else []) + ([math.log(v)] if est_nu else []))

    state = {"th": th0, "s": s0}
    if est_nu:
        def profile(lnu):
            th, s = em(math.exp(lnu), state["th"], state["s"])
            state["th"], state["s"] = th, s
            return nll(pack(th, s, math.exp(lnu)))
        opt = optimize.minimize_scalar(profile, bounds=(math.log(0.2), math.log(1e4)), method="bounded",
                                       options={"xatol": 1e-6})
        v = math.exp(opt.x)
    else:
        v = nu
    th, s = em(v, state["th"], state["s"], iters=1000)
    x = pack(th, s, v)
    th, ls, lnu = unpack(x)
    cov_full = _inv_info(nll, x)
    return Estimate(th, None if cov_full is None else cov_full[:p, :p], y - phi @ th, -float(nll(x)),
                    p + est_s + est_nu, "ml", {"density": "student_t", "scale": math.exp(ls), "nu": math.exp(lnu)})


def _fit_exponential(phi, y, **_):
    n, p = phi.shape
    # maximise N log N − N − N log Σε  <=>  minimise Σε = Σy − (Σφ)ᵀθ subject to Φθ <= y (ε >= 0)
    res = optimize.linprog(-phi.sum(axis=0), A_ub=phi, b_ub=y, bounds=[(None, None)] * p, method="highs")
    if res.status == 2:
        raise _support_error("exponential", 0.0, np.inf)
    if res.status != 0:
        raise EstimationError("exponential-noise ML does not exist: Σε can be made arbitrarily small on the "
                              "support (the linear program is unbounded); expected regressors that bound ε >= 0")
    th = res.x
    e = y - phi @ th
    e = np.where(np.abs(e) < 1e-12 * max(1.0, np.max(np.abs(y))), 0.0, e)
    s = float(np.sum(e))
    if s <= 0:
        raise EstimationError("exponential-noise ML degenerate: all residuals are zero (Σε = 0)")
    mu = n / s
    loglik = n * math.log(n) - n - n * math.log(s)
    return Estimate(th, None, e, loglik, p + 1, "ml",
                    {"density": "exponential", "mu": mu, "active_constraints": int(np.sum(e == 0)),
                     "cov_note": "support depends on θ: non-regular ML, no information-based covariance"})


def _fit_rayleigh(phi, y, theta0, **_):
    n, p = phi.shape
    x0, _box = _feasible_set(phi, y, 0.0, np.inf, "rayleigh")
    if theta0 is not None and np.all(y - phi @ np.asarray(theta0, dtype=float) > 0):
        x0 = np.asarray(theta0, dtype=float)

    def nprof(th):  # −[Σ log ε − N log(εᵀε/2N) − N]
        e = y - phi @ th
        if np.any(e <= 0):
            return np.inf
        return -float(np.sum(np.log(e)) - n * math.log(e @ e / (2 * n)) - n)

    res = _minimise(nprof, x0)
    th = res.x
    e = y - phi @ th
    s2 = float(e @ e / (2 * n))

    def nll_full(x):
        t, ls2 = x[:p], x[p]
        ee = y - phi @ t
        if np.any(ee <= 0):
            return np.inf
        return -float(np.sum(np.log(ee)) - n * ls2 - np.sum(ee * ee) / (2 * math.exp(ls2)))

    cov_full = _inv_info(nll_full, np.concatenate([th, [math.log(s2)]]))
    return Estimate(th, None if cov_full is None else cov_full[:p, :p], e, -float(res.fun), p + 1, "ml",
                    {"density": "rayleigh", "sigma2": s2})


def _check_bounds(density, low, high, mode=None):
    if low is None or high is None or not (np.isfinite(low) and np.isfinite(high)) or not high > low:
        raise EstimationError(f"{density} density needs finite support bounds low < high, got low={low}, high={high}")
    if density == "triangular" and (mode is None or not low <= mode <= high):
        raise EstimationError(f"triangular density needs low <= mode <= high, got mode={mode} on [{low}, {high}]")


def _fit_uniform(phi, y, *, low, high, **_):
    _check_bounds("uniform", low, high)
    n, p = phi.shape
    centre, box = _feasible_set(phi, y, low, high, "uniform")
    e = y - phi @ centre
    return Estimate(centre, None, e, -n * math.log(high - low), p, "ml",
                    {"density": "uniform", "feasible_box": box, "unique": bool(np.all(box[:, 0] == box[:, 1])),
                     "cov_note": "likelihood flat on the feasible set: ML not unique, no covariance"})


def _fit_triangular(phi, y, *, low, high, mode, **_):
    _check_bounds("triangular", low, high, mode)
    n, p = phi.shape
    prm = {"low": low, "high": high, "mode": mode}
    x0, box = _feasible_set(phi, y, low, high, "triangular")

    def ll(th):
        return float(np.sum(_logpdf("triangular", y - phi @ th, prm)))

    if p == 1:
        lo, hi = box[0]
        width = hi - lo
        h = 1e-7 * max(width, 1e-12)
        if width <= 0:
            th = np.array([lo])
        elif ll(np.array([lo])) >= ll(np.array([lo + h])):  # concave log-likelihood: max at the left end
            th = np.array([lo])
        elif ll(np.array([hi])) >= ll(np.array([hi - h])):
            th = np.array([hi])
        else:
            r = optimize.minimize_scalar(lambda t: -ll(np.array([t])), bounds=(lo, hi), method="bounded",
                                         options={"xatol": 1e-12 * max(1.0, abs(lo), abs(hi))})
            th = np.array([r.x])
    else:
        cons = [{"type": "ineq", "fun": lambda t: (y - phi @ t) - low},
                {"type": "ineq", "fun": lambda t: high - (y - phi @ t)}]
        r = optimize.minimize(lambda t: -ll(t) if np.isfinite(ll(t)) else 1e300, x0, method="SLSQP",
                              constraints=cons, options={"ftol": 1e-14, "maxiter": 500})
        th = r.x
    e = y - phi @ th
    loglik = ll(th)
    active = bool(np.any(np.isclose(e, low, atol=1e-9)) or np.any(np.isclose(e, high, atol=1e-9)))
    cov = None if active else _inv_info(lambda t: -ll(t), th)
    return Estimate(th, cov, e, loglik, p, "ml",
                    {"density": "triangular", "likelihood": math.exp(loglik) if loglik > -700 else 0.0,
                     "feasible_box": box, "support_active": active})
