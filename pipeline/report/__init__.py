"""HTML report v2: one self-contained, deterministic file (Jinja2, autoescape on; figures as inline
PNG; no script, no external resource). Sections: first screen (answer in words + one figure), data,
measured vs simulated, residual analysis, why/fix/worth, model comparison and recommendation,
parameters and uncertainty, configuration and provenance.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import yaml
from jinja2 import Environment, PackageLoader, select_autoescape

from .. import progress
from ..diagnostics.engine import fit_percent, rmse
from ..diagnostics.adequacy import FIR_ORDER
from ..fit import defined_validation_rows, excited_inputs, param_intervals, region_critical, undefined_from
from ..hac import hotelling_critical
from . import analysis, figures, view

ZOOM = 400              # samples in the zoom window beside a long trace
BAND_DRAWS = 40         # parameter draws for the response band


def _fit_rows(ctx, labels) -> list[dict]:
    """One row per model of the chain; a model whose simulation stops on the validation part (only the
    nominal one may) is measured on the samples before, as in summary.json (``runs.model_block``)."""
    prob = ctx.prob
    es = prob.split.est_slice()
    rows = []
    for f, lab in zip(ctx.diag.fits, labels):
        sl = defined_validation_rows(f.Yhat, prob)
        stop = undefined_from(f.Yhat, prob)
        ok = len(prob.Y[sl]) > 0
        rows.append({"name": lab, "val_fit": fit_percent(prob.Y[sl], f.Yhat[sl]) if ok else None,
                     "val_rmse": rmse(prob.Y[sl] - f.Yhat[sl]) if ok else None,
                     "est_fit": fit_percent(prob.Y[es], f.Yhat[es]), "n_params": f.n_params,
                     "stops_at": None if stop is None else float(prob.t[stop])})
    return rows


def _chain_labels(ctx) -> list[str]:
    names = [m["name"] for m in ctx.summary.get("models", []) if m.get("estimator") == "output_error_ls"]
    n = len(ctx.diag.fits)
    return (names + [f"model {k}" for k in range(len(names), n)])[:n]


def _figures(ctx, units: dict, alpha: float, labels: list[str]) -> dict:
    diag, prob = ctx.diag, ctx.prob
    fits = diag.fits
    figs: dict = {}
    # when no cause was accepted the final model is the nominal one: drawn once, not twice under one name
    first = ([diag.nominal, diag.final], [labels[0], labels[-1]]) if len(fits) > 1 else ([diag.nominal], [labels[0]])
    jobs = [("first", lambda: figures.compare(ctx, *first, units, ZOOM)),
            ("overview", lambda: figures.overview(ctx, units)),
            ("resid", lambda: figures.residuals(ctx, [diag.nominal, diag.final] if len(fits) > 1 else [diag.nominal],
                                                [labels[0], labels[-1]] if len(fits) > 1 else [labels[0]], units)),
            ("corr_nominal", lambda: figures.correlations(ctx, diag.nominal, alpha))]
    if len(fits) > 1:      # with the nominal model alone these would repeat the figures above
        jobs.insert(2, ("compare_all", lambda: figures.compare(ctx, fits, labels, units, ZOOM)))
        jobs.append(("corr_final", lambda: figures.correlations(ctx, diag.final, alpha)))
    es = prob.split.est_slice()
    excited = excited_inputs(prob)
    if excited:
        def emm():
            rows = []
            for i, out in enumerate(prob.out_names):    # one panel per output × excited input
                for j in excited:
                    u = prob.U[es, j]
                    items = [(labels[0], analysis.error_model(diag.nominal.resid_est[:, i], u, ctx.rec.dt))]
                    if len(fits) > 1:
                        items.append((labels[-1], analysis.error_model(diag.final.resid_est[:, i], u, ctx.rec.dt)))
                    rows.append((out, ctx.model.inputs[j], items))
            return figures.error_model_plot(rows, units)
        jobs.append(("error_model", emm))
    jobs.append(("ellipses_nominal", lambda: figures.corner(diag.nominal, region_critical(diag.nominal.identifiability, 2))))
    if diag.unaccepted:    # an unexplained verdict: what the best refits that were not accepted would change
        jobs.append(("unaccepted", lambda: figures.compare(ctx, [diag.final] + [f for _, f in diag.unaccepted],
                                                           [labels[-1]] + [lab for lab, _ in diag.unaccepted],
                                                           units, ZOOM)))
    for k, fit in enumerate(fits[1:]):
        jobs.append((f"finding_{k}", lambda k=k, fit=fit: figures.compare(ctx, [fits[k], fit], [labels[k], labels[k + 1]],
                                                                          units, ZOOM)))
    st = ctx.summary.get("structures")
    if st:
        if st.get("frols"):
            jobs.append(("err", lambda: figures.err_chart(st["frols"])))
        if st.get("takagi_sugeno"):
            jobs.append(("ts", lambda: figures.ts_memberships(st["takagi_sugeno"], units)))
        rls = [r for r in ctx.comparison.results if "theta_trajectory" in r.extra]
        best = [r for r in rls if r.name == st.get("selected")] or rls
        if best:
            jobs.append(("rls", lambda: figures.rls_trajectories(best[0])))
    for key, fn in progress.bar(jobs, len(jobs), "figures"):
        figs[key] = fn()
    return figs


def _uncertainty(ctx, units: dict) -> dict:
    """Ellipses of the final model (with the emcee posterior when ``uncertainty: mcmc``) and its
    response band from Gauss (or posterior) parameter draws."""
    diag, cfg = ctx.diag, ctx.lc.cfg
    out: dict = {"posterior": None, "ellipses_final": None, "band": None, "band_what": None}
    post = None
    if cfg.uncertainty == "mcmc":
        with progress.stage("mcmc"):
            post = analysis.mcmc_posterior(diag.final, ctx.prob, cfg.seed)
        out["posterior"] = post
    if len(diag.fits) > 1 or post is not None:
        out["ellipses_final"] = figures.corner(diag.final, region_critical(diag.final.identifiability, 2), posterior=post)
    if post is not None and len(post.samples) >= BAND_DRAWS:
        idx = np.linspace(0, len(post.samples) - 1, BAND_DRAWS).astype(int)
        draws, what = post.samples[idx], "emcee posterior draws"
    else:
        draws, what = analysis.parameter_draws(diag.final, BAND_DRAWS, cfg.seed) or (None, None)
    if draws is not None:
        lohi = analysis.response_band(diag.final, ctx.prob, draws)
        if lohi is not None:
            out["band"] = figures.band(ctx, diag.final, lohi, units, ZOOM, what)
            out["band_what"] = what
    return out


def _provenance(ctx) -> dict:
    from ..runs import _git_info, _versions
    return {"config_yaml": yaml.safe_dump(ctx.lc.canonical(), sort_keys=False, allow_unicode=True),
            "config_path": str(ctx.lc.path), "data_path": str(ctx.rec.path), "data_sha256": ctx.rec.sha256,
            "git": _git_info(), "versions": _versions()}


def _unc_law(fit) -> dict:
    """What the ± σ, the 95 % intervals and the ellipses of one fit rest on (:func:`pipeline.fit.region_critical`)."""
    idf = fit.identifiability
    nu = None if idf is None else idf.cov_dof
    own = list((getattr(idf, "param_dof", None) or {}).values())
    nu_max = max(own) if own else None
    return {"nu": nu, "t": math.sqrt(region_critical(idf, 1)), "c2": region_critical(idf, 2),
            "ci": param_intervals(fit),
            # each parameter's own ν (its interval's t); shown as a range when they differ by 5 % or more
            "nu_max": nu_max if nu_max is not None and nu is not None and nu_max > 1.05 * nu else None,
            "t_min": math.sqrt(hotelling_critical(nu_max, 1)) if nu_max is not None else None,
            "thin": analysis.thin_pairs(fit)}


def render_report(ctx) -> str:
    """The report of one analysed run (``runs.RunContext``) as an HTML string."""
    s = ctx.summary
    cfg = ctx.lc.cfg
    units = dict(getattr(cfg, "units", {}) or {})
    alpha = cfg.diagnose.alpha
    labels = _chain_labels(ctx)
    with progress.stage("report"), plt.rc_context(figures.RC):
        figs = _figures(ctx, units, alpha, labels)
        unc = _uncertainty(ctx, units)
    diag = ctx.diag
    nominal_tests, final_tests = view.split_tests(s.get("diagnosis") or {})
    env = Environment(loader=PackageLoader("pipeline.report", "templates"), autoescape=select_autoescape(["html"]))
    env.filters["sig"] = view.sig
    env.filters["text"] = view.numbers_in_text
    env.filters["pct"] = lambda x, d=3: "–" if x is None else view.sig(100 * x, d)
    env.globals["plural"] = view.plural
    tpl = env.get_template("report.html")
    post = unc["posterior"]
    return tpl.render(
        s=s, cfg=cfg, figs=figs, unc=unc, first=view.first_screen(s), rec=view.recommendation(s),
        labels=labels, fit_rows=_fit_rows(ctx, labels), nominal_tests=nominal_tests, final_tests=final_tests,
        nominal_params=list(zip(diag.nominal.names, diag.nominal.theta, diag.nominal.std)),
        final_params=list(zip(diag.final.names, diag.final.theta, diag.final.std)),
        post_rows=None if post is None else [
            (n, float(np.mean(post.samples[:, i])), float(np.std(post.samples[:, i], ddof=1)),
             *map(float, np.percentile(post.samples[:, i], [2.5, 97.5])))
            for i, n in enumerate(post.names)],
        post=post, nominal_eqs=ctx.model.describe_equations(), final_eqs=diag.final.model.describe_equations(),
        log=ctx.rec.log, structure_rows=view.model_rows(s), equation_error_note=view.equation_error_note(s),
        prov=_provenance(ctx), zoom=ZOOM,
        n_val=int(ctx.prob.split.val[1] - ctx.prob.split.val[0]), n_models=len(diag.fits),
        nominal_unc=_unc_law(diag.nominal), final_unc=_unc_law(diag.final), n_out=len(ctx.prob.out_names),
        n_pairs=len(ctx.prob.out_names) * len(excited_inputs(ctx.prob)),
        fir_order=FIR_ORDER,
        band_draws=BAND_DRAWS)
