"""sysid assignment make: each record differs, the key names each hidden effect, no student folder
holds the key or a hint, regeneration is reproducible, and bad instructor input exits 2."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline import synthetic
from pipeline.assignment.make import draw, make_assignment
from pipeline.assignment.template import load_template
from pipeline.cli import main
from pipeline.config import ALL_FAMILY_IDS

from .conftest import ROSTER, TEMPLATE

# parameters the diagnosis contract §2 lists for each family
CONTRACT_KEYS = {"offset": {"coefficient"}, "output_offset": {"value"}, "cubic_stiffness": {"coefficient", "term"},
                 "quadratic_damping": {"coefficient", "term"}, "coulomb_friction": {"coefficient", "term"},
                 "periodic_disturbance": {"frequency_hz", "amplitude"}, "input_delay": {"delay_s"}}


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_five_records_differ_and_hashes_match_the_key(klass):
    out, key = klass
    assert [s["id"] for s in key["students"]] == ["s01", "s02", "s03", "s04", "s05"]
    shas = [_sha(out / "students" / s["id"] / "record.csv") for s in key["students"]]
    assert len(set(shas)) == 5
    assert shas == [s["data_sha256"] for s in key["students"]]
    ys = [pd.read_csv(out / "students" / s["id"] / "record.csv")["x"].to_numpy() for s in key["students"]]
    for i in range(5):
        for j in range(i + 1, 5):
            assert np.max(np.abs(ys[i] - ys[j])) > 0.01


def test_key_names_the_effect_in_each_record(klass):
    """The instructor's record is the generator's record of the family and size the key names; the
    issued record is its first `samples` rows; the key carries the contract's parameters."""
    out, key = klass
    tpl = load_template(TEMPLATE)
    for s in key["students"]:
        assert s["family"] in tpl.families
        assert CONTRACT_KEYS[s["family"]] <= set(s["parameters"])
        lo, hi = tpl.families[s["family"]]
        assert lo <= s["strength"] <= hi
        syn = synthetic.generate("msd", s["family"], s["record_seed"], n=tpl.samples + tpl.heldout_samples,
                                 noise=tpl.noise, strength=s["strength"])
        full = pd.read_csv(out / s["instructor_record"])
        np.testing.assert_allclose(full["x"].to_numpy(), syn.y, rtol=1e-9, atol=1e-9 * np.max(np.abs(syn.y)))
        issued = pd.read_csv(out / "students" / s["id"] / "record.csv")
        assert len(issued) == tpl.samples
        np.testing.assert_array_equal(issued.to_numpy(), full.to_numpy()[:tpl.samples])
        main_value = s["parameters"][s["main_parameter"]]
        truth = {k: v for k, v in syn.truth.items() if k in s["parameters"]}
        assert truth[s["main_parameter"]] == pytest.approx(main_value, rel=1e-9)


def test_draw_is_seeded_by_the_seed_and_the_student_id():
    tpl = load_template(TEMPLATE)
    assert draw(tpl, 1, "s01") == draw(tpl, 1, "s01")
    ids = [f"x{i}" for i in range(40)]
    assert len({draw(tpl, 1, i)[2] for i in ids}) == 40               # record seeds differ
    assert len({draw(tpl, 1, i)[0] for i in ids}) == len(tpl.families)  # every family is drawn
    assert [draw(tpl, 1, i) for i in ids] != [draw(tpl, 2, i) for i in ids]


def test_no_student_folder_holds_the_key_or_a_hint(klass):
    out, key = klass
    students = out / "students"
    names = {s["id"]: sorted(p.name for p in (students / s["id"]).iterdir()) for s in key["students"]}
    assert all(v == ["README.md", "config.yaml", "record.csv"] for v in names.values())
    # "intersample" is also the data key every starter config holds (data.intersample: zoh), not a hint
    words = (set(ALL_FAMILY_IDS) - {"intersample"}) | {"key", "hidden", "effect", "strength", "truth", "heldout",
                                                      "answer key"}
    for s in key["students"]:
        folder = students / s["id"]
        text = "\n".join(p.read_text() for p in folder.iterdir()).lower()
        for w in words | {w.replace("_", " ") for w in words}:
            assert not re.search(rf"\b{re.escape(w)}\b", text), (s["id"], w)
        # none of the key's numbers (coefficients, strength, seed) in the config or the instructions
        prose = (folder / "config.yaml").read_text() + (folder / "README.md").read_text()
        nums = [v for v in s["parameters"].values() if isinstance(v, float)] + [s["strength"]]
        for v in nums:
            assert f"{abs(v):.4g}" not in prose, (s["id"], v)
        assert str(s["record_seed"]) not in prose
        assert (folder / "record.csv").read_text().splitlines()[0] == "t,u,x"
    # the starter configs are the same for every student but for the run name
    cfgs = {s["id"]: (students / s["id"] / "config.yaml").read_text().replace(s["id"], "ID") for s in key["students"]}
    assert len(set(cfgs.values())) == 1
    readmes = {(students / s["id"] / "README.md").read_text() for s in key["students"]}
    assert len(readmes) == 1
    assert not list(students.rglob("key*")) and not list(students.rglob("*.json"))


def test_regeneration_is_byte_identical(klass, tmp_path):
    out, _ = klass
    again = tmp_path / "again"
    make_assignment(ROSTER, TEMPLATE, again)
    files = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for f in files:
        assert (out / f).read_bytes() == (again / f).read_bytes(), f
    other = tmp_path / "other"
    make_assignment(ROSTER, TEMPLATE, other, seed=7)
    assert (other / "students/s01/record.csv").read_bytes() != (out / "students/s01/record.csv").read_bytes()


def _cli(capsys, *args) -> tuple[int, str]:
    rc = main(list(args))
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("roster, needle", [
    ("name,email\nAda,\n", "no column 'id'"),
    ("id,name\ns01,Ada\ns01,Bob\n", "row 3: id: id 's01' appears twice"),
    ("id,name\ns 1,Ada\n", "row 2: id"),
    ("id,name\n../x,Ada\n", "row 2: id"),
    ("id,name\n.hidden,Ada\n", "row 2: id: id '.hidden' starts with '.'"),   # hidden folders (a probe)
    ("id,name\ns01,\n", "row 2: name: empty name"),
    ("id,name\n", "no students"),
    ("", "empty"),
    ("id,name,id\ns01,Ada,s99\n", "the header names the column 'id' 2 times"),    # which id? (a probe)
])
def test_bad_roster_exits_2_with_one_line(tmp_path, capsys, roster, needle):
    r = tmp_path / "roster.csv"
    r.write_text(roster)
    rc, err = _cli(capsys, "assignment", "make", "--roster", str(r), "--template", str(TEMPLATE),
                   "--out", str(tmp_path / "out"))
    assert rc == 2
    assert err.startswith("error: ") and err.count("\n") == 1 and needle in err and str(r) in err
    assert not (tmp_path / "out").exists()


def test_a_quoted_name_over_two_lines_is_one_student_with_a_space():
    """csv's own line handling: the text was split into lines first, so a quoted name with a line break
    became "AdaLovelace" (an independent probe)."""
    import tempfile
    from pipeline.assignment.roster import load_roster
    with tempfile.TemporaryDirectory() as d:
        r = Path(d) / "roster.csv"
        r.write_text('id,name,email\ns01,"Ada\nLovelace",ada@x.org\ns02,Bob,\n')
        got = load_roster(r)
    assert [(s.id, s.name, s.email) for s in got] == [("s01", "Ada Lovelace", "ada@x.org"), ("s02", "Bob", None)]


@pytest.mark.parametrize("edit, needle", [
    ("families: {input_saturation: [1, 1]}", "unknown or ungradable family 'input_saturation'"),
    ("rubric: {delay_tolerance_samples: 0}", "rubric.delay_tolerance_samples"),
    ("families: {spring: [1, 1]}", "unknown or ungradable family 'spring'"),
    ("families: {offset: [1.5, 1.0]}", "0 < low <= high <= 5"),
    ("families: {}", "families"),
    ("colour: red", "colour: unknown key"),
    ("system: boat", "system"),
    ("rubric: {weights: {cause: 0, parameter: 0, validation: 0, gain: 0}}", "sum to 0"),
    ("samples: ten", "samples"),
    ("noise: .nan", "noise: Input should be a finite number"),       # was "less than or equal to 0.5"
])
def test_bad_template_exits_2_with_one_line(tmp_path, capsys, edit, needle):
    base = "name: t\nsystem: msd\nfamilies: {offset: [1, 1]}\n"
    k = edit.split(":", 1)[0]
    text = "\n".join(line for line in base.splitlines() if not line.startswith(k + ":")) + "\n" + edit + "\n"
    t = tmp_path / "t.yaml"
    t.write_text(text)
    rc, err = _cli(capsys, "assignment", "make", "--roster", str(ROSTER), "--template", str(t),
                   "--out", str(tmp_path / "out"))
    assert rc == 2 and err.startswith("error: ") and err.count("\n") == 1 and needle in err, err


def test_out_folder_not_ours_is_refused_and_kept(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    rc, err = _cli(capsys, "assignment", "make", "--roster", str(ROSTER), "--template", str(TEMPLATE),
                   "--out", str(out))
    assert rc == 2 and "--out" in err
    assert (out / "notes.txt").read_text() == "precious" and sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temporary folder left


def test_cli_subprocess_bad_instructor_input_contract(tmp_path):
    """The real CLI in a subprocess (tests/hostile harness): exit 2, one error line, no traceback,
    nothing written."""
    from tests.hostile.harness import assert_bad_input, run_cli, snapshot
    r = tmp_path / "roster.csv"
    r.write_bytes(b"id,name\n\xff\xfe,x\n")
    before = snapshot(tmp_path)
    res = run_cli("assignment", "make", "--roster", str(r), "--template", str(TEMPLATE), "--out", str(tmp_path / "o"))
    assert_bad_input(res, str(r), "UTF-8")
    res = run_cli("grade", "--key", str(tmp_path / "nokey.json"), "--submissions", str(tmp_path),
                  "--out", str(tmp_path / "g.csv"))
    assert_bad_input(res, "nokey.json", "key not found")
    assert snapshot(tmp_path) == before


def test_an_earlier_output_is_replaced_only_while_it_holds_just_its_own_files(tmp_path, capsys, monkeypatch):
    """An independent probe: with one of its key.json files inside, --out DIR was emptied whatever else
    it held (the instructor's notes, the submissions), and --out . emptied the working folder."""
    out = tmp_path / "class"
    args = ["assignment", "make", "--roster", str(ROSTER), "--template", str(TEMPLATE), "--out", str(out)]
    assert _cli(capsys, *args)[0] == 0
    assert _cli(capsys, *args)[0] == 0                      # its own output: replaced
    (out / "notes.txt").write_text("grading notes")
    (out / "submissions" / "s01").mkdir(parents=True)
    (out / "submissions" / "s01" / "answer.yaml").write_text("mine")
    rc, err = _cli(capsys, *args)
    assert rc == 2 and "--out" in err and "did not write" in err
    assert (out / "notes.txt").read_text() == "grading notes"
    assert (out / "submissions" / "s01" / "answer.yaml").read_text() == "mine"
    # the working folder holding a copy of the key: refused as the current folder, nothing removed
    work = tmp_path / "work"
    work.mkdir()
    (work / "key.json").write_bytes((out / "key.json").read_bytes())
    (work / "thesis.txt").write_text("my thesis")
    monkeypatch.chdir(work)
    rc, err = _cli(capsys, "assignment", "make", "--roster", str(ROSTER), "--template", str(TEMPLATE), "--out", ".")
    assert rc == 2 and "current folder" in err
    assert sorted(p.name for p in work.iterdir()) == ["key.json", "thesis.txt"]


def test_an_edited_key_is_not_overwritten(tmp_path, capsys):
    out = tmp_path / "class"
    args = ["assignment", "make", "--roster", str(ROSTER), "--template", str(TEMPLATE), "--out", str(out)]
    assert _cli(capsys, *args)[0] == 0
    key = (out / "key.json").read_text()
    (out / "key.json").write_text(key.replace('"', "'", 1))  # same size, other content
    rc, err = _cli(capsys, *args)
    assert rc == 2 and (out / "key.json").read_text() != key
