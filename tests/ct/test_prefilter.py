"""Prefilter stage: zero-phase low-pass, notch, decimation, SVF, derivatives, bad input."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.prefilter import (
    Prefilter,
    ct_filter,
    decimate,
    derivative,
    dominant_frequency,
    lowpass_zero_phase,
    notch,
    notch_coefficients,
    notch_detected,
    remove_mean,
    remove_trend,
    state_variable_filter,
)

FS = 100.0
DT = 1.0 / FS
T = np.arange(2000) * DT


def _amp_phase(x, t, omega):
    """Least-squares amplitude and phase of the sin(omega t) component (x ~ A sin(omega t + phi))."""
    X = np.column_stack([np.sin(omega * t), np.cos(omega * t)])
    s, c = np.linalg.lstsq(X, x, rcond=None)[0]
    return np.hypot(s, c), np.arctan2(c, s)


# ------------------------------------------------------------------------------------ bad input
def test_bad_input_messages_name_option_and_range():
    x = np.sin(T)
    with pytest.raises(InputError, match=r"cutoff: .*\(0, 50\) Hz"):
        lowpass_zero_phase(x, FS, 50.0)
    with pytest.raises(InputError, match="cutoff"):
        lowpass_zero_phase(x, FS, 60.0)
    with pytest.raises(InputError, match=r"order: expected a positive integer"):
        lowpass_zero_phase(x, FS, 5.0, order=0)
    with pytest.raises(InputError, match=r"order"):
        lowpass_zero_phase(x, FS, 5.0, order=-2)
    with pytest.raises(InputError, match=r"window: .*\[4, 50\]"):
        derivative(x[:50], DT, "savgol", window=51)
    with pytest.raises(InputError, match="x: the zero-phase filter"):
        lowpass_zero_phase(x[:15], FS, 5.0, order=4)
    with pytest.raises(InputError, match="omega0"):
        notch(x, DT, omega0=np.pi / DT)
    with pytest.raises(InputError, match="q: expected a positive integer"):
        decimate(x, 0)
    with pytest.raises(InputError, match="method"):
        derivative(x, DT, "magic")
    with pytest.raises(InputError, match="omega_c"):
        state_variable_filter(x, DT, 2, omega_c=1000.0)
    with pytest.raises(InputError, match="order"):
        state_variable_filter(x, DT, 0, omega_c=10.0)
    with pytest.raises(InputError, match="name"):
        Prefilter("wavelet")


# ------------------------------------------------------------------------------------- low-pass
def test_zero_phase_lowpass_passband_sinusoid():
    """A 1 Hz sinusoid well inside the 10 Hz pass band: < 1 % amplitude error and zero phase shift."""
    omega = 2 * np.pi * 1.0
    x = np.sin(omega * T + 0.3)
    y = lowpass_zero_phase(x, FS, cutoff=10.0, order=4)
    mid = slice(200, -200)
    amp, ph = _amp_phase(y[mid], T[mid], omega)
    assert abs(amp - 1.0) < 0.01
    assert abs(ph - 0.3) < 1e-3
    # lag estimate by cross-correlation: zero samples
    lag = np.argmax(np.correlate(y[mid], x[mid], "full")) - (y[mid].size - 1)
    assert lag == 0
    # and the stop band is attenuated
    z = lowpass_zero_phase(np.sin(2 * np.pi * 30.0 * T), FS, cutoff=10.0, order=4)
    assert np.std(z[mid]) < 0.01


def test_remove_mean_and_trend():
    x = 3.0 + 0.5 * T + np.sin(2 * np.pi * T)
    assert abs(remove_mean(x).mean()) < 1e-12
    r = remove_trend(x)
    assert abs(np.polyfit(T, r, 1)[0]) < 0.02


# ---------------------------------------------------------------------------------------- notch
def test_notch_removes_w0_by_40db_and_passes_far_frequency():
    w0, dt = 2.0, 0.1
    t = np.arange(6000) * dt
    b, a = notch_coefficients(w0, 0.7, dt)
    # discrete frequency response: zero at w0, unity at DC
    z = np.exp(1j * w0 * dt)
    assert abs(np.polyval(b, z) / np.polyval(a, z)) < 1e-12
    assert abs(np.sum(b) / np.sum(a) - 1.0) < 1e-12
    x = np.sin(w0 * t + 0.4)
    y = notch(x, dt, w0, 0.7)
    late = slice(3000, None)  # after the filter transient
    att_db = 20 * np.log10(np.std(y[late]) / np.std(x[late]))
    assert att_db < -40
    for far in (0.05 * w0, 10 * w0):
        xf = np.sin(far * t)
        yf = notch(xf, dt, w0, 0.7)
        g = np.std(yf[late]) / np.std(xf[late])
        assert g > 0.98
    # zero-phase variant too
    y0 = notch(x, dt, w0, 0.7, zero_phase=True)
    assert 20 * np.log10(np.std(y0[1000:-1000]) / np.std(x[1000:-1000])) < -40


def test_notch_at_detected_frequency():
    dt = 0.1
    t = np.arange(4000) * dt
    rng = np.random.default_rng(3)
    x = 0.3 * rng.standard_normal(t.size) + 2.0 * np.sin(1.7 * t)
    w = dominant_frequency(x, dt)
    assert abs(w - 1.7) < 0.01
    y, w0 = notch_detected(x, dt)
    assert w0 == pytest.approx(w)
    amp, _ = _amp_phase(y[2000:], t[2000:], 1.7)
    assert amp < 0.1  # from 2.0


# ----------------------------------------------------------------------------- decimation / SVF
def test_decimate_zero_phase():
    x = np.sin(2 * np.pi * 0.5 * T) + 0.5 * np.sin(2 * np.pi * 40 * T)
    y = decimate(x, 4)
    assert y.size == 500
    tt = T[::4]
    mid = slice(50, -50)
    amp, ph = _amp_phase(y[mid], tt[mid], 2 * np.pi * 0.5)
    assert abs(amp - 1.0) < 0.01 and abs(ph) < 1e-2
    resid = y[mid] - np.sin(2 * np.pi * 0.5 * tt[mid])
    assert np.std(resid) < 0.01  # the 40 Hz component (aliases to 10 Hz) removed


def test_state_variable_filter_rows_are_derivatives():
    x = np.sin(1.3 * T)
    rows = state_variable_filter(x, DT, order=3, omega_c=20.0)
    assert rows.shape == (4, T.size)
    for k in range(3):
        d = np.gradient(rows[k], DT)
        np.testing.assert_allclose(d[100:-100], rows[k + 1][100:-100], atol=2e-3 * (1 + np.abs(rows[k + 1]).max()))


def test_ct_filter_matches_analytic_first_order():
    """1/(1 + s) from rest on a ramp u = t (piecewise linear, so exact): y = t - 1 + exp(-t)."""
    t = np.arange(200) * 0.05
    y = ct_filter(t, 0.05, [1.0], [1.0, 1.0])
    np.testing.assert_allclose(y, t - 1 + np.exp(-t), atol=1e-10)


# ---------------------------------------------------------------------------------- derivatives
def test_derivative_methods_clean_signal_no_warning():
    x = np.sin(1.3 * T)
    true = 1.3 * np.cos(1.3 * T)
    for method, kw, tol in (("fd", {}, 1e-3), ("savgol", {"window": 21, "polyorder": 3}, 1e-3),
                            ("spline", {}, 2e-2), ("tv", {"alpha": 1e-6}, 5e-2)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            dx, msg = derivative(x, DT, method, **kw)
        assert msg is None
        assert np.max(np.abs(dx[50:-50] - true[50:-50])) < tol, method


def test_derivative_warns_on_noise_amplification():
    rng = np.random.default_rng(7)
    x = np.sin(1.3 * T) + 0.01 * rng.standard_normal(T.size)  # 37 dB SNR
    with pytest.warns(UserWarning, match="amplifies noise"):
        dx, msg = derivative(x, DT, "fd")
    assert msg and "fs/4" in msg
    # smoothing derivatives do not trigger the rule and are far more accurate
    true = 1.3 * np.cos(1.3 * T)
    err_fd = np.std(dx - true)
    for method, kw in (("savgol", {"window": 101, "polyorder": 3}), ("spline", {})):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            ds, msg_s = derivative(x, DT, method, **kw)
        assert msg_s is None
        assert np.std((ds - true)[100:-100]) < 0.2 * err_fd


def test_tv_derivative_piecewise_linear():
    rng = np.random.default_rng(11)
    t = np.arange(400) * 0.01
    slope = np.where(t < 2.0, 1.0, -1.0)
    x = np.cumsum(slope) * 0.01 + 0.002 * rng.standard_normal(t.size)
    dx, _ = derivative(x, 0.01, "tv", alpha=2e-3, warn=False)
    assert np.median(np.abs(dx[20:180] - 1.0)) < 0.1
    assert np.median(np.abs(dx[220:380] + 1.0)) < 0.1


# ------------------------------------------------------------------------------------ step object
def test_prefilter_step_dict_and_apply():
    step = Prefilter("lowpass", {"cutoff": 5.0, "order": 3})
    assert step.to_dict() == {"name": "lowpass", "params": {"cutoff": 5.0, "order": 3}}
    res = step.apply(np.sin(T), DT)
    assert res.y.shape == T.shape and res.warnings == []
    rng = np.random.default_rng(1)
    with pytest.warns(UserWarning):
        r2 = Prefilter("derivative", {"method": "fd"}).apply(np.sin(T) + 0.01 * rng.standard_normal(T.size), DT)
    assert r2.warnings and "amplifies noise" in r2.warnings[0]
    r3 = Prefilter("notch", {"xi": 0.7}).apply(np.sin(3.0 * T), DT)
    assert r3.info["omega0_detected"] == pytest.approx(3.0, abs=0.05)
    with pytest.raises(InputError, match="lowpass"):
        Prefilter("lowpass", {"cutof": 5.0}).apply(np.sin(T), DT)
