"""Run every benchmark section and write BENCHMARKS.md (``--quick`` for a smoke run)."""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import sys
import time
from pathlib import Path

SECTIONS = ["pipeline.bench.core", "pipeline.bench.estimators", "pipeline.bench.structures",
            "pipeline.bench.assignment", "pipeline.bench.report"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke run, numbers not meaningful)")
    ap.add_argument("--out", default="BENCHMARKS.md")
    ap.add_argument("--only", nargs="*", help="module names to run (e.g. core)")
    a = ap.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    parts = ["# Benchmarks\n",
             f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
             f"{platform.platform()}. Command: `make bench` (`python -m pipeline.bench`). "
             f"Run on {time.strftime('%Y-%m-%d')}.\n"]
    for name in SECTIONS:
        short = name.rsplit(".", 1)[1]
        if a.only and short not in a.only:
            continue
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            parts.append(f"\n## {short}\n\nnot available: {exc}\n")
            continue
        print(f"[bench] {short} ...", file=sys.stderr, flush=True)
        parts.append("\n" + mod.run(quick=a.quick).strip() + "\n")
    out = Path(a.out)
    # keep the section of `make bench-diagnosis` (pipeline.bench.diagnosis), which runs separately
    from .diagnosis import END, START
    old = out.read_text() if out.exists() else ""
    if a.only and old:
        # replace only the sections that ran (by their "## " heading); every other section stays
        text = old
        for part in parts[2:]:
            part = part.strip()
            head = part.splitlines()[0]
            if head in text:
                i = text.index(head)
                ends = [j for j in (text.find("\n## ", i + len(head)), text.find(START, i + len(head))) if j >= 0]
                j = min(ends) if ends else len(text)
                text = text[:i] + part + "\n" + text[j:]
            else:
                text = text.rstrip() + "\n\n" + part + "\n"
        out.write_text(text)
        print(f"updated {', '.join(a.only)} in {a.out}")
        return 0
    if START in old and END in old:
        parts.append("\n" + old[old.index(START):old.index(END) + len(END)] + "\n")
    out.write_text("\n".join(parts))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
