"""The instructor's summary page: one self-contained HTML file (Jinja2 with autoescape, the figure
embedded as a PNG data URI, no external resources): the distribution of scores, which causes the class
found or missed (per hidden family), and a table with a link to each student's run report."""

from __future__ import annotations

import base64
import io
import os
from collections import Counter
from pathlib import Path

from jinja2 import Environment

FIRST_LINE = "<!DOCTYPE html><!-- written by sysid grade -->"

_PAGE = FIRST_LINE + """
<html lang="en"><head><meta charset="utf-8"><title>{{ assignment }}: grading summary</title>
<style>
body{font-family:sans-serif;margin:2em;max-width:75em} table{border-collapse:collapse;font-size:90%}
td,th{border:1px solid #ccc;padding:.25em .5em;text-align:left} th{background:#f3f3f3}
.bad{color:#a00} .num{text-align:right}
</style></head><body>
<h1>Assignment {{ assignment }}: grading summary</h1>
<p>{{ n }} students: {% for k, v in status %}{{ v }} {{ k }}{% if not loop.last %}, {% endif %}{% endfor %}.
Mean score of the graded submissions: {{ mean }}; median {{ median }}.</p>
<img alt="score distribution and causes found or missed" src="data:image/png;base64,{{ figure }}">
<h2>Causes found or missed</h2>
<table><tr><th>hidden cause</th><th>students</th><th>named correctly</th><th>named wrongly</th><th>not graded</th></tr>
{% for f in families %}<tr><td>{{ f.family }}</td><td class="num">{{ f.total }}</td><td class="num">{{ f.found }}</td>
<td class="num">{{ f.missed }}</td><td class="num">{{ f.ungraded }}</td></tr>
{% endfor %}</table>
<h2>Students</h2>
<table><tr><th>id</th><th>name</th><th>status</th><th>hidden cause</th><th>claimed cause</th><th>score</th>
<th>held-out gain</th><th>claimed gain reproduces</th><th>data as issued</th><th>run report</th><th>reason</th></tr>
{% for r in rows %}<tr><td>{{ r.student_id }}</td><td>{{ r.name }}</td>
<td{% if r.status != 'graded' %} class="bad"{% endif %}>{{ r.status }}</td><td>{{ r.cause_key }}</td>
<td>{{ r.cause_claimed }}</td><td class="num">{{ r.score }}</td><td class="num">{{ r.heldout_gain }}</td>
<td>{{ r.gain_reproduces }}</td><td{% if r.data_issued == 'no' %} class="bad"{% endif %}>{{ r.data_issued }}</td>
<td>{% if r.link %}<a href="{{ r.link }}">{{ r.run_id }}</a>{% else %}–{% endif %}</td><td>{{ r.reason }}</td></tr>
{% endfor %}</table>
<p>Score: rubric of the template (pipeline/assignment/rubric.py); every number is measured by re-running the
submission, none is taken from the student's answer.</p>
</body></html>
"""


def _figure(scores: list[float], families: list[dict]) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.4))
    a1.hist(scores, bins=[0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100.0001], color="tab:blue", edgecolor="k")
    a1.set_xlabel("score")
    a1.set_ylabel("students")
    a1.set_title("score distribution (graded submissions)")
    names = [f["family"] for f in families]
    x = range(len(names))
    found = [f["found"] for f in families]
    missed = [f["missed"] for f in families]
    ungraded = [f["ungraded"] for f in families]
    a2.bar(x, found, color="tab:green", label="named correctly")
    a2.bar(x, missed, bottom=found, color="tab:red", label="named wrongly")
    a2.bar(x, ungraded, bottom=[a + b for a, b in zip(found, missed)], color="0.7", label="not graded")
    a2.set_xticks(list(x), names, rotation=20, ha="right", fontsize=8)
    a2.set_ylabel("students")
    a2.set_title("hidden causes found or missed")
    a2.legend(fontsize=7)
    from matplotlib.ticker import MaxNLocator
    for ax in (a1, a2):
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylim(0, max(ax.get_ylim()[1], 1) * 1.15)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def render_summary(assignment: str, rows: list[dict], page: Path, runs_dir: Path | None) -> str:
    """The HTML page; links to ``runs_dir/<id>/report.html`` relative to ``page``'s folder."""
    fams: dict[str, Counter] = {}
    for r in rows:
        c = fams.setdefault(r["cause_key"], Counter())
        c["total"] += 1
        if r["status"] != "graded":
            c["ungraded"] += 1
        elif r["cause_correct"] == "yes":
            c["found"] += 1
        else:
            c["missed"] += 1
    families = [{"family": f, "total": c["total"], "found": c["found"], "missed": c["missed"],
                 "ungraded": c["ungraded"]} for f, c in sorted(fams.items())]
    scores = sorted(float(r["score"]) for r in rows if r["status"] == "graded")
    view = []
    for r in rows:
        link = None
        if runs_dir is not None and r["run_id"]:
            rep = runs_dir / r["student_id"] / "report.html"
            if rep.is_file():
                link = Path(os.path.relpath(rep, page.parent)).as_posix()
        view.append(dict(r, link=link))
    status = sorted(Counter(r["status"] for r in rows).items())
    med = "–"
    if scores:
        k = len(scores)
        med = f"{(scores[(k - 1) // 2] + scores[k // 2]) / 2:.1f}"
    env = Environment(autoescape=True)
    return env.from_string(_PAGE).render(
        assignment=assignment, n=len(rows), status=status, rows=view, families=families,
        mean=f"{sum(scores) / len(scores):.1f}" if scores else "–", median=med,
        figure=_figure(scores, families))
