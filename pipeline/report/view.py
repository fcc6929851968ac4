"""What the report says in words, computed from ``summary.json`` content (so it also works on the
keys the diagnosis contract adds later, and tolerates their absence on old runs):

* the first screen: how much of the validation output the simulation misses, the main cause (with an
  "unexplained" verdict: the largest partial finding), its gain
  with interval, and a plain warning when a model is unusable (negative fit) or the verdict is
  "unexplained";
* one recommendation reconciling the diagnosis loop's model with the structure stage's CV winner;
* nominal and final residual tests as separate tables.
"""

from __future__ import annotations

import math
import re
from typing import Any

from ..diagnostics.adequacy import is_informational
from ..diagnostics.coverage import coverage_text

_LONG_FLOAT = re.compile(r"(?<![\w.])-?\d+\.\d{5,}(?:[eE][-+]?\d+)?")


def sig(x: Any, digits: int = 4) -> str:
    """A number to ``digits`` significant digits (``–`` for None/NaN); text unchanged."""
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        if not math.isfinite(x):
            return "–"
        s = f"{x:.{digits - 1}e}" if 0 < abs(x) < 1e-3 else f"{x:.{digits}g}"   # 0.00016204 -> 1.6204e-4
        return s.replace("e-0", "e-").replace("e+0", "e").replace("e+", "e")
    return str(x)


def numbers_in_text(s: Any, digits: int = 4) -> str:
    """Long floats inside a sentence (``0.003704119612513139``) to ``digits`` significant digits."""
    if s is None:
        return ""
    return _LONG_FLOAT.sub(lambda m: sig(float(m.group()), digits), str(s))


def plural(n: int, word: str, many: str | None = None) -> str:
    return f"{n} {word if n == 1 else (many or word + 's')}"


def split_tests(diag: dict) -> tuple[list[dict], list[dict]]:
    """(nominal rows, final rows). New runs: ``tests`` / ``final_tests``; old runs mixed both in
    ``tests`` and told them apart by ``on``."""
    tests = list(diag.get("tests") or [])
    if "final_tests" in diag:
        return tests, list(diag.get("final_tests") or [])
    nominal = [t for t in tests if "nominal" in str(t.get("on", "nominal"))]
    final = [t for t in tests if "nominal" not in str(t.get("on", "nominal"))]
    return nominal, final


def _cv_winner(s: dict) -> dict | None:
    name = s.get("selected_structure")
    if not name:
        return None
    rows = [m for m in s.get("models") or [] if m.get("name") == name and m.get("cv_mean") is not None]
    return min(rows, key=lambda m: m["cv_mean"]) if rows else None


def recommendation(s: dict) -> dict:
    """Which model to use and why. The diagnosis loop's final grey-box model and the structure stage's
    CV winner are different kinds of model; both are free-run simulations on the same validation part,
    which neither was fitted on, so that RMSE decides. Within 10 % the grey-box model is preferred (its
    parameters are physical)."""
    final = s.get("final") or {}
    diag_name = s.get("selected_model") or "final"
    d_rmse = (final.get("validation") or {}).get("rmse_sim")
    d_fit = (final.get("validation") or {}).get("fit_percent")
    w = _cv_winner(s)
    out = {"model": diag_name, "kind": "diagnosis", "rmse": d_rmse, "fit": d_fit, "text": "", "cv": w}
    if w is None or w.get("validation_rmse_sim") is None or d_rmse is None:
        per = (final.get("validation") or {}).get("per_output") or {}
        out["text"] = (f"Use the diagnosis loop's model {diag_name}: validation free-run "
                       + (f"fit {_fit_text(final.get('validation') or {})}." if len(per) > 1 else
                          f"RMSE {sig(d_rmse)}, fit {sig(d_fit, 3)} %."))
        return out
    c_rmse = w["validation_rmse_sim"]
    cname = f"{w['name']} ({w.get('estimator')})"
    ratio = max(d_rmse, c_rmse) / max(min(d_rmse, c_rmse), 1e-300)
    if c_rmse < d_rmse / 1.1:
        out.update(model=cname, kind="structure", rmse=c_rmse, fit=None)
        why = (f"the structure stage's CV winner {cname} simulates the validation data {sig(ratio, 3)}× better "
               f"(RMSE {sig(c_rmse)} vs {sig(d_rmse)} for the diagnosis loop's {diag_name})")
    else:
        better = "better" if d_rmse <= c_rmse else "about as well"
        why = (f"the diagnosis loop's {diag_name} simulates the validation data {better} (RMSE {sig(d_rmse)} vs "
               f"{sig(c_rmse)} for the structure stage's CV winner {cname}"
               + (f", {sig(ratio, 3)}× lower" if d_rmse < c_rmse / 1.1 else "") + ") and keeps physical parameters")
    out["text"] = (f"Use {out['model']}: {why}. The CV winner was chosen on estimation folds only "
                   f"(CV free-run RMSE {sig(w.get('cv_mean'))}); the validation part decides between the two.")
    return out


def _key_text(f: dict) -> str:
    """The finding's key parameter (contract §2) in a few words, for the first screen: what a reader
    needs to act on it (a delay of how long, a limit at what level, a jump of what and when)."""
    g = f.get
    fam = g("family")
    if fam == "input_delay" and g("delay_s") is not None:
        return f"{sig(g('delay_s'), 3)} s" + (f" ({sig(g('delay_samples'), 2)} samples)" if g("delay_samples") is not None else "")
    if fam == "unmodeled_dynamics" and g("time_constant_s") is not None:
        if g("state") and not g("input"):
            return f"a missing state coupled to {g('state')}, time constant {sig(g('time_constant_s'), 3)} s"
        return f"time constant {sig(g('time_constant_s'), 3)} s" + (f" on input {g('input')}" if g("input") else "")
    if fam == "input_saturation" and g("limit") is not None:
        return f"{g('input') or 'the input'} clipped at ±{sig(g('limit'), 3)}"
    if fam == "state_saturation" and g("limit") is not None:
        return f"{g('state') or 'a state'} stops at {sig(g('limit'), 3)}"
    if fam == "dead_zone" and g("width") is not None:
        return f"width {sig(g('width'), 3)}" + (f" on input {g('input')}" if g("input") else "")
    if fam == "periodic_disturbance" and g("frequency_hz") is not None:
        return f"{sig(g('frequency_hz'), 4)} Hz"
    if fam == "parameter_jump" and g("time_s") is not None:
        return f"{g('parameter')} from {sig(g('before'), 3)} to {sig(g('after'), 3)} at t = {sig(g('time_s'), 4)} s"
    if fam == "parameter_drift" and g("rate_per_s") is not None:
        return f"{g('parameter')} drifting by {sig(100 * g('rate_per_s'), 3)} % of its value per s"
    if fam == "intersample" and g("chosen"):
        return f"{g('chosen')} instead of the configured {g('configured')}"
    return ""


def _fit_text(v: dict) -> str:
    """"F % (RMSE R)", or per output "F1 % on y1 (RMSE R1), F2 % on y2 (RMSE R2)" when there are several."""
    per = v.get("per_output") or {}
    if len(per) > 1:
        return ", ".join(f"{sig(o['fit_percent'], 3)} % on {name} (RMSE {sig(o['rmse_sim'])})" for name, o in per.items())
    return f"{sig(v.get('fit_percent'), 3)} % (RMSE {sig(v.get('rmse_sim'))})"


def first_screen(s: dict) -> dict:
    """Sentences of the first screen, and warnings."""
    nom = (s.get("nominal") or {}).get("validation") or {}
    fin = (s.get("final") or {}).get("validation") or {}
    diag = s.get("diagnosis") or {}
    verdict = diag.get("verdict", "")
    findings = diag.get("findings") or []
    data = s.get("data") or {}
    val = data.get("validation") or [0, 0]
    n_val = (val[1] - val[0]) if len(val) == 2 and None not in val else None
    horizon = (f"{n_val} samples = {sig(n_val * data['sample_time'], 3)} s" if n_val and data.get("sample_time")
               else "the validation part")
    nf = nom.get("fit_percent")
    lines = []
    per = nom.get("per_output") or {}
    opening = f"On validation data ({horizon}, free-run simulation, never used for fitting) the nominal model misses "
    stops = nom.get("undefined_from_s")
    if stops is not None:
        # its simulation stops on the validation part (a NaN or a divergence): that comes first, and the
        # numbers are over the samples before
        opening = (f"On validation data ({horizon}, free-run simulation, never used for fitting) the nominal "
                   f"model's simulation stops at t = {sig(stops, 6)} s (NaN or divergence) and has no value on "
                   f"the rest; over the {nom.get('samples')} samples before, it misses ")
    if len(per) > 1:
        # several outputs: each in its own scale (a pooled fit or RMSE would mix their units)
        lines.append(opening + ", ".join(f"{sig(100 - v['fit_percent'], 3)} % of {name}'s variation "
                                         f"(fit {sig(v['fit_percent'], 3)} %, RMSE {sig(v['rmse_sim'])})"
                                         for name, v in per.items()) + ".")
    elif nf is not None:
        lines.append(opening + f"{sig(100 - nf, 3)} % of the output's variation (fit {sig(nf, 3)} %, "
                     f"RMSE {sig(nom.get('rmse_sim'))}).")
    if findings:
        f0 = findings[0]
        g = f0.get("gain") or {}
        ci = g.get("ci95") or [None, None]
        where = f0.get("equation") or f0.get("output") or ""
        term = f0.get("term")
        cause = f"{f0.get('family')}" + (f" in the equation of {where}" if f0.get("equation") else
                                         (f" on output {where}" if where else "")) + (f" ({term})" if term else "")
        key = _key_text(f0)
        if key:
            cause += f", {key}"
        partial = verdict == "unexplained_discrepancy"
        # several outputs: the gain is on each output's RMSE over its standard deviation, pooled
        err = ("error (each output's RMSE over its standard deviation, pooled)"
               if g.get("metric") == "validation_nrmse_sim_pooled" else "RMSE")
        # with the verdict unexplained the findings explain part of the misfit only: not "the cause"
        gg = f0.get("gain_given")
        tied = ", ".join(str(t.get("hypothesis")) for t in f0.get("tied_with") or [])
        head = (f"{'Largest partial finding' if partial else 'Main cause'}: {cause}"
                + (f", or {tied}: these data cannot tell them apart." if tied else "."))
        disputed = f0.get("disputed_by") or []
        if disputed:
            # the estimation part chose it by strong evidence (6 units or more), the validation part prefers another
            head += (" The record's two parts disagree: the validation part prefers "
                     + ", ".join(f"{t.get('hypothesis')} (validation error {sig(100 * t['relative'], 3)} % lower)"
                                 for t in disputed) + ".")
        interval = (f"{sig(100 * ci[0], 3) if ci[0] is not None else '–'} to "
                    f"{sig(100 * ci[1], 3) if ci[1] is not None else '–'} %")
        if gg:
            # accepted by the look-ahead: its gain given the other first, its own gain (interval not above 0,
            # point gain possibly negative) after it
            rel = g.get("relative")
            their = "their " if ", " in str(gg.get("with")) else f"{gg.get('with')}'s "
            alone = ("–" if rel is None else
                     f"{'lowers' if rel >= 0 else 'raises'} it by {sig(abs(100 * rel), 3)} %")
            lines.append(f"{head} With {gg.get('with')} in the model too, adding it lowers the validation {err} by "
                         f"{sig(100 * gg['relative'], 3)} % (95 % interval {sig(100 * gg['ci95'][0], 3)} to "
                         f"{sig(100 * gg['ci95'][1], 3)} % for this validation input). Alone it {alone} (95 % "
                         f"interval of the gain {interval})" + (
                             "." if ci[0] is not None and ci[0] > 0 else
                             f", an interval not above 0: {their}misfit was still in the validation residual."))
        elif g.get("metric") == "validation_nll":
            # a noise model: its gain is in likelihood, and the simulation is the one before
            aci = g.get("absolute_ci95") or [None, None]
            lines.append(f"{head} Adding it lowers the validation negative log-likelihood per sample from "
                         f"{sig(g.get('before'))} to {sig(g.get('after'))} (a drop of {sig(g.get('absolute'))}, 95 % "
                         f"interval {sig(aci[0])} to {sig(aci[1])}); for Gaussian errors that is an error scale "
                         f"{sig(100 * g['relative'], 3)} % smaller (95 % interval {interval}) for this validation "
                         "input. A noise model does not change the free-run simulation.")
        else:
            lines.append(f"{head} Adding it lowers the validation {err} by "
                         f"{sig(100 * g['relative'], 3) if g.get('relative') is not None else '–'} % (95 % interval "
                         f"{interval} for this validation input"
                         + (f"; on the {g['samples_compared']} of {g['samples']} validation samples where the "
                            "nominal model's simulation is defined" if g.get("samples_compared") is not None else "")
                         + (f"; one-sided p = {sig(g['p_not_lower'], 2)} that it is not lower"
                            if g.get("p_not_lower") is not None else "") + ").")
        if len(findings) > 1:
            lines.append(f"{plural(len(findings), 'partial finding' if partial else 'cause')} found in all: "
                         + ", ".join(str(f.get("family")) for f in findings)
                         + f"; with all of them the fit is {_fit_text(fin)}.")
        elif (f0.get("gain") or {}).get("metric") == "validation_nll":
            lines.append(f"The free-run fit is unchanged: {_fit_text(fin)}.")
        else:
            lines.append(f"With it the fit is {_fit_text(fin)}.")
    elif diag.get("rounding_level"):
        lines.append(f"Nothing to diagnose: {diag['rounding_level']}.")
    elif verdict == "no_significant_discrepancy":
        lines.append("No effect family explains the residual: the nominal model is adequate at the tested "
                     f"level α = {diag.get('alpha')}.")
    warnings = []
    if fin.get("undefined_from_s") is not None:
        warnings.append(f"The final model's free-run simulation stops at t = {sig(fin['undefined_from_s'], 6)} s of the "
                        "validation part (an expression undefined there, e.g. the root of a negative state, or a "
                        "state growing without bound): it cannot be used to simulate this record; its validation "
                        f"numbers are over the {fin.get('samples')} samples before.")
    ff = fin.get("fit_percent")
    if ff is not None and ff < 0:
        warnings.append(f"The final model is unusable on validation data: fit {sig(ff, 3)} % is worse than "
                        "predicting the mean of the output. Do not use it for simulation; the improvement from "
                        f"{sig(nf, 3)} % is not a fix.")
    elif nf is not None and nf < 0:
        warnings.append(f"The nominal model is unusable on validation data (fit {sig(nf, 3)} %, worse than the "
                        "output's mean); only the extended model should be used.")
    # by name too: a summary written before the ``informational`` key
    flagged = [t for t in diag.get("tests") or [] if (t.get("informational") or is_informational(str(t.get("name", ""))))
               and t.get("tested", True) and not t.get("passed")]
    if flagged:
        # a row about the data, not the model: said beside the verdict so that the failed row in the tests
        # table does not read as a failed adequacy test
        warnings.append("Not part of the verdict: the nominal residual correlates with the input's future ("
                        + "; ".join(f"{t['name']}, p = {sig(t.get('p_value'), 2)}" for t in flagged)
                        + "). Either the input responds to the output (closed-loop data: output-error estimates of "
                        "a misspecified model are then biased), or the input is predictable from its past (a line "
                        "spectrum such as a multisine) and a small misfit it drives shows at negative lags.")
    remaining = [t for t in diag.get("final_tests") or [] if t.get("tested", True) and not t.get("passed")
                 and not t.get("informational")]
    if verdict == "discrepancy" and remaining:
        # the causes named explain the misfit; a residual test that still fails beside them is said, not hidden
        warnings.append("After the causes named, the final model's residual still fails "
                        + "; ".join(f"{t['name']} (p = {sig(t.get('p_value'), 2)}"
                                    + (f", {sig(100 * t['explained_share'], 2)} % of the residual"
                                       if t.get("explained_share") is not None else "") + ")" for t in remaining[:4])
                        + (f" and {len(remaining) - 4} more" if len(remaining) > 4 else "")
                        + "; no structural test explains 2 % of the residual or more, so nothing left is "
                        "material to the model's structure (section 3 has the tests).")
    if verdict == "unexplained_discrepancy":
        warnings.append("Verdict: unexplained discrepancy. The residual tests still fail and no effect family's "
                        "extension explains what remains" + (" (the findings listed are partial)." if findings
                                                             else "."))
        where = diag.get("unexplained") or {}
        if where.get("failed_tests"):
            warnings.append("Where the model fails: " + "; ".join(where["failed_tests"][:3])
                            + (f"; largest misfit of the final model on the estimation part in t = "
                               f"{sig(where['time_window_s'][0], 4)}–{sig(where['time_window_s'][1], 4)} s and output range "
                               f"{sig(where['amplitude_range'][0], 4)} to {sig(where['amplitude_range'][1], 4)}"
                               if where.get("time_window_s") else "") + ".")
        why = (where.get("why") or {}).get("sentence")
        if why:
            warnings.append("Why no cause is named: " + why)
    if verdict == "unexplained_discrepancy" and diag.get("not_testable"):
        # what a guard kept from being tested may be what the model misses
        warnings.append("Not tested, because these data cannot test it: " + "; ".join(
            f"{g['family']}: {g['reason']}" for g in diag["not_testable"]) + ".")
    cov = coverage_text((s.get("data") or {}).get("coverage") or [], lambda x: sig(x, 3))
    if cov:
        warnings.append(cov)
    for label, block in (("nominal", s.get("nominal") or {}), ("final", s.get("final") or {})):
        idf = block.get("identifiability") or {}
        if idf.get("unidentifiable"):
            dirs = "; ".join(_direction_text(d) for d in idf.get("directions") or [])
            warnings.append(f"The {label} model's parameters {', '.join(idf['unidentifiable'])} are not identifiable "
                            f"from these data (rank {idf.get('rank')} of {idf.get('n_params')}): changing them together as "
                            f"{dirs or 'a combination'} (each change scaled by its sensitivity's norm) leaves the "
                            "simulation unchanged; they have no standard error.")
    return {"lines": lines, "warnings": warnings, "verdict": verdict, "horizon": horizon}


def _direction_text(d: dict) -> str:
    """A null direction {name: coefficient} as "0.71 Δk2 − 0.7 Δk4"."""
    parts = []
    for i, (name, c) in enumerate(d.items()):
        c = float(c)
        mag = sig(abs(c), 2)
        sign = ("−" if c < 0 else "") if i == 0 else (" − " if c < 0 else " + ")
        parts.append(f"{sign}{mag} Δ{name}")
    return "".join(parts)


def model_rows(s: dict) -> list[dict]:
    """The structure comparison rows, CV winner first order: by CV mean (None last)."""
    rows = [dict(m) for m in s.get("models") or [] if "cv_rmse_one_step" in m]
    for m in rows:
        os_ = m.get("cv_rmse_one_step") or []
        m["_cv_one_step"] = sum(os_) / len(os_) if os_ else None
        th, sd = m.get("theta") or [], m.get("theta_std") or []
        m["_params"] = [(t, th[i] if i < len(th) else None, sd[i] if i < len(sd) else None)
                        for i, t in enumerate(m.get("terms") or [])]
    rows.sort(key=lambda m: (m.get("cv_mean") is None, m.get("cv_mean") or 0.0))
    return rows


def equation_error_note(s: dict) -> str:
    """What the structures table's ``cv_rmse_one_step`` column is: the rows' ``cv_rmse_one_step_measures``
    (the regression target is d(eq)/dt, so an equation error of the derivative, not a one-step
    prediction); a run written before that key gets the same words without the unit."""
    eq = ((s.get("structures") or {}).get("settings") or {}).get("equation") or "x"
    said = next((m["cv_rmse_one_step_measures"] for m in s.get("models") or []
                 if m.get("cv_rmse_one_step_measures")), None)
    return said or (f"equation error of d{eq}/dt, in units of {eq} per second: RMS of the regression residual "
                    f"on the fold; not a one-step-ahead prediction of {eq}")
