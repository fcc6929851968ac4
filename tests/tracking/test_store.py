"""The run store on three runs: list, filter, sort, compare (library and CLI)."""

import json
import math
import shutil
from pathlib import Path

import pytest
import yaml

from pipeline import store
from pipeline.cli import main
from pipeline.errors import InputError


def _summary(p: Path) -> dict:
    return json.loads((p / "summary.json").read_text())


def test_list_reads_every_complete_run_and_skips_incomplete_folders(batch_runs, tmp_path):
    root = tmp_path / "runs"
    shutil.copytree(batch_runs["root"], root)
    # a hidden temp folder (a run being written) and a folder without manifest.json are not runs
    shutil.copytree(next(root.iterdir()), root / ".demo-x.tmp-1")
    (root / "half").mkdir()
    (root / "half" / "summary.json").write_text("{}")
    runs = store.list_runs(root)
    assert sorted(r.path.name for r in runs) == sorted(p.name for p in batch_runs["root"].iterdir())
    for r in runs:
        s = _summary(r.path)
        row = r.row()
        assert row["run_id"] == s["run_id"] and row["verdict"] == s["diagnosis"]["verdict"]
        assert row["val_fit"] == s["final"]["validation"]["fit_percent"]
        assert row["bic"] == s["final"]["bic"] and row["data"] == "demo.csv"
        f = s["diagnosis"]["findings"]
        assert row["main_cause"] == (f[0]["family"] if f else None)
        if f:
            assert row["gain"] == pytest.approx(100 * f[0]["gain"]["relative"])


def test_filter_and_sort(batch_runs):
    runs = store.list_runs(batch_runs["root"])
    names = lambda rs: [r.row()["name"] for r in rs]  # noqa: E731
    found = store.filter_runs(runs, ["main_cause=cubic_stiffness"])
    assert sorted(names(found)) == ["demo", "demo_b"]          # demo_c was not allowed a finding
    assert names(store.filter_runs(runs, ["config.diagnose.alpha=0.05"])) == ["demo_b"]
    assert sorted(names(store.filter_runs(runs, ["name!=demo_b", "val_fit>90"]))) == ["demo"]
    by_fit = store.sort_runs(runs, "val_fit")
    fits = [r.row()["val_fit"] for r in by_fit]
    assert fits == sorted(fits) and names(by_fit)[0] == "demo_c"  # the nominal model fits worst
    assert names(store.sort_runs(runs, "-val_fit"))[-1] == "demo_c"
    assert names(store.sort_runs(runs, "name")) == ["demo", "demo_b", "demo_c"]
    # a key no run has is a typo: bad input, not an empty table
    with pytest.raises(InputError, match="no run has 'verdikt'"):
        store.filter_runs(runs, ["verdikt=discrepancy"])
    with pytest.raises(InputError, match="KEY=VALUE"):
        store.filter_runs(runs, ["verdict"])
    with pytest.raises(InputError, match="no run has"):
        store.sort_runs(runs, "bicc")


def test_compare_names_what_changed(batch_runs):
    root = batch_runs["root"]
    by = {r.row()["name"]: r for r in store.list_runs(root)}
    c = store.compare(store.resolve(by["demo"].run_id, root), store.resolve(by["demo_c"].run_id[:9], root))
    cfg = {row["key"]: (row["a"], row["b"]) for row in c["config"]}
    assert cfg["diagnose.max_findings"] == (3, 0) and cfg["name"] == ("demo", "demo_c")
    assert c["data"] == []                                     # same record
    assert c["findings"]["only_a"] == ["cubic_stiffness in v (x**3)"] and c["findings"]["b"] == []
    sa, sc = _summary(by["demo"].path), _summary(by["demo_c"].path)
    params = {row["key"]: row for row in c["parameters"]}
    assert params["final.k"]["a"] == sa["final"]["params"]["k"] and params["final.k"]["b"] == sc["final"]["params"]["k"]
    assert params["final.cubic_stiffness_v_x"]["b"] is None    # only the extended model has it
    m = {row["key"]: row for row in c["metrics"]}
    fa, fc = sa["final"]["validation"]["fit_percent"], sc["final"]["validation"]["fit_percent"]
    assert m["final.validation.fit_percent"]["delta"] == pytest.approx(fc - fa)
    text = store.format_compare(c)
    for needle in ("## config", "diagnose.max_findings", "## parameters", "## findings", "## metrics"):
        assert needle in text


def test_runs_and_compare_cli(batch_runs, capsys):
    root = str(batch_runs["root"])
    assert main(["runs", "--root", root, "--sort=-val_fit"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[:2] == ["name", "run"] and "main cause" in out[0] and "val. fit %" in out[0]
    assert [line.split()[0] for line in out[2:]] == ["demo", "demo_b", "demo_c"] or \
        [line.split()[0] for line in out[2:]] == ["demo_b", "demo", "demo_c"]
    assert main(["runs", "--root", root, "--where", "main_cause=cubic_stiffness", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert sorted(r["name"] for r in rows) == ["demo", "demo_b"]
    assert main(["compare", "demo-", "demo_c", "--root", root]) == 0
    assert "diagnose.max_findings" in capsys.readouterr().out
    assert main(["compare", "demo", "nosuch", "--root", root]) == 2   # "demo" prefixes three runs
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1


def test_ordering_where_on_text_or_a_mapping_is_bad_input(batch_runs, capsys):
    """An independent probe: ``verdict>3`` and ``diagnosis>3`` (a mapping, compared as its text) listed
    every run with exit 0. > and < compare numbers with numbers, or text with text that is not a number
    (an ISO date with ``created``); anything else is exit 2 naming --where."""
    root = str(batch_runs["root"])
    for w, what in (("verdict>3", "'verdict' is text"), ("diagnosis>3", "'diagnosis' is a dict (a mapping)"),
                    ("metrics.final<=0", "'metrics.final' is a dict")):
        assert main(["runs", "--root", root, "--where", w]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: --where: ") and what in err and err.count("\n") == 1, err
    assert main(["runs", "--root", root, "--where", "created>2000-01-01", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 3
    assert main(["runs", "--root", root, "--where", "created>2999-01-01", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == []
    assert main(["runs", "--root", root, "--where", "metrics.final.validation.fit_percent>-1e9", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 3


def test_one_run_id_in_two_folders_asks_for_the_folder(batch_runs, tmp_path, capsys):
    """The same config and data run into two folders share a run id, so no longer prefix tells them apart
    (an independent probe got "give more of the run id" where there was none to give): the message lists
    the folders and asks for one; the folder's path then resolves."""
    import shutil
    root = tmp_path / "runs"
    shutil.copytree(batch_runs["root"], root)
    a = next(p for p in root.iterdir() if p.name.startswith("demo-"))
    shutil.copytree(a, root / "copy_of_demo")
    rid = json.loads((a / "summary.json").read_text())["run_id"]
    assert main(["compare", rid, "demo_c", "--root", str(root)]) == 2
    err = capsys.readouterr().err
    assert f"matches 2 runs ({rid} in " in err and str(root / "copy_of_demo") in err, err
    assert err.rstrip().endswith("give the run folder's path") and err.count("\n") == 1
    assert main(["compare", str(root / "copy_of_demo"), "demo_c", "--root", str(root)]) == 0


def test_runs_says_which_edited_run_folders_it_skips(batch_runs, tmp_path, capsys):
    """A run folder whose files were changed by hand is no longer listed (its marker does not match);
    an independent probe found it skipped silently. ``runs`` names it on stderr and lists the others."""
    import shutil
    root = tmp_path / "runs"
    shutil.copytree(batch_runs["root"], root)
    edited = next(p for p in root.iterdir() if p.name.startswith("demo_b"))
    with open(edited / "params.yaml", "a") as fh:
        fh.write("# my note\n")
    assert main(["runs", "--root", str(root), "--json"]) == 0
    out, err = capsys.readouterr()
    assert sorted(r["name"] for r in json.loads(out)) == ["demo", "demo_c"]
    assert err.count("\n") == 1 and err.startswith(f"warning: skipped {edited}: its files changed after the run")


def test_compare_refuses_an_edited_run_folder_and_names_a_folder_that_is_not_one(batch_runs, tmp_path, capsys):
    """An independent probe set a run's verdict to ['x'] by hand and `compare` reported
    "verdict: discrepancy -> ['x']" with exit 0; a folder without summary.json got "no run … under
    reports". Now the edited folder is exit 2 naming the edited file (a note added beside the files is
    fine: it changes nothing the run says), and the plain folder is named as not a run folder."""
    import shutil
    root = tmp_path / "runs"
    shutil.copytree(batch_runs["root"], root)
    a, b = (next(p for p in root.iterdir() if p.name.startswith(n)) for n in ("demo-", "demo_b"))
    (b / "my_notes.txt").write_text("looked at this on Monday\n")
    assert main(["compare", str(a), str(b), "--root", str(root)]) == 0
    capsys.readouterr()
    s = json.loads((b / "summary.json").read_text())
    s["diagnosis"]["verdict"] = ["x"]
    (b / "summary.json").write_text(json.dumps(s))
    assert main(["compare", str(a), str(b), "--root", str(root)]) == 2
    out, err = capsys.readouterr()
    assert not out and err == f"error: {b}: was changed after the run (edited: summary.json): its numbers are " \
                              "not this tool's; rerun its config\n"
    (tmp_path / "plain").mkdir()
    assert main(["compare", str(a), str(tmp_path / "plain"), "--root", str(root)]) == 2
    assert "plain: is a folder but not a run folder (no summary.json)" in capsys.readouterr().err


def test_metrics_and_params_follow_dvc_conventions(batch_runs):
    """DVC reads metrics as a tree of mappings with numeric leaves (lists and nulls are not metrics);
    params.yaml is what the stage consumed (the config)."""
    for p in batch_runs["root"].iterdir():
        m = json.loads((p / "metrics.json").read_text())

        def walk(x, path=""):
            if isinstance(x, dict):
                assert x, path
                for k, v in x.items():
                    walk(v, f"{path}.{k}")
            else:
                assert isinstance(x, (int, float)) and math.isfinite(x), (path, x)
        walk(m)
        s = _summary(p)
        assert m["final"]["validation"]["fit_percent"] == s["final"]["validation"]["fit_percent"]
        assert m["nominal"]["params"] == s["nominal"]["params"]
        assert set(m["models"]) == {x["name"] for x in s["models"]}
        params = yaml.safe_load((p / "params.yaml").read_text())
        assert params == yaml.safe_load((p / "config.resolved.yaml").read_text())
