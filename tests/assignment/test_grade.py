"""sysid grade: full marks for the right cause with a good model, not for a wrong cause; a tampered data
file and a false claimed gain are flagged; missing/broken submissions are rows with the reason; the
gradebook is byte-identical across runs and --jobs; the instructor's bad input exits 2."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import pytest
import yaml

from pipeline.assignment.grade import HEADER, Task, grade_one, load_key
from pipeline.cli import main

from .conftest import write_submission


@pytest.fixture(scope="session")
def graded(klass, submissions, tmp_path_factory):
    """The CLI run twice: --jobs 1 and --jobs 2 into different folders."""
    out, _ = klass
    subs, _ = submissions
    res = {}
    for jobs in (1, 2):
        d = tmp_path_factory.mktemp(f"grade{jobs}")
        rc = main(["grade", "--key", str(out / "key.json"), "--submissions", str(subs), "--out",
                   str(d / "gradebook.csv"), "--jobs", str(jobs)])
        assert rc == 0
        res[jobs] = d
    return res


def _rows(d: Path) -> dict[str, dict]:
    return {r["student_id"]: r for r in csv.DictReader(io.StringIO((d / "gradebook.csv").read_text()))}


def test_gradebook_byte_identical_across_runs_and_jobs(graded):
    a, b = (graded[1] / "gradebook.csv").read_bytes(), (graded[2] / "gradebook.csv").read_bytes()
    assert a == b
    text = a.decode()
    assert text.splitlines()[0] == HEADER and len(text.splitlines()) == 6
    assert "/tmp" not in text and str(Path.home()) not in text
    assert [r["student_id"] for r in csv.DictReader(io.StringIO(text))] == ["s01", "s02", "s03", "s04", "s05"]


def test_right_cause_with_a_good_model_scores_full_marks(graded, klass):
    _, key = klass
    r = _rows(graded[1])["s01"]
    st = next(s for s in key["students"] if s["id"] == "s01")
    assert r["status"] == "graded" and r["cause_correct"] == "yes" and r["data_issued"] == "yes"
    assert r["gain_reproduces"] == "yes" and r["reason"] == ""
    assert float(r["score"]) == 100.0
    assert float(r["parameter_rel_error"]) < 0.05
    # the correct model's free-run error on the held-out part is the measurement noise (the key's std)
    assert float(r["heldout_rmse"]) == pytest.approx(st["noise_std"], rel=0.15)
    assert float(r["heldout_rmse_nominal"]) > 2 * float(r["heldout_rmse"])
    assert r["run_id"].startswith("msd-lab-s01-")
    summary = json.loads((graded[1] / "runs" / "s01" / "summary.json").read_text())
    assert summary["run_id"] == r["run_id"] and summary["data_sha256"] == st["data_sha256"]


def test_wrong_cause_does_not_score_full_marks(graded):
    r = _rows(graded[1])["s02"]
    assert r["status"] == "graded" and r["cause_correct"] == "no" and r["cause_claimed"] != r["cause_key"]
    assert float(r["score"]) <= 40.0      # cause (40) and parameter (20) lost, gain claim (10) not reproduced


def test_tampered_data_file_is_detected_by_its_hash(graded):
    r = _rows(graded[1])["s03"]
    assert r["status"] == "graded" and r["data_issued"] == "no"
    assert float(r["score"]) == 0.0 and "sha256" in r["reason"]


def test_false_claimed_gain_is_flagged(graded):
    r = _rows(graded[1])["s04"]
    assert r["cause_correct"] == "yes" and r["gain_reproduces"] == "no"
    assert abs(float(r["claimed_gain"]) - float(r["measured_gain"])) > 0.25
    assert "does not reproduce" in r["reason"] and float(r["score"]) == 90.0


def test_broken_submission_is_a_row_with_the_reason(graded):
    r = _rows(graded[1])["s05"]
    assert r["status"] == "invalid" and float(r["score"]) == 0.0
    assert r["reason"].startswith("s05/answer.yaml: cause: ") and "unknown family 'friction'" in r["reason"]


def test_summary_page_is_self_contained_and_links_the_reports(graded):
    d = graded[1]
    html = (d / "summary.html").read_text()
    assert "http://" not in html and "https://" not in html and "<script" not in html
    assert 'src="data:image/png;base64,' in html
    for sid in ("s01", "s02", "s03", "s04"):
        assert f'href="runs/{sid}/report.html"' in html and (d / "runs" / sid / "report.html").is_file()
    assert 'href="runs/s05/' not in html


def _task(klass, subs: Path, sid: str) -> Task:
    key, key_dir = load_key(klass[0] / "key.json")
    st = next(s for s in key.students if s.id == sid)
    return Task(st, key_dir, subs, None, key.template)


@pytest.mark.parametrize("break_it, status, needle", [
    (lambda d: shutil.rmtree(d), "missing", "no submission folder"),
    (lambda d: (d / "answer.yaml").unlink(), "invalid", "s05/answer.yaml: not in the submission"),
    (lambda d: (d / "config.yaml").write_text("name: [\n"), "invalid", "s05/config.yaml: not valid YAML"),
    (lambda d: (d / "record.csv").unlink(), "invalid", "data file not found"),
    (lambda d: (d / "answer.yaml").write_text("cause: offset\nparameter: zz\nclaimed_gain: 0.1\n"), "invalid",
     "s05/answer.yaml: parameter: 'zz' is not a free parameter"),
    (lambda d: (d / "answer.yaml").write_text("cause: offset\nparameter: c\nclaimed_gain: 2\n"), "invalid",
     "claimed_gain"),
    (lambda d: (d / "record.csv").write_text("a,b\n1,2\n"), "invalid", "s05/record.csv: column 'u' (input) not found"),
])
def test_missing_or_broken_submissions_give_a_row(klass, tmp_path, break_it, status, needle):
    out, key = klass
    st = next(s for s in key["students"] if s["id"] == "s05")
    d = write_submission(out, tmp_path, st, st["family"], 0.5)
    break_it(d)
    row = grade_one(_task(klass, tmp_path, "s05"))
    assert row["status"] == status and row["score"] == "0.0" and needle in row["reason"], row["reason"]
    assert str(tmp_path) not in row["reason"]


@pytest.mark.parametrize("edit, needle", [
    (lambda k, d: k.write_text("{"), "not a JSON file"),
    (lambda k, d: k.write_text(json.dumps({"schema": "x"})), "not an assignment key"),
    (lambda k, d: (d / "instructor" / "s01" / "record.csv").write_text("t,u,x\n"), "differs from the one"),
    (lambda k, d: k.write_text(k.read_text().replace('"rubric"', '"rubrik"', 1)), "rubrik: unknown key"),
    # an id naming another folder would read a submission outside --submissions and write a run outside runs/
    (lambda k, d: k.write_text(json.dumps(dict(json.loads(k.read_text()), students=[
        dict(s, id="../x") if i == 1 else s for i, s in enumerate(json.loads(k.read_text())["students"])]))),
     "key.json: students.1.id: id '../x' may only use letters"),
    # a wrong sample count in the key blamed every student's config ("the config reads 1200 samples of the
    # instructor's record, expected 100400"; an independent probe)
    (lambda k, d: k.write_text(json.dumps(dict(json.loads(k.read_text()), students=[
        dict(s, issued_samples=s["issued_samples"] + 99000) if i == 2 else s
        for i, s in enumerate(json.loads(k.read_text())["students"])]))),
     "key.json: students.2: issued_samples + heldout_samples = "),
])
def test_instructors_bad_key_exits_2(klass, submissions, tmp_path, capsys, edit, needle):
    d = tmp_path / "class"
    shutil.copytree(klass[0], d)
    k = d / "key.json"
    edit(k, d)
    rc = main(["grade", "--key", str(k), "--submissions", str(submissions[0]), "--out", str(tmp_path / "g.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "g.csv").exists() and not (tmp_path / "runs").exists()
    assert not (tmp_path / "x").exists()


def test_foreign_gradebook_is_not_overwritten(klass, submissions, tmp_path, capsys):
    g = tmp_path / "grades.csv"
    g.write_text("my own spreadsheet\n")
    rc = main(["grade", "--key", str(klass[0] / "key.json"), "--submissions", str(submissions[0]),
               "--out", str(g)])
    assert rc == 2 and "not written by sysid grade" in capsys.readouterr().err
    assert g.read_text() == "my own spreadsheet\n"
    rc = main(["grade", "--key", str(klass[0] / "key.json"), "--submissions", str(submissions[0]),
               "--out", str(tmp_path / "x.csv"), "--jobs", "0"])
    assert rc == 2


def test_dask_executor_gives_the_same_gradebook(klass, submissions, graded, tmp_path):
    """`sysid grade --executor dask` (a Dask LocalCluster, the sysid batch executor): the same bytes."""
    pytest.importorskip("distributed")
    out, _ = klass
    rc = main(["grade", "--key", str(out / "key.json"), "--submissions", str(submissions[0]), "--out",
               str(tmp_path / "gradebook.csv"), "--jobs", "2", "--executor", "dask"])
    assert rc == 0
    assert (tmp_path / "gradebook.csv").read_bytes() == (graded[1] / "gradebook.csv").read_bytes()
    for sid in ("s01", "s02", "s03", "s04"):
        assert ((tmp_path / "runs" / sid / "summary.json").read_bytes()
                == (graded[1] / "runs" / sid / "summary.json").read_bytes())


def test_unknown_executor_exits_2(klass, submissions, tmp_path, capsys):
    rc = main(["grade", "--key", str(klass[0] / "key.json"), "--submissions", str(submissions[0]),
               "--out", str(tmp_path / "g.csv"), "--executor", "slurm"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and "--executor" in err and "slurm" in err
    assert not (tmp_path / "g.csv").exists()


def _regrade(klass, submissions, d: Path) -> int:
    return main(["grade", "--key", str(klass[0] / "key.json"), "--submissions", str(submissions[0]),
                 "--out", str(d / "gradebook.csv")])


def _snapshot(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("name, line", [("gradebook.csv", 2), ("summary.html", 3)])
def test_hand_edited_gradebook_or_summary_is_not_overwritten(klass, submissions, graded, tmp_path, capsys,
                                                             name, line):
    """A manual bonus typed into a row (below the first line, which alone used to be checked) is the
    instructor's: grade refuses before grading and leaves every file as it was; the same folder
    without the edit is graded again as before."""
    d = tmp_path / "grades"
    shutil.copytree(graded[1], d)
    f = d / name
    original = f.read_bytes()
    lines = original.decode().split("\n")
    lines[line - 1] += ",manual: +5 bonus" if name.endswith(".csv") else "<!-- my note -->"
    f.write_text("\n".join(lines))
    before = _snapshot(d)
    rc = _regrade(klass, submissions, d)
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"error: {f}: ") and "edited after sysid grade wrote it" in err, err
    assert err.count("\n") == 1 and _snapshot(d) == before
    f.write_bytes(original)
    assert _regrade(klass, submissions, d) == 0
    assert (d / "gradebook.csv").read_bytes() == (graded[1] / "gradebook.csv").read_bytes()


def test_gradebook_without_a_record_of_what_was_written_is_not_overwritten(klass, submissions, tmp_path, capsys):
    """A file that starts like a gradebook but has no record beside it (an older release wrote it, or
    it was pasted together by hand) may hold edits nobody can see: refused."""
    d = tmp_path / "grades"
    d.mkdir()
    (d / "gradebook.csv").write_text(HEADER + "\ns01,Ada,graded,offset,offset,yes,,,,,,,,,95.0,,bonus\n")
    before = _snapshot(d)
    rc = _regrade(klass, submissions, d)
    err = capsys.readouterr().err
    assert rc == 2 and "no record" in err and "gradebook.csv" in err and _snapshot(d) == before


@pytest.mark.parametrize("edit, needle", [
    (lambda runs: (runs / "s01" / "mynotes.txt").write_text("notes\n"), "s01: holds files this tool did not "
     "write (added: mynotes.txt)"),
    (lambda runs: (runs / "s02" / "params.yaml").open("a").write("# tweak\n"), "s02: holds files this tool did "
     "not write (edited: params.yaml)"),
])
def test_edited_run_folder_stops_grading_before_it_starts(klass, submissions, graded, tmp_path, capsys, edit,
                                                          needle):
    """The instructor's change in runs/<id> is not the student's fault: exit 2 naming the folder, the
    earlier gradebook and the edited folder left as they were (it used to become an "invalid" row
    with score 0 and exit 0)."""
    d = tmp_path / "grades"
    shutil.copytree(graded[1], d)
    edit(d / "runs")
    before = _snapshot(d)
    rc = _regrade(klass, submissions, d)
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    assert f"{d / 'runs'}/{needle}" in err and "nothing was graded" in err, err
    assert _snapshot(d) == before


def _starter_like(klass, subs: Path, edit_model) -> tuple[Task, dict]:
    """A submission of a student whose hidden cause is a term of a state equation: the issued
    folder, the starter config changed by ``edit_model`` and the right cause named in the answer."""
    out, key = klass
    # Coulomb friction first: the starter's linear damping absorbs it best (the probe's case, score 70)
    order = ("coulomb_friction", "quadratic_damping", "cubic_stiffness", "offset")
    st = min((s for s in key["students"] if s["family"] in order), key=lambda s: order.index(s["family"]))
    d = subs / st["id"]
    shutil.copytree(out / "students" / st["id"], d)
    cfg = yaml.safe_load((d / "config.yaml").read_text())
    param = edit_model(cfg["model"], st["acts_on"])
    (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    (d / "answer.yaml").write_text(yaml.safe_dump({"cause": st["family"], "parameter": param,
                                                   "claimed_gain": 0.0}))
    return _task(klass, subs, st["id"]), st


def _unchanged_naming_damping(model: dict, eq: str) -> str:
    return "c"


def _added_input_term(model: dict, eq: str) -> str:
    model["params"]["p_in"] = 0.0
    model["free"].append("p_in")
    model["equations"][eq] = f"({model['equations'][eq]}) + p_in*u"
    return "p_in"


@pytest.mark.parametrize("edit_model, needle", [
    (_unchanged_naming_damping, "parameter 'c' is a parameter of the starter model"),
    (_added_input_term, "parameter 'p_in' does not multiply a term of the cause's form"),
])
def test_no_parameter_credit_without_a_term_of_the_causes_form(klass, tmp_path, edit_model, needle):
    """The starter model unchanged, naming its linear damping c, or with an added term of another form:
    the change the parameter makes correlates with the key's term, but it is not the cause's size."""
    task, st = _starter_like(klass, tmp_path, edit_model)
    row = grade_one(task)
    assert row["status"] == "graded" and row["cause_correct"] == "yes", row
    assert row["parameter_rel_error"] == "" and needle in row["reason"], row
    # the cause (40) and the claimed gain (10, 0 reproduces for a model no better than the starter), never
    # the parameter's 20 points; the validation share is at most a sliver
    assert 50.0 <= float(row["score"]) < 60.0, row


def test_the_results_runs_folder_among_the_submissions_is_no_submission(klass, submissions, tmp_path, capsys):
    """A class folder with the submissions and the gradebook beside them (``--submissions class --out
    class/gradebook.csv``): the second grade listed the results' own runs/ folder as a submission the key
    lacks (an independent probe). It is not one; the folders the key lacks still are."""
    cls = tmp_path / "class"
    shutil.copytree(submissions[0], cls)
    made = tmp_path / "made"
    shutil.copytree(klass[0], made)
    key = json.loads((made / "key.json").read_text())
    key["students"] = [s for s in key["students"] if s["id"] == "s01"]     # one student: one run a grade
    (made / "key.json").write_text(json.dumps(key))
    for _ in range(2):
        rc = main(["grade", "--key", str(made / "key.json"), "--submissions", str(cls),
                   "--out", str(cls / "gradebook.csv")])
        err = capsys.readouterr().err
        assert rc == 0, err
    assert (cls / "runs" / "s01").is_dir()
    note = next(line for line in err.splitlines() if line.startswith("note: folders not in the key"))
    listed = note.rsplit(": ", 1)[1].split(", ")
    assert "s02" in listed and "runs" not in listed
