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


# a section's hand-written history goes below this line; a re-run of the section keeps it
NOTES = "<!-- notes: written by hand, kept when this section is re-run -->"


def _section_span(text: str, head: str, start_mark: str) -> tuple[int, int] | None:
    """[i, j) of the section whose first line is ``head``: up to the next "## " heading or the
    diagnosis bench's start marker."""
    if head not in text:
        return None
    i = text.index(head)
    ends = [j for j in (text.find("\n## ", i + len(head)), text.find(start_mark, i + len(head))) if j >= 0]
    return i, (min(ends) if ends else len(text))


def with_notes(old: str, part: str, start_mark: str) -> str:
    """``part`` (a freshly generated section) followed by the hand-written notes of the same section in
    ``old``, from its :data:`NOTES` line on (nothing when it has none)."""
    part = part.strip()
    span = _section_span(old, part.splitlines()[0], start_mark)
    if span is None:
        return part
    sec = old[span[0]:span[1]]
    return part if NOTES not in sec else part + "\n\n" + sec[sec.index(NOTES):].rstrip()


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
    parts = parts[:2] + ["\n" + with_notes(old, part, START) + "\n" for part in parts[2:]]
    if a.only and old:
        # replace only the sections that ran (by their "## " heading); every other section stays
        text = old
        for part in parts[2:]:
            part = part.strip()
            span = _section_span(text, part.splitlines()[0], START)
            if span is not None:
                text = text[:span[0]] + part + "\n" + text[span[1]:]
            else:
                text = text.rstrip() + "\n\n" + part + "\n"
        out.write_text(text)
        print(f"updated {', '.join(a.only)} in {a.out}")
        return 0
    if START in old and END in old:
        # with the text written below its end marker (the held-out seeds' tables), up to the next section
        j = old.find("\n## ", old.index(END))
        parts.append("\n" + old[old.index(START):j if j >= 0 else len(old)].rstrip() + "\n")
    out.write_text("\n".join(parts))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
