"""Report figures (matplotlib, Agg). Each returns a PNG as base64; PNG metadata is stripped of the
software version so the bytes depend only on the data."""

from __future__ import annotations

import base64
import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from ..diagnostics import stats as rstats  # noqa: E402

CHI2_2_95 = float(stats.chi2.ppf(0.95, 2))  # 5.991


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _shade(ax, t, split):
    ax.axvspan(t[split.est[0]], t[split.est[1] - 1], color="tab:blue", alpha=0.06, label="estimation")
    ax.axvspan(t[split.val[0]], t[split.val[1] - 1], color="tab:orange", alpha=0.08, label="validation")


def overview(ctx) -> str:
    t, prob = ctx.prob.t, ctx.prob
    nu = prob.U.shape[1] if ctx.model.inputs else 0
    fig, axes = plt.subplots(nu + len(prob.out_names), 1, figsize=(9, 1.8 * (nu + len(prob.out_names))),
                             sharex=True, squeeze=False)
    for j, name in enumerate(ctx.model.inputs):
        axes[j, 0].plot(t, prob.U[:, j], lw=0.5, color="k")
        axes[j, 0].set_ylabel(f"input {name}")
        _shade(axes[j, 0], t, prob.split)
    for i, name in enumerate(prob.out_names):
        ax = axes[nu + i, 0]
        ax.plot(t, prob.Y[:, i], lw=0.5, color="k")
        ax.set_ylabel(f"output {name}")
        _shade(ax, t, prob.split)
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    return _png(fig)


def compare(ctx, fits: list, labels: list[str], title: str) -> str:
    """Measured vs free-run simulation on the validation data."""
    prob = ctx.prob
    sl = prob.split.val_slice()
    t = prob.t[sl]
    fig, axes = plt.subplots(len(prob.out_names), 1, figsize=(9, 2.6 * len(prob.out_names)), squeeze=False)
    for i, name in enumerate(prob.out_names):
        ax = axes[i, 0]
        ax.plot(t, prob.Y[sl, i], color="k", lw=0.8, label="measured")
        for fit, lab, col in zip(fits, labels, ("tab:red", "tab:green", "tab:purple", "tab:brown")):
            ax.plot(t, fit.Yhat[sl, i], color=col, lw=0.8, label=lab)
        ax.set_ylabel(name)
    axes[0, 0].set_title(title, fontsize=10)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s] (validation data, free-run simulation)")
    return _png(fig)


def residuals(ctx, fit, label: str) -> str:
    prob = ctx.prob
    r = prob.Y - fit.Yhat
    fig, ax = plt.subplots(1, 1, figsize=(9, 2.2))
    _shade(ax, prob.t, prob.split)
    ax.plot(prob.t, r[:, 0], lw=0.5, color="k")
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_ylabel(f"y - ŷ ({prob.out_names[0]})")
    ax.set_title(f"free-run simulation error, {label}", fontsize=10)
    ax.set_xlabel("time [s]")
    return _png(fig)


def correlations(ctx, fit, alpha: float) -> str:
    prob = ctx.prob
    e = fit.resid_est[:, 0]
    r, bound = rstats.autocorr(e, 25, 1 - alpha)
    fig, axes = plt.subplots(1, 2 if ctx.model.inputs else 1, figsize=(9, 2.6), squeeze=False)
    ax = axes[0, 0]
    ax.stem(np.arange(1, 26), r[1:], basefmt=" ")
    ax.axhspan(-bound, bound, color="tab:blue", alpha=0.15)
    ax.set_title(f"residual autocorrelation, ±{bound:.3g} ({100 * (1 - alpha):.0f} %)", fontsize=9)
    ax.set_xlabel("lag [samples]")
    if ctx.model.inputs:
        u = prob.U[prob.split.est_slice(), 0]
        lags, c, b = rstats.crosscorr(e, u, 25, 1 - alpha)
        ax = axes[0, 1]
        ax.stem(lags, c, basefmt=" ")
        ax.axhspan(-b, b, color="tab:blue", alpha=0.15)
        ax.set_title(f"input–residual cross-correlation, ±{b:.3g}", fontsize=9)
        ax.set_xlabel("lag [samples]")
    return _png(fig)


def ellipses(fit, max_pairs: int = 6) -> str | None:
    """95 % confidence ellipses (θ−θ̂)ᵀP⁻¹(θ−θ̂) ≤ χ²₂(0.95) = 5.991 for pairs of estimated quantities."""
    n = len(fit.theta)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)][:max_pairs]
    if not pairs or not np.all(np.isfinite(fit.cov)):
        return None
    fig, axes = plt.subplots(1, len(pairs), figsize=(3.0 * len(pairs), 2.8), squeeze=False)
    ang = np.linspace(0, 2 * np.pi, 200)
    for ax, (i, j) in zip(axes[0], pairs):
        P = fit.cov[np.ix_([i, j], [i, j])]
        w, V = np.linalg.eigh(P)
        pts = V @ (np.sqrt(np.clip(w, 0, None) * CHI2_2_95)[:, None] * np.vstack([np.cos(ang), np.sin(ang)]))
        ax.plot(fit.theta[i] + pts[0], fit.theta[j] + pts[1], color="tab:blue")
        ax.plot(fit.theta[i], fit.theta[j], "k+")
        ax.set_xlabel(fit.names[i], fontsize=8)
        ax.set_ylabel(fit.names[j], fontsize=8)
        ax.tick_params(labelsize=7)
        ax.ticklabel_format(style="sci", scilimits=(-3, 4))
    fig.suptitle("95 % confidence ellipses (χ²₂ = 5.991)", fontsize=9)
    fig.tight_layout()
    return _png(fig)


def err_chart(frols: dict) -> str:
    """ERR of each selected term (FROLS), in selection order, with the cumulative sum."""
    names, err = frols["names"], np.asarray(frols["err"], float)
    fig, ax = plt.subplots(1, 1, figsize=(7, 2.6))
    x = np.arange(len(names))
    ax.bar(x, 100 * err, color="tab:blue")
    ax.plot(x, 100 * np.cumsum(err), "k.-", lw=0.8, label="cumulative")
    ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("ERR [%]")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title(f"ERR of the selected terms ({frols['n_candidates']} candidates, stop: {frols['criterion']})",
                 fontsize=9)
    return _png(fig)


def ts_memberships(ts: dict) -> str:
    """Normalised Takagi–Sugeno memberships over the first premise input."""
    grid = np.asarray(ts["grid"])
    c = np.asarray(ts["centres"])[:, 0]
    s = np.asarray(ts["sigmas"])[:, 0]
    beta = np.exp(-((grid[:, None] - c[None, :]) / s[None, :]) ** 2)
    w = beta / beta.sum(axis=1, keepdims=True)
    fig, ax = plt.subplots(1, 1, figsize=(7, 2.4))
    ax.plot(grid, w, lw=1)
    ax.set_xlabel(ts["inputs"][0])
    ax.set_ylabel("normalised membership")
    ax.set_title(f"Takagi–Sugeno: {ts['rules']} rules chosen by blocked CV from {ts['candidates']}", fontsize=9)
    return _png(fig)


def rls_trajectories(res) -> str:
    """RLS parameter trajectories θ̂_k of one structure (a drifting or jumping parameter shows here)."""
    th = res.extra["theta_trajectory"]
    fig, ax = plt.subplots(1, 1, figsize=(8, 2.6))
    for j, name in enumerate(res.terms):
        ax.plot(res.extra["t"], th[:, j], lw=0.8, label=name)
    ax.set_xlabel("time [s] (estimation data)")
    ax.set_ylabel("θ̂")
    lim = np.percentile(np.abs(th[len(th) // 10:]), 99.5) * 1.5 if len(th) > 10 else None
    if lim and np.isfinite(lim) and lim > 0:
        ax.set_ylim(-lim, lim)
    ax.legend(fontsize=7, ncol=min(4, len(res.terms)))
    ax.set_title(f"RLS parameter trajectories, structure {res.name}", fontsize=9)
    return _png(fig)
