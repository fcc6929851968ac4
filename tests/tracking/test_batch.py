"""sysid batch: failures are reported, not fatal; the Dask executor gives the same bytes."""

import json
from pathlib import Path

import pytest

from pipeline.batch import exit_code, run_batch
from pipeline.cli import main


def test_batch_runs_the_good_configs_and_reports_the_broken_one(batch_runs):
    res = batch_runs["results"]
    # results come back in input order, whatever order the workers finished in
    assert [Path(r.config).stem for r in res] == ["a", "broken", "b", "c"]
    assert [r.ok for r in res] == [True, False, True, True]
    bad = res[1]
    assert bad.kind == "input" and bad.path is None
    assert "model.free" in bad.error and "nosuch" in bad.error
    for r in (res[0], res[2], res[3]):
        s = json.loads((Path(r.path) / "summary.json").read_text())
        assert s["run_id"] == r.run_id and Path(r.path).name == r.run_id
    assert exit_code(res) == 2
    # only complete run folders are left in the root: no temp folder of the failed config
    assert sorted(p.name for p in batch_runs["root"].iterdir()) == sorted(r.run_id for r in res if r.ok)


def test_batch_cli_prints_the_runs_table_and_the_error(batch_runs, capsys, tmp_path):
    cfgs = batch_runs["configs"]
    code = main(["batch", str(cfgs["a"]), str(cfgs["broken"]), "--jobs", "1", "--root", str(tmp_path)])
    out, err = capsys.readouterr()
    assert code == 2
    assert "demo-" in out and "cubic_stiffness" in out and "1 of 2 configs ran; 1 failed" in out
    assert err.count("error:") == 1 and "nosuch" in err and "Traceback" not in err


def test_configs_that_are_one_run_are_listed_once_with_a_note(batch_runs, capsys, tmp_path):
    """Two files with the same config and data are one run (one run id, one folder): an independent probe
    saw the folder listed once per config (and `--track` would log it as that many MLflow runs)."""
    cfgs = batch_runs["configs"]
    copy = tmp_path / "copy_of_a.yaml"
    copy.write_text(Path(cfgs["a"]).read_text())
    assert main(["batch", str(cfgs["a"]), str(copy), "--jobs", "1", "--root", str(tmp_path / "r")]) == 0
    out, err = capsys.readouterr()
    rows = [line for line in out.splitlines() if "demo-" in line]
    assert len(rows) == 1 and "2 of 2 configs ran (1 run folder)\n" in out, out
    assert err.count("\n") == 1 and err.startswith(f"note: {copy} is the same run as {cfgs['a']}"), err


def test_a_batch_where_every_config_fails_leaves_no_folder_it_made(batch_runs, capsys, tmp_path):
    """Nothing half-written: when no run succeeds, the --root folder this batch created is removed (it is
    empty, and so are the parents it created); a --root that existed before is left as it was."""
    cfgs = batch_runs["configs"]
    assert main(["batch", str(cfgs["broken"]), "--jobs", "1", "--root", str(tmp_path / "new" / "root")]) == 2
    assert "0 of 1 configs ran" in capsys.readouterr().out
    assert not (tmp_path / "new").exists()
    (tmp_path / "mine").mkdir()
    assert main(["batch", str(cfgs["broken"]), "--jobs", "1", "--root", str(tmp_path / "mine")]) == 2
    assert (tmp_path / "mine").is_dir()


def test_bad_batch_options_are_input_errors(capsys):
    assert main(["batch", "x.yaml", "--jobs", "0"]) == 2
    assert main(["batch", "x.yaml", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert "--jobs" in err and "--executor dask" in err and "Traceback" not in err


def test_dask_local_cluster_gives_byte_identical_summaries(batch_runs, tmp_path):
    pytest.importorskip("distributed")
    cfgs = batch_runs["configs"]
    res = run_batch([str(cfgs["a"]), str(cfgs["broken"]), str(cfgs["c"])], jobs=2, executor="dask",
                    root=tmp_path)
    assert [r.ok for r in res] == [True, False, True]
    assert "nosuch" in res[1].error
    local = {r.run_id: Path(r.path) for r in batch_runs["results"] if r.ok}
    for r in (res[0], res[2]):
        for f in ("summary.json", "metrics.json", "params.yaml"):
            assert (Path(r.path) / f).read_bytes() == (local[r.run_id] / f).read_bytes(), f


def test_run_tasks_keeps_input_order_on_every_executor():
    """The generic executor path `sysid grade` uses: any picklable callable, results in input order."""
    from pipeline.batch import run_tasks
    from pipeline.errors import InputError
    items = [-3, 1, -2, 5, -4]
    assert run_tasks(abs, items, jobs=1) == [3, 1, 2, 5, 4]
    assert run_tasks(abs, items, jobs=2) == [3, 1, 2, 5, 4]
    assert run_tasks(abs, [], jobs=2) == []
    for kw in ({"jobs": 0}, {"executor": "slurm"}, {"scheduler": "tcp://x:1"}):
        with pytest.raises(InputError):
            run_tasks(abs, items, **kw)
