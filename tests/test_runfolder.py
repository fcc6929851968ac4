"""pipeline.runfolder in-process: what counts as a (complete, replaceable) run folder, the name limits,
the temp folder, publishing, cleaning stale folders, the reader's iterator, and the kernel cache."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline import runfolder as rf
from pipeline.errors import InputError
from tests.hostile.demo_project import read_only
from tests.hostile.harness import assert_bad_input, run_cli

ROOT = Path(__file__).resolve().parents[1]


def _make_run(folder: Path, files: dict[str, str] | None = None, run_id: str = "demo-0") -> Path:
    """A complete run folder written the way write_run writes it (temp, files, finalize, publish)."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = rf.make_temp(folder)
    for name, text in (files or {"summary.json": "{}\n", "metrics.json": "[]\n"}).items():
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp / name).write_text(text)
    rf.finalize(tmp, run_id)
    return rf.publish(tmp, folder)


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


# ------------------------------------------------------------ recognising run folders

def test_marker_lists_every_file_with_its_size_and_only_complete_folders_count(tmp_path):
    run = _make_run(tmp_path / "run", {"summary.json": "{}\n", "sub/fig.png": "xyz"})
    m = json.loads((run / rf.MARKER).read_text())
    sha = lambda b: hashlib.sha256(b).hexdigest()
    assert m["tool"] == "sysid-pipeline" and m["format"] == 2
    assert m["files"] == {"summary.json": {"size": 3, "sha256": sha(b"{}\n")},
                          "sub/fig.png": {"size": 3, "sha256": sha(b"xyz")}}
    assert rf.is_complete_run(run) and rf.is_replaceable_run(run)
    (run / "summary.json").write_text("[]\n")              # the user's edit, same size
    assert rf.is_complete_run(run) and not rf.is_replaceable_run(run)
    with pytest.raises(InputError, match="--out.*did not write"):
        rf.check_target(run, inputs=[], default=False)
    (run / "sub" / "fig.png").write_text("xy")             # truncated
    assert not rf.is_complete_run(run)
    (run / "sub" / "fig.png").unlink()                     # missing
    assert not rf.is_complete_run(run)


def test_a_run_folder_with_a_users_file_is_complete_but_not_replaceable(tmp_path):
    run = _make_run(tmp_path / "run")
    (run / "notes.md").write_text("mine\n")
    assert rf.is_complete_run(run) and not rf.is_replaceable_run(run)
    with pytest.raises(InputError, match="--out.*did not write"):
        rf.check_target(run, inputs=[], default=False)


@pytest.mark.parametrize("marker", [
    {"tool": "other-tool", "format": 1, "files": {}},
    {"tool": "sysid-pipeline", "files": {"../outside.txt": 2}},
    {"tool": "sysid-pipeline", "files": {"/etc/hostname": 2}},
    "not an object",
])
def test_foreign_or_hostile_markers_are_not_run_folders(tmp_path, marker):
    d = tmp_path / "d"
    d.mkdir()
    (tmp_path / "outside.txt").write_text("x\n")
    (d / rf.MARKER).write_text(json.dumps(marker))
    assert not rf.is_complete_run(d)


def test_symlink_to_a_run_folder_is_not_a_run_folder(tmp_path):
    run = _make_run(tmp_path / "run")
    (tmp_path / "lnk").symlink_to(run)
    assert not rf.is_complete_run(tmp_path / "lnk")


def test_legacy_run_folder_recognised_only_with_the_old_files(tmp_path):
    d = tmp_path / "old"
    d.mkdir()
    (d / "summary.json").write_text(json.dumps({"schema": "sysid-summary/1"}))
    (d / "manifest.json").write_text(json.dumps({"versions": {"sysid-pipeline": "0.1.0"}}))
    (d / "report.html").write_text("<html></html>")
    assert rf.is_complete_run(d) and rf.is_replaceable_run(d)
    (d / "thesis.tex").write_text("x")
    assert not rf.is_complete_run(d)


def test_iter_run_folders_yields_complete_ones_only_never_hidden_or_linked(tmp_path):
    a = _make_run(tmp_path / "a")
    b = _make_run(tmp_path / "group" / "b")
    _make_run(tmp_path / ".hidden-run")
    stale = tmp_path / f".c.tmp-{_dead_pid()}-0123abcd"       # a complete copy under a temp name
    stale.mkdir()
    (stale / "summary.json").write_text("{}\n")
    rf.finalize(stale, "demo-0")
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / "summary.json").write_text("{}\n")
    (tmp_path / "link").symlink_to(a)
    (tmp_path / "file.json").write_text("{}")
    assert list(rf.iter_run_folders(tmp_path)) == [a, b]


# ------------------------------------------------------------ names and the temp folder

def test_longest_allowed_name_can_really_be_written_and_one_byte_more_is_refused(tmp_path):
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    # the temp name adds "." + "." + "tmp-" + pid (up to 10 digits) + "-" + 8 hex = 25 bytes
    longest = "r" * (name_max - 25)
    target = rf.check_target(tmp_path / longest, inputs=[], default=False)
    _make_run(target)
    assert rf.is_complete_run(target)
    _make_run(target)                                      # a rerun uses the ".old-" name too
    assert os.listdir(tmp_path) == [longest]
    with pytest.raises(InputError, match=f"--out.*{name_max - 24} bytes"):
        rf.check_target(tmp_path / (longest + "r"), inputs=[], default=False)


@pytest.mark.parametrize("umask,mode", [(0o022, 0o755), (0o077, 0o700), (0o002, 0o775)])
def test_temp_folder_is_hidden_unique_and_follows_the_umask(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        t1, t2 = rf.make_temp(tmp_path / "run"), rf.make_temp(tmp_path / "run")
    finally:
        os.umask(old)
    assert t1 != t2
    for t in (t1, t2):
        assert re.fullmatch(rf"\.run\.tmp-{os.getpid()}-[0-9a-f]{{8}}", t.name)
        assert t.stat().st_mode & 0o7777 == mode
        assert not (t / rf.MARKER).exists() and not rf.is_complete_run(t)


# ------------------------------------------------------------ publishing

def test_publish_replaces_a_complete_run_and_leaves_nothing_hidden(tmp_path):
    target = _make_run(tmp_path / "run", {"summary.json": "old\n", "report.html": "old\n"})
    _make_run(target, {"summary.json": "new\n"})
    assert sorted(os.listdir(target)) == [rf.MARKER, "summary.json"]
    assert (target / "summary.json").read_text() == "new\n"
    assert os.listdir(tmp_path) == ["run"]


def test_publish_refuses_a_target_that_got_user_files_during_the_run(tmp_path):
    target = tmp_path / "run"
    target.mkdir()
    rf.check_target(target, inputs=[], default=False)      # empty: accepted before the analysis
    tmp = rf.make_temp(target)
    (tmp / "summary.json").write_text("{}\n")
    rf.finalize(tmp, "demo-0")
    (target / "precious.txt").write_text("created while the run was analysing\n")
    with pytest.raises(InputError, match="--out"):
        rf.publish(tmp, target)
    assert os.listdir(target) == ["precious.txt"]
    assert (target / "precious.txt").read_text() == "created while the run was analysing\n"


def test_check_waits_for_a_concurrent_publish_instead_of_seeing_its_half_way_state(tmp_path):
    """Between a publish's two renames the target is absent; a check that had just seen it there
    called it foreign ("holds files this tool did not write"): CI failure of 2026-12-03, four
    concurrent runs of one config. The check now inspects under a shared lock on the parent."""
    import threading
    target = _make_run(tmp_path / "run", {"summary.json": "old\n"})
    tmp = rf.make_temp(target)
    (tmp / "summary.json").write_text("new\n")
    rf.finalize(tmp, "demo-1")
    outcome: list = []

    def check():
        try:
            outcome.append(rf.check_target(target, inputs=[], default=False))
        except InputError as exc:   # pragma: no cover - the failure this test guards against
            outcome.append(exc)

    with rf._publish_lock(target):                       # a publisher, half-way through its swap
        old = tmp_path / ".run.old-1-00000000"
        os.rename(target, old)
        th = threading.Thread(target=check)
        th.start()
        th.join(0.5)
        assert th.is_alive(), "the check did not wait for the publisher's lock"
        os.rename(tmp, target)
        import shutil
        shutil.rmtree(old)
    th.join(10)
    assert outcome == [target.resolve()]
    assert (target / "summary.json").read_text() == "new\n"


def test_publish_does_not_follow_a_symlink_planted_during_the_run(tmp_path):
    (tmp_path / "victim").mkdir()
    (tmp_path / "victim" / "keep.txt").write_text("keep\n")
    target = tmp_path / "run"
    tmp = rf.make_temp(target)
    rf.finalize(tmp, "demo-0")
    target.symlink_to(tmp_path / "victim")
    with pytest.raises(InputError, match="--out"):
        rf.publish(tmp, target)
    assert os.listdir(tmp_path / "victim") == ["keep.txt"]


# ------------------------------------------------------------ stale folders

def test_clean_stale_removes_only_dead_or_day_old_folders_of_this_tools_naming(tmp_path):
    dead, me = _dead_pid(), os.getpid()
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("keep\n")
    made = {
        f".demo.tmp-{dead}-0123abcd": "dir", f".other.old-{dead}-89abcdef": "dir",
        f".demo.tmp-{me}-0123abcd": "dir", f".demo.tmp-{me}-fedcba98": "dir-day-old",
        f".demo.tmp-{dead}-0123abc": "dir",            # 7 hex: not our naming
        f"demo.tmp-{dead}-0123abcd": "dir",            # not hidden: not our naming
        f".demo.tmp-{dead}-0123ABCD": "dir",           # upper-case hex: not our naming
        f".demo.bak-{dead}-0123abcd": "dir",
        f".demo.tmp-{dead}-aaaaaaaa": "file",
        f".demo.tmp-{dead}-bbbbbbbb": "link",
        f".demo.tmp-{dead}-cccccccc": "empty",         # killed between mkdir and the token
        f".thesis.tmp-{dead}-deadbeef": "user",        # our naming, but a user's folder: no token
        f".thesis.old-{dead}-deadbeef": "user",        # ... and no run marker
    }
    for name, kind in made.items():
        p = tmp_path / name
        if kind == "file":
            p.write_text("x")
        elif kind == "link":
            p.symlink_to(victim)
        elif kind == "empty":
            p.mkdir()
        elif kind == "user":
            p.mkdir()
            (p / "chapter1.tex").write_text("mine\n")
        else:
            p.mkdir()
            (p / "summary.json").write_text("{}")
            if ".old-" in name:
                rf.finalize(p, "old-run")                 # a moved-aside run carries its marker
            else:
                (p / rf.TMP_TOKEN).write_text("sysid-pipeline\n")
            if kind == "dir-day-old":
                t = time.time() - 2 * rf.STALE_AGE_S
                os.utime(p, (t, t))
    removed = {p.name for p in rf.clean_stale(tmp_path)}
    assert removed == {f".demo.tmp-{dead}-0123abcd", f".other.old-{dead}-89abcdef", f".demo.tmp-{me}-fedcba98",
                       f".demo.tmp-{dead}-cccccccc"}
    assert (tmp_path / f".thesis.tmp-{dead}-deadbeef" / "chapter1.tex").read_text() == "mine\n"
    assert set(os.listdir(tmp_path)) == (set(made) - removed) | {"victim"}
    assert os.listdir(victim) == ["keep.txt"]


# ------------------------------------------------------------ check_target details

def test_inputs_are_compared_after_resolving_symlinks(tmp_path):
    (tmp_path / "data").mkdir()
    rec = tmp_path / "data" / "rec.csv"
    rec.write_text("t,u\n")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "rec.csv").symlink_to(rec)  # the input is named through a link
    with pytest.raises(InputError, match="contains the input"):
        rf.check_target(tmp_path / "data", inputs=[tmp_path / "elsewhere" / "rec.csv"], default=False)
    assert rf.check_target(tmp_path / "data" / "run", inputs=[rec], default=False) == tmp_path / "data" / "run"


def test_default_parent_may_be_missing_a_given_one_may_not(tmp_path):
    assert rf.check_target(tmp_path / "reports" / "r", inputs=[], default=True) == tmp_path / "reports" / "r"
    assert not (tmp_path / "reports").exists()             # created only when the run is written
    with pytest.raises(InputError, match="does not exist"):
        rf.check_target(tmp_path / "reports" / "r", inputs=[], default=False)


def test_read_only_parent_is_refused_in_process(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    with read_only(d):
        with pytest.raises(InputError, match="--out.*(not writable|cannot create)"):
            rf.check_target(d / "run", inputs=[], default=False)


# ------------------------------------------------------------ kernel cache

def test_kernel_cache_that_is_a_file_is_bad_input(tmp_path, monkeypatch):
    from pipeline.simulate import _cache_dir
    (tmp_path / "cache").write_text("a file\n")
    monkeypatch.setenv("SYSID_KERNEL_CACHE", str(tmp_path / "cache"))
    with pytest.raises(InputError, match=f"SYSID_KERNEL_CACHE={re.escape(str(tmp_path / 'cache'))}"):
        _cache_dir()


def test_kernel_cache_in_a_read_only_place_is_bad_input(tmp_path, monkeypatch):
    from pipeline.simulate import _cache_dir
    d = tmp_path / "ro"
    d.mkdir()
    with read_only(d):
        monkeypatch.setenv("SYSID_KERNEL_CACHE", str(d / "cache"))
        with pytest.raises(InputError, match="SYSID_KERNEL_CACHE=.*ro/cache"):
            _cache_dir()
    monkeypatch.setenv("SYSID_KERNEL_CACHE", "/proc/sysid-cache")
    with pytest.raises(InputError, match="SYSID_KERNEL_CACHE=/proc/sysid-cache"):
        _cache_dir()


def test_kernel_cache_problem_through_the_cli_is_one_error_line(tmp_path):
    (tmp_path / "cache").write_text("a file\n")
    (tmp_path / "out").mkdir()
    res = run_cli("diagnose", str(ROOT / "configs" / "demo.yaml"), "--out", str(tmp_path / "out" / "r"),
                  env={"SYSID_KERNEL_CACHE": str(tmp_path / "cache")})
    assert_bad_input(res, "SYSID_KERNEL_CACHE", str(tmp_path / "cache"))
    assert os.listdir(tmp_path / "out") == []


def test_a_ctrl_c_lost_in_a_callback_still_publishes_nothing(tmp_path, capsys, monkeypatch):
    """Python drops a KeyboardInterrupt raised while a weakref callback runs ("Exception ignored in");
    an independent probe saw a run go on to publish its folder and exit 0 after Ctrl-C (1 in 12 tries).
    The CLI's SIGINT handler marks the process, and publish refuses once marked: here the handler runs
    and its exception is swallowed, as in that case."""
    import signal as _signal

    from pipeline import runs
    from pipeline.cli import main
    real = runs.analyse

    def analyse_then_interrupted(lc):
        ctx = real(lc)
        try:
            _signal.getsignal(_signal.SIGINT)(_signal.SIGINT, None)
        except KeyboardInterrupt:
            pass                                   # lost, as in a weakref callback
        return ctx

    monkeypatch.setattr(runs, "analyse", analyse_then_interrupted)
    cfg = Path(__file__).resolve().parents[1] / "configs" / "demo.yaml"
    out = tmp_path / "run"
    code = main(["diagnose", str(cfg), "--out", str(out)])
    assert code == 130 and "interrupted; no run folder written" in capsys.readouterr().err
    assert not out.exists() and not any(tmp_path.iterdir())
    assert not rf.INTERRUPTED.is_set()             # cleared for the next command in this process


@pytest.mark.parametrize("inside", [".git/sysid", ".git/hooks/r", ".hg/r", ".git"])
def test_a_target_inside_version_control_internals_is_refused(tmp_path, inside):
    """An independent probe wrote a run folder into a checkout's .git/ (accepted as any new folder): it
    would become part of git's internals. The checkout itself may hold run folders (reports/NAME)."""
    (tmp_path / ".git" / "hooks").mkdir(parents=True)
    (tmp_path / ".hg").mkdir()
    with pytest.raises(InputError, match="belongs to version control"):
        rf.check_target(tmp_path / inside, inputs=[], default=False)
    assert sorted(p.name for p in (tmp_path / ".git").iterdir()) == ["hooks"]
    assert rf.check_target(tmp_path / "reports_r", inputs=[], default=False) == (tmp_path / "reports_r").resolve()
