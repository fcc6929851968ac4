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
   It is left blank (no parameter credit, the reason says why) when the parameter is one of the
   starter model's (its linear damping, fitted to absorb a friction, projects on ``sign(v)`` with about
   the key's size), or when ``g`` explains less than :data:`FORM_SHARE_MIN` of ``Δ``: the parameter
   does not multiply a term of the cause's form.
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
import hashlib
import io
import json
import math
import os
import secrets
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
from ..runfolder import is_replaceable_run, why_not_replaceable
from ..simulate import outputs, simulate_states
from . import KEY_SCHEMA, rubric
from .roster import id_problem
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
    for i, s in enumerate(key.students):   # ids name folders: the roster's rule, or grading leaves them
        problem = id_problem(s.id)
        if problem:
            raise InputError(problem, file=f, key=f"students.{i}.id")
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
        # the record's length is the key's issued + held-out samples: else every submission reading it
        # would be blamed ("the config reads 1200 samples …, expected 100400") for the key's error
        n = load_record(load_config(base / s.starter_config)).n
        if s.issued_samples < 1 or s.heldout_samples < 1 or s.issued_samples + s.heldout_samples != n:
            raise InputError(f"issued_samples + heldout_samples = {s.issued_samples} + {s.heldout_samples}; the "
                             f"instructor's record of {s.id} has {n} samples (issued and held-out parts, each at "
                             "least 1)", file=f, key=f"students.{i}")
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


# the least share of the named parameter's change that the key's term must explain for the parameter
# to count as sizing the cause (module docstring, step 5); a term of the key's form, however written
# (sign, scaling, a division by a fixed mass), explains all of it
FORM_SHARE_MIN = 0.9


def cause_projection(model: Model, param: str, st: KeyStudent, t: np.ndarray, U: np.ndarray, X: np.ndarray,
                     out_name: str | None) -> tuple[float, float]:
    """The size of the key's cause in the student's fitted model (module docstring, step 5) and the
    share of the named parameter's change that the key's term explains (``1 - |Δ - g c|² / |Δ|²``;
    NaN when the parameter changes nothing). The share is what tells a parameter of the cause's term
    from one whose change merely correlates with it: a linear damping ``c`` fitted to absorb a Coulomb
    friction has a non-zero projection on ``sign(v)`` but is not a friction coefficient."""
    if param not in model.params:
        return math.nan, math.nan
    m0 = model.with_params({param: 0.0})
    fam, p = st.family, st.parameters
    if fam == "output_offset":
        if out_name is None:
            return math.nan, math.nan
        d = outputs(model, t, U, X, [out_name])[:, 0] - outputs(m0, t, U, X, [out_name])[:, 0]
        G = np.ones((len(d), 1))
    else:
        eq = st.acts_on
        if eq not in model.states:
            return math.nan, math.nan
        j = model.states.index(eq)
        d = rhs_vectorized(model, X, U, t)[:, j] - rhs_vectorized(m0, X, U, t)[:, j]
        if fam == "periodic_disturbance":
            w = 2 * np.pi * float(p["frequency_hz"]) * t
            G = np.column_stack([np.sin(w), np.cos(w)])
        elif fam == "offset":
            G = np.ones((len(d), 1))
        else:
            names = list(model.states)
            g = np.broadcast_to(np.asarray(vectorize(parse(p["term"], set(names)), names)(*X.T), float), t.shape)
            G = np.asarray(g, float).reshape(-1, 1)
    if not np.all(np.isfinite(d)) or not np.any(G):
        return math.nan, math.nan
    if G.shape[1] == 1:   # the closed form (as before the share was computed: same bytes in the gradebook)
        g = G[:, 0]
        a = np.array([float(g @ d) / float(g @ g)])
    else:
        a = np.linalg.lstsq(G, d, rcond=None)[0]
    dd = float(d @ d)
    share = 1.0 - float(np.sum(np.square(d - G @ a))) / dd if dd > 0 else math.nan
    if fam == "periodic_disturbance":
        return float(np.hypot(*a)), share
    return float(a[0]), share


def cause_size(model: Model, param: str, st: KeyStudent, t: np.ndarray, U: np.ndarray, X: np.ndarray,
               out_name: str | None) -> float:
    """The size of the key's cause in the student's fitted model (module docstring, step 5)."""
    return cause_projection(model, param, st, t, U, X, out_name)[0]


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
        param = sub.answer.parameter
        sim = simulate_states(model, prob.t[:n], prob.U[:n], x0, bound=prob.bound)
        if sim.diverged_at is None:
            size, share = cause_projection(model, param, st, prob.t[:n], prob.U[:n], sim.X, out_name)
        else:
            size, share = math.nan, math.nan
        # a parameter sizes the cause only when it multiplies a term of the cause's form that the
        # student added: the starter's own parameters (c, k, ...) absorb part of any effect and would
        # otherwise earn parameter credit for an unchanged starter model
        if cause_ok and param in m_nom.params:
            size = math.nan
            notes.append(f"parameter {param!r} is a parameter of the starter model, not of a term the "
                         "submission added for the cause: no parameter credit")
        elif cause_ok and math.isfinite(share) and share < FORM_SHARE_MIN:
            size = math.nan
            notes.append(f"parameter {param!r} does not multiply a term of the cause's form (the key's term "
                         f"explains {100 * max(share, 0.0):.0f}% of its change, at least "
                         f"{100 * FORM_SHARE_MIN:.0f}% expected): no parameter credit")
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
        bases = [task.submissions, task.key_dir] + ([task.runs_dir.parent] if task.runs_dir is not None else [])
        return _empty_row(st, status, _relative(res.error or "", *bases))
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


WRITTEN_SUFFIX = ".sysid-grade"   # the record of what sysid grade wrote: .<file name>.sysid-grade beside it


def written_record(path: Path) -> Path:
    """The hidden file beside ``path`` recording the sha256 of what this tool last wrote there."""
    return path.parent / f".{path.name}{WRITTEN_SUFFIX}"


def _read_record(rec: Path) -> dict | None:
    try:
        data = json.loads(rec.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = isinstance(data, dict) and data.get("tool") == "sysid grade" and isinstance(data.get("sha256"), str)
    return data if ok else None


def check_writable(path: Path, first_line: str | None, what: str) -> None:
    """Refuse to overwrite a file unless it is byte for byte what this tool last wrote there.

    The first line tells a foreign file at once; an edit further down (a bonus typed into a row of the
    gradebook) is caught by the sha256 recorded in :func:`written_record` when the file was written,
    so the instructor's change is never lost silently. A file with the first line but no record (an
    older release, or the record deleted) is refused too: whether it was edited cannot be known. A
    foreign file at the record's own name is refused, as it would be overwritten."""
    rec = written_record(path)
    if path.exists():
        ok = path.is_file() and first_line is not None
        if ok:
            with open(path, encoding="utf-8", errors="replace") as fh:
                ok = fh.readline().rstrip("\n") == first_line
        if not ok:
            raise InputError(f"exists and was not written by sysid grade; choose another {what}", file=str(path))
        data = _read_record(rec)
        if data is None:
            raise InputError(f"exists, but there is no record ({rec.name} beside it) of what sysid grade wrote, "
                             f"so it may hold your edits; move it away or choose another {what}", file=str(path))
        if file_sha256(path) != data["sha256"]:
            raise InputError(f"was edited after sysid grade wrote it (its sha256 differs from the one in "
                             f"{rec.name}); move it away or choose another {what}; nothing was changed",
                             file=str(path))
    elif os.path.lexists(rec) and _read_record(rec) is None:
        raise InputError(f"exists and was not written by sysid grade (it would be overwritten with the record "
                         f"of {path.name}); move it away or choose another {what}", file=str(rec))


def write_tracked(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` (through a temporary file and a rename, so a reader never sees half
    of it) and then its record (:func:`written_record`), which the next :func:`check_writable` needs
    to overwrite it. Interrupted between the two, the next run refuses the file: the safe side."""
    data = text.encode("utf-8")
    path.parent.mkdir(parents=True, exist_ok=True)
    for target, payload in ((path, data), (written_record(path), (json.dumps(
            {"tool": "sysid grade", "file": path.name, "sha256": hashlib.sha256(data).hexdigest()},
            sort_keys=True) + "\n").encode())):
        # created with mode 0o666 and the umask applied by open() itself, as any file the user writes
        tmp = target.parent / f".{target.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(payload)
            os.replace(tmp, target)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise


def check_runs_dir(runs: Path, ids: list[str]) -> None:
    """Before any grading: each ``runs/<id>`` is absent, empty, or a run folder exactly as this tool
    wrote it (:func:`pipeline.runfolder.is_replaceable_run`, the test the run writer applies). Found
    only by the run writer, an edited folder became the student's ``invalid`` row with score 0 and
    overwrote the earlier grade; the instructor's change is the instructor's error: exit 2."""
    if runs.exists() and not runs.is_dir():
        raise InputError("exists and is not a folder", file=str(runs), key="--runs")
    for sid in ids:
        d = runs / sid
        if not os.path.lexists(d):
            continue
        if d.is_dir() and not d.is_symlink() and not any(os.scandir(d)):
            continue
        if not is_replaceable_run(d):
            raise InputError(f"{why_not_replaceable(d)}; move it away or choose another --runs folder; nothing was "
                             "graded", file=str(d))


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
