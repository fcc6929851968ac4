"""Many runs: ``sysid batch CONFIG… [--jobs N] [--executor local|dask] [--scheduler ADDRESS]``.

Each config runs in its own worker (a spawned process pool by default; a Dask cluster with
``--executor dask``, a ``distributed.LocalCluster`` of ``--jobs`` single-threaded worker processes
unless ``--scheduler`` names a running scheduler, whose workers must see the same file system). A
config that fails does not stop the others: its error is kept and reported. Results come back in
the order the configs were given, whatever order they finish in; every run is the same deterministic
``analyse`` + ``write_run`` as ``sysid diagnose``, so the executor cannot change a ``summary.json``.

Other commands that run many pipeline runs (``sysid grade``) use the same executors through
:func:`run_tasks` (any picklable module-level callable over a list of items, results in input order)
and :func:`run_one` with ``name`` (the run folder's name under ``root`` instead of the run id).
"""

from __future__ import annotations

import contextlib
import io
import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from functools import partial
from pathlib import Path
from typing import Any

from . import progress, runfolder
from .errors import InputError

EXECUTORS = ("local", "dask")


@dataclass
class BatchResult:
    """One config's outcome: the run folder, or the error (``kind``: "input" = bad input, exit 2;
    "internal" = a bug, exit 1)."""

    config: str
    ok: bool
    path: str | None = None
    run_id: str | None = None
    error: str | None = None
    kind: str | None = None
    seconds: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)


def run_one(config: str, root: str, html: bool = False, name: str | None = None) -> BatchResult:
    """Run one config into ``root/<run-id>`` (``root/<name>`` when ``name`` is given); never raises
    (the error is returned). The pipeline's console lines are captured (a batch prints its own
    progress)."""
    t0 = time.perf_counter()
    os.environ.setdefault("MPLBACKEND", "Agg")
    from .config import load_config
    from .runs import analyse, write_run
    buf = io.StringIO()
    try:
        with contextlib.redirect_stderr(buf), progress.silenced():
            lc = load_config(config)
            ctx = analyse(lc)
            path = write_run(ctx, Path(root) / (name or ctx.run_id), html=html)
        return BatchResult(config, True, str(path), ctx.run_id, seconds=time.perf_counter() - t0)
    except InputError as exc:
        return BatchResult(config, False, error=str(exc), kind="input", seconds=time.perf_counter() - t0)
    except Exception as exc:  # a bug in one config's run must not stop the batch
        tb = traceback.format_exc(limit=3).strip().splitlines()[-1]
        return BatchResult(config, False, error=f"internal error: {type(exc).__name__}: {exc} ({tb})",
                           kind="internal", seconds=time.perf_counter() - t0)


def _unique(configs: list[str]) -> list[str]:
    out, seen = [], set()
    for c in configs:
        k = os.path.realpath(c)
        if k not in seen:
            seen.add(k)
            out.append(c)
    return out


def check_options(jobs: int, executor: str, scheduler: str | None) -> None:
    """InputError (exit 2) for an unknown executor, ``jobs < 1`` or a scheduler without Dask."""
    if executor not in EXECUTORS:
        raise InputError(f"unknown executor {executor!r}; expected one of {', '.join(EXECUTORS)}", key="--executor")
    if jobs < 1:
        raise InputError(f"expected --jobs >= 1, got {jobs}", key="--jobs")
    if scheduler and executor != "dask":
        raise InputError("--scheduler needs --executor dask", key="--scheduler")


def iter_results(fn: Callable[[Any], Any], items: Sequence, *, jobs: int = 2, executor: str = "local",
                 scheduler: str | None = None) -> Iterator[tuple[int, Any]]:
    """``(index, fn(item))`` as the items finish: in this process for ``jobs == 1``, else a spawned
    process pool of ``jobs`` workers, or Dask. ``fn`` must be picklable (module level, or a
    ``functools.partial`` of one) and should return its errors rather than raise."""
    check_options(jobs, executor, scheduler)
    items = list(items)
    if not items:
        return
    if executor == "dask":
        yield from _dask(fn, items, jobs, scheduler)
    elif jobs == 1:
        for i, item in enumerate(items):
            yield i, fn(item)
    else:
        yield from _pool(fn, items, jobs)


def run_tasks(fn: Callable[[Any], Any], items: Sequence, *, jobs: int = 2, executor: str = "local",
              scheduler: str | None = None) -> list:
    """``[fn(item) for item in items]`` on the batch executors (see :func:`iter_results`), in input order."""
    items = list(items)
    results = dict(iter_results(fn, items, jobs=jobs, executor=executor, scheduler=scheduler))
    return [results[i] for i in range(len(items))]


def run_batch(configs: list[str], *, jobs: int = 2, executor: str = "local", scheduler: str | None = None,
              root: str | Path = "reports", html: bool = False) -> list[BatchResult]:
    """Run every config; results in input order. ``jobs`` workers (local pool or LocalCluster)."""
    check_options(jobs, executor, scheduler)
    if not configs:
        raise InputError("no config given", key="CONFIG")
    configs = [os.path.abspath(c) for c in _unique(configs)]
    root = str(runfolder.check_new_path(root, key="--root", folder=True))
    made = [p for p in [Path(root), *Path(root).parents] if not os.path.lexists(p)]   # created below
    try:
        Path(root).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{root}: cannot create the folder: {exc.strerror}", key="--root") from None
    results: dict[int, BatchResult] = {}
    fn = partial(run_one, root=root, html=html)
    with progress.stage("batch", total=len(configs)):
        it = iter_results(fn, configs, jobs=jobs, executor=executor, scheduler=scheduler)
        for i, res in progress.bar(it, len(configs), "runs"):
            results[i] = res
            name = Path(res.config).name
            progress.emit(f"[batch] {'ok' if res.ok else 'FAILED'} {name}"
                          + (f" -> {res.path} ({res.seconds:.1f} s)" if res.ok else f": {res.error}"))
    if made and not any(r.ok for r in results.values()):
        # every config failed: the folders this call created hold nothing (rmdir removes only an empty
        # folder, so nothing another process put there meanwhile is touched)
        with contextlib.suppress(OSError):
            for p in made:
                os.rmdir(p)
    return [results[i] for i in range(len(configs))]


def _pool(fn, items, jobs):
    with ProcessPoolExecutor(max_workers=min(jobs, len(items)), mp_context=get_context("spawn")) as ex:
        futs = {ex.submit(fn, item): i for i, item in enumerate(items)}
        for f in as_completed(futs):
            yield futs[f], f.result()


def _dask(fn, items, jobs, scheduler):
    try:
        from dask.distributed import Client, LocalCluster
        from dask.distributed import as_completed as d_as_completed
    except ImportError:
        raise InputError("the Dask executor needs the optional extra: pip install -e '.[dask]'",
                         key="--executor") from None
    cluster = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise InputError(f"cannot reach the Dask scheduler at {scheduler!r} ({exc})", key="--scheduler") from None
        else:
            cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        with client:
            futs = client.map(fn, items, pure=False)
            index = {f.key: i for i, f in enumerate(futs)}
            for f in d_as_completed(futs):
                yield index[f.key], f.result()
    finally:
        if cluster is not None:
            cluster.close()


def exit_code(results: list[BatchResult]) -> int:
    """0 all ran; 2 some config was bad input; 1 some run hit an internal error."""
    if any(r.kind == "internal" for r in results):
        return 1
    return 2 if any(not r.ok for r in results) else 0
