"""Report figures (matplotlib, Agg). Each returns a PNG as base64; the PNG metadata carries no
software version or date, so the bytes depend only on the data.

Readability rules (issue 10): tick labels ≥ 8 pt at 100 dpi shown at ~1:1 (figures ≤ 9.6 in wide in a
1000 px column), legends above the axes (never over data), axis units from the config's ``units``,
long traces as a min/max envelope beside a full-resolution zoom window.
"""

from __future__ import annotations

import base64
import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from ..diagnostics import stats as rstats  # noqa: E402
from ..fit import excited_inputs  # noqa: E402
from . import analysis  # noqa: E402

CHI2_2_95 = float(stats.chi2.ppf(0.95, 2))  # 5.991
WIDTH_IN = 9.6
DPI = 100
COLORS = ("tab:red", "tab:green", "tab:purple", "tab:brown", "tab:cyan", "tab:olive")
RC = {"font.size": 9, "axes.titlesize": 9.5, "axes.labelsize": 9, "xtick.labelsize": 8.5,
      "ytick.labelsize": 8.5, "legend.fontsize": 8.5, "svg.hashsalt": "sysid", "path.simplify": True,
      # user text (names, expressions) is drawn literally: "$x$" in a name is not mathtext, and a "$" never crashes
      "text.parse_math": False}


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _fig(*args, **kw):
    """``plt.subplots``; the caller (``render_report``) holds ``plt.rc_context(RC)``."""
    return plt.subplots(*args, **kw)


def label(name: str, units: dict[str, str]) -> str:
    u = units.get(name)
    return f"{name} [{u}]" if u else f"{name} [data units]"


def _legend_above(ax, ncol: int = 4) -> None:
    h, lab = ax.get_legend_handles_labels()
    if h:
        ax.legend(h, lab, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=min(ncol, len(h)), frameon=False,
                  fontsize=8.5, borderaxespad=0.0)


def _trace(ax, t, y, color, lab, *, lw=0.8, measured=False):
    """A line, or for a long trace its min/max envelope (filled for the measurement, outlined for a
    model) so the measured signal stays visible under the simulations."""
    env = analysis.envelope(t, y)
    if env is None:
        ax.plot(t, y, color=color, lw=lw, label=lab, zorder=3 if measured else 4)
        return
    tb, lo, hi = env
    if measured:  # on top, slightly transparent: model outlines show where they leave the measurement
        ax.fill_between(tb, lo, hi, color="0.55", alpha=0.8, lw=0, label=f"{lab} (min/max envelope)", zorder=5)
    else:
        ax.plot(tb, hi, color=color, lw=0.6, label=lab, zorder=3)
        ax.plot(tb, lo, color=color, lw=0.6, zorder=3)


def _shade(ax, t, split):
    ax.axvspan(t[split.est[0]], t[split.est[1] - 1], color="tab:blue", alpha=0.07, label="estimation part")
    ax.axvspan(t[split.val[0]], t[split.val[1] - 1], color="tab:orange", alpha=0.10, label="validation part")


def overview(ctx, units: dict[str, str]) -> str:
    """Every input and output over the whole record with the estimation/validation parts shaded."""
    t, prob = ctx.prob.t, ctx.prob
    names = [("input", n, prob.U[:, j]) for j, n in enumerate(ctx.model.inputs)] + \
            [("output", n, prob.Y[:, i]) for i, n in enumerate(prob.out_names)]
    fig, axes = _fig(len(names), 1, figsize=(WIDTH_IN, 1.9 * len(names) + 0.4), sharex=True, squeeze=False)
    for ax, (kind, n, y) in zip(axes[:, 0], names):
        _shade(ax, t, prob.split)
        _trace(ax, t, y, "k", f"{kind} {n}", measured=True)
        ax.set_ylabel(label(n, units))
    _legend_above(axes[0, 0])
    axes[-1, 0].set_xlabel("time [s]")
    return _png(fig)


def compare(ctx, fits: list, labels: list[str], units: dict[str, str], zoom: int = 400) -> str:
    """Measured vs free-run simulation on the validation part: the whole part (envelope when long)
    and, beside it, a full-resolution window of ``zoom`` samples where the first model errs most."""
    prob = ctx.prob
    sl = prob.split.val_slice()
    t = prob.t[sl]
    ny = len(prob.out_names)
    # a part no longer than the window is drawn whole at full resolution: a zoom would repeat it
    zoomed = len(t) > zoom
    fig, axes = _fig(ny, 2 if zoomed else 1, figsize=(WIDTH_IN, 2.9 * ny + 0.4), squeeze=False,
                     **({"gridspec_kw": {"width_ratios": [2.0, 1.0]}} if zoomed else {}))
    for i, name in enumerate(prob.out_names):
        y = prob.Y[sl, i]
        ax = axes[i, 0]
        _trace(ax, t, y, "k", "measured", measured=True)
        for fit, lab, col in zip(fits, labels, COLORS):
            _trace(ax, t, fit.Yhat[sl, i], col, lab)
            stop = ~np.isfinite(fit.Yhat[sl, i])
            if stop.any():     # the simulation stops (NaN or divergence) from here: say so where it ends
                k = int(np.argmax(stop))
                ax.axvline(t[k], color=col, ls=":", lw=1.0)
                ax.annotate("simulation stops", (t[k], 0.97), xycoords=("data", "axes fraction"), color=col,
                            fontsize=8, ha="right", va="top", rotation=90)
        ax.set_ylabel(label(name, units))
        ax.set_xlabel("time [s]")
        if not zoomed:
            continue
        a, b = analysis.zoom_window(y - fits[0].Yhat[sl, i], zoom)
        az = axes[i, 1]
        az.plot(t[a:b], y[a:b], color="k", lw=1.4, label="measured", zorder=3)
        for fit, lab, col in zip(fits, labels, COLORS):
            az.plot(t[a:b], fit.Yhat[sl, i][a:b], color=col, lw=0.9, label=lab, zorder=4)
        ax.axvspan(t[a], t[b - 1], color="gold", alpha=0.25, lw=0, zorder=1)
        az.set_title(f"zoom: {b - a} samples where '{labels[0]}' errs most", fontsize=8.5)
        az.set_xlabel("time [s]")
    h, lab = axes[0, -1].get_legend_handles_labels()
    if analysis.envelope(t, prob.Y[sl, 0]) is not None:
        h, lab = axes[0, 0].get_legend_handles_labels()
    top = 1 - 0.45 / (2.9 * ny + 0.4)
    fig.tight_layout(rect=(0, 0, 1, top))
    fig.legend(h, lab, loc="upper left", bbox_to_anchor=(0.0, 1.0), ncol=min(4, len(h)), frameon=False, fontsize=8.5)
    return _png(fig)


def residuals(ctx, fits: list, labels: list[str], units: dict[str, str]) -> str:
    """Free-run simulation error y − ŷ over the whole record for each model, one panel per output."""
    prob = ctx.prob
    ny = len(prob.out_names)
    fig, axes = _fig(ny, 1, figsize=(WIDTH_IN, 2.3 * ny + 0.3), squeeze=False, sharex=True)
    for i, name in enumerate(prob.out_names):
        ax = axes[i, 0]
        _shade(ax, prob.t, prob.split)
        for fit, lab, col in zip(fits, labels, COLORS):
            r = prob.Y[:, i] - fit.Yhat[:, i]
            env = analysis.envelope(prob.t, r)
            if env is None:
                ax.plot(prob.t, r, lw=0.6, color=col, label=lab)
            else:
                ax.fill_between(env[0], env[1], env[2], color=col, alpha=0.45, lw=0, label=f"{lab} (min/max envelope)")
        ax.axhline(0, color="grey", lw=0.5)
        ax.set_ylabel(f"y − ŷ: {label(name, units)}")
    axes[-1, 0].set_xlabel("time [s]")
    _legend_above(axes[0, 0])
    return _png(fig)


def correlations(ctx, fit, alpha: float) -> str:
    """Residual autocorrelation and input cross-correlation with their (1 − α) bounds, and the
    Billings–Voon higher-order correlations with ±1.96/√N: one row per output and excited input (the
    autocorrelation on each output's first row only)."""
    prob = ctx.prob
    es = prob.split.est_slice()
    inputs = excited_inputs(prob) or [None]
    ny, nu = len(prob.out_names), len(inputs)
    ncol = 3 if inputs[0] is not None else 2
    rows = ny * nu
    fig, axes = _fig(rows, ncol, figsize=(WIDTH_IN, 2.7 * rows), squeeze=False)
    small = {"fontsize": 8.5} if rows > 1 else {}
    for i, name in enumerate(prob.out_names):
        e = fit.resid_est[:, i]
        tag = f"{name}: " if ny > 1 else ""
        r, bound = rstats.autocorr(e, 25, 1 - alpha)
        ax = axes[i * nu, 0]
        ax.stem(np.arange(1, 26), r[1:], basefmt=" ")
        ax.axhspan(-bound, bound, color="tab:blue", alpha=0.15)
        ax.set_title(f"{tag}autocorrelation, bound ±{bound:.3g} ({100 * (1 - alpha):.0f} %)", **small)
        for k, j in enumerate(inputs):
            row = i * nu + k
            if k:
                axes[row, 0].set_visible(False)
            u = None if j is None else prob.U[es, j]
            pair = f"{ctx.model.inputs[j]}→{name}: " if nu > 1 else tag
            col = 1
            if u is not None:
                lags, c, b = rstats.crosscorr(e, u, 25, 1 - alpha)
                ax = axes[row, 1]
                ax.stem(lags, c, basefmt=" ")
                ax.axhspan(-b, b, color="tab:blue", alpha=0.15)
                ax.set_title(f"{pair}input–residual cross-corr., ±{b:.3g}", **small)
                col = 2
            ho = analysis.billings_voon(e, u, 20)
            ax = axes[row, col]
            for (hname, cur), colour in zip(ho.curves.items(), COLORS):
                ax.plot(ho.lags, cur, ".-", lw=0.8, ms=3, color=colour, label=hname)
            ax.axhspan(-ho.bound, ho.bound, color="tab:blue", alpha=0.15)
            ax.set_title(f"{pair}higher-order (Billings–Voon), ±{ho.bound:.3g}", **small)
    for j in range(ncol):     # the autocorrelation column's last panel is the last output's first row
        axes[(ny - 1) * nu if j == 0 else -1, j].set_xlabel("lag τ [samples]" if j == ncol - 1 else "lag [samples]")
    axes[-1, ncol - 1].legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=3, frameon=False, fontsize=8.5)
    fig.tight_layout()
    return _png(fig)


def error_model_plot(rows: list[tuple[str, str, list[tuple[str, "analysis.ErrorModel"]]]],
                     units: dict[str, str]) -> str | None:
    """|G(f)| of the model-error model (FIR from an input to the residual) with its 99 % band: one panel
    per output × input pair (``rows``: (output name, input name, [(model label, error model)])), the
    pair named in each panel's label."""
    rows = [(out, inp, [(lab, em) for lab, em in items if em is not None]) for out, inp, items in rows]
    rows = [(out, inp, items) for out, inp, items in rows if items]
    if not rows:
        return None
    n = len(rows)
    fig, axes = _fig(n, 1, figsize=(WIDTH_IN, 2.8 if n == 1 else 2.5 * n + 0.3), squeeze=False)
    for ax, (out_name, in_name, items) in zip(axes[:, 0], rows):
        for (lab, em), col in zip(items, COLORS):
            ax.plot(em.f_hz, em.mag, color=col, lw=1.0, label=f"{lab}: |G|")
            ax.fill_between(em.f_hz, np.clip(em.mag - em.band, 0, None), em.mag + em.band, color=col, alpha=0.2,
                            lw=0, label=f"{lab}: 99 % band")
        uu, yu = units.get(in_name), units.get(out_name)
        # the pair is in the label: with units too when there are several panels
        ax.set_ylabel((f"{in_name} → {out_name}\n" if n > 1 else "") + f"|G| [{yu}/{uu}]" if uu and yu
                      else f"|G| [{out_name} per {in_name}]")
        ax.set_xlim(0, items[0][1].f_hz[-1])
    axes[-1, 0].set_xlabel("frequency [Hz]")
    _legend_above(axes[0, 0], ncol=4)
    return _png(fig)


def corner(fit, level_chi2: float = CHI2_2_95, posterior=None, title_level: str = "95 %") -> str | None:
    """Confidence ellipses (θ−θ̂)ᵀP⁻¹(θ−θ̂) ≤ ``level_chi2`` for **every** pair of estimated quantities, as
    a lower-triangular corner plot; with ``posterior`` its draws are overlaid. The caller passes the
    level of the fit's covariance (:func:`pipeline.fit.region_critical`: Hotelling's T² with the sandwich's
    degrees of freedom; χ²₂(0.95) = 5.991, the default, only for the classic covariance)."""
    n = len(fit.theta)
    if n < 2 or not np.all(np.isfinite(fit.cov)):
        return None
    m = n - 1
    cell = min(2.4, WIDTH_IN / m)
    fig, axes = _fig(m, m, figsize=(cell * m + 0.6, cell * m + 0.3), squeeze=False)
    ang = np.linspace(0, 2 * np.pi, 200)
    for r in range(m):
        for c in range(m):
            ax = axes[r, c]
            i, j = c, r + 1   # x: parameter c, y: parameter r+1
            if c > r:
                ax.set_visible(False)
                continue
            if posterior is not None:
                s = posterior.samples
                step = max(1, len(s) // 1500)
                ax.plot(s[::step, i], s[::step, j], ".", ms=1.5, color="tab:orange", alpha=0.35,
                        label="emcee posterior draws", rasterized=True)
            P = fit.cov[np.ix_([i, j], [i, j])]
            w, V = np.linalg.eigh(P)
            pts = V @ (np.sqrt(np.clip(w, 0, None) * level_chi2)[:, None] * np.vstack([np.cos(ang), np.sin(ang)]))
            ax.plot(fit.theta[i] + pts[0], fit.theta[j] + pts[1], color="tab:blue", lw=1.1,
                    label=f"{title_level} confidence ellipse")
            ax.plot(fit.theta[i], fit.theta[j], "k+", ms=7)
            ax.ticklabel_format(style="sci", scilimits=(-3, 4))
            ax.locator_params(nbins=4)
            if r == m - 1:
                ax.set_xlabel(fit.names[i])
            else:
                ax.tick_params(labelbottom=False)
            if c == 0:
                ax.set_ylabel(fit.names[j])
            else:
                ax.tick_params(labelleft=False)
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / (cell * m + 0.3)))
    fig.legend(h, lab, loc="upper left", frameon=False, fontsize=8.5, markerscale=5, ncol=2,
               bbox_to_anchor=(0.0, 1.0))
    return _png(fig)


def band(ctx, fit, lohi: np.ndarray, units: dict[str, str], zoom: int = 400, what: str = "") -> str:
    """Measured vs the final model with its 95 % response band (parameter uncertainty) on the
    validation zoom window: one panel per output, each zoomed where that output's misfit is largest."""
    prob = ctx.prob
    sl = prob.split.val_slice()
    t = prob.t[sl]
    ny = len(prob.out_names)
    fig, axes = _fig(ny, 1, figsize=(WIDTH_IN, 2.7 if ny == 1 else 2.4 * ny + 0.3), squeeze=False)
    for i, (ax, name) in enumerate(zip(axes[:, 0], prob.out_names)):
        y = prob.Y[sl, i]
        a, b = analysis.zoom_window(y - fit.Yhat[sl, i], zoom)
        ax.fill_between(t[a:b], lohi[0][sl, i][a:b], lohi[1][sl, i][a:b], color="tab:green", alpha=0.3, lw=0,
                        label=f"95 % response band ({what})")
        ax.plot(t[a:b], y[a:b], "k", lw=1.2, label="measured")
        ax.plot(t[a:b], fit.Yhat[sl, i][a:b], color="tab:green", lw=0.9, label="final model")
        ax.set_ylabel(label(name, units))
    axes[-1, 0].set_xlabel("time [s] (validation part)")
    _legend_above(axes[0, 0])
    return _png(fig)


def err_chart(frols: dict) -> str:
    """ERR of each selected term (FROLS), in selection order, with the cumulative sum."""
    names, err = frols["names"], np.asarray(frols["err"], float)
    fig, ax = _fig(1, 1, figsize=(7.5, 2.8))
    x = np.arange(len(names))
    ax.bar(x, 100 * err, color="tab:blue", label="ERR of the term")
    ax.plot(x, 100 * np.cumsum(err), "k.-", lw=0.8, label="cumulative")
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.set_ylabel("ERR [%]")
    ax.set_yscale("log")
    _legend_above(ax)
    return _png(fig)


def ts_memberships(ts: dict, units: dict[str, str]) -> str:
    """Normalised Takagi–Sugeno memberships over the first premise input."""
    grid = np.asarray(ts["grid"])
    c = np.asarray(ts["centres"])[:, 0]
    s = np.asarray(ts["sigmas"])[:, 0]
    beta = np.exp(-((grid[:, None] - c[None, :]) / s[None, :]) ** 2)
    w = beta / beta.sum(axis=1, keepdims=True)
    fig, ax = _fig(1, 1, figsize=(7.5, 2.6))
    ax.plot(grid, w, lw=1)
    ax.set_xlabel(label(ts["inputs"][0], units))
    ax.set_ylabel("normalised membership [–]")
    return _png(fig)


def rls_trajectories(res) -> str:
    """RLS parameter trajectories θ̂_k of one structure (a drifting or jumping parameter shows here)."""
    th = res.extra["theta_trajectory"]
    fig, ax = _fig(1, 1, figsize=(WIDTH_IN, 2.8))
    for j, name in enumerate(res.terms):
        ax.plot(res.extra["t"], th[:, j], lw=0.8, label=name)
    ax.set_xlabel("time [s] (estimation data)")
    ax.set_ylabel("θ̂ (coefficient of the term)")
    lim = np.percentile(np.abs(th[len(th) // 10:]), 99.5) * 1.5 if len(th) > 10 else None
    if lim and np.isfinite(lim) and lim > 0:
        ax.set_ylim(-lim, lim)
    _legend_above(ax, ncol=min(6, len(res.terms)))
    return _png(fig)
