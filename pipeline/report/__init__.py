"""HTML report: Jinja2 template (autoescape on) with inline matplotlib figures."""

from __future__ import annotations

import sys

from jinja2 import Environment, PackageLoader, select_autoescape

from . import figures


def _fmt(x, digits: int = 4):
    if x is None:
        return "–"
    if isinstance(x, (int, float)):
        return f"{x:.{digits}g}"
    return str(x)


def render_report(ctx) -> str:
    print("[report] drawing figures", file=sys.stderr, flush=True)
    diag = ctx.diag
    alpha = ctx.lc.cfg.diagnose.alpha
    figs = {"overview": figures.overview(ctx),
            "compare_nominal": figures.compare(ctx, [diag.nominal], ["nominal"],
                                               "measured vs nominal model"),
            "resid_nominal": figures.residuals(ctx, diag.nominal, "nominal model"),
            "corr_nominal": figures.correlations(ctx, diag.nominal, alpha),
            "ellipses_nominal": figures.ellipses(diag.nominal)}
    finding_figs = []
    for k, fit in enumerate(diag.fits[1:]):
        finding_figs.append({
            "compare": figures.compare(ctx, [diag.fits[k], fit], ["before", "after"],
                                       f"finding {k + 1}: measured vs extended model"),
            "corr": figures.correlations(ctx, fit, alpha)})
    figs["ellipses_final"] = figures.ellipses(diag.final) if diag.findings else None
    params = []
    for name in diag.nominal.names:
        i = diag.nominal.names.index(name)
        params.append({"name": name, "nominal": diag.nominal.theta[i], "nominal_std": diag.nominal.std[i]})
    final_params = [{"name": n, "value": v, "std": s}
                    for n, v, s in zip(diag.final.names, diag.final.theta, diag.final.std)]
    st = ctx.summary.get("structures")
    if st:
        figs["err"] = figures.err_chart(st["frols"]) if st.get("frols") else None
        figs["ts"] = figures.ts_memberships(st["takagi_sugeno"]) if st.get("takagi_sugeno") else None
        rls = [r for r in ctx.comparison.results if "theta_trajectory" in r.extra]
        best = [r for r in rls if r.name == st.get("selected")] or rls
        figs["rls"] = figures.rls_trajectories(best[0]) if best else None
    structure_rows = [m for m in ctx.summary["models"] if "cv_rmse_one_step" in m]
    structure_rows.sort(key=lambda m: (m["cv_mean"] is None, m["cv_mean"] if m["cv_mean"] is not None else 0))
    env = Environment(loader=PackageLoader("pipeline.report", "templates"), autoescape=select_autoescape(["html"]))
    env.filters["fmt"] = _fmt
    tpl = env.get_template("report.html")
    return tpl.render(s=ctx.summary, cfg=ctx.lc.cfg, figs=figs, finding_figs=finding_figs, params=params,
                      final_params=final_params, nominal_eqs=ctx.model.describe_equations(),
                      final_eqs=diag.final.model.describe_equations(), log=ctx.rec.log,
                      structure_rows=structure_rows)
