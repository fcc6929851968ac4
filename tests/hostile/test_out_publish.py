"""Publishing a run folder through the real CLI: replacing an earlier run, filling an empty folder, the
folder's mode, SIGKILL at every step of a fresh run and of a rerun, and concurrent runs of one config."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.runfolder import is_replaceable_run

from .demo_project import make_project, marker, run_files, tree
from .harness import ROOT, run_cli



@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """A project and two complete runs of it made by the CLI: ``report`` (with report.html) and
    ``diagnose`` (without), each in its own parent, for the tests to copy."""
    base = tmp_path_factory.mktemp("ref")
    p = make_project(base)
    for cmd in ("report", "diagnose"):
        (base / cmd).mkdir()
        res = run_cli(cmd, str(p.config), "--out", str(base / cmd / "run"), cwd=p.root)
        assert res.rc == 0, res.stderr[-2000:]
    return p, base / "report" / "run", base / "diagnose" / "run"


def _is_new_diagnose_run(folder: Path, ref_diag: Path) -> bool:
    """``folder`` is a complete ``diagnose`` run with the same files as the reference one."""
    return (is_replaceable_run(folder) and not (folder / "report.html").exists()
            and run_files(folder) == run_files(ref_diag))


def _hidden(parent: Path) -> list[str]:
    return sorted(n for n in os.listdir(parent) if n.startswith("."))


def test_rerun_replaces_a_complete_earlier_run(tmp_path, reference):
    p, ref_report, ref_diag = reference
    target = tmp_path / "run"
    shutil.copytree(ref_report, target)
    assert (target / "report.html").exists()
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root)
    assert res.rc == 0, res.stderr[-2000:]
    # the old run's report.html is gone: the folder was replaced, not written over
    assert _is_new_diagnose_run(target, ref_diag)
    assert sorted(marker(target)["files"]) == sorted(n for n in os.listdir(target) if n != ".sysid-run")
    assert _hidden(tmp_path) == []


def test_rerun_replaces_a_legacy_run_folder(tmp_path, reference):
    """Run folders of releases before the marker (same files, no ``.sysid-run``) are replaced too."""
    p, ref_report, ref_diag = reference
    target = tmp_path / "run"
    shutil.copytree(ref_report, target)
    (target / ".sysid-run").unlink()
    (target / "simulation.csv").unlink()   # legacy runs had no simulated series
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root)
    assert res.rc == 0, res.stderr[-2000:]
    assert _is_new_diagnose_run(target, ref_diag)


def test_empty_folder_is_filled_with_mode_0755_under_umask_022(tmp_path, reference):
    p, _, ref_diag = reference
    target = tmp_path / "run"
    target.mkdir(mode=0o700)
    old = os.umask(0o022)
    try:
        res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root)
    finally:
        os.umask(old)
    assert res.rc == 0, res.stderr[-2000:]
    assert _is_new_diagnose_run(target, ref_diag)
    assert target.stat().st_mode & 0o7777 == 0o755
    assert all(f.stat().st_mode & 0o7777 == 0o644 for f in target.iterdir())


def test_default_reports_folder_is_created_and_rerun_in_place(tmp_path, reference):
    p, _, ref_diag = reference
    for _ in range(2):
        res = run_cli("diagnose", str(p.config), cwd=p.root)
        assert res.rc == 0, res.stderr[-2000:]
    runs = os.listdir(p.root / "reports")
    assert len(runs) == 1 and runs[0].startswith("demo-")
    assert _is_new_diagnose_run(p.root / "reports" / runs[0], ref_diag)
    assert (p.root / "reports").stat().st_mode & 0o7777 == 0o755


FRESH_POINTS = ("after_temp_created", "after_summary_written", "after_new_renamed_in")
RERUN_POINTS = ("after_temp_created", "after_summary_written", "after_old_moved_aside",
                "after_new_renamed_in", "before_old_deleted")


@pytest.mark.parametrize("point", FRESH_POINTS)
def test_kill_during_a_fresh_run_never_leaves_a_partial_folder(tmp_path, reference, point):
    p, _, ref_diag = reference
    target = tmp_path / "run"
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root,
                  env={"SYSID_TEST_KILL_AT": point})
    assert res.rc == -signal.SIGKILL, f"the hook did not fire: exit {res.rc}\n{res.stderr[-1000:]}"
    if point == "after_new_renamed_in":
        assert _is_new_diagnose_run(target, ref_diag)
    else:
        assert not os.path.lexists(target)
        assert _hidden(tmp_path), "the killed run's temp folder should be there to clean"
    # the next run into the same parent publishes and removes the dead run's temp folder
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root)
    assert res.rc == 0, res.stderr[-2000:]
    assert _is_new_diagnose_run(target, ref_diag)
    assert _hidden(tmp_path) == []


@pytest.mark.parametrize("point", RERUN_POINTS)
def test_kill_during_a_rerun_leaves_the_old_or_the_new_run(tmp_path, reference, point):
    p, ref_report, ref_diag = reference
    target = tmp_path / "run"
    shutil.copytree(ref_report, target)
    old_tree = tree(target)
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root,
                  env={"SYSID_TEST_KILL_AT": point})
    assert res.rc == -signal.SIGKILL, f"the hook did not fire: exit {res.rc}\n{res.stderr[-1000:]}"
    if point in ("after_temp_created", "after_summary_written"):
        assert tree(target) == old_tree                 # the complete old run, untouched
    elif point == "after_old_moved_aside":
        assert not os.path.lexists(target)              # absent; the old run is hidden aside
        aside = [n for n in _hidden(tmp_path) if ".old-" in n]
        assert len(aside) == 1 and tree(tmp_path / aside[0]) == old_tree
    else:
        assert _is_new_diagnose_run(target, ref_diag)   # the complete new run
    assert _hidden(tmp_path), "the killed run leaves a hidden temp or old folder to clean"
    res = run_cli("diagnose", str(p.config), "--out", str(target), cwd=p.root)
    assert res.rc == 0, res.stderr[-2000:]
    assert _is_new_diagnose_run(target, ref_diag)
    assert _hidden(tmp_path) == []


def test_four_concurrent_runs_of_one_config_three_rounds(tmp_path, reference):
    p, _, ref_diag = reference
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
               MPLBACKEND="Agg")
    for rnd in range(3):
        procs = [subprocess.Popen([sys.executable, "-m", "pipeline", "diagnose", str(p.config)],
                                  cwd=p.root, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True) for _ in range(4)]
        outs = [pr.communicate(timeout=300) for pr in procs]
        for pr, (_, err) in zip(procs, outs):
            assert pr.returncode == 0, f"round {rnd}: exit {pr.returncode}\n{err[-2000:]}"
        entries = os.listdir(p.root / "reports")
        assert len(entries) == 1, f"round {rnd}: {entries}"
        assert _is_new_diagnose_run(p.root / "reports" / entries[0], ref_diag)
