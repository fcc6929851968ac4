"""Issue 10 benchmarks: report rendering time and HTML size (demo, Silverbox), and batch throughput
(runs per minute) for 20 demo-sized configs with 2 workers, local process pool vs Dask LocalCluster.

Rendering time is ``render_report`` alone (figures + template) on an analysed run, in this process,
best of ``repeat``; the analysis itself is benchmarked in the core section. Batch throughput is the
wall time of ``run_batch`` (worker start-up included) for 20 copies of the demo that differ in seed.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
SILVERBOX = ROOT.parent / "shared" / "datasets" / "silverbox" / "SNLS80mV.csv"


def _render(config: Path, repeat: int) -> tuple[float, int]:
    from ..config import load_config
    from ..report import render_report
    from ..runs import analyse
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(config))
        best, html = float("inf"), ""
        for _ in range(repeat):
            t0 = time.perf_counter()
            html = render_report(ctx)
            best = min(best, time.perf_counter() - t0)
    return best, len(html.encode("utf-8"))


def bench_render(quick: bool) -> list[str]:
    rows = []
    t, size = _render(ROOT / "configs" / "demo.yaml", 1 if quick else 2)
    rows.append(f"| report rendering, demo (3 000 samples) | {t:.2f} s | {size / 1024:.0f} KiB | – |")
    if not quick and SILVERBOX.exists():
        t, size = _render(ROOT / "configs" / "silverbox.yaml", 1)
        rows.append(f"| report rendering, Silverbox (131 072 samples) | {t:.2f} s | {size / 1024 / 1024:.2f} MiB | "
                    f"{'yes' if size < 5 * 1024 * 1024 else 'no'} (< 5 MB) |")
    return rows


def bench_batch(n: int) -> list[str]:
    from ..batch import run_batch
    base = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    base["data"]["path"] = str(ROOT / "data" / "demo.csv")
    rows = []
    with tempfile.TemporaryDirectory() as d:
        cfgs = []
        for i in range(n):
            c = dict(base, name=f"bench{i:02d}", seed=i)
            p = Path(d) / f"c{i:02d}.yaml"
            p.write_text(yaml.safe_dump(c))
            cfgs.append(str(p))
        for ex in ("local", "dask"):
            try:
                t0 = time.perf_counter()
                res = run_batch(cfgs, jobs=2, executor=ex, root=Path(d) / f"runs-{ex}")
                dt = time.perf_counter() - t0
            except Exception as exc:  # dask not installed
                rows.append(f"| batch, {n} demo configs, 2 workers, {ex} | not available: {exc} | – | – |")
                continue
            ok = sum(r.ok for r in res)
            rows.append(f"| batch, {n} demo configs, 2 workers, {ex} | {dt:.1f} s ({ok}/{n} ok) | "
                        f"{60 * n / dt:.1f} runs/min | – |")
    return rows


def run(quick: bool = False) -> str:
    rows = ["## Issue 10: report rendering and batch throughput", "",
            "| what | time | size / throughput | target met |", "|---|---|---|---|"]
    print("[bench] report rendering", file=sys.stderr, flush=True)
    rows += bench_render(quick)
    print("[bench] batch throughput", file=sys.stderr, flush=True)
    rows += bench_batch(4 if quick else 20)
    rows += ["", "Rendering: `render_report` only (figures, response band from 40 simulations, template), best of 2 "
             "(Silverbox: 1). Batch: `sysid batch` wall time including worker start-up; each demo run is the full "
             "`diagnose` (no HTML)."]
    return "\n".join(rows)
