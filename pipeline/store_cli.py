"""CLI commands of the run store, tracking and batches (registered via ``cli.COMMAND_MODULES``):

* ``sysid runs [--root DIR] [--where KEY=VALUE]… [--sort [-]METRIC] [--json]``
* ``sysid compare RUN_A RUN_B [--root DIR] [--json]``
* ``sysid batch CONFIG… [--jobs N] [--executor local|dask] [--scheduler ADDRESS] [--root DIR] [--html]
  [--track [URI]]``
* ``sysid track RUN… [--uri URI] [--experiment NAME]`` (log existing run folders to MLflow)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import store
from .errors import InputError


def register(sub) -> dict:
    p = sub.add_parser("runs", help="list the run folders: name, data, verdict, main cause, gain, fit, BIC")
    p.add_argument("--root", default=str(store.DEFAULT_ROOT), help="folder holding the run folders (default reports)")
    p.add_argument("--where", action="append", default=[], metavar="KEY=VALUE",
                   help="keep runs where KEY (a column or a dotted summary.json path) = VALUE; also != >= <= > <")
    p.add_argument("--sort", metavar="METRIC", help="sort by a column or dotted path (--sort=-bic: descending)")
    p.add_argument("--desc", action="store_true", help="sort descending")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    p = sub.add_parser("compare", help="what changed between two runs: config, data, parameters, findings, metrics")
    p.add_argument("run_a", metavar="RUN_A", help="run folder, run id or unique prefix")
    p.add_argument("run_b", metavar="RUN_B")
    p.add_argument("--root", default=str(store.DEFAULT_ROOT))
    p.add_argument("--json", action="store_true")
    p = sub.add_parser("batch", help="run many configs (process pool or Dask); failures are reported, not fatal")
    p.add_argument("configs", nargs="+", metavar="CONFIG")
    p.add_argument("--jobs", type=int, default=2, help="parallel workers (default 2)")
    p.add_argument("--executor", default="local", choices=["local", "dask"])
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler address (default: a LocalCluster)")
    p.add_argument("--root", default=str(store.DEFAULT_ROOT), help="where the run folders go (default reports)")
    p.add_argument("--html", action="store_true", help="also write report.html in each run folder")
    p.add_argument("--track", nargs="?", const="default", metavar="URI",
                   help="log each run to MLflow (default sqlite:///reports/mlruns.db)")
    p = sub.add_parser("track", help="log run folders to MLflow (extra [mlflow])")
    p.add_argument("runs", nargs="+", metavar="RUN", help="run folder, run id or unique prefix")
    p.add_argument("--root", default=str(store.DEFAULT_ROOT))
    p.add_argument("--uri", default=None, help="tracking URI (default sqlite:///reports/mlruns.db)")
    p.add_argument("--experiment", default="sysid")
    return {"runs": cmd_runs, "compare": cmd_compare, "batch": cmd_batch, "track": cmd_track}


def _existing_root(root: str) -> Path:
    """--root of a command that reads run folders: an existing folder (a typo listed "no runs")."""
    p = Path(root)
    if not p.is_dir():
        raise InputError(f"{root}: {'is not a folder' if p.exists() else 'no such folder'}; expected the folder "
                         "holding the run folders", key="--root")
    return p


def cmd_runs(a: argparse.Namespace) -> int:
    key = ("-" + a.sort.lstrip("-") if a.desc else a.sort) if a.sort else None
    if a.root != str(store.DEFAULT_ROOT):
        _existing_root(a.root)
    runs = store.sort_runs(store.filter_runs(store.list_runs(Path(a.root)), a.where), key)
    if a.json:
        print(json.dumps([r.row() | {"path": str(r.path)} for r in runs], indent=2))
    else:
        print(store.runs_table(runs))
    return 0


def cmd_compare(a: argparse.Namespace) -> int:
    ra, rb = store.resolve(a.run_a, Path(a.root)), store.resolve(a.run_b, Path(a.root))
    c = store.compare(ra, rb)
    print(json.dumps(c, indent=2, default=str) if a.json else store.format_compare(c), end="" if not a.json else "\n")
    return 0


def cmd_track(a: argparse.Namespace) -> int:
    from .tracking.mlflow_backend import log_run, read_run, resolve_uri
    uri = resolve_uri(a.uri)
    runs = [store.resolve(ref, Path(a.root)) for ref in a.runs]
    for r in runs:              # every folder readable before any is logged: nothing half-logged
        read_run(Path(r.path))
    for r in runs:
        rid = log_run(r.path, uri, a.experiment)
        print(f"{r.run_id}: MLflow run {rid} in {uri}")
    return 0


def cmd_batch(a: argparse.Namespace) -> int:
    from .batch import exit_code, run_batch
    if a.track:
        from .tracking.mlflow_backend import check_tracking
        check_tracking(a.track, key="--track")
    results = run_batch(a.configs, jobs=a.jobs, executor=a.executor, scheduler=a.scheduler, root=a.root,
                        html=a.html)
    # configs with the same content and data are one run (one run id, one folder): listed and tracked once
    first: dict[str, str] = {}
    for r in results:
        if r.ok:
            first.setdefault(r.path, r.config)
    ran = [r for r in results if r.ok]
    folders = [r for r in ran if first[r.path] == r.config]
    if a.track:
        from .tracking.mlflow_backend import log_run, resolve_uri
        uri = resolve_uri(a.track)
        for r in folders:
            log_run(r.path, uri)
        print(f"tracked {len(folders)} runs in {uri}")
    print(store.runs_table([store.RunInfo.load(Path(r.path)) for r in folders]))
    for r in ran:
        if first[r.path] != r.config:
            print(f"note: {r.config} is the same run as {first[r.path]} (the same config and data): one run "
                  f"folder, {r.path}", file=sys.stderr)
    failed = [r for r in results if not r.ok]
    for r in failed:
        print(f"error: {r.error}" if r.config in (r.error or "") else f"error: {r.config}: {r.error}",
              file=sys.stderr)
    print(f"{len(ran)} of {len(results)} configs ran" + (f" ({len(folders)} run folder{'s' * (len(folders) != 1)})" if len(folders) < len(ran) else "")
          + (f"; {len(failed)} failed" if failed else ""))
    return exit_code(results)
