"""Integral-equation identification of continuous-time models (Tsang & Billings 1991, sections 4-6).

Model (eqs. 29-30, 47):  A(D) y + sum_k gamma_k g_k(y, u, derivatives) = B(D) u  with
A(D) = a_0 D^n + a_1 D^(n-1) + ... + a_(n-1) D + 1 and B(D) = b_1 D^(n-1) + ... + b_n.

For each window of ``window`` samples (time base centred on zero, t_s in [s0, s1], T = s1 - s0) the
input and output are approximated by the orthogonal series of eqs. (6)-(8) with ERR stopping (eq. 10).
Integrating the model n+1 times from s0 to s1 gives eq. (32)/(37):

    Y^(n+1) = - sum_{j=0}^{n-1} a_j Q_y^(j+1) + sum_{j=1}^{n} b_j Q_u^(j+1) - sum_k gamma_k G_k^(n+1)

with the repeated integrals Y^(j) = sum_i f_i Im_i^j (eq. 36, Im from eqs. 15-16) and the
initial-condition corrections of eqs. (38)-(39), taken from the fitted polynomial (eq. 35):

    Q_x^(j+1) = X^(j+1) - sum_{m=0}^{n-j-1} T^(m+j+1)/(m+j+1)! x^(m)(s0).

Nonlinear terms (eqs. 48-50) are integrated n+1 times directly from the product of the fitted
polynomials.  Successive windows (shifted by one sample) give the simultaneous equations (40), solved
by least squares or by extended least squares with an MA model of the equation error (eqs. 41-42;
steps 7-8 of section 6).  :func:`iterated_prefiltering` repeats the identification on data filtered
by the current model F(s) = B(s)/A(s) (eq. 46, section 7.1 and Table 6).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import factorial

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from pipeline.ct.orthogonal import fit_windows, orthogonal_basis, orthogonal_integrals, repeated_monomial_integrals
from pipeline.errors import EstimationError, InputError
from pipeline.prefilter import ct_filter

__all__ = [
    "WindowStates",
    "window_states",
    "NonlinearTerm",
    "build_regression",
    "extended_least_squares",
    "CTEstimate",
    "identify_ct",
    "iterated_prefiltering",
]


@dataclass
class WindowStates:
    """Per-window orthogonal estimates of one signal (rows = windows).

    ``integrals[:, j-1]`` = X^(j) (eq. 36), ``ic[:, m]`` = x^(m)(s0) (eq. 35), ``beta`` monomial
    coefficients on the window time base (eq. 8), ``orders`` the ERR-chosen orders, ``s0``, ``s1``."""

    integrals: np.ndarray
    ic: np.ndarray
    beta: np.ndarray
    orders: np.ndarray
    s0: float
    s1: float


def window_states(x, h: float, n_int: int, n_ic: int, window: int = 41, threshold: float | None = 99.999,
                  m_max: int = 15) -> WindowStates:
    """Orthogonal approximation (eqs. 6-10) of every ``window``-sample segment of ``x`` (shift one sample)
    on the centred base t_s = (k - (window-1)/2) h, then integrals of orders 1..n_int (eqs. 15-16, 36) and
    derivatives of orders 0..n_ic-1 at the window start (eq. 35)."""
    x = np.asarray(x, dtype=float).ravel()
    if not isinstance(window, (int, np.integer)) or window < 2 or window > x.size:
        raise InputError(f"window: expected an integer in [2, {x.size}] (signal length), got {window!r}", key="window")
    if not isinstance(m_max, (int, np.integer)) or m_max < 0 or m_max > window - 1:
        raise InputError(f"m_max: expected an integer in [0, {window - 1}] (window - 1), got {m_max!r}", key="m_max")
    if h <= 0:
        raise InputError(f"h: expected a positive sampling period, got {h!r}", key="h")
    ts = (np.arange(window) - (window - 1) / 2.0) * h
    s0, s1 = float(ts[0]), float(ts[-1])
    basis = orthogonal_basis(ts, int(m_max))
    F, _, M = fit_windows(basis, sliding_window_view(x, window), threshold, m_max)
    S = np.vstack([orthogonal_integrals(basis, j, s0, s1) for j in range(1, n_int + 1)])  # (n_int, m+1)
    coef = basis.coef  # w_i(t) = sum_k coef[i, k] t^k
    beta = F @ coef
    D = np.zeros((max(n_ic, 0), m_max + 1))
    for m in range(n_ic):
        for i in range(m_max + 1):
            c = np.polynomial.polynomial.polyder(coef[i], m=m) if m else coef[i]
            D[m, i] = np.polynomial.polynomial.polyval(s0, c)
    return WindowStates(integrals=F @ S.T, ic=F @ D.T, beta=beta, orders=M, s0=s0, s1=s1)


def _q_terms(st: WindowStates, n: int, j: int) -> np.ndarray:
    """Q_x^(j+1) of eqs. (38)-(39): X^(j+1) minus the initial-condition terms of the n+1-fold integral
    of D^(n-j) x."""
    T = st.s1 - st.s0
    q = st.integrals[:, j].copy()
    for m in range(n - j):
        p = m + j + 1
        q -= T**p / factorial(p) * st.ic[:, m]
    return q


@dataclass(frozen=True)
class NonlinearTerm:
    """A product of signal derivatives, e.g. ``NonlinearTerm((("y", 0), ("y", 0)))`` = y^2 (eq. 47);
    ``name`` is used for the parameter label (default like 'y*y' or "y'*u")."""

    factors: tuple
    name: str | None = None

    def label(self) -> str:
        if self.name:
            return self.name
        return "*".join(s + "'" * d for s, d in self.factors)


def _poly_mul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    out = np.zeros((A.shape[0], A.shape[1] + B.shape[1] - 1))
    for i in range(A.shape[1]):
        out[:, i : i + B.shape[1]] += A[:, i : i + 1] * B
    return out


def _poly_der(B: np.ndarray, m: int) -> np.ndarray:
    for _ in range(m):
        if B.shape[1] == 1:
            return np.zeros_like(B)
        B = B[:, 1:] * np.arange(1, B.shape[1])
    return B


def build_regression(u, y, h: float, n: int, *, window: int = 41, threshold: float | None = 99.999,
                     threshold_u: float | None = None, m_max: int = 15, nonlinear=()):
    """Simultaneous equations (40): returns ``(Gamma, Phi, names, info)`` with Gamma = Y^(n+1) per window
    and the columns of Phi ordered as theta = [a_0..a_(n-1), b_1..b_n, gamma_1..] so that
    Gamma = Phi theta + zeta (signs of eq. 37 folded into Phi)."""
    u = np.asarray(u, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if u.size != y.size:
        raise InputError(f"u, y: expected equal lengths, got {u.size} and {y.size}", key="u")
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"n: expected a model order >= 1, got {n!r}", key="n")
    thr_u = threshold if threshold_u is None else threshold_u
    sy = window_states(y, h, n + 1, n, window, threshold, m_max)
    su = window_states(u, h, n + 1, n, window, thr_u, m_max)
    cols, names = [], []
    for j in range(n):
        cols.append(-_q_terms(sy, n, j))
        names.append(f"a{j}")
    for j in range(1, n + 1):
        cols.append(_q_terms(su, n, j))
        names.append(f"b{j}")
    if nonlinear:
        for term in nonlinear:
            term = term if isinstance(term, NonlinearTerm) else NonlinearTerm(tuple(term))
            prod = np.ones((sy.beta.shape[0], 1))
            for sig, d in term.factors:
                if sig not in ("y", "u"):
                    raise InputError(f"nonlinear: factor signal must be 'y' or 'u', got {sig!r}", key="nonlinear")
                prod = _poly_mul(prod, _poly_der((sy if sig == "y" else su).beta, d))
            Jn = repeated_monomial_integrals(prod.shape[1] - 1, n + 1, sy.s0, sy.s1)
            cols.append(-(prod @ Jn))
            names.append(f"gamma[{term.label()}]")
    Phi = np.column_stack(cols)
    info = {"orders_y": sy.orders, "orders_u": su.orders}
    return sy.integrals[:, n], Phi, names, info


def extended_least_squares(Phi, Gamma, n_ma: int = 0, n_iter: int = 10):
    """Least squares (n_ma = 0) or extended least squares with an MA(n_ma) model of the equation error
    (eqs. 41-42): the regressor is augmented with xi(k-1)..xi(k-n_ma), where xi is the residual sequence
    of the previous pass (section 6, step 7), and the fit is repeated ``n_iter`` times.  Solved with
    ``numpy.linalg.lstsq`` (same solution as the normal equations (41), better conditioned).
    Returns ``(theta_system, d, xi)``."""
    Phi = np.asarray(Phi, dtype=float)
    Gamma = np.asarray(Gamma, dtype=float)
    if Phi.shape[0] <= Phi.shape[1] + n_ma:
        raise EstimationError(f"too few equations ({Phi.shape[0]}) for {Phi.shape[1] + n_ma} parameters")
    theta, *_ = np.linalg.lstsq(Phi, Gamma, rcond=None)
    xi = Gamma - Phi @ theta
    d = np.zeros(n_ma)
    if n_ma > 0:
        for _ in range(n_iter):
            lags = np.column_stack([np.concatenate((np.zeros(k), xi[:-k])) for k in range(1, n_ma + 1)])
            ext = np.hstack([Phi, lags])
            th, *_ = np.linalg.lstsq(ext, Gamma, rcond=None)
            theta, d = th[: Phi.shape[1]], th[Phi.shape[1] :]
            xi = Gamma - ext @ th
    return theta, d, xi


@dataclass
class CTEstimate:
    """Continuous-time estimate: A(D) = a_0 D^n + ... + a_(n-1) D + 1, B(D) = b_1 D^(n-1) + ... + b_n,
    nonlinear coefficients ``gamma``, MA noise coefficients ``d`` (eq. 42)."""

    a: np.ndarray
    b: np.ndarray
    gamma: np.ndarray
    d: np.ndarray
    names: list[str]
    residuals: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def theta(self) -> np.ndarray:
        return np.concatenate([self.a, self.b, self.gamma])

    @property
    def num(self) -> np.ndarray:
        """Transfer-function numerator B(s), highest power first."""
        return np.asarray(self.b, dtype=float)

    @property
    def den(self) -> np.ndarray:
        """Transfer-function denominator A(s), highest power first (constant term 1)."""
        return np.concatenate([self.a, [1.0]])

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in zip(self.names, self.theta)} | {f"d{i + 1}": float(v) for i, v in enumerate(self.d)}


def identify_ct(u, y, h: float, n: int, *, window: int = 41, threshold: float | None = 99.999,
                threshold_u: float | None = None, m_max: int = 15, n_ma: int = 0, n_iter: int = 10,
                nonlinear=()) -> CTEstimate:
    """Orthogonal approximation + integral equation + (extended) least squares: the algorithm of
    section 6 (steps 1-8) for the model of eqs. (29)/(47)."""
    Gamma, Phi, names, info = build_regression(u, y, h, n, window=window, threshold=threshold,
                                               threshold_u=threshold_u, m_max=m_max, nonlinear=nonlinear)
    theta, d, xi = extended_least_squares(Phi, Gamma, n_ma, n_iter)
    return CTEstimate(a=theta[:n], b=theta[n : 2 * n], gamma=theta[2 * n :], d=d, names=names, residuals=xi, info=info)


def _check_stable(den) -> None:
    roots = np.roots(den)
    if den[0] == 0 or np.any(roots.real >= 0):
        raise EstimationError(f"prefilter: the current model denominator {list(np.round(den, 6))} is not stable "
                              f"(roots {roots}); cannot use it as a filter (eq. 46)")


def iterated_prefiltering(u, z, h: float, n: int, *, stages: int = 3, threshold_initial: float = 90.0,
                          threshold_filtered: float = 99.9999, m_max: int = 15, window: int = 41, n_ma: int = 2,
                          n_iter: int = 10, cumulative: bool = False) -> list[CTEstimate]:
    """Iterated prefiltering with the current model as the filter (eq. 46; section 7.1, eqs. 53-57 and
    Table 6).  Stage 0 identifies from the raw data with ``threshold_initial``; each further stage filters
    u and z by F(s) = B(s)/A(s) of the previous estimate (from rest, linear interpolation between
    samples) and re-identifies with ``threshold_filtered``.  The raw data are filtered at each stage
    unless ``cumulative`` (then the previous stage's filtered data are filtered again).  Returns the
    estimates of stages 0..stages."""
    u = np.asarray(u, dtype=float)
    z = np.asarray(z, dtype=float)
    est = identify_ct(u, z, h, n, window=window, threshold=threshold_initial, m_max=m_max, n_ma=n_ma, n_iter=n_iter)
    out = [est]
    uf, zf = u, z
    for _ in range(stages):
        _check_stable(est.den)
        src_u, src_z = (uf, zf) if cumulative else (u, z)
        uf = ct_filter(src_u, h, est.num, est.den)
        zf = ct_filter(src_z, h, est.num, est.den)
        est = identify_ct(uf, zf, h, n, window=window, threshold=threshold_filtered, m_max=m_max, n_ma=n_ma,
                          n_iter=n_iter)
        out.append(est)
    return out
