"""The diagnosis bench's grid and scoring (pipeline.bench.diagnosis)."""

import json

import pytest

from pipeline.bench import diagnosis as bd
from pipeline.bench.independent import menu
from pipeline.bench.independent.effects import identifiable
from pipeline.errors import ConfigError


def test_tuning_and_test_seeds_are_disjoint_and_the_grid_covers_every_kind():
    assert not set(bd.TUNE_SEEDS) & set(bd.TEST_SEEDS)
    assert not (set(bd.TUNE_SEEDS) | set(bd.TEST_SEEDS)) & set(bd.HOLDOUT_SEEDS)
    assert not (set(bd.TUNE_SEEDS) | set(bd.TEST_SEEDS) | set(bd.HOLDOUT_SEEDS)) & set(bd.HOLDOUT2_SEEDS)
    g = bd.grid(bd.TUNE_SEEDS)
    fams = {f for f, v in menu()["families"].items()}
    assert {s.family for s in g} == fams
    assert {s.seed for s in g} <= set(bd.TUNE_SEEDS)
    for fam in fams - {"none"}:
        mine = [s for s in g if s.family == fam]
        assert {s.noise for s in mine} == set(bd.NOISE_LEVELS), fam
        assert len({s.magnitude for s in mine}) == 3, fam
    assert all(identifiable(s.family, s.input_kind, s.base) for s in g)
    # u**2 of a two-level PRBS is a constant: never generated off the tank (it was, and failed)
    assert not any(s.family == "static_nonlinearity" and s.input_kind == "prbs" and s.base != "tank" for s in g)
    assert identifiable("static_nonlinearity", "prbs", "tank")        # the sqrt outflow is fine with it
    nulls = [s for s in g if s.family == "none"]
    assert len(nulls) >= 40 and {s.colour for s in nulls} == {"white", "ar0.5", "ar0.9"}
    assert len(set(g)) == len(g)
    q = bd.grid(bd.TEST_SEEDS, quick=True)
    assert {s.family for s in q} == fams and {s.seed for s in q} == {bd.TEST_SEEDS[0]}


def test_label_is_the_first_finding_else_the_verdict():
    assert bd.label_of("discrepancy", [{"family": "offset"}, {"family": "colored_noise"}]) == "offset"
    assert bd.label_of("no_significant_discrepancy", []) == "none"
    assert bd.label_of("unexplained_discrepancy", []) == "unexplained_discrepancy"


def _truth(family, params, n=1000, dt=0.02):
    return {"family": family, "params": params, "n": n, "dt": dt, "noise": {"phi": 0.0}}


def test_parameter_errors_use_the_issue_tolerances():
    e = bd.parameter_error(_truth("cubic_stiffness", {"equation": "v", "term": "x**3", "coefficient": -2.0}),
                           {"equation": "v", "term": "x ** 3", "coefficient": -2.2})
    assert e["coefficient"]["error"] == pytest.approx(0.1) and e["coefficient"]["ok"]
    assert e["term"]["ok"] and e["equation"]["ok"]
    e = bd.parameter_error(_truth("input_delay", {"delay_s": 0.02}), {"delay_s": 0.07})
    assert e["delay_s"]["error"] == pytest.approx(2.5) and not e["delay_s"]["ok"]
    e = bd.parameter_error(_truth("parameter_jump", {"parameter": "k", "time_s": 8.0, "before": 4.0, "after": 5.0}),
                           {"parameter": "k", "time_s": 9.5, "before": 4.1, "after": 5.0})
    assert e["time_s"]["error"] == pytest.approx(1.5 / 20.0) and not e["time_s"]["ok"]
    assert e["before"]["ok"] and e["after"]["error"] == 0.0
    e = bd.parameter_error(_truth("periodic_disturbance", {"equation": "v", "frequency_hz": 1.0, "amplitude": 2.0}),
                           {"equation": "x", "frequency_hz": 1.06, "amplitude": 2.0})
    assert not e["frequency_hz"]["ok"] and not e["equation"]["ok"]
    e = bd.parameter_error(_truth("dead_zone", {"width": 0.5}), {"family": "dead_zone"})
    assert e["width"]["error"] is None and not e["width"]["ok"]        # key missing counts as wrong


def test_null_false_alarms():
    white = _truth("none", {})
    ar = dict(white, noise={"phi": 0.9})
    assert bd.null_outcome(white, []) == {"physical_false_alarm": False, "any_false_alarm": False}
    assert bd.null_outcome(ar, [{"family": "colored_noise"}]) == {"physical_false_alarm": False, "any_false_alarm": False}
    assert bd.null_outcome(white, [{"family": "colored_noise"}])["any_false_alarm"]
    assert bd.null_outcome(ar, [{"family": "coulomb_friction"}])["physical_false_alarm"]


def test_section_replaces_only_its_own_block(tmp_path):
    p = tmp_path / "BENCHMARKS.md"
    p.write_text("# Benchmarks\n\n## Issue 2\n\nrow\n")
    sec1 = f"{bd.START}\n## Diagnosis\nfirst\n{bd.END}\n"
    bd.write_section(p, sec1)
    bd.write_section(p, sec1.replace("first", "second"))
    text = p.read_text()
    assert text.startswith("# Benchmarks\n\n## Issue 2\n\nrow\n")
    assert "second" in text and "first" not in text and text.count(bd.START) == 1


def test_one_record_is_diagnosed_and_an_input_error_is_counted(tmp_path, monkeypatch):
    spec = bd.Spec("offset", "dcmotor", bd.TEST_SEEDS[0], "large", 0.02, "white", "band", n=600)
    r = bd.run_one(spec, str(tmp_path))
    assert r["status"] == "ok" and r["truth"]["family"] == "offset"
    assert r["label"] == "offset" and r["parameter_error"]["equation"]["ok"]
    assert 0 < r["seconds_analyse"] < 120
    assert "coverage" in r and "coverage_same_input" in r
    quick = bd.run_one(spec, str(tmp_path), coverage=False)            # --no-coverage: same answer, no check
    assert quick["label"] == "offset" and "coverage" not in quick and "coverage_same_input" not in quick
    assert not (tmp_path / r["name"]).exists()                        # the case folder is cleaned up

    import pipeline.runs

    def bad(lc):
        raise ConfigError("broken", file="x.yaml", key="model")
    monkeypatch.setattr(pipeline.runs, "analyse", bad)
    r = bd.run_one(spec, str(tmp_path))
    assert r["status"] == "input_error" and r["label"] == "input_error" and "broken" in r["error"]
    s = bd.summarise([r])
    assert s["status"] == {"input_error": 1}


def test_a_miss_is_counted_as_a_stated_tie_only_when_its_finding_names_the_hidden_family():
    def rec(truth, first, tied, noise=0.1):
        return {"truth": {"kind": "effect", "family": truth, "accept": [truth]}, "spec": {"noise": noise},
                "status": "ok", "label": first, "verdict": "discrepancy", "seconds_generate": 0.1,
                "seconds_analyse": 1.0,
                "findings": [{"family": first, "tied_with": [{"family": f} for f in tied]}]}
    s = bd.summarise([rec("input_delay", "unmodeled_dynamics", ["input_delay"]),      # a stated tie
                      rec("input_delay", "unmodeled_dynamics", ["offset"]),           # a tie, not with the truth
                      rec("input_delay", "intersample", []),                          # a plain miss
                      rec("input_delay", "input_delay", ["unmodeled_dynamics"]),      # right: not a miss
                      rec("offset", "output_offset", ["offset"], noise=0.02)])
    assert s["top1_miss_stated_tie"] == {"0.02": [1, 1], "0.1": [1, 3]}


@pytest.mark.parametrize("args, says", [(["--only", "offset,frobnication"], "--only: unknown frobnication"),
                                        (["--noise", "0.05"], "--noise: 0.05 is not a level of the grid"),
                                        (["--bases", "msd,rocket"], "--bases: unknown rocket"),
                                        (["--json", "/no/such/folder/r.json"], "--json: the folder of")])
def test_bad_bench_options_stop_before_any_record_with_exit_2(args, says, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        bd.main(args)
    assert e.value.code == 2 and says in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_a_partial_run_leaves_benchmarks_md_alone_unless_asked(tmp_path, monkeypatch):
    """--only/--noise/--limit/--no-coverage make a partial table: it is printed, and written only to an
    explicit --out (the published section of BENCHMARKS.md is the full grid's)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "BENCHMARKS.md").write_text("# Benchmarks\n")
    part = ["--only", "none", "--bases", "tank", "--noise", "0.02", "--limit", "1", "--no-coverage", "--workers", "1",
            "--n", "600", "--json", "part.json"]
    assert bd.main(part) == 0
    assert (tmp_path / "BENCHMARKS.md").read_text() == "# Benchmarks\n"
    assert bd.main(part + ["--out", "part.md"]) == 0
    text = (tmp_path / "part.md").read_text()
    assert "(partial: --only none --bases tank --noise 0.02 --limit 1 --no-coverage)" in text and "1 records" in text
    assert [r["spec"]["base"] for r in json.loads((tmp_path / "part.json").read_text())["records"]] == ["tank"]


def test_backlash_of_a_two_level_prbs_is_a_gain_change_so_it_is_not_generated():
    """The play operator of a ±a PRBS is ±(a − w/2) after every switch: a dead zone's (or a gain's)
    output, so no record can tell backlash from them, and the bench does not generate it (as for
    saturation and dead zone of a PRBS)."""
    import numpy as np

    from pipeline.bench.independent.signals import Play, prbs
    rng = np.random.default_rng(5)
    u = prbs(rng, dt=0.01, n=2000, clock=7, std=1.0)
    w = 0.8
    t = np.arange(2000) * 0.01
    raw = u.sample(t)[:, 0]
    played = Play(u, w, t[-1], 0.01).sample(t)[:, 0]
    first = int(np.argmax(np.abs(np.diff(raw)) > 0)) + 1        # after the first switch
    np.testing.assert_allclose(played[first:], np.sign(raw[first:]) * (1.0 - w / 2), atol=1e-12)
    assert not identifiable("backlash", "prbs", "msd")
    assert not any(s.family == "backlash" and s.input_kind == "prbs" for s in bd.grid(bd.TUNE_SEEDS))
    assert {s.input_kind for s in bd.grid(bd.TUNE_SEEDS) if s.family == "backlash"} == {"band", "held"}


def test_the_footer_names_the_seed_set_that_made_the_table():
    # a holdout run must not be footed "tuning seeds for this table" (the footer was fixed text before)
    for name, seeds in bd.SEED_SETS.items():
        assert bd._seed_words(name).startswith(f"{name} seeds {list(seeds)} for this table")
    assert bd.HOLDOUT_SEEDS == (3000, 3001, 3002)   # BENCHMARKS.md's holdout column was measured on these
