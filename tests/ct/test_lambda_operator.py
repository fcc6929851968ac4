"""Johansson Exercises 12.1 (lambda-operator DC motor) and 12.2 (notch prefilter + RLS)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from pipeline.ct.lambda_operator import (
    dc_motor_from_lambda,
    identify_lambda,
    lambda_filter,
    lambda_ls,
    lambda_to_tf,
)
from pipeline.errors import InputError
from pipeline.estimators.rls import rls
from pipeline.prefilter import notch
from tests.seedcases import case

# ----------------------------------------------------------------------------------------- 12.1
KJ, DJ, TAU = 2.0, 1.0, 0.5


def _u121(t):
    return np.sin(0.7 * t) + 0.5 * np.sin(2.3 * t)


def _simulate_dc_motor():
    """y' = -D/J y + K/J u with continuous lambda filters lambda{y}, lambda{u} (tau = 0.5), RK4 1 ms,
    40 s, sampled at 20 Hz; returns (y, lambda{y}, lambda{u}, u) at the samples."""
    dt, sub, n_samp = 1e-3, 50, 801
    tg = np.arange(2 * (n_samp - 1) * sub + 1) * (dt / 2)
    ug = _u121(tg).tolist()
    y = ly = lu = 0.0
    out = [(0.0, 0.0, 0.0)]
    for k in range((n_samp - 1) * sub):
        u0, u1, u2 = ug[2 * k], ug[2 * k + 1], ug[2 * k + 2]

        def f(y, ly, lu, u):
            return -DJ * y + KJ * u, (y - ly) / TAU, (u - lu) / TAU

        a = f(y, ly, lu, u0)
        b = f(y + 0.5 * dt * a[0], ly + 0.5 * dt * a[1], lu + 0.5 * dt * a[2], u1)
        c = f(y + 0.5 * dt * b[0], ly + 0.5 * dt * b[1], lu + 0.5 * dt * b[2], u1)
        d = f(y + dt * c[0], ly + dt * c[1], lu + dt * c[2], u2)
        y += dt / 6 * (a[0] + 2 * b[0] + 2 * c[0] + d[0])
        ly += dt / 6 * (a[1] + 2 * b[1] + 2 * c[1] + d[1])
        lu += dt / 6 * (a[2] + 2 * b[2] + 2 * c[2] + d[2])
        if (k + 1) % sub == 0:
            out.append((y, ly, lu))
    arr = np.array(out)
    return arr[:, 0], arr[:, 1], arr[:, 2], _u121(np.arange(n_samp) * 0.05)


def test_joh_12_1_dc_motor_lambda():
    """Corrected (12.2): y = (1 - tau D/J) lambda{y} + (K tau/J) lambda{u}; coefficients 0.5 and 1.0
    (tolerance 1e-4, continuous filters), so K/J = 2 and D/J = 1 are recovered."""
    c = case("joh_12_1_dc_motor_lambda")
    y, ly, lu, u = _simulate_dc_motor()
    est = lambda_ls(y, np.column_stack([ly, lu]), TAU)
    coeffs = [est.c[0], est.d[0]]
    np.testing.assert_allclose(coeffs, c["expected"]["instance_coeffs"], atol=1e-4)
    # the document's sign (-1 + tau D/J) = -0.5 is wrong (misprint #42)
    assert est.c[0] == pytest.approx(1 - TAU * DJ, abs=1e-4) and est.c[0] != pytest.approx(-1 + TAU * DJ, abs=0.5)
    phys = dc_motor_from_lambda(est)
    assert phys["K/J"] == pytest.approx(KJ, abs=1e-3) and phys["D/J"] == pytest.approx(DJ, abs=1e-3)
    num, den = est.num, est.den
    np.testing.assert_allclose(den, [1.0, DJ], atol=1e-3)
    np.testing.assert_allclose(num, [KJ], atol=1e-3)


def test_joh_12_1_from_samples():
    """The same regression with the lambda filters applied to the 20 Hz samples: cubic-spline
    interpolation (O(h^4)) meets the 1e-4 tolerance; linear interpolation is biased by ~h^2 w^2/12."""
    y, _, _, u = _simulate_dc_motor()
    est = identify_lambda(y, u, 0.05, TAU, interp="cubic")
    np.testing.assert_allclose([est.c[0], est.d[0]], [0.5, 1.0], atol=1e-4)
    lin = identify_lambda(y, u, 0.05, TAU, interp="linear")
    np.testing.assert_allclose([lin.c[0], lin.d[0]], [0.5, 1.0], atol=1e-3)


def test_lambda_to_tf_second_order():
    """lambda_to_tf: G(lambda) = sum d_k lambda^k / (1 - sum c_k lambda^k) with lambda = 1/(1 + tau s)
    equals num(s)/den(s) on the imaginary axis (second-order instance)."""
    tau, c, d = 0.7, [0.9, -0.3], [0.2, 0.5]
    num, den = lambda_to_tf(c, d, tau)
    assert den[0] == 1.0 and len(den) == 3
    s = 1j * np.logspace(-2, 2, 25)
    lam = 1.0 / (1.0 + tau * s)
    g_lam = (d[0] * lam + d[1] * lam**2) / (1 - c[0] * lam - c[1] * lam**2)
    np.testing.assert_allclose(np.polyval(num, s) / np.polyval(den, s), g_lam, rtol=1e-12)


def test_lambda_bad_input():
    with pytest.raises(InputError, match="tau"):
        lambda_filter(np.ones(10), 0.1, 0.0)
    with pytest.raises(InputError, match="power"):
        lambda_filter(np.ones(10), 0.1, 1.0, power=0)


# ----------------------------------------------------------------------------------------- 12.2
ALPHA, BETA, TAU2, OMEGA, XI = 0.5, 1.0, 1.0, 2.0, 0.7


@njit(cache=False)
def _sim_122(freqs, phases, wseq, dt, sub, nsamp):
    """y = -alpha lambda{y} + beta lambda{u} + v, v'' = -omega^2 v + w (white), i.e.
    tau y' + (1 + alpha) y = beta u + v + tau v'; continuous lambda{y}, lambda{u}; RK4."""
    out = np.zeros((nsamp, 4))
    x = np.zeros(5)  # y, v, v', lambda{y}, lambda{u}
    out[0, 3] = np.sum(np.sin(phases))
    for k in range((nsamp - 1) * sub):
        t = k * dt
        w = wseq[k]
        K = np.zeros((4, 5))
        for st in range(4):
            if st == 0:
                z = x
                u = np.sum(np.sin(freqs * t + phases))
            elif st == 3:
                z = x + dt * K[2]
                u = np.sum(np.sin(freqs * (t + dt) + phases))
            else:
                z = x + 0.5 * dt * K[st - 1]
                u = np.sum(np.sin(freqs * (t + 0.5 * dt) + phases))
            K[st, 0] = (BETA * u + z[1] + TAU2 * z[2] - (1 + ALPHA) * z[0]) / TAU2
            K[st, 1] = z[2]
            K[st, 2] = -OMEGA * OMEGA * z[1] + w
            K[st, 3] = (z[0] - z[3]) / TAU2
            K[st, 4] = (u - z[4]) / TAU2
        x = x + dt / 6 * (K[0] + 2 * K[1] + 2 * K[2] + K[3])
        if (k + 1) % sub == 0:
            j = (k + 1) // sub
            out[j, 0] = x[0]
            out[j, 1] = x[3]
            out[j, 2] = x[4]
            out[j, 3] = np.sum(np.sin(freqs * (t + dt) + phases))
    return out


def test_joh_12_2_notch_filter_rls():
    """Derived instance (alpha = 0.5, beta = 1, w = 2 rad/s, xi = 0.7, tau = 1): RK4 1 ms, 300 s sampled
    at 10 Hz, white-noise intensity 0.2 (seed 1), input = 5 sinusoids at 0.1, 0.35, 0.8, 3, 5 rad/s.
    RLS (12.6)-(12.8) on [-lambda{y}, lambda{u}]: with the notch F(s) at w0 = w applied to y and both
    regressors the bias is small (< 0.06, i.e. 12 % of alpha: the remaining noise
    W/(s^2 + 2 xi w0 s + w0^2) is coloured, so LS is not exactly unbiased - discrepancy #43); without it
    the bias is large (> 0.3 and > 5 x the notched one).  Thresholds calibrated on noise seeds 1-5
    (notched bias 0.005-0.043, raw bias 0.35-1.1), not on this seed alone."""
    case("joh_12_2_notch_filter_rls")
    rng = np.random.default_rng(1)
    dt, sub, T = 1e-3, 100, 300.0
    nsamp = int(T / (dt * sub)) + 1
    wseq = rng.standard_normal((nsamp - 1) * sub) * 0.2 / np.sqrt(dt)
    freqs = np.array([0.1, 0.35, 0.8, 3.0, 5.0])
    phases = rng.uniform(0, 2 * np.pi, 5)
    y, ly, lu, _u = _sim_122(freqs, phases, wseq, dt, sub, nsamp).T
    h = dt * sub
    phi = np.column_stack([-ly, lu])
    raw = rls(phi, y, lam=1.0, p0=1e4).theta
    yf = notch(y, h, OMEGA, XI)
    phif = np.column_stack([notch(col, h, OMEGA, XI) for col in phi.T])
    filt = rls(phif, yf, lam=1.0, p0=1e4).theta
    true = np.array([ALPHA, BETA])
    bias_notch = np.max(np.abs(filt - true))
    bias_raw = np.max(np.abs(raw - true))
    assert bias_notch < 0.06, filt
    assert bias_raw > 0.3 and bias_raw > 5 * bias_notch, raw
