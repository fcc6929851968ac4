"""Issue 11 benchmark: generate and grade a class of 30 (wall time; target under 3 minutes).

Both commands run as CLI subprocesses (interpreter start and imports included), grading with
``--jobs 2`` (the machine's two cores). The class between them is a realistic mix, written untimed:
24 students hand in the reference extension of their own hidden effect with the gain the pipeline's
report of their starter config states, 3 name a wrong cause, 1 changes a sample of the data file, 1
hands in nothing and 1 an answer with an unknown cause.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import sys
import tempfile
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import yaml

from .core import ROOT, _timed

TEMPLATE = ROOT / "configs" / "assignment" / "template.yaml"


def _starter_gain(config: str) -> float:
    from ..config import load_config
    from ..runs import analyse
    with contextlib.redirect_stderr(io.StringIO()):
        f = analyse(load_config(config)).summary["diagnosis"]["findings"]
    return float(f[0]["gain"]["relative"]) if f else 0.0


def _submissions(klass: Path, subs: Path) -> None:
    from ..assignment.solution import extend_config
    key = json.loads((klass / "key.json").read_text())
    students = key["students"]
    with ProcessPoolExecutor(2) as ex:
        gains = list(ex.map(_starter_gain, [str(klass / "students" / s["id"] / "config.yaml") for s in students]))
    fams = list(key["template"]["families"])
    for i, (s, gain) in enumerate(zip(students, gains)):
        if i == 28:
            continue                                             # hands in nothing
        d = subs / s["id"]
        shutil.copytree(klass / "students" / s["id"], d)
        fam = s["family"] if i < 24 or i >= 27 else next(f for f in fams if f != s["family"])
        starter = yaml.safe_load((d / "config.yaml").read_text())
        cfg, p = extend_config(starter, key["template"]["system"], fam, s["parameters"].get("frequency_hz", 1.0),
                               delay_s=s["parameters"].get("delay_s", 0.0))
        (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
        answer = {"cause": "friction" if i == 29 else fam, "parameter": p, "claimed_gain": gain}
        (d / "answer.yaml").write_text(yaml.safe_dump(answer))
        if i == 27:
            lines = (d / "record.csv").read_text().splitlines()
            t, u, x = lines[50].split(",")
            lines[50] = f"{t},{u},{float(x) + 0.01!r}"
            (d / "record.csv").write_text("\n".join(lines) + "\n")


def run(quick: bool = False) -> str:
    n = 6 if quick else 30
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        roster = d / "roster.csv"
        roster.write_text("id,name\n" + "".join(f"st{i + 1:02d},Student {i + 1}\n" for i in range(n)))
        env = dict(os.environ, MPLBACKEND="Agg")
        print(f"[bench] assignment make, {n} students", file=sys.stderr, flush=True)
        mk = _timed([sys.executable, "-m", "pipeline", "assignment", "make", "--roster", str(roster),
                     "--template", str(TEMPLATE), "--out", str(d / "class")], env)
        if mk["rc"] != 0:
            return f"## Issue 11: assignments\n\nassignment make failed: {mk['stderr']}"
        print("[bench] writing the class's submissions (untimed)", file=sys.stderr, flush=True)
        subs = d / "subs"
        subs.mkdir()
        if n == 30:
            _submissions(d / "class", subs)
        else:
            for s in json.loads((d / "class" / "key.json").read_text())["students"]:
                shutil.copytree(d / "class" / "students" / s["id"], subs / s["id"])
        print("[bench] grade --jobs 2", file=sys.stderr, flush=True)
        gr = _timed([sys.executable, "-m", "pipeline", "grade", "--key", str(d / "class" / "key.json"),
                     "--submissions", str(subs), "--out", str(d / "out" / "gradebook.csv"), "--jobs", "2"], env)
        if gr["rc"] != 0:
            return f"## Issue 11: assignments\n\ngrade failed: {gr['stderr']}"
        rows = list(csv.DictReader((d / "out" / "gradebook.csv").open()))
    total = mk["seconds"] + gr["seconds"]
    status = ", ".join(f"{v} {k}" for k, v in sorted(Counter(r["status"] for r in rows).items()))
    scores = Counter(r["score"] for r in rows)
    lines = ["## Issue 11: generating and grading an assignment", "",
             f"Template `configs/assignment/template.yaml` (mass-spring-damper, 3000 issued + 1500 held-out "
             f"samples per student), {n} students; the class as described in `pipeline/bench/assignment.py`. "
             f"Load average at start (1/5/15 min): {load} on {os.cpu_count()} cores.", "",
             "| what | measured | target | met |", "|---|---|---|---|",
             f"| `sysid assignment make`, {n} students | {mk['seconds']:.1f} s | – | – |",
             f"| `sysid grade --jobs 2` ({status}; run folder with report per graded submission) | "
             f"{gr['seconds']:.1f} s, {gr['maxrss_mb']:.0f} MB peak | – | – |",
             f"| generate + grade | {total:.1f} s | < 180 s | {'yes' if total < 180 else 'no'} |", "",
             "Scores (score: students): " + ", ".join(f"{k}: {v}" for k, v in
                                                        sorted(scores.items(), key=lambda kv: -float(kv[0]))) + "."]
    return "\n".join(lines)
