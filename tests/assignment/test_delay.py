"""input_delay as an assignable hidden effect: the key names the delay in seconds, the record is
delayed by it, a submission stating the right ``model.input_delay`` scores full marks on the cause and
the parameter, one five samples off loses the parameter points (rubric: 1.5 samples)."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy import signal

from pipeline import synthetic
from pipeline.assignment.make import make_assignment
from pipeline.assignment.solution import extend_config
from pipeline.cli import main

from .conftest import pipeline_gain

DT = synthetic.BASE["msd"]["dt"]
# seed 13 with this roster: d01 draws input_delay, d02 cubic_stiffness (pipeline.assignment.make.draw)
TEMPLATE = """name: msd-lab4
system: msd
samples: 3000
heldout_samples: 1500
noise: 0.02
seed: 13
families:
  input_delay: [0.8, 1.2]
  cubic_stiffness: [0.7, 1.3]
rubric:
  weights: {cause: 40, parameter: 20, validation: 30, gain: 10}
  delay_tolerance_samples: 1.5
"""


@pytest.fixture(scope="module")
def delay_class(tmp_path_factory) -> tuple[Path, dict]:
    d = tmp_path_factory.mktemp("delay")
    (d / "t.yaml").write_text(TEMPLATE)
    (d / "roster.csv").write_text("id,name\nd01,Ada Delay\nd02,Bo Cubic\n")
    key = make_assignment(d / "roster.csv", d / "t.yaml", d / "class")
    return d / "class", json.loads(key.read_text())


def _student(key: dict, sid: str) -> dict:
    return next(s for s in key["students"] if s["id"] == sid)


def _submit(out: Path, subs: Path, st: dict, delay_s: float, claimed: float, parameter: str = "input_delay") -> Path:
    d = subs / st["id"]
    shutil.copytree(out / "students" / st["id"], d)
    starter = yaml.safe_load((d / "config.yaml").read_text())
    cfg, _ = extend_config(starter, "msd", "input_delay", delay_s=delay_s)
    (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    (d / "answer.yaml").write_text(yaml.safe_dump({"cause": "input_delay", "parameter": parameter,
                                                   "claimed_gain": claimed}))
    return d


def test_key_names_the_delay_in_seconds_and_the_record_is_delayed(delay_class):
    out, key = delay_class
    st, other = _student(key, "d01"), _student(key, "d02")
    assert st["family"] == "input_delay" and other["family"] == "cubic_stiffness"
    assert st["acts_on"] == "input u" and st["main_parameter"] == "delay_s"
    # the generator's documented size: strength 1 = five samples of dead time
    assert st["parameters"]["delay_s"] == pytest.approx(5 * DT * st["strength"], rel=1e-12)
    assert st["parameters"]["delay_samples"] == pytest.approx(5 * st["strength"], rel=1e-9)
    assert 4.0 <= st["parameters"]["delay_samples"] <= 6.0
    # independent check of the record: the msd transfer function 1/(m s^2 + c s + k) (scipy.signal.lsim,
    # the nominal parameters) explains the instructor's record with the key's delay, not without it
    rec = pd.read_csv(out / st["instructor_record"])
    t, u, y = rec["t"].to_numpy(), rec["u"].to_numpy(), rec["x"].to_numpy()
    p = synthetic.BASE["msd"]["params"]
    sys = signal.lti([1.0], [p["m"], p["c"], p["k"]])

    def rmse(delay: float) -> float:
        ud = np.interp(t - delay, t, u, left=u[0])
        return float(np.sqrt(np.mean((y - signal.lsim(sys, ud, t)[1]) ** 2)))

    with_delay, without = rmse(st["parameters"]["delay_s"]), rmse(0.0)
    assert with_delay < 0.3 * without
    assert with_delay < 3 * st["noise_std"]
    # the students' files do not reveal it
    for p_ in (out / "students" / "d01").iterdir():
        assert "delay" not in p_.read_text().lower()


@pytest.fixture(scope="module")
def delay_graded(delay_class, tmp_path_factory):
    out, key = delay_class
    st = _student(key, "d01")
    d_key = st["parameters"]["delay_s"]
    claimed = pipeline_gain(out / "students" / "d01" / "config.yaml")
    res = {}
    for name, delay in (("right", d_key), ("off2", d_key - 2 * DT), ("off5", d_key + 5 * DT)):
        subs = tmp_path_factory.mktemp(f"subs_{name}")
        _submit(out, subs, st, delay, claimed)
        g = tmp_path_factory.mktemp(f"grade_{name}")
        assert main(["grade", "--key", str(out / "key.json"), "--submissions", str(subs),
                     "--out", str(g / "gradebook.csv")]) == 0
        res[name] = {r["student_id"]: r for r in csv.DictReader(io.StringIO((g / "gradebook.csv").read_text()))}
    return key, res


def test_right_delay_scores_full_marks(delay_graded):
    key, res = delay_graded
    r = res["right"]["d01"]
    assert r["status"] == "graded" and r["cause_key"] == "input_delay" and r["cause_correct"] == "yes"
    assert float(r["parameter_rel_error"]) == 0.0
    assert r["data_issued"] == "yes" and r["gain_reproduces"] == "yes", r
    assert float(r["score"]) == 100.0 and r["reason"] == ""
    # the right delay explains the held-out part down to the measurement noise
    assert float(r["heldout_rmse"]) == pytest.approx(_student(key, "d01")["noise_std"], rel=0.15)
    # the other student handed in nothing: a row with the reason
    assert res["right"]["d02"]["status"] == "missing" and res["right"]["d02"]["score"] == "0.0"


def test_delay_off_by_five_samples_loses_the_parameter_points(delay_graded):
    key, res = delay_graded
    st = _student(key, "d01")
    r = res["off5"]["d01"]
    assert r["status"] == "graded" and r["cause_correct"] == "yes"
    assert float(r["parameter_rel_error"]) == pytest.approx(5 * DT / st["parameters"]["delay_s"], abs=1e-4)
    assert "5.0 samples" in r["reason"] and "tolerance 1.5" in r["reason"]
    # the score without the parameter's 20 points: 40 (cause) + 30 * validation share + 10 * gain, the
    # validation share from the row's held-out RMSEs (rubric: clip(s / 0.8, 0, 1))
    nom, stu, truth = float(r["heldout_rmse_nominal"]), float(r["heldout_rmse"]), st["heldout_rmse_truth"]
    v = min(1.0, max(0.0, (nom - stu) / (nom - truth) / 0.8))
    expected = 40 + 30 * v + 10 * (r["gain_reproduces"] == "yes")
    assert float(r["score"]) == pytest.approx(expected, abs=0.05)
    assert float(r["score"]) < float(res["right"]["d01"]["score"]) - 19.9


def test_delay_tolerance_is_in_samples(delay_graded):
    """Two samples off: share 2 - 2 / 1.5 = 2/3 of the parameter's 20 points (a relative tolerance of
    0.25 would give 2 - 0.447 / 0.25 = 0.21 of them)."""
    key, res = delay_graded
    st = _student(key, "d01")
    r = res["off2"]["d01"]
    nom, stu, truth = float(r["heldout_rmse_nominal"]), float(r["heldout_rmse"]), st["heldout_rmse_truth"]
    v = min(1.0, max(0.0, (nom - stu) / (nom - truth) / 0.8))
    expected = 40 + 20 * (2 - 2 / 1.5) + 30 * v + 10 * (r["gain_reproduces"] == "yes")
    assert float(r["score"]) == pytest.approx(expected, abs=0.05)
    assert "2.0 samples" in r["reason"]


def test_delay_answer_without_model_input_delay_is_a_row_with_the_reason(delay_class, tmp_path):
    from pipeline.assignment.grade import Task, grade_one, load_key
    out, key = delay_class
    d = _submit(out, tmp_path, _student(key, "d01"), 0.1, 0.5)
    cfg = yaml.safe_load((d / "config.yaml").read_text())
    del cfg["model"]["input_delay"]
    (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    k, key_dir = load_key(out / "key.json")
    row = grade_one(Task(next(s for s in k.students if s.id == "d01"), key_dir, tmp_path, None, k.template))
    assert row["status"] == "invalid" and row["score"] == "0.0"
    assert "d01/answer.yaml" in row["reason"] and "does not set" in row["reason"], row["reason"]
