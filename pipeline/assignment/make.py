"""``sysid assignment make``: one record and starter config per student, and the answer key.

For each student of the roster the hidden effect is drawn from
``numpy.random.default_rng([seed, *sha256(student id) as eight 32-bit words])``: the family uniformly
among the template's families, its strength uniformly in that family's range, and the seed of the
record (input and noise) from the same generator. The record is
``pipeline.synthetic.generate(system, family, record_seed, n=samples + heldout_samples, ...)``: the
first ``samples`` rows go to the student, the whole record stays with the instructor, so the held-out
part is the same system continuing (same parameters, same effect) and a student's model is scored on
it by simulating the whole record from sample 0.

Layout of ``--out DIR`` (the key and the held-out part are outside the student folders)::

    DIR/key.json                        answer key (family, acts-on, parameters, sha256 per student)
    DIR/instructor/<id>/record.csv      the whole record (issued part + held-out part)
    DIR/instructor/<id>/starter.yaml    the starter config reading that record
    DIR/students/<id>/record.csv        the issued part (t, u, measured output; nothing else)
    DIR/students/<id>/config.yaml       the starter config: the nominal model, no hint
    DIR/students/<id>/README.md         the instructions, the same for every student

File names, CSV headers and configs are the same for every student whatever the effect. ``DIR`` is
written as a run folder is (:mod:`pipeline.runfolder`): checked before any work (not the current
folder or an ancestor, not a symlink, a file or a pseudo filesystem), written into a hidden temp folder
beside it, marked complete by ``.sysid-run`` (every file with its size and sha256) and renamed into
place. It must not exist, be empty, or be an earlier output of this command holding exactly the files
its marker lists, unchanged; then it is replaced. A folder with anything else in it (the instructor's
notes, the students' submissions, an edited key) is refused and left as it is.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import yaml

from .. import runfolder, synthetic
from ..data import file_sha256
from ..errors import InputError
from ..jsonutil import dumps
from . import KEY_SCHEMA
from .roster import Student, load_roster
from .submission import student_readme
from .template import Template, load_template

SYSTEM_TEXT = {
    "msd": "mass-spring-damper (input u: force, output x: position)",
    "pendulum": "damped pendulum (input u: torque per inertia, output th: angle)",
    "tank": "tank (input u: inflow, output h: level)",
    "dcmotor": "DC motor (input u: voltage, output w: speed)",
}
MAIN_PARAMETER = {"offset": "coefficient", "cubic_stiffness": "coefficient", "quadratic_damping": "coefficient",
                  "coulomb_friction": "coefficient", "periodic_disturbance": "amplitude", "output_offset": "value",
                  "input_delay": "delay_s"}
CSV_FORMAT = "%.10g"


def student_rng(seed: int, student_id: str) -> np.random.Generator:
    """The generator of one student's draw: seeded by the assignment seed and sha256 of the id."""
    digest = hashlib.sha256(student_id.encode("utf-8")).digest()
    words = [int.from_bytes(digest[i:i + 4], "big") for i in range(0, 32, 4)]
    return np.random.default_rng([seed, *words])


def draw(tpl: Template, seed: int, student_id: str) -> tuple[str, float, int]:
    """(family, strength, record seed) of one student, deterministic from the seed and the id."""
    rng = student_rng(seed, student_id)
    fams = list(tpl.families)
    family = fams[int(rng.integers(len(fams)))]
    lo, hi = tpl.families[family]
    strength = float(rng.uniform(lo, hi))
    return family, strength, int(rng.integers(0, 2 ** 31 - 1))


def _acts_on(truth: dict) -> str:
    if truth["family"] == "input_delay":
        return "input u"
    return f"output {truth['output']}" if truth["family"] == "output_offset" else str(truth["equation"])


def _write_csv(frame, path: Path) -> None:
    frame.to_csv(path, index=False, float_format=CSV_FORMAT, lineterminator="\n")


def make_student(tpl: Template, seed: int, st: Student, out: Path) -> dict:
    """Write one student's folder and instructor folder under ``out``; return the key entry."""
    family, strength, rseed = draw(tpl, seed, st.id)
    n, nh = tpl.samples, tpl.heldout_samples
    kw = dict(n=n + nh, strength=strength)
    syn = synthetic.generate(tpl.system, family, rseed, noise=tpl.noise, **kw)
    clean = synthetic.generate(tpl.system, family, rseed, noise=0.0, **kw)  # same draws, no noise
    frame = syn.to_frame()
    sdir, idir = out / "students" / st.id, out / "instructor" / st.id
    sdir.mkdir(parents=True)
    idir.mkdir(parents=True)
    _write_csv(frame.iloc[:n], sdir / "record.csv")
    _write_csv(frame, idir / "record.csv")
    name = f"{tpl.name}-{st.id}"
    for folder in (sdir, idir):
        cfg = synthetic.config_for(syn, "record.csv", name=name, seed=0)
        fname = "config.yaml" if folder is sdir else "starter.yaml"
        (folder / fname).write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    (sdir / "README.md").write_text(student_readme(tpl.name, SYSTEM_TEXT[tpl.system]), encoding="utf-8")
    held = slice(n, n + nh)
    truth = dict(syn.truth)
    params = {k: v for k, v in truth.items() if k not in ("family", "equation", "noise", "output")}
    if family == "input_delay":  # the key stores the delay in seconds; in samples for the instructor
        params["delay_samples"] = params["delay_s"] / synthetic.BASE[tpl.system]["dt"]
    return {
        "id": st.id, "name": st.name, "family": family, "acts_on": _acts_on(truth),
        "parameters": params, "main_parameter": MAIN_PARAMETER[family], "strength": strength,
        "record_seed": rseed, "noise_std": truth["noise"]["std"],
        "data_sha256": file_sha256(sdir / "record.csv"), "issued_samples": n, "heldout_samples": nh,
        "instructor_record": f"instructor/{st.id}/record.csv",
        "instructor_record_sha256": file_sha256(idir / "record.csv"),
        "starter_config": f"instructor/{st.id}/starter.yaml",
        "heldout_rmse_truth": float(np.sqrt(np.mean((syn.y[held] - clean.y[held]) ** 2))),
    }


def make_assignment(roster_path: str | Path, template_path: str | Path, out: str | Path,
                    seed: int | None = None) -> Path:
    """Generate the class; returns the path of key.json. InputError for a bad roster, template or --out."""
    tpl = load_template(template_path)
    students = load_roster(roster_path)
    seed = tpl.seed if seed is None else seed
    if seed < 0:
        raise InputError(f"the seed must be a non-negative integer, got {seed}", key="--seed")
    target = runfolder.check_target(out, inputs=[Path(roster_path), Path(template_path)], default=True)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = runfolder.make_temp(target)
    try:
        entries = [make_student(tpl, seed, st, tmp) for st in students]
        key = {"schema": KEY_SCHEMA, "assignment": tpl.name, "seed": seed,
               "template": tpl.model_dump(mode="json"), "students": entries}
        (tmp / "key.json").write_text(dumps(key), encoding="utf-8")
        runfolder.finalize(tmp, f"assignment-{tpl.name}")
        runfolder.publish(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return Path(out) / "key.json"
