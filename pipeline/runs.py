"""One run: config + record → diagnosis → run folder ``reports/<run-id>/``.

The run id is ``<name>-<8 hex>`` from the hashes of the canonical config and the data file, not the
clock, so a rerun reproduces it. ``--out`` is checked before the analysis (:func:`runfolder.check_target`:
a user's files, the data's folder or the current folder are refused, exit 2); everything is written into
a hidden temporary folder beside the target, marked complete last and published by renames
(:mod:`pipeline.runfolder`): a crashed run never looks complete and never replaces anything but an
empty folder or an earlier complete run. ``summary.json`` (contract §3)
holds no times or paths and its floats are rounded to 10 significant digits, so two runs of the same
config on the same data are byte-identical.
"""

from __future__ import annotations

import hashlib
import json
import platform
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from . import __version__
from .jsonutil import clean as _clean
from .jsonutil import dumps
from .config import LoadedConfig, implemented_families, load_config, noise_families
from .errors import ConfigError, InputError, SimulationError, in_file
from .data import Record, Split, apply_prefilters, file_sha256, load_record, make_split, remove_means
from .diagnostics.adequacy import is_informational
from .diagnostics.coverage import coverage
from .diagnostics.engine import Diagnoser, Diagnosis, bic_of, fit_percent, rmse
from .diagnostics.why import why_unexplained
from .fit import (FitResult, Problem, at_bounds, defined_validation_rows, equation_error_start, param_intervals,
                  undefined_from)
from .extended import extended_config
from .model import Model
from .runfolder import check_target, finalize, kill_point, make_temp, publish
from .series import simulation_csv

SCHEMA = "sysid-summary/1"


@dataclass
class RunContext:
    lc: LoadedConfig
    rec: Record
    split: Split
    model: Model
    prob: Problem
    diag: Diagnosis
    run_id: str
    summary: dict
    comparison: object = None


def model_block(fit: FitResult, prob: Problem) -> dict:
    """A model's summary block; when its simulation stops on the validation part (only the nominal
    model's may: :func:`pipeline.fit.simulate_full` with ``partial``) the validation numbers are over the
    samples where it is defined (those before the stop, and those of a later validation record that
    starts again), ``samples`` of them, and ``undefined_from_s`` says from when."""
    stop = undefined_from(fit.Yhat, prob)
    sl = defined_validation_rows(fit.Yhat, prob)
    r = prob.Y[sl] - fit.Yhat[sl]
    return {"params": dict(zip(fit.names, fit.theta)), "param_std": dict(zip(fit.names, fit.std)),
            # 95 % intervals θ̂ ± t_ν σ with the covariance's own degrees of freedom (fit.param_intervals)
            "param_ci95": {n: (list(ci) if ci else None) for n, ci in zip(fit.names, param_intervals(fit))},
            "estimation": {"rmse_sim": rmse(fit.resid_est),
                           "fit_percent": fit_percent(prob.Y[prob.split.est_slice()],
                                                      fit.Yhat[prob.split.est_slice()])},
            "validation": {"rmse_sim": rmse(r) if len(r) else None,
                           "fit_percent": fit_percent(prob.Y[sl], fit.Yhat[sl]) if len(r) else None,
                           **({"per_output": {name: {"rmse_sim": rmse(r[:, i]),
                                                     "fit_percent": fit_percent(prob.Y[sl, i], fit.Yhat[sl, i])}
                                              for i, name in enumerate(prob.out_names)}}
                              if r.shape[1] > 1 else {}),
                           **({"undefined_from_s": float(prob.t[stop]), "samples": len(r)}
                              if stop is not None else {})},
            "bic": bic_of(fit), "n_params": fit.n_params, "converged": fit.success,
            "identifiability": fit.identifiability.record() if fit.identifiability else None,
            **({"at_bound": at_bounds(fit)} if fit.model.bounds else {})}


def families_of(lc: LoadedConfig) -> list[str]:
    fam = lc.cfg.diagnose.families
    return list(implemented_families()) if fam == "all" else [f for f in fam if f in implemented_families()]


def run_id_of(lc: LoadedConfig, data_sha256: str) -> str:
    """``<name>-<8 hex>`` from the canonical config hash and the data file's hash."""
    return f"{lc.cfg.name}-{hashlib.sha256((lc.sha256() + data_sha256).encode()).hexdigest()[:8]}"


def input_paths(lc: LoadedConfig) -> list[Path]:
    """The files a run reads: the config, ``data.path`` and any other ``path`` under ``data`` (e.g. a
    separate validation record or experiments), relative ones taken from the config's folder."""
    out = [Path(lc.path), lc.data_path]

    def walk(v):
        if isinstance(v, dict):
            for k, x in v.items():
                if k == "path" and isinstance(x, str):
                    p = Path(x)
                    out.append(p if p.is_absolute() else Path(lc.path).parent / p)
                else:
                    walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)

    walk(lc.cfg.data.model_dump(mode="json"))
    return list(dict.fromkeys(out))


def analyse(lc: LoadedConfig) -> RunContext:
    """The whole analysis of a loaded config. An input error raised deep in a stage that names no file
    is re-raised naming the config (and ``structures`` for the structure stage's own settings)."""
    try:
        return _analyse(lc)
    except InputError as exc:
        if exc.file:
            raise
        raise in_file(exc, str(lc.path)) from None


def _analyse(lc: LoadedConfig) -> RunContext:
    rec = load_record(lc)
    delay = lc.cfg.model.input_delay
    span = rec.n * rec.dt
    if delay and delay >= span:
        raise ConfigError(f"{delay:g} s is not shorter than the record ({span:g} s): the model would never see "
                          "the input", file=str(lc.path), key="model.input_delay")
    prefilter_log = (apply_prefilters(rec, lc.cfg.prefilter, str(lc.path), lc.cfg.data.min_samples)
                     if lc.cfg.prefilter else [])
    split = make_split(lc, rec)
    if lc.cfg.data.remove_mean:
        remove_means(rec, split)
    model = Model.from_config(lc)
    prob = Problem.from_record(rec, model, split, lc.cfg.split.warmup)
    d = lc.cfg.diagnose
    dg = Diagnoser(prob, alpha=d.alpha, families=families_of(lc), max_findings=d.max_findings,
                   seed=lc.cfg.seed, n_boot=d.bootstrap, max_delay_s=d.max_delay_s, dt=rec.dt,
                   couplings=d.couplings)
    try:
        diag = dg.run(model, start=equation_error_start(model, prob))
    except SimulationError as exc:  # name the config: the parameters or equations are the cause
        if exc.key:                 # a key of its own (a declared output): keep it
            raise in_file(exc, str(lc.path)) from None
        raise SimulationError(str(exc), file=str(lc.path), key="model") from None
    comparison = None
    if lc.cfg.structures is not None:
        from .compare import Comparer
        try:
            comparison = Comparer(lc, rec, split, model).run()
        except InputError as exc:
            raise in_file(exc, str(lc.path), "structures") from None
    cfg_sha = lc.sha256()
    run_id = run_id_of(lc, rec.sha256)
    summary = build_summary(lc, rec, prob, diag, run_id, cfg_sha)
    summary["data"]["prefilter"] = prefilter_log
    if comparison is not None:
        summary["models"] += [r.record() for r in comparison.results]
        summary["structures"] = {"settings": comparison.settings, "selected": comparison.selected,
                                 "frols": comparison.frols, "sindy": comparison.sindy,
                                 "takagi_sugeno": comparison.takagi_sugeno, "warnings": comparison.warnings}
        summary["selected_structure"] = comparison.selected
        summary["notes"]["cv_rmse_sim"] = ("per-fold free-run RMSE of blocked k-fold CV on the estimation part "
                                           "(candidate structures); null for the diagnosis chain")
    return RunContext(lc, rec, split, model, prob, diag, run_id, summary, comparison)


def build_summary(lc, rec, prob, diag: Diagnosis, run_id: str, cfg_sha: str) -> dict:
    nominal = model_block(diag.nominal, prob)
    ignored = [f for f in (lc.cfg.diagnose.families if isinstance(lc.cfg.diagnose.families, list) else [])
               if f not in implemented_families()]
    models = [{"name": "nominal", "estimator": "output_error_ls", "bic": nominal["bic"],
               "n_params": nominal["n_params"], "validation_rmse_sim": nominal["validation"]["rmse_sim"],
               "cv_rmse_sim": None}]
    name = "nominal"
    for f, fit in zip([f for f in diag.findings if f["family"] not in noise_families()], diag.fits[1:]):
        name = f"{name}+{f['family']}"
        b = model_block(fit, prob)
        models.append({"name": name, "estimator": "output_error_ls", "bic": b["bic"], "n_params": b["n_params"],
                       "validation_rmse_sim": b["validation"]["rmse_sim"], "cv_rmse_sim": None,
                       "equations": fit.model.describe_equations()})
    return {
        "schema": SCHEMA, "run_id": run_id, "config_sha256": cfg_sha, "data_sha256": rec.sha256,
        "data": {"n_samples": rec.n, "sample_time": rec.dt, "estimation": list(prob.split.est),
                 "validation": list(prob.split.val), "intersample": lc.cfg.data.intersample,
                 "outputs": prob.out_names, "log": rec.log,
                 "coverage": coverage(prob.U, prob.Y, list(diag.nominal.model.inputs), prob.out_names,
                                      prob.split.est, prob.split.val)},
        "nominal": nominal,
        "final": model_block(diag.final, prob),
        "diagnosis": {
            "verdict": diag.verdict,
            "findings": diag.findings,
            "tests": _test_rows(diag.tests, "nominal model, estimation data"),
            "final_tests": _test_rows(diag.final_tests, "final model, estimation data")
                           + _test_rows([t for t in diag.noise_tests
                                         if t.name not in {f.name for f in diag.final_tests}],
                                        "final model, estimation data (noise families)"),
            "adequacy": _test_rows(diag.adequacy, "final model, estimation data (structural adequacy)"),
            "adequacy_nominal": _test_rows(diag.adequacy_nominal, "nominal model, estimation data (structural adequacy)"),
            "unexplained": None if diag.where is None else {
                **diag.where, "families_tried": _tried(diag.history, {f["family"] for f in diag.findings},
                                                   diag.revisit or []),
                "why": why_unexplained(diag.history, diag.adequacy)},
            "not_testable": _not_testable(diag.history),
            "families_tested": [] if diag.rounding else families_of(lc), "families_not_available": ignored,
            "alpha": lc.cfg.diagnose.alpha, "history": diag.history, "revisit": diag.revisit,
            **({"rounding_level": diag.rounding} if diag.rounding else {}),
        },
        "models": models,
        "selected_model": name,
        "notes": {"rmse_sim": "free-run simulation error (not one-step prediction)",
                  "cv_rmse_sim": "blocked k-fold CV is not computed yet (null)",
                  # the Silverbox's two records give the same final structure's parameters 4 to 15 sigma apart
                  "param_ci95": ("theta +- t_nu sigma: the noise's sampling uncertainty for this record's input, "
                                 "given the model's structure; a model the diagnosis says misses something has "
                                 "the parameters that best fit this input, and another excitation can move them "
                                 "by several sigma")},
    }


TAKEN = "accepted"
NOT_TAKEN = "met the acceptance rule in its round, not taken: another extension explained more"


def _tried(history: list[dict], found: set[str] = frozenset(), moves: list[dict] = ()) -> list[dict]:
    """Per family, the last reason it was not taken, from the diagnosis history; "accepted" for a
    family among the findings (``found``; a later round's "not significant" of its remaining
    hypotheses does not undo a finding). A candidate's own reason "accepted" means it met the
    acceptance rule; for a family that is not a finding that reads :data:`NOT_TAKEN`, or, when the
    backward step removed its finding (``moves``: ``diagnosis.revisit``, a swap or a drop), what the
    step did."""
    out: dict[str, str] = {}
    for it in history:
        for c in it.get("candidates", []):
            out[c["family"]] = c.get("reason") or ""
        for sk in it.get("skipped", []):
            out.setdefault(sk["family"], sk["reason"])
    removed = {m["family"]: m["short"] for m in moves if m.get("family") and m["family"] not in found}

    def reason(f: str, r: str) -> str:
        if f in found:
            return TAKEN
        if f in removed:
            return f"{TAKEN}, then removed by the backward step: {removed[f]}"
        return NOT_TAKEN if r == TAKEN else r
    return [{"family": f, "reason": reason(f, r)} for f, r in out.items()]


def _not_testable(history: list[dict]) -> list[dict]:
    """What a family's guard kept from being tested, and why (each reason once, first iteration first):
    e.g. a periodic term with too few cycles in the estimation window."""
    seen = dict.fromkeys((sk["family"], sk["reason"]) for it in history for sk in it.get("skipped", []))
    return [{"family": f, "reason": r} for f, r in seen]


def _test_rows(tests, on: str) -> list[dict]:
    """Contract §3 test rows, extended: ``tested`` is false on a row that was not run (a noise family
    on an inadequate structure), whose ``passed`` is then false without anything having failed;
    ``informational`` (only where true) marks a row about the data that is not part of the verdict
    (:func:`.diagnostics.adequacy.is_informational`: the closed-loop sign); ``output`` and ``input`` (with
    several outputs or excited inputs only) the output and input a row is on."""
    return [{"name": t.name, "statistic": t.statistic, "p_value": t.p_value, "bound": t.bound,
             "passed": t.passed, "tested": not (t.detail or "").startswith("not tested"), "detail": t.detail,
             "on": getattr(t, "on", None) or on, **({"informational": True} if is_informational(t.name) else {}),
             **{k: getattr(t, k) for k in ("output", "input") if getattr(t, k, None) is not None},
             **({} if t.r2 is None else {"explained_share": t.r2, "material": (not t.passed) and t.r2 >= 0.02})}
            for t in tests]


def _git_info() -> dict:
    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip() != ""
        return {"commit": commit or None, "dirty": dirty if commit else None}
    except Exception:
        return {"commit": None, "dirty": None}


def _versions() -> dict:
    import importlib.metadata as md
    out = {"python": platform.python_version(), "sysid-pipeline": __version__}
    for p in ("numpy", "scipy", "pandas", "numba", "pydantic", "matplotlib", "jinja2", "pyyaml", "scikit-learn",
              "pysindy", "emcee"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            out[p] = None
    return out


def default_target(run_id: str) -> Path:
    return Path("reports") / run_id


def write_run(ctx: RunContext, out: Path | None, *, html: bool) -> Path:
    """Write the run folder ``out`` (default ``reports/<run-id>``) and return it as given.

    The target is checked again (:func:`runfolder.check_target`, it may have changed during the
    analysis), the files are written into a fresh hidden temp folder, the completion marker last, and
    the folder is published atomically (:func:`runfolder.publish`)."""
    default = out is None
    target = Path(out) if out else default_target(ctx.run_id)
    if default:
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError:
            pass  # check_target names the problem
    resolved = check_target(target, inputs=input_paths(ctx.lc), default=default)
    tmp = make_temp(resolved)
    try:
        t0 = time.perf_counter()
        (tmp / "summary.json").write_text(dumps(ctx.summary))
        kill_point("after_summary_written")
        from .tracking import dvc_metrics, dvc_params  # DVC conventions: numeric tree; params = inputs
        (tmp / "metrics.json").write_text(dumps(dvc_metrics(_clean(ctx.summary))))
        (tmp / "params.yaml").write_text(yaml.safe_dump(dvc_params(ctx.lc.canonical()), sort_keys=False))
        (tmp / "config.resolved.yaml").write_text(yaml.safe_dump(ctx.lc.canonical(), sort_keys=False))
        ext = extended_config(ctx.lc.canonical(), ctx.diag.final.model, ctx.lc.path, ctx.lc.data_path, target)
        (tmp / "extended.yaml").write_text("# the final model of run " + ctx.run_id + " as a runnable config\n"
                                           + yaml.safe_dump(ext, sort_keys=False, allow_unicode=True))
        (tmp / "simulation.csv").write_bytes(simulation_csv(ctx.prob, ctx.diag, ctx.rec))
        if html:
            from .report import render_report
            (tmp / "report.html").write_text(render_report(ctx), encoding="utf-8")
        manifest = {"run_id": ctx.run_id, "config": str(ctx.lc.path), "config_sha256": ctx.summary["config_sha256"],
                    "data": ctx.rec.path, "data_sha256": ctx.rec.sha256, "seed": ctx.lc.cfg.seed,
                    "git": _git_info(), "versions": _versions(), "platform": platform.platform(),
                    "command": " ".join(sys.argv),
                    "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "report_seconds": round(time.perf_counter() - t0, 3)}
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
        finalize(tmp, ctx.run_id)
        publish(tmp, resolved)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


def run(config_path: str | Path, out: str | Path | None = None, *, html: bool = True,
        track: str | None = None) -> Path:
    """Load the config, check ``--out`` (before any analysis), analyse, write the run folder, and log it
    to MLflow when ``track`` is a tracking URI."""
    lc = load_config(config_path)
    inputs = input_paths(lc)
    if track:   # a bad URI or a missing MLflow fails now, not after the analysis and the run folder
        from .tracking.mlflow_backend import check_tracking
        track = check_tracking(track, key="--track")
    if out is not None:
        check_target(out, inputs=inputs, default=False)   # "" is refused, not taken as the default
    else:  # the run id follows from the two hashes: check reports/<run-id> now (the data is read later)
        try:
            data_sha = file_sha256(lc.data_path)
        except OSError:
            data_sha = None   # load_record names the problem
        if data_sha is not None:
            check_target(default_target(run_id_of(lc, data_sha)), inputs=inputs, default=True)
    ctx = analyse(lc)
    path = write_run(ctx, Path(out) if out is not None else None, html=html)
    if track:  # MLflow, after the folder is published (pipeline.tracking.mlflow_backend)
        from .tracking.mlflow_backend import log_run
        log_run(path, track)
    return path
