"""The run store: the run folders under a root (default ``reports/``), listed, filtered, sorted and
compared (``sysid runs``, ``sysid compare``).

A run folder counts when it is complete: not dot-prefixed (``runs.write_run`` writes into a hidden
``.name.*`` temp folder and renames it at the end) and holding ``manifest.json`` (written last) and
``summary.json``. Everything shown is read from the folder's files, never recomputed.
"""

from __future__ import annotations

import json
import math
import operator
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import yaml

from . import runfolder
from .errors import InputError
from .tracking.dvc import dvc_metrics, flatten

DEFAULT_ROOT = Path("reports")

# the table of `sysid runs`: column -> header
COLUMNS: dict[str, str] = {"name": "name", "run_id": "run id", "data": "data", "verdict": "verdict",
                           "main_cause": "main cause", "gain": "gain %", "val_fit": "val. fit %",
                           "bic": "BIC", "created": "created"}


def iter_run_folders(root: Path, skipped: list[Path] | None = None):
    """Complete run folders under ``root``, in name order: the run-folder module's rule (a complete
    marker; hidden temp and moved-aside folders never listed); ``skipped`` collects the edited ones."""
    from .runfolder import iter_run_folders as _complete
    if not Path(root).is_dir():
        return
    yield from _complete(Path(root), skipped)


@dataclass
class RunInfo:
    """One run folder's files, parsed."""

    path: Path
    summary: dict
    manifest: dict
    config: dict = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path) -> "RunInfo":
        try:
            summary = json.loads((path / "summary.json").read_text(encoding="utf-8"))
            manifest = json.loads((path / "manifest.json").read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable run folder ({exc})", file=str(path)) from None
        cfg = {}
        cp = path / "config.resolved.yaml"
        if cp.is_file():
            try:
                cfg = yaml.safe_load(cp.read_text(encoding="utf-8")) or {}
            except yaml.YAMLError:
                cfg = {}
        if not isinstance(summary, dict) or not isinstance(manifest, dict):
            raise InputError("summary.json / manifest.json is not a JSON object", file=str(path))
        bad = _layout_problem(summary)
        if bad:
            raise InputError(f"summary.json does not have this tool's layout: {bad}", file=str(path))
        return cls(path, summary, manifest, cfg if isinstance(cfg, dict) else {})

    @property
    def run_id(self) -> str:
        return str(self.summary.get("run_id") or self.path.name)

    def findings(self) -> list[dict]:
        return list((self.summary.get("diagnosis") or {}).get("findings") or [])

    def row(self) -> dict[str, Any]:
        """The values of the ``sysid runs`` table."""
        f = self.findings()
        gain = (f[0].get("gain") or {}).get("relative") if f else None
        final = self.summary.get("final") or {}
        data = self.manifest.get("data")
        return {"name": self.config.get("name") or self.run_id.rsplit("-", 1)[0],
                "run_id": self.run_id,
                "data": Path(str(data)).name if data else None,
                "verdict": (self.summary.get("diagnosis") or {}).get("verdict"),
                "main_cause": f[0].get("family") if f else None,
                "gain": 100.0 * gain if isinstance(gain, (int, float)) else None,
                "val_fit": (final.get("validation") or {}).get("fit_percent"),
                "bic": final.get("bic"),
                "created": self.manifest.get("created")}

    def get(self, key: str) -> Any:
        """A table column, or a dotted path into summary.json (``diagnosis.verdict``), the config
        (``config.seed``), the manifest (``manifest.git.commit``) or the metrics (``metrics.final.bic``)."""
        row = self.row()
        if key in row:
            return row[key]
        for prefix, tree in (("config.", self.config), ("manifest.", self.manifest)):
            if key.startswith(prefix):
                return _lookup(tree, key[len(prefix):])
        if key.startswith("metrics."):
            return _lookup(dvc_metrics(self.summary), key[len("metrics."):])
        return _lookup(self.summary, key)


def _layout_problem(summary: dict) -> str | None:
    """What in ``summary`` is not shaped as the table and comparisons read it (a folder edited by hand
    or written by another tool), or None."""
    diag = summary.get("diagnosis")
    if diag is not None and not isinstance(diag, dict):
        return "diagnosis is not an object"
    findings = (diag or {}).get("findings")
    if findings is not None and (not isinstance(findings, list) or not all(isinstance(f, dict) for f in findings)):
        return "diagnosis.findings is not a list of objects"
    for f in findings or []:
        if f.get("gain") is not None and not isinstance(f["gain"], dict):
            return "a finding's gain is not an object"
    for block in ("nominal", "final"):
        b = summary.get(block)
        if b is not None and (not isinstance(b, dict) or not isinstance(b.get("validation") or {}, dict)
                              or not isinstance(b.get("params") or {}, dict)):
            return f"{block} is not an object with validation and params objects"
    if summary.get("models") is not None and not isinstance(summary["models"], list):
        return "models is not a list"
    return None


def _lookup(tree: Any, dotted: str) -> Any:
    cur = tree
    for part in dotted.split("."):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.isdigit() and int(part) < len(cur):
            cur = cur[int(part)]
        else:
            return None
    return cur


def list_runs(root: Path = DEFAULT_ROOT) -> list[RunInfo]:
    """Every complete run under ``root``; an unreadable folder, and one whose files were changed after
    the run wrote them (it carries the run marker but is no longer complete), is skipped with a warning
    on stderr (an independent probe found the second skipped silently)."""
    out: list[RunInfo] = []
    edited: list[Path] = []
    for p in iter_run_folders(Path(root), edited):
        try:
            out.append(RunInfo.load(p))
        except InputError as exc:
            print(f"warning: skipped {exc}", file=sys.stderr)
    for p in edited:
        print(f"warning: skipped {p}: its files changed after the run wrote them (a file edited, added or "
              "removed), so it is no longer this tool's run folder", file=sys.stderr)
    return out


# ------------------------------------------------------------------ filter and sort

_OPS: list[tuple[str, Callable[[Any, Any], bool]]] = [
    ("!=", operator.ne), (">=", operator.ge), ("<=", operator.le), ("=", operator.eq), (">", operator.gt),
    ("<", operator.lt)]


def _parse_where(expr: str) -> tuple[str, str, Callable[[Any, Any], bool], str]:
    for sym, fn in _OPS:
        if sym in expr:
            key, value = expr.split(sym, 1)
            key = key.strip()
            if not key:
                break
            return key, sym, fn, value.strip()
    raise InputError(f"expected KEY=VALUE (or KEY!=, >=, <=, >, <), got {expr!r}", key="--where")


def _coerce(value: str, like: Any) -> Any:
    if isinstance(like, bool):
        return value.lower() in ("1", "true", "yes")
    if isinstance(like, (int, float)):
        try:
            return float(value)
        except ValueError:
            raise InputError(f"{value!r} is not a number", key="--where") from None
    return value


def _known_keys(runs: list[RunInfo], key: str) -> bool:
    return any(r.get(key) is not None for r in runs)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _check_ordered(key: str, sym: str, value: str, values: list) -> None:
    """``> < >= <=`` compare numbers with a number, or text with text that is not a number (an ISO date
    with ``created``). Anything else is bad input: an independent probe found ``verdict>3`` and
    ``diagnosis>3`` (a mapping, compared as its text) matching every run, with exit 0."""
    for v in values:
        if v is None or isinstance(v, (int, float)) and not isinstance(v, bool):
            continue
        if isinstance(v, str) and not _is_number(value):
            continue
        what = {dict: "a dict (a mapping)", list: "a list", str: f"text ({v!r})"}.get(type(v), type(v).__name__)
        raise InputError(f"{key!r} is {what}, and {sym} compares a number with a number or text with text that "
                         f"is not a number (got {value!r}); use = or != for {key!r}"
                         + (", or a dotted path to one of its numbers (e.g. metrics.final.validation.rmse_sim)"
                            if isinstance(v, dict) else ""), key="--where")


def filter_runs(runs: list[RunInfo], wheres: list[str]) -> list[RunInfo]:
    """Runs matching every ``KEY=VALUE`` (numbers compare as numbers; ``!= >= <= > <`` too). A key that
    no run has is bad input (a typo would otherwise silently match nothing)."""
    out = list(runs)
    for w in wheres or []:
        key, sym, fn, value = _parse_where(w)
        if runs and not _known_keys(runs, key):
            raise InputError(f"no run has {key!r}; columns: {', '.join(COLUMNS)}, or a dotted path into "
                             "summary.json (e.g. diagnosis.verdict), config.*, manifest.*, metrics.*",
                             key="--where")
        if sym not in ("=", "!="):
            _check_ordered(key, sym, value, [r.get(key) for r in out])
        kept = []
        for r in out:
            v = r.get(key)
            if v is None:
                continue
            try:
                ok = fn(v, _coerce(value, v)) if sym in ("=", "!=") or isinstance(v, (int, float)) else \
                    fn(str(v), value)
            except TypeError:
                ok = False
            if ok:
                kept.append(r)
        out = kept
    return out


def sort_runs(runs: list[RunInfo], metric: str | None) -> list[RunInfo]:
    """Sort by a column or dotted path (``-bic`` for descending); runs without the value go last.
    Default: by creation time, then run id."""
    if not metric:
        return sorted(runs, key=lambda r: (str(r.get("created") or ""), r.run_id))
    desc = metric.startswith("-")
    key = metric.lstrip("-+")
    if runs and not _known_keys(runs, key):
        raise InputError(f"no run has {key!r}; columns: {', '.join(COLUMNS)} or a dotted path", key="--sort")
    have = [r for r in runs if r.get(key) is not None]
    missing = [r for r in runs if r.get(key) is None]

    def k(r):
        v = r.get(key)
        return (0, float(v), r.run_id) if isinstance(v, (int, float)) else (1, str(v), r.run_id)
    return sorted(have, key=k, reverse=desc) + missing


# ------------------------------------------------------------------ formatting

def fmt_value(v: Any, digits: int = 4) -> str:
    """Numbers to ``digits`` significant digits, None as ``–``."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}"
    return str(v)


def format_table(rows: list[dict[str, Any]], columns: dict[str, str]) -> str:
    """Plain-text table (left-aligned text, right-aligned numbers)."""
    cells = [[fmt_value(r.get(c)) for c in columns] for r in rows]
    heads = list(columns.values())
    widths = [max([len(h)] + [len(row[i]) for row in cells]) for i, h in enumerate(heads)]
    num = [all(isinstance(r.get(c), (int, float)) or r.get(c) is None for r in rows) for c in columns]

    def line(vals):
        return "  ".join(v.rjust(w) if n else v.ljust(w) for v, w, n in zip(vals, widths, num)).rstrip()
    out = [line(heads), line(["-" * w for w in widths])]
    out += [line(row) for row in cells]
    return "\n".join(out)


def runs_table(runs: list[RunInfo]) -> str:
    if not runs:
        return "no runs"
    return format_table([r.row() for r in runs], COLUMNS)


# ------------------------------------------------------------------ resolve and compare

def resolve(ref: str, root: Path = DEFAULT_ROOT) -> RunInfo:
    """A run by folder path, by run id under ``root``, or by a unique prefix of one."""
    p = Path(ref)
    if p.is_dir() and ((p / "summary.json").is_file() or (p / runfolder.MARKER).is_file()):
        # a hand-edited run folder says what the tool did not compute (`sysid runs` skips it too)
        why = runfolder.why_not_as_written(p)
        if why:
            raise InputError(f"{why}: its numbers are not this tool's; rerun its config", file=str(p))
        return RunInfo.load(p)
    runs = list_runs(root)
    exact = [r for r in runs if r.run_id == ref or r.path.name == ref]
    if len(exact) == 1:
        return exact[0]
    pref = [r for r in runs if r.run_id.startswith(ref) or r.path.name.startswith(ref)]
    if len(pref) == 1:
        return pref[0]
    if pref:
        # several folders can hold the same run id (the same config and data run twice into two folders):
        # then no longer prefix tells them apart, and the folder is what to give
        same = len({r.run_id for r in pref}) == 1
        listed = ", ".join(f"{r.run_id} in {r.path}" if same else r.run_id for r in pref[:5])
        raise InputError(f"{ref!r} matches {len(pref)} runs ({listed}); "
                         + ("give the run folder's path" if same else "give more of the run id or the run folder's path"),
                         key="RUN")
    if p.is_dir():
        raise InputError("is a folder but not a run folder (no summary.json); give a run folder or a run id "
                         "from `sysid runs`", file=str(p))
    raise InputError(f"no run {ref!r} under {root} (give a run folder or a run id from `sysid runs`)", key="RUN")


def _changed(a: dict, b: dict) -> list[dict]:
    fa, fb = flatten(a), flatten(b)
    rows = []
    for k in sorted(set(fa) | set(fb)):
        va, vb = fa.get(k), fb.get(k)
        if va != vb:
            row = {"key": k, "a": va, "b": vb}
            if isinstance(va, (int, float)) and isinstance(vb, (int, float)) and not isinstance(va, bool):
                row["delta"] = vb - va
            rows.append(row)
    return rows


def _finding_label(f: dict) -> str:
    where = f.get("equation") or f.get("output") or f.get("on") or ""
    term = f.get("term") or ""
    return f"{f.get('family')}" + (f" in {where}" if where else "") + (f" ({term})" if term else "")


def compare(a: RunInfo, b: RunInfo) -> dict[str, Any]:
    """What changed from run A to run B: config, data, parameters, findings, metrics."""
    sa, sb = a.summary, b.summary
    data = [{"key": k, "a": va, "b": vb} for k, va, vb in (
        ("data", a.manifest.get("data"), b.manifest.get("data")),
        ("data_sha256", sa.get("data_sha256"), sb.get("data_sha256")),
        ("n_samples", (sa.get("data") or {}).get("n_samples"), (sb.get("data") or {}).get("n_samples")))
        if va != vb]
    params = []
    for which in ("nominal", "final"):
        pa = (sa.get(which) or {}).get("params") or {}
        pb = (sb.get(which) or {}).get("params") or {}
        qa = (sa.get(which) or {}).get("param_std") or {}
        qb = (sb.get(which) or {}).get("param_std") or {}
        for n in sorted(set(pa) | set(pb)):
            row = {"key": f"{which}.{n}", "a": pa.get(n), "b": pb.get(n), "std_a": qa.get(n), "std_b": qb.get(n)}
            if isinstance(row["a"], (int, float)) and isinstance(row["b"], (int, float)):
                row["delta"] = row["b"] - row["a"]
            if row["a"] != row["b"]:
                params.append(row)
    la, lb = [_finding_label(f) for f in a.findings()], [_finding_label(f) for f in b.findings()]
    findings = {"a": la, "b": lb, "only_a": [x for x in la if x not in lb], "only_b": [x for x in lb if x not in la],
                "verdict": [sa.get("diagnosis", {}).get("verdict"), sb.get("diagnosis", {}).get("verdict")]}
    ma, mb = dvc_metrics(sa), dvc_metrics(sb)
    for m in (ma, mb):  # parameters are shown above
        for which in ("nominal", "final"):
            m.get(which, {}).pop("params", None)
            m.get(which, {}).pop("param_std", None)
    return {"a": a.run_id, "b": b.run_id, "config": _changed(a.config, b.config), "data": data,
            "parameters": params, "findings": findings, "metrics": _changed(ma, mb)}


def format_compare(c: dict[str, Any]) -> str:
    out = [f"A = {c['a']}", f"B = {c['b']}", ""]

    def section(title: str, rows: list[dict], cols: dict[str, str]):
        out.append(f"## {title}")
        out.append(format_table(rows, cols) if rows else "(no change)")
        out.append("")
    section("config", c["config"], {"key": "key", "a": "A", "b": "B"})
    section("data", c["data"], {"key": "key", "a": "A", "b": "B"})
    section("parameters", c["parameters"], {"key": "parameter", "a": "A", "std_a": "± A", "b": "B",
                                            "std_b": "± B", "delta": "B − A"})
    f = c["findings"]
    out.append("## findings")
    out.append(f"verdict: {f['verdict'][0]} -> {f['verdict'][1]}")
    out.append("A: " + (", ".join(f["a"]) or "none"))
    out.append("B: " + (", ".join(f["b"]) or "none"))
    if f["only_a"] or f["only_b"]:
        out.append("only in A: " + (", ".join(f["only_a"]) or "none") + "; only in B: " + (", ".join(f["only_b"]) or "none"))
    else:
        out.append("(same findings)")
    out.append("")
    section("metrics", c["metrics"], {"key": "metric", "a": "A", "b": "B", "delta": "B − A"})
    return "\n".join(out).rstrip() + "\n"
