"""A class of five made from the worked example (configs/assignment), and its submissions."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
from pathlib import Path

import pytest
import yaml

from pipeline.assignment.make import make_assignment
from pipeline.assignment.solution import extend_config
from pipeline.config import load_config
from pipeline.runs import analyse

ROOT = Path(__file__).resolve().parents[2]
ROSTER = ROOT / "configs" / "assignment" / "roster.csv"
TEMPLATE = ROOT / "configs" / "assignment" / "template.yaml"


@pytest.fixture(scope="session")
def klass(tmp_path_factory) -> tuple[Path, dict]:
    """(class folder, key) of the worked example."""
    out = tmp_path_factory.mktemp("class") / "lab"
    key_path = make_assignment(ROSTER, TEMPLATE, out)
    return out, json.loads(key_path.read_text())


def pipeline_gain(config: Path) -> float:
    """The gain a student reads in the report of the starter config: the first finding's relative
    validation gain, from the pipeline's own diagnosis (not from the grader)."""
    with contextlib.redirect_stderr(io.StringIO()):
        s = analyse(load_config(config)).summary
    return float(s["diagnosis"]["findings"][0]["gain"]["relative"])


def write_submission(klass_dir: Path, subs: Path, st: dict, family: str, claimed: float) -> Path:
    """A submission folder: the issued folder with the config extended by ``family``."""
    d = subs / st["id"]
    shutil.copytree(klass_dir / "students" / st["id"], d)
    starter = yaml.safe_load((d / "config.yaml").read_text())
    cfg, param = extend_config(starter, "msd", family, st["parameters"].get("frequency_hz", 1.0),
                               delay_s=st["parameters"].get("delay_s", 0.0))
    (d / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    (d / "answer.yaml").write_text(yaml.safe_dump({"cause": family, "parameter": param, "claimed_gain": claimed}))
    return d


@pytest.fixture(scope="session")
def submissions(klass, tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """One scenario per student: good, wrong cause, tampered data, false claimed gain, broken answer."""
    out, key = klass
    subs = tmp_path_factory.mktemp("subs")
    st = {s["id"]: s for s in key["students"]}
    scen = {"s01": "good", "s02": "wrong_cause", "s03": "tampered", "s04": "false_claim", "s05": "broken"}
    g1 = pipeline_gain(out / "students" / "s01" / "config.yaml")
    write_submission(out, subs, st["s01"], st["s01"]["family"], g1)
    wrong = "cubic_stiffness" if st["s02"]["family"] != "cubic_stiffness" else "coulomb_friction"
    write_submission(out, subs, st["s02"], wrong, 0.5)
    d3 = write_submission(out, subs, st["s03"], st["s03"]["family"], 0.5)
    lines = (d3 / "record.csv").read_text().splitlines()
    t, u, x = lines[100].split(",")
    lines[100] = ",".join([t, u, repr(float(x) + 0.05)])        # one sample changed
    (d3 / "record.csv").write_text("\n".join(lines) + "\n")
    g4 = pipeline_gain(out / "students" / "s04" / "config.yaml")
    write_submission(out, subs, st["s04"], st["s04"]["family"], g4 - 0.3)
    d5 = write_submission(out, subs, st["s05"], st["s05"]["family"], 0.5)
    (d5 / "answer.yaml").write_text("cause: friction\nparameter: p_fix\nclaimed_gain: 0.5\n")
    return subs, scen
