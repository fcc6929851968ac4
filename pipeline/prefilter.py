"""Prefilter stage: pure functions on sampled signals plus a loggable :class:`Prefilter` step.

Functions (all take a 1-D numpy array ``x`` and the sampling period ``dt`` [s] or rate ``fs`` [Hz]):

* :func:`remove_mean`, :func:`remove_trend` - offsets and linear drifts;
* :func:`lowpass_zero_phase` - Butterworth low-pass (``scipy.signal.butter`` second-order sections)
  run forwards and backwards (``sosfiltfilt``): zero phase, squared magnitude;
* :func:`ct_filter` - a continuous-time transfer function B(s)/A(s) applied to samples from rest,
  with the input linearly interpolated between samples (exact for piecewise-linear input); used for
  Tsang-Billings prefiltering with the current model (eq. 46) and for lambda-operator filters;
* :func:`state_variable_filter` - SVF outputs s^k/(1 + s/w_c)^n x, k = 0..n (filtered derivatives);
* :func:`notch_coefficients`, :func:`notch`, :func:`notch_detected` - Johansson (12.2)
  F(s) = (s^2 + w0^2)/(s^2 + 2 xi w0 s + w0^2), discretised with the bilinear transform pre-warped at
  w0 so the discrete zero lies exactly at w0 (infinite attenuation there); ``notch_detected`` puts w0
  at the largest (non-DC) periodogram peak;
* :func:`decimate` - ``scipy.signal.decimate`` with anti-alias filtering, zero phase;
* :func:`derivative` - finite difference, Savitzky-Golay, smoothing spline or total-variation
  regularised differentiation, with a noise-amplification check (:func:`noise_amplification`).

Noise-amplification rule (documented in :func:`noise_amplification`): let r_d be the fraction of the
derivative's power above fs/4 (the upper half of the Nyquist band) and r_x the same fraction for the
signal.  Differentiation multiplies the spectrum by w^2, so a derivative dominated by high-frequency
content is dominated by amplified noise.  A warning is issued (``warnings.warn`` and a returned string)
when r_d > ``hf_fraction_max`` (default 0.10).  The gain r_d / r_x is reported in the message.

Bad options (a cut-off at or above Nyquist, a non-positive order, a window longer than the signal ...)
raise :class:`~pipeline.errors.InputError` naming the option and its allowed range.
"""

from __future__ import annotations

import inspect
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy import signal
from scipy.interpolate import make_smoothing_spline
from scipy.sparse.linalg import LinearOperator, cg

from pipeline.errors import InputError

__all__ = [
    "Prefilter",
    "PrefilterResult",
    "remove_mean",
    "remove_trend",
    "lowpass_zero_phase",
    "ct_filter",
    "state_variable_filter",
    "notch_coefficients",
    "notch",
    "dominant_frequency",
    "notch_detected",
    "decimate",
    "derivative",
    "noise_amplification",
]


# ----------------------------------------------------------------------------------------- checks
def _signal(x, name: str = "x", min_len: int = 2) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise InputError(f"expected a 1-D signal, got an array of shape {x.shape}", key=name)
    if x.size < min_len:
        raise InputError(f"expected at least {min_len} samples, got {x.size}", key=name)
    if not np.all(np.isfinite(x)):
        raise InputError("expected finite samples, found NaN or inf", key=name)
    return x


def _positive(value, name: str) -> float:
    if isinstance(value, bool):     # float(True) is 1.0: a YAML `true` is not a number
        raise InputError(f"expected a positive number, got {value!r}", key=name)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected a positive number, got {value!r}", key=name) from None
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"expected a positive number (> 0), got {value!r}", key=name)
    return v


def _order(value, name: str = "order", max_value: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        rng = f"[1, {max_value}]" if max_value else ">= 1"
        raise InputError(f"expected a positive integer {rng}, got {value!r}", key=name)
    if max_value is not None and value > max_value:
        raise InputError(f"expected a positive integer in [1, {max_value}], got {value!r}", key=name)
    return int(value)


def _below_nyquist(freq, fs: float, name: str) -> float:
    f = _positive(freq, name)
    nyq = fs / 2.0
    if f >= nyq:
        raise InputError(f"expected a frequency in (0, {nyq:g}) Hz (below Nyquist fs/2), got {freq!r}", key=name)
    return f


# ----------------------------------------------------------------------------------- basic steps
def remove_mean(x) -> np.ndarray:
    """x - mean(x)."""
    x = _signal(x)
    return x - x.mean()


def remove_trend(x) -> np.ndarray:
    """Remove the least-squares straight line (``scipy.signal.detrend(type='linear')``)."""
    return signal.detrend(_signal(x), type="linear")


def lowpass_zero_phase(x, fs: float, cutoff: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass: ``butter(order, cutoff, fs=fs, output='sos')`` + ``sosfiltfilt``.

    ``cutoff`` in Hz must lie in (0, fs/2); ``order`` >= 1 (the effective order is doubled by the
    forward-backward pass, and the -3 dB point becomes -6 dB).  The signal must be longer than the
    filter's edge padding (3 * (2 * number of sections + 1) samples)."""
    fs = _positive(fs, "fs")
    cutoff = _below_nyquist(cutoff, fs, "cutoff")
    order = _order(order, "order", 20)
    sos = signal.butter(order, cutoff, fs=fs, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    x = _signal(x)
    if x.size <= padlen:
        raise InputError(
            f"x: the zero-phase filter of order {order} needs more than {padlen} samples (edge padding), got {x.size}",
            key="x",
        )
    return signal.sosfiltfilt(sos, x)


def ct_filter(x, dt: float, num, den) -> np.ndarray:
    """Continuous-time filter B(s)/A(s) (coefficients highest power first) applied to the samples ``x``
    from rest (zero initial state at the first sample), with linear interpolation of the input between
    samples (``scipy.signal.lsim(interp=True)``: exact for piecewise-linear input).  Used for the
    Tsang-Billings prefilter F(D) of eq. (46) and for lambda / state-variable filters."""
    x = _signal(x)
    dt = _positive(dt, "dt")
    num = np.atleast_1d(np.asarray(num, dtype=float))
    den = np.atleast_1d(np.asarray(den, dtype=float))
    den = np.trim_zeros(den, "f")
    if den.size == 0 or np.trim_zeros(num, "f").size > den.size:
        raise InputError("num/den: expected a proper transfer function (deg num <= deg den, den != 0)", key="den")
    t = np.arange(x.size) * dt
    if den.size == 1:
        return float(num[-1]) / den[0] * x
    _, y, _ = signal.lsim((num, den), x, t, interp=True)
    return np.asarray(y, dtype=float)


def state_variable_filter(x, dt: float, order: int, omega_c: float) -> np.ndarray:
    """State-variable filter: rows k = 0..order of s^k / (1 + s/omega_c)^order applied to ``x``
    (from rest, linear interpolation between samples).  Row k is a filtered k-th derivative of ``x``;
    the same filter applied to input and output leaves a linear model unchanged (cf. T&B eq. 46)."""
    order = _order(order, "order", 10)
    omega_c = _positive(omega_c, "omega_c")
    dt = _positive(dt, "dt")
    if omega_c >= np.pi / dt:
        raise InputError(f"expected a frequency in (0, {np.pi / dt:g}) rad/s (below Nyquist), got {omega_c!r}", key="omega_c")
    den = np.poly1d([1.0 / omega_c, 1.0]) ** order
    out = np.empty((order + 1, np.asarray(x).size))
    for k in range(order + 1):
        num = np.zeros(k + 1)
        num[0] = 1.0
        out[k] = ct_filter(x, dt, num, den.coeffs)
    return out


# ------------------------------------------------------------------------------------------ notch
def notch_coefficients(omega0: float, xi: float, dt: float):
    """Discrete (b, a) of F(s) = (s^2 + w0^2)/(s^2 + 2 xi w0 s + w0^2) (Johansson, Exercise 12.2) by the
    bilinear transform s = K (1 - z^-1)/(1 + z^-1) with pre-warping K = w0 / tan(w0 dt / 2), so that
    the discrete notch lies exactly at w0 and has unit gain at DC and at Nyquist."""
    dt = _positive(dt, "dt")
    omega0 = _positive(omega0, "omega0")
    nyq = np.pi / dt
    if omega0 >= nyq:
        raise InputError(f"expected a frequency in (0, {nyq:g}) rad/s (below Nyquist pi/dt), got {omega0!r}", key="omega0")
    xi = _positive(xi, "xi")
    K = omega0 / np.tan(omega0 * dt / 2.0)
    w2 = omega0**2
    # (1 - z^-1)^2 = [1, -2, 1]; (1 - z^-2) = [1, 0, -1]; (1 + z^-1)^2 = [1, 2, 1]
    m, c, p = np.array([1.0, -2.0, 1.0]), np.array([1.0, 0.0, -1.0]), np.array([1.0, 2.0, 1.0])
    b = K**2 * m + w2 * p
    a = K**2 * m + 2 * xi * omega0 * K * c + w2 * p
    return b / a[0], a / a[0]


def notch(x, dt: float, omega0: float, xi: float = 0.7, zero_phase: bool = False) -> np.ndarray:
    """Apply the discretised notch F of Johansson (12.2) at ``omega0`` [rad/s] (causal by default,
    forward-backward when ``zero_phase``)."""
    x = _signal(x)
    b, a = notch_coefficients(omega0, xi, dt)
    if zero_phase:
        if x.size <= 9:
            raise InputError(f"zero-phase notch needs more than 9 samples, got {x.size}", key="x")
        return signal.filtfilt(b, a, x)
    return signal.lfilter(b, a, x)


def dominant_frequency(x, dt: float) -> float:
    """Angular frequency [rad/s] of the largest non-DC periodogram peak (mean removed, Hann window),
    refined by parabolic interpolation of the log-spectrum around the peak bin."""
    x = _signal(x, min_len=8)
    dt = _positive(dt, "dt")
    f, pxx = signal.periodogram(x - x.mean(), fs=1.0 / dt, window="hann")
    k = int(np.argmax(pxx[1:])) + 1
    fk = f[k]
    if 1 <= k < len(pxx) - 1 and np.all(pxx[k - 1 : k + 2] > 0):
        l0, l1, l2 = np.log(pxx[k - 1 : k + 2])
        d = l0 - 2 * l1 + l2
        if d < 0:
            fk = f[k] + 0.5 * (l0 - l2) / d * (f[1] - f[0])
    return float(2 * np.pi * fk)


def notch_detected(x, dt: float, xi: float = 0.7, zero_phase: bool = False):
    """Notch at the detected disturbance frequency (largest periodogram peak); returns (y, omega0)."""
    w0 = dominant_frequency(x, dt)
    return notch(x, dt, w0, xi, zero_phase), w0


# ------------------------------------------------------------------------------------- decimation
def decimate(x, q: int, ftype: str = "iir", order: int | None = None) -> np.ndarray:
    """Keep every q-th sample after zero-phase anti-alias filtering (``scipy.signal.decimate``,
    ``zero_phase=True``; Chebyshev-I order 8 for 'iir', Hamming FIR of 20q+1 taps for 'fir')."""
    x = _signal(x)
    q = _order(q, "q")
    if ftype not in ("iir", "fir"):
        raise InputError(f"expected 'iir' or 'fir', got {ftype!r}", key="ftype")
    if order is not None:
        order = _order(order, "order", 30)
    n_taps = (order if order is not None else (20 * q if ftype == "fir" else 8)) + 1
    need = 3 * n_taps if ftype == "fir" else 3 * (2 * (n_taps // 2) + 1) + 1
    if x.size <= need:
        raise InputError(f"decimation by {q} ({ftype}) needs more than {need} samples, got {x.size}", key="x")
    return signal.decimate(x, q, n=order, ftype=ftype, zero_phase=True)


# ------------------------------------------------------------------------------------ derivatives
def noise_amplification(x, dx, dt: float, hf_fraction_max: float = 0.10):
    """Noise-amplification check for a derivative estimate.

    r_d = fraction of the power of ``dx`` above fs/4, r_x = same fraction for ``x`` (periodograms of
    the linearly detrended signals, Hann window).  Differentiation weights the spectrum by w^2, so when
    r_d exceeds ``hf_fraction_max`` the derivative is dominated by amplified high-frequency content
    (noise).  Returns ``(r_d, r_x, message_or_None)``."""
    fs = 1.0 / dt
    def hf_fraction(s):
        s = signal.detrend(np.asarray(s, dtype=float))
        f, p = signal.periodogram(s, fs=fs, window="hann")
        tot = p.sum()
        return float(p[f > fs / 4].sum() / tot) if tot > 0 else 0.0
    r_d, r_x = hf_fraction(dx), hf_fraction(x)
    msg = None
    if r_d > hf_fraction_max:
        gain = r_d / r_x if r_x > 0 else np.inf
        msg = (
            f"differentiation amplifies noise: {100 * r_d:.1f}% of the derivative's power lies above fs/4 "
            f"(signal: {100 * r_x:.2f}%, ratio {gain:.3g}); threshold {100 * hf_fraction_max:.0f}%. "
            "Consider smoothing (Savitzky-Golay, spline, TV) or an integral formulation."
        )
    return r_d, r_x, msg


def _tv_derivative(x, dt, alpha, n_iter=30, eps=1e-8):
    """Total-variation regularised differentiation (Chartrand 2011): minimise
    alpha * sum |D u| + 1/2 ||A u - (x - x0)||^2 with A the trapezoidal cumulative integral, by lagged
    diffusivity (each step a symmetric positive-definite solve by conjugate gradients)."""
    n = x.size
    f = x - x[0]

    def A(u):
        c = np.concatenate(([0.0], np.cumsum(0.5 * (u[1:] + u[:-1]) * dt)))
        return c

    def AT(v):
        # adjoint of A: A = C S where S averages neighbours and C cumsum with leading zero
        w = np.cumsum(v[::-1])[::-1][1:] * dt  # (n-1,)  sum_{k>=i+1} v_k
        out = np.zeros(n)
        out[:-1] += 0.5 * w
        out[1:] += 0.5 * w
        return out

    u = np.gradient(x, dt)
    ATf = AT(f)
    for _ in range(n_iter):
        du = np.diff(u)
        wgt = 1.0 / np.sqrt(du**2 + eps)

        def mv(v, wgt=wgt):
            dv = np.diff(v)
            L = np.zeros(n)
            L[:-1] -= wgt * dv
            L[1:] += wgt * dv
            return AT(A(v)) + alpha * L

        op = LinearOperator((n, n), matvec=mv, dtype=float)
        u_new, _ = cg(op, ATf, x0=u, maxiter=200)
        if np.linalg.norm(u_new - u) <= 1e-6 * (np.linalg.norm(u) + 1e-12):
            u = u_new
            break
        u = u_new
    return u


def derivative(x, dt: float, method: str = "fd", *, window: int = 11, polyorder: int = 3, lam: float | None = None,
               alpha: float = 1e-3, hf_fraction_max: float = 0.10, warn: bool = True):
    """Derivative estimate of ``x`` sampled every ``dt``.

    ``method``: 'fd' (second-order central differences, ``numpy.gradient``), 'savgol'
    (Savitzky-Golay, odd ``window`` > ``polyorder``, window <= len(x)), 'spline' (smoothing spline,
    ``scipy.interpolate.make_smoothing_spline``; ``lam=None`` selects the smoothing by GCV) or 'tv'
    (total-variation regularised, weight ``alpha``).  Returns ``(dx, warning)``; ``warning`` is the
    string of :func:`noise_amplification` (also issued with ``warnings.warn``) or None."""
    x = _signal(x, min_len=3)
    dt = _positive(dt, "dt")
    if method == "fd":
        dx = np.gradient(x, dt, edge_order=2)
    elif method == "savgol":
        window = _order(window, "window")
        if window > x.size:
            raise InputError(f"expected an odd integer in [{polyorder + 1}, {x.size}] (signal length), got {window}", key="window")
        if window % 2 == 0:
            raise InputError(f"expected an odd integer, got {window}", key="window")
        if not isinstance(polyorder, (int, np.integer)) or polyorder < 1 or polyorder >= window:
            raise InputError(f"expected an integer in [1, {window - 1}], got {polyorder!r}", key="polyorder")
        dx = signal.savgol_filter(x, window, polyorder, deriv=1, delta=dt)
    elif method == "spline":
        if x.size < 5:
            raise InputError(f"smoothing spline needs at least 5 samples, got {x.size}", key="x")
        if lam is not None:
            lam = _positive(lam, "lam")
        t = np.arange(x.size) * dt
        spl = make_smoothing_spline(t, x, lam=lam)
        dx = spl.derivative()(t)
    elif method == "tv":
        alpha = _positive(alpha, "alpha")
        dx = _tv_derivative(x, dt, alpha)
    else:
        raise InputError(f"expected one of 'fd', 'savgol', 'spline', 'tv', got {method!r}", key="method")
    _, _, msg = noise_amplification(x, dx, dt, hf_fraction_max)
    if msg and warn:
        warnings.warn(msg, stacklevel=2)
    return dx, msg


# --------------------------------------------------------------------------------- step objects
@dataclass
class PrefilterResult:
    y: np.ndarray
    warnings: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)


def _run_remove_mean(x, dt):
    return remove_mean(x), [], {}


def _run_remove_trend(x, dt):
    return remove_trend(x), [], {}


def _run_lowpass(x, dt, cutoff, order=4):
    return lowpass_zero_phase(x, 1.0 / dt, cutoff, order), [], {}


def _run_svf(x, dt, order, omega_c, output=0):
    return state_variable_filter(x, dt, order, omega_c)[output], [], {}


def _run_notch(x, dt, omega0=None, xi=0.7, zero_phase=False):
    if omega0 is None:
        y, w0 = notch_detected(x, dt, xi, zero_phase)
        return y, [], {"omega0_detected": w0}
    return notch(x, dt, omega0, xi, zero_phase), [], {}


def _run_decimate(x, dt, q, ftype="iir"):
    return decimate(x, q, ftype), [], {"dt_out": dt * q}


def _run_derivative(x, dt, method="fd", **kw):
    dx, msg = derivative(x, dt, method, **kw)
    return dx, ([msg] if msg else []), {}


_STEPS: dict[str, Callable] = {
    "remove_mean": _run_remove_mean,
    "remove_trend": _run_remove_trend,
    "lowpass": _run_lowpass,
    "state_variable_filter": _run_svf,
    "notch": _run_notch,
    "decimate": _run_decimate,
    "derivative": _run_derivative,
}


@dataclass
class Prefilter:
    """A loggable prefilter step: ``name`` (one of remove_mean, remove_trend, lowpass,
    state_variable_filter, notch, decimate, derivative) and keyword ``params`` of the matching function.
    ``to_dict()`` gives ``{"name": ..., "params": {...}}`` for logs; ``apply(x, dt)`` runs the step."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if self.name not in _STEPS:
            raise InputError(f"name: expected one of {sorted(_STEPS)}, got {self.name!r}", key="prefilter")

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "params": dict(self.params)}

    def apply(self, x, dt: float) -> PrefilterResult:
        fn = _STEPS[self.name]
        sig = inspect.signature(fn)
        if not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
            known = [k for k in sig.parameters if k not in ("x", "dt")]
            unknown = sorted(set(self.params) - set(known))
            if unknown:
                raise InputError(f"{self.name} has no parameter {', '.join(map(repr, unknown))}; expected "
                                 f"{'params ' + ', '.join(known) if known else 'no params'}")
            missing = [k for k in known if sig.parameters[k].default is inspect.Parameter.empty
                       and k not in self.params]
            if missing:
                raise InputError(f"{self.name} needs params {', '.join(missing)} (e.g. params: "
                                 f"{{{', '.join(f'{k}: ...' for k in missing)}}})")
        try:
            y, warns, info = fn(x, dt, **self.params)
        except TypeError as exc:
            raise InputError(f"params of {self.name}: {exc}") from None
        return PrefilterResult(y=np.asarray(y), warnings=list(warns), info=info)
