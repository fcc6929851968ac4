"""Commands ``sysid assignment make`` and ``sysid grade`` (registered via ``pipeline.cli.COMMAND_MODULES``).

``sysid assignment make --roster roster.csv --template T.yaml --out DIR [--seed S]``
``sysid grade --key DIR/key.json --submissions SUBS [--out gradebook.csv] [--jobs N] [--executor local|dask]
[--runs DIR] [--html PAGE]``

The submissions run on the executors of ``sysid batch`` (:mod:`pipeline.batch`).

The instructor's own bad input (roster, template, key, options) raises InputError: exit 2, one line.
Bad submissions are rows of the gradebook with the reason.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from ..errors import InputError


def _make(args: argparse.Namespace) -> int:
    from .make import make_assignment
    key = make_assignment(args.roster, args.template, args.out, seed=args.seed)
    print(f"key: {key}\nstudent folders: {Path(args.out) / 'students'} (hand out each <id>/ folder)")
    return 0


def _grade(args: argparse.Namespace) -> int:
    from .grade import HEADER, check_writable, grade, gradebook_csv, write_tracked
    from .summary import FIRST_LINE, render_summary
    from ..runfolder import check_new_path
    if args.jobs < 1:
        raise InputError(f"expected a positive number of parallel workers, got {args.jobs}", key="--jobs")
    out = Path(args.out)
    runs = Path(args.runs) if args.runs else out.parent / "runs"
    page = Path(args.html) if args.html else out.parent / "summary.html"
    # where the results go, checked before any submission runs (a /proc path failed after grading)
    check_new_path(out, key="--out", folder=False)
    check_new_path(page, key="--html", folder=False)
    check_new_path(runs, key="--runs" if args.runs else "--out (its runs/ folder)", folder=True)
    if out.resolve() == page.resolve():
        raise InputError("the gradebook and the summary page must be different files", key="--html")
    check_writable(out, HEADER, "--out")
    check_writable(page, FIRST_LINE, "--html")
    key, rows = grade(args.key, args.submissions, jobs=args.jobs, executor=args.executor, runs_dir=runs)
    book, html = gradebook_csv(rows), render_summary(key.assignment, rows, page, runs)
    # again: grading takes minutes, and the instructor may have opened and saved a file meanwhile
    check_writable(out, HEADER, "--out")
    check_writable(page, FIRST_LINE, "--html")
    write_tracked(out, book)
    write_tracked(page, html)
    known = {r["student_id"] for r in rows}
    # the results' own runs/ folder may sit among the submissions (grade --submissions . --out gb.csv):
    # it is not a submission the key lacks
    extra = sorted(p.name for p in Path(args.submissions).iterdir()
                   if p.is_dir() and p.name not in known and p.resolve() != runs.resolve())
    if extra:
        print(f"note: folders not in the key, not graded: {', '.join(extra)}", file=sys.stderr)
    counts = ", ".join(f"{v} {k}" for k, v in sorted(Counter(r["status"] for r in rows).items()))
    print(f"gradebook: {out} ({len(rows)} students: {counts})\nsummary: {page}\nrun reports: {runs}")
    return 0


def _assignment(args: argparse.Namespace) -> int:
    return {"make": _make}[args.assignment_cmd](args)


def register(subparsers) -> dict:
    p = subparsers.add_parser("assignment", help="generate an assignment: one record per student and a key")
    sub = p.add_subparsers(dest="assignment_cmd", required=True)
    m = sub.add_parser("make", help="records, starter configs and key.json from a roster and a template")
    m.add_argument("--roster", required=True, help="CSV with columns id, name[, email]")
    m.add_argument("--template", required=True, help="assignment template YAML (see configs/assignment/)")
    m.add_argument("--out", required=True, help="folder to create (key.json, instructor/, students/)")
    m.add_argument("--seed", type=int, default=None, help="assignment seed (default: the template's seed)")
    g = subparsers.add_parser("grade", help="re-run every submission and write the gradebook")
    g.add_argument("--key", required=True, help="key.json written by `sysid assignment make`")
    g.add_argument("--submissions", required=True, help="folder with one <student id>/ folder per submission")
    g.add_argument("--out", default="gradebook.csv", help="gradebook CSV (default gradebook.csv)")
    g.add_argument("--jobs", type=int, default=1, help="submissions graded in parallel (default 1)")
    g.add_argument("--executor", default="local", help="local (process pool, default) or dask (a Dask "
                   "LocalCluster of --jobs workers; needs the [dask] extra), as in sysid batch")
    g.add_argument("--runs", default=None, help="folder for the run folders (default: runs/ beside --out)")
    g.add_argument("--html", default=None, help="summary page (default: summary.html beside --out)")
    return {"assignment": _assignment, "grade": _grade}
