"""State-variable-filter / lambda-operator regression (Johansson, Exercises 12.1-12.2).

With lambda = 1/(1 + s tau) the Laplace variable is s = (1/tau)(1 - lambda)/lambda (Johansson 12.1).
A continuous-time model of order n written in lambda has the linear regression form

    y = sum_{k=1}^{n} c_k lambda^k{y} + sum_{k=1}^{n} d_k lambda^k{u}                       (*)

i.e. G(lambda) = (sum_k d_k lambda^k) / (1 - sum_k c_k lambda^k).  Multiplying numerator and denominator
by (1 + tau s)^n gives the transfer function

    G(s) = sum_k d_k (1 + tau s)^(n-k) / [ (1 + tau s)^n - sum_k c_k (1 + tau s)^(n-k) ].

For the DC motor G0(s) = K/(J s + D) (n = 1) this is (12.2) with the corrected sign (seed-case
discrepancy #42):  y = (1 - tau D/J) lambda{y} + (K tau/J) lambda{u},  so only K/J and D/J are
identifiable.  Johansson 12.2 writes the same first-order model as y = -alpha lambda{y} + beta lambda{u}
(alpha = -c_1, beta = d_1).

The lambda filters are applied to sampled data with :func:`pipeline.prefilter.ct_filter` (continuous
filter from rest, input linearly interpolated between samples), or the caller may pass
continuously-filtered signals to :func:`lambda_ls`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from pipeline.errors import EstimationError, InputError
from pipeline.prefilter import ct_filter

__all__ = [
    "lambda_filter",
    "lambda_regressors",
    "LambdaEstimate",
    "lambda_ls",
    "identify_lambda",
    "lambda_to_tf",
    "dc_motor_from_lambda",
]


def lambda_filter(x, h: float, tau: float, power: int = 1, interp: str = "linear", upsample: int = 8) -> np.ndarray:
    """lambda^power {x} with lambda = 1/(1 + s tau), from rest.

    ``interp='linear'``: the input is linearly interpolated between samples (exact for piecewise-linear
    input; for smooth signals the error is about h^2 w^2/12 relative at frequency w).
    ``interp='cubic'``: the samples are first interpolated by a cubic spline on a grid ``upsample`` times
    finer (error O(h^4)), filtered there and read back at the sample instants."""
    if tau <= 0:
        raise InputError(f"tau: expected a positive filter time constant, got {tau!r}", key="tau")
    if not isinstance(power, (int, np.integer)) or power < 1:
        raise InputError(f"power: expected an integer >= 1, got {power!r}", key="power")
    den = np.poly1d([tau, 1.0]) ** int(power)
    if interp == "linear":
        return ct_filter(x, h, [1.0], den.coeffs)
    if interp != "cubic":
        raise InputError(f"interp: expected 'linear' or 'cubic', got {interp!r}", key="interp")
    if not isinstance(upsample, (int, np.integer)) or upsample < 1:
        raise InputError(f"upsample: expected an integer >= 1, got {upsample!r}", key="upsample")
    x = np.asarray(x, dtype=float)
    t = np.arange(x.size) * h
    tf = np.arange((x.size - 1) * upsample + 1) * (h / upsample)
    xf = CubicSpline(t, x)(tf)
    return ct_filter(xf, h / upsample, [1.0], den.coeffs)[::upsample]


def lambda_regressors(y, u, h: float, tau: float, n: int = 1, interp: str = "linear") -> np.ndarray:
    """Columns [lambda^1{y} .. lambda^n{y}, lambda^1{u} .. lambda^n{u}] of regression (*)."""
    cols = [lambda_filter(y, h, tau, k, interp) for k in range(1, n + 1)]
    cols += [lambda_filter(u, h, tau, k, interp) for k in range(1, n + 1)]
    return np.column_stack(cols)


def lambda_to_tf(c, d, tau: float):
    """(num, den) in s, highest power first, of G(lambda) = sum d_k lambda^k / (1 - sum c_k lambda^k);
    the denominator is normalised to be monic."""
    c = np.atleast_1d(np.asarray(c, dtype=float))
    d = np.atleast_1d(np.asarray(d, dtype=float))
    n = max(c.size, d.size)
    p = np.poly1d([tau, 1.0])
    num = np.poly1d([0.0])
    den = p**n
    for k in range(1, n + 1):
        if k <= d.size:
            num = num + d[k - 1] * p ** (n - k)
        if k <= c.size:
            den = den - c[k - 1] * p ** (n - k)
    lead = den.coeffs[0]
    if lead == 0:
        raise EstimationError("lambda_to_tf: the denominator degenerates (leading coefficient 0)")
    return np.atleast_1d(num.coeffs / lead), den.coeffs / lead


@dataclass
class LambdaEstimate:
    """Estimate of regression (*): ``c`` (lambda^k{y} coefficients), ``d`` (lambda^k{u} coefficients),
    ``tau``, residuals; ``num``/``den`` the continuous transfer function (monic denominator)."""

    c: np.ndarray
    d: np.ndarray
    tau: float
    residuals: np.ndarray

    @property
    def num(self) -> np.ndarray:
        return lambda_to_tf(self.c, self.d, self.tau)[0]

    @property
    def den(self) -> np.ndarray:
        return lambda_to_tf(self.c, self.d, self.tau)[1]


def lambda_ls(y, Phi, tau: float, n: int = 1) -> LambdaEstimate:
    """Least squares of y on the lambda regressors ``Phi`` (columns as :func:`lambda_regressors`)."""
    y = np.asarray(y, dtype=float).ravel()
    Phi = np.asarray(Phi, dtype=float)
    if Phi.shape != (y.size, 2 * n):
        raise InputError(f"Phi: expected shape ({y.size}, {2 * n}), got {Phi.shape}", key="Phi")
    theta, *_ = np.linalg.lstsq(Phi, y, rcond=None)
    return LambdaEstimate(c=theta[:n], d=theta[n:], tau=float(tau), residuals=y - Phi @ theta)


def identify_lambda(y, u, h: float, tau: float, n: int = 1, skip: int = 0, interp: str = "linear") -> LambdaEstimate:
    """Filter the samples with lambda^k (k = 1..n) and solve regression (*) by least squares; the first
    ``skip`` samples (filter start-up) may be left out.  ``interp`` as in :func:`lambda_filter`."""
    Phi = lambda_regressors(y, u, h, tau, n, interp)
    return lambda_ls(np.asarray(y, dtype=float)[skip:], Phi[skip:], tau, n)


def dc_motor_from_lambda(est: LambdaEstimate) -> dict:
    """K/J and D/J from the first-order estimate y = c lambda{y} + d lambda{u} (corrected (12.2)):
    D/J = (1 - c)/tau, K/J = d/tau."""
    if est.c.size != 1:
        raise InputError("est: expected a first-order lambda estimate", key="est")
    return {"K/J": float(est.d[0] / est.tau), "D/J": float((1.0 - est.c[0]) / est.tau)}
