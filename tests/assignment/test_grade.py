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
])
def test_instructors_bad_key_exits_2(klass, submissions, tmp_path, capsys, edit, needle):
    d = tmp_path / "class"
    shutil.copytree(klass[0], d)
    k = d / "key.json"
    edit(k, d)
    rc = main(["grade", "--key", str(k), "--submissions", str(submissions[0]), "--out", str(tmp_path / "g.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("error: ") and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "g.csv").exists()


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
