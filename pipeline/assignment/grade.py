"""``sysid grade``: re-run every submission with the pipeline and write the gradebook.

Nothing a student claims is trusted. For each student of the key (sorted by id):

1. The submission folder is validated (:mod:`.submission`); a missing or broken one gets a row with
   the reason (status ``missing`` / ``invalid`` / ``failed``), never a crash.
2. The student's config is run by the pipeline through :func:`pipeline.batch.run_one` (the same
   ``runs.analyse`` + ``runs.write_run`` as ``sysid batch``): the run folder ``runs/<id>/`` with its
   report, and the run id; the grade reads that run's ``summary.json``. The config's model is fitted
   by output error on the student's record; the data file's sha256 is compared with the key's.
3. The fitted model is simulated (free run, from sample 0 and the fitted initial state) over the
   instructor's whole record; its RMSE on the held-out part (after the issued samples) is the
   validation error. The starter model is fitted the same way (``fit.fit_output_error`` on the same
   estimation samples of the issued record) and simulated the same way: the comparison.
4. The measured gain ``1 - RMSE(student) / RMSE(starter)`` on the validation part of the student's own
   split is compared with the claimed one.
5. The size of the cause: the change the named parameter makes to the key's equation,
   ``Δ_k = f(x_k, u_k, t_k; θ̂) - f(x_k, u_k, t_k; θ̂ with the parameter set to 0)`` along the fitted
   model's simulated trajectory on the issued part, projected by least squares on the key's term
   ``g``: ``c = Σ Δ_k g_k / Σ g_k²`` (for a periodic disturbance the amplitude
   ``hypot(a_sin, a_cos)`` of the projection on sin and cos at the key's frequency; for an output offset
   the mean change of the measured output). This makes the comparison independent of how the student
   wrote the term (sign, name, a division by a fixed mass). ``parameter_rel_error = |c - c_key| / |c_key|``.
   For an input delay the size is the config's ``model.input_delay`` (seconds; 0 when absent): the
   gradebook shows the relative error, and the rubric scores the error in samples,
   ``|d - d_key| / dt``, against ``rubric.delay_tolerance_samples`` (1.5 samples, the diagnosis
   contract's accuracy of a found delay).
6. The score (:mod:`.rubric`).

The submissions are graded on the executors of ``sysid batch`` (:func:`pipeline.batch.run_tasks`:
in this process for ``--jobs 1``, else a spawned process pool of ``--jobs`` workers, or a Dask
``LocalCluster`` with ``--executor dask``); each task is one student, :func:`grade_one`.

Same inputs give a byte-identical gradebook on any machine and for any ``--jobs``: rows sorted by id,
fixed float formats, no times and no absolute paths (messages name files relative to the submissions
folder).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from .. import batch
from ..config import LoadedConfig, load_config
from ..data import Split, file_sha256, load_record, make_split
from ..errors import InputError, SimulationError
from ..expressions import parse, vectorize
from ..fit import Problem, equation_error_start, fit_output_error, initial_state, simulate_full
from ..model import Model, rhs_vectorized
from ..simulate import outputs, simulate_states
from . import KEY_SCHEMA, rubric
from .submission import Submission, load_submission
from .template import Template, validation_message

COLUMNS = ["student_id", "name", "status", "cause_key", "cause_claimed", "cause_correct", "parameter_rel_error",
           "heldout_rmse", "heldout_rmse_nominal", "heldout_gain", "claimed_gain", "measured_gain",
           "gain_reproduces", "data_issued", "score", "run_id", "reason"]
HEADER = ",".join(COLUMNS)


class KeyStudent(BaseModel):
    model_config = ConfigDict(extra="ignore")
    id: str
    name: str
    family: str
    acts_on: str
    parameters: dict
    main_parameter: str
    data_sha256: str
    issued_samples: int
    heldout_samples: int
    instructor_record: str
    instructor_record_sha256: str
    starter_config: str
    heldout_rmse_truth: float


class KeyFile(BaseModel):
    model_config = ConfigDict(extra="ignore")
    schema_: str
    assignment: str
    seed: int
    template: Template
    students: list[KeyStudent]


def load_key(path: str | Path) -> tuple[KeyFile, Path]:
    """Read and check the key and the instructor's files it names. InputError (exit 2) otherwise."""
    path = Path(path)
    f = str(path)
    if not path.is_file():
        raise InputError("key not found", file=f)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"not a JSON file ({exc})", file=f) from None
    if not isinstance(raw, dict) or raw.get("schema") != KEY_SCHEMA:
        raise InputError(f"not an assignment key (expected \"schema\": \"{KEY_SCHEMA}\")", file=f, key="schema")
    raw = dict(raw, schema_=raw["schema"])
    try:
        key = KeyFile.model_validate(raw)
    except ValidationError as exc:
        raise InputError(validation_message(exc), file=f) from None
    ids = [s.id for s in key.students]
    if len(set(ids)) != len(ids) or not ids:
        raise InputError("student ids must be unique and at least one", file=f, key="students")
    base = path.parent
    for i, s in enumerate(key.students):
        rec = base / s.instructor_record
        if not rec.is_file():
            raise InputError(f"the instructor's record of {s.id} is missing", file=str(rec))
        if file_sha256(rec) != s.instructor_record_sha256:
            raise InputError(f"the instructor's record of {s.id} differs from the one the key was made with",
                             file=str(rec))
        load_config(base / s.starter_config)
    return key, base


@dataclass
class Task:
    """One student's grading job (picklable for the process pool)."""

    student: KeyStudent
    key_dir: Path
    submissions: Path
    runs_dir: Path | None
    template: Template


def _fmt(x: float | None, spec: str) -> str:
    return "" if x is None or not math.isfinite(x) else format(x, spec)


def _rmse(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(r)))) if r.size else math.nan


def _relative(msg: str, *bases: Path) -> str:
    """``msg`` with the given folders removed from the paths it names (no absolute paths in a row)."""
    names = {str(b.resolve()) for b in bases} | {str(b) for b in bases if str(b) not in (".", "")}
    for s in sorted(names, key=len, reverse=True):
        msg = msg.replace(s + os.sep, "").replace(s, ".")
    return " ".join(msg.split())


def _on_record(lc: LoadedConfig, path: Path) -> LoadedConfig:
    """The student's config reading another file (the instructor's whole record)."""
    cfg = lc.cfg.model_copy(update={"data": lc.cfg.data.model_copy(update={"path": str(path.resolve())})})
    return LoadedConfig(cfg, lc.path, lc.equations, lc.output_exprs, lc.input_map, lc.output_map)


def cause_size(model: Model, param: str, st: KeyStudent, t: np.ndarray, U: np.ndarray, X: np.ndarray,
               out_name: str | None) -> float:
    """The size of the key's cause in the student's fitted model (module docstring, step 5)."""
    if param not in model.params:
        return math.nan
    m0 = model.with_params({param: 0.0})
    fam, p = st.family, st.parameters
    if fam == "output_offset":
        if out_name is None:
            return math.nan
        d = outputs(model, t, U, X, [out_name])[:, 0] - outputs(m0, t, U, X, [out_name])[:, 0]
        return float(np.mean(d))
    eq = st.acts_on
    if eq not in model.states:
        return math.nan
    j = model.states.index(eq)
    d = rhs_vectorized(model, X, U, t)[:, j] - rhs_vectorized(m0, X, U, t)[:, j]
    if fam == "periodic_disturbance":
        w = 2 * np.pi * float(p["frequency_hz"]) * t
        G = np.column_stack([np.sin(w), np.cos(w)])
        a = np.linalg.lstsq(G, d, rcond=None)[0]
        return float(np.hypot(*a))
    if fam == "offset":
        g = np.ones_like(t)
    else:
        names = list(model.states)
        g = np.broadcast_to(np.asarray(vectorize(parse(p["term"], set(names)), names)(*X.T), float), t.shape)
    gg = float(g @ g)
    return float(g @ d) / gg if gg > 0 else math.nan


def _empty_row(st: KeyStudent, status: str, reason: str) -> dict:
    row = {c: "" for c in COLUMNS}
    row.update(student_id=st.id, name=st.name, status=status, cause_key=st.family, score=_fmt(0.0, ".1f"),
               reason=reason)
    return row


def _split_of(summary: dict, lc: LoadedConfig, n: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The student's estimation and validation ranges (from the run, else from the config)."""
    d = summary.get("data", {}) if isinstance(summary, dict) else {}
    try:
        est, val = tuple(int(v) for v in d["estimation"]), tuple(int(v) for v in d["validation"])
        if len(est) == 2 and len(val) == 2 and 0 <= est[0] < est[1] <= n and 0 <= val[0] < val[1] <= n:
            return est, val
    except (KeyError, TypeError, ValueError):
        pass
    s = make_split(lc, n)
    return s.est, s.val


def _grade_submission(task: Task, sub: Submission, summary: dict, run_id: str) -> dict:
    """The row of a submission whose pipeline run gave ``summary`` (its summary.json)."""
    st, tpl = task.student, task.template
    lc = sub.config
    data_issued = summary.get("data_sha256") == st.data_sha256
    fitted = {k: float(v) for k, v in summary["nominal"]["params"].items()}
    n, nh = st.issued_samples, st.heldout_samples
    full_path = task.key_dir / st.instructor_record
    lc_full = _on_record(lc, full_path)
    try:
        rec = load_record(lc_full)
    except InputError as exc:
        raise InputError(f"the config does not read the issued record's columns ({exc})",
                         file=str(lc.path), key="data") from None
    if rec.n != n + nh:
        raise InputError(f"the config reads {rec.n} samples of the instructor's record, expected {n + nh}",
                         file=str(lc.path), key="data")
    est, val = _split_of(summary, lc, n)
    held = (n, n + nh)
    model = Model.from_config(lc_full)
    model = model.with_params({k: v for k, v in fitted.items() if k in model.params})
    prob = Problem.from_record(rec, model, Split(est, held))
    notes = []
    x0 = initial_state(model, prob, values=fitted)
    try:
        Yh = simulate_full(model, prob, x0)
    except SimulationError:
        Yh = np.full_like(prob.Y, np.nan)
        notes.append("the fitted model diverges on the held-out part")
    # the starter model, fitted on the same estimation samples of the instructor's copy
    lc_nom = load_config(task.key_dir / st.starter_config)
    rec_nom = load_record(lc_nom)
    m_nom = Model.from_config(lc_nom)
    prob_nom = Problem.from_record(rec_nom, m_nom, Split(est, held))
    fit_nom = fit_output_error(m_nom, prob_nom, start=equation_error_start(m_nom, prob_nom))
    Y = prob.Y
    ho_s = _rmse(Y[n:] - Yh[n:]) if np.all(np.isfinite(Yh[n:])) else math.inf
    ho_n = _rmse(prob_nom.Y[n:] - fit_nom.Yhat[n:])
    vs, vn = _rmse(Y[val[0]:val[1]] - Yh[val[0]:val[1]]), _rmse(prob_nom.Y[val[0]:val[1]] - fit_nom.Yhat[val[0]:val[1]])
    measured = 1.0 - vs / vn if math.isfinite(vs) and vn > 0 else math.nan
    claimed = sub.answer.claimed_gain
    reproduces = math.isfinite(measured) and abs(claimed - measured) <= tpl.rubric.gain_tolerance
    cause_ok = sub.answer.cause == st.family
    # size of the cause along the fitted model's trajectory on the issued part
    out_col = st.acts_on.split(" ", 1)[1] if st.family == "output_offset" else None
    out_name = lc_full.output_map.get(out_col) if out_col else None
    ref = float(st.parameters[st.main_parameter])
    tolerance = score_error = None
    if st.family == "input_delay":
        size = float(lc.cfg.model.input_delay or 0.0)
        score_error, tolerance = abs(size - ref) / rec.dt, tpl.rubric.delay_tolerance_samples
        if cause_ok and score_error > tolerance:
            notes.append(f"input delay {size:.4g} s is {score_error:.1f} samples from the key's "
                         f"(tolerance {tolerance:g})")
    else:
        sim = simulate_states(model, prob.t[:n], prob.U[:n], x0, bound=prob.bound)
        if sim.diverged_at is None:
            size = cause_size(model, sub.answer.parameter, st, prob.t[:n], prob.U[:n], sim.X, out_name)
        else:
            size = math.nan
    if st.family == "periodic_disturbance":
        ref = abs(ref)
    perr = abs(size - ref) / abs(ref) if math.isfinite(size) and ref != 0 else math.nan
    share = rubric.validation_share(ho_n, ho_s, st.heldout_rmse_truth)
    items = rubric.shares(tpl.rubric, cause_correct=cause_ok,
                          parameter_error=perr if score_error is None else score_error, validation=share,
                          gain_reproduces=reproduces, tolerance=tolerance)
    total = rubric.score(tpl.rubric, items, data_issued)
    if not data_issued:
        notes.insert(0, "the data file is not the one issued (sha256 differs)")
    if not reproduces:
        notes.append(f"claimed gain {claimed:.4f} does not reproduce (measured {_fmt(measured, '.4f') or 'n/a'})")
    row = {
        "student_id": st.id, "name": st.name, "status": "graded", "cause_key": st.family,
        "cause_claimed": sub.answer.cause, "cause_correct": "yes" if cause_ok else "no",
        "parameter_rel_error": _fmt(perr, ".4f"), "heldout_rmse": _fmt(ho_s, ".6g") or "diverged",
        "heldout_rmse_nominal": _fmt(ho_n, ".6g"),
        "heldout_gain": _fmt(1.0 - ho_s / ho_n if math.isfinite(ho_s) and ho_n > 0 else math.nan, ".4f"),
        "claimed_gain": _fmt(claimed, ".4f"), "measured_gain": _fmt(measured, ".4f"),
        "gain_reproduces": "yes" if reproduces else "no", "data_issued": "yes" if data_issued else "no",
        "score": _fmt(total, ".1f"), "run_id": run_id, "reason": "; ".join(notes),
    }
    return row


def _run(task: Task, sub: Submission, root: Path) -> dict:
    """Run the submission's config with :func:`pipeline.batch.run_one` into ``root/<id>`` and grade it."""
    st = task.student
    res = batch.run_one(str(sub.config.path), str(root), html=task.runs_dir is not None, name=st.id)
    if not res.ok:
        status = "invalid" if res.kind == "input" else "failed"
        return _empty_row(st, status, _relative(res.error or "", task.submissions, task.key_dir))
    summary = json.loads((Path(res.path) / "summary.json").read_text(encoding="utf-8"))
    return _grade_submission(task, sub, summary, res.run_id or "")


def grade_one(task: Task) -> dict:
    """One gradebook row; never raises (missing/broken submissions give a row with the reason).
    The run folder goes to ``task.runs_dir/<id>``, or to a temporary folder when it is None."""
    st = task.student
    folder = task.submissions / st.id
    if not folder.is_dir():
        return _empty_row(st, "missing", "no submission folder")
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            sub = load_submission(folder)
            if task.runs_dir is not None:
                return _run(task, sub, task.runs_dir)
            with tempfile.TemporaryDirectory(prefix="sysid-grade-") as tmp:
                return _run(task, sub, Path(tmp))
    except InputError as exc:
        return _empty_row(st, "invalid", _relative(str(exc), task.submissions, task.key_dir))
    except Exception as exc:  # an internal failure on one submission must not stop the class
        return _empty_row(st, "failed", _relative(f"internal error: {type(exc).__name__}: {exc}",
                                                  task.submissions, task.key_dir))


def check_writable(path: Path, first_line: str | None, what: str) -> None:
    """Refuse to overwrite a file this tool did not write (recognised by its first line)."""
    if path.exists():
        ok = path.is_file() and first_line is not None
        if ok:
            with open(path, encoding="utf-8", errors="replace") as fh:
                ok = fh.readline().rstrip("\n") == first_line
        if not ok:
            raise InputError(f"exists and was not written by sysid grade; choose another {what}", file=str(path))


def check_runs_dir(runs: Path, ids: list[str]) -> None:
    """Run folders are replaced only when they are run folders (they hold a manifest.json)."""
    if runs.exists() and not runs.is_dir():
        raise InputError("exists and is not a folder", file=str(runs), key="--runs")
    for sid in ids:
        d = runs / sid
        if d.exists() and not (d.is_dir() and (d / "manifest.json").is_file()):
            raise InputError("exists and is not a run folder; choose another --runs folder", file=str(d))


def gradebook_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


def grade(key_path: str | Path, submissions: str | Path, *, jobs: int = 1, executor: str = "local",
          runs_dir: str | Path | None = None) -> tuple[KeyFile, list[dict]]:
    """Grade every student of the key on the ``sysid batch`` executors; rows sorted by student id."""
    if jobs < 1:
        raise InputError(f"must be at least 1, got {jobs}", key="--jobs")
    batch.check_options(jobs, executor, None)
    key, key_dir = load_key(key_path)
    subs = Path(submissions)
    if not subs.is_dir():
        raise InputError("submissions folder not found", file=str(subs), key="--submissions")
    runs = Path(runs_dir) if runs_dir is not None else None
    if runs is not None:
        check_runs_dir(runs, [s.id for s in key.students])
        runs.mkdir(parents=True, exist_ok=True)
    # absolute folders: the workers of a process pool or a Dask cluster may run elsewhere
    runs = runs.resolve() if runs is not None else None
    tasks = [Task(s, key_dir.resolve(), subs.resolve(), runs, key.template)
             for s in sorted(key.students, key=lambda s: s.id)]
    rows = batch.run_tasks(grade_one, tasks, jobs=min(jobs, len(tasks)), executor=executor)
    return key, sorted(rows, key=lambda r: r["student_id"])
