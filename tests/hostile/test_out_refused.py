"""Data-loss corpus: every ``--out`` that would destroy or cannot hold a run folder is refused before
the analysis (exit 2, one ``error:`` line naming ``--out``, no traceback, no ``[diagnose]`` progress,
fast) and every file that was there before is byte-identical afterwards (nothing added either)."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from .demo_project import Project, make_project, read_only, tree
from .harness import assert_bad_input, run_cli

FAST_S = 10.0  # the demo's analysis alone takes ~3 s, import + config load well under 2 s


def _user_folder(tmp: Path, p: Project) -> tuple[str, Path]:
    d = tmp / "mystuff"
    (d / "sub").mkdir(parents=True)
    (d / "thesis.tex").write_text("years of work\n")
    (d / "sub" / "notes.txt").write_text("more\n")
    (d / ".hidden").write_text("dotfile\n")
    return str(d), p.root


def _git_checkout_dot(tmp: Path, p: Project) -> tuple[str, Path]:
    subprocess.run(["git", "init", "-q", str(p.root)], check=True)
    (p.root / "README").write_text("my repo\n")
    return ".", p.root


def _data_folder(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(p.data.parent), p.root


def _config_folder(tmp: Path, p: Project) -> tuple[str, Path]:
    return "configs", p.root


def _data_ancestor(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(p.root), tmp


def _data_file_itself(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(p.data), p.root


def _a_file(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "results.txt").write_text("not a folder\n")
    return str(tmp / "results.txt"), p.root


def _symlink_to_folder(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "elsewhere").mkdir()
    (tmp / "elsewhere" / "keep.txt").write_text("keep\n")
    (tmp / "lnk").symlink_to(tmp / "elsewhere")
    return str(tmp / "lnk"), p.root


def _symlink_to_empty_folder(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "empty").mkdir()
    (tmp / "lnk").symlink_to(tmp / "empty")
    return str(tmp / "lnk"), p.root


def _symlink_to_file(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "f.txt").write_text("x\n")
    (tmp / "lnk").symlink_to(tmp / "f.txt")
    return str(tmp / "lnk"), p.root


def _dangling_symlink(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "lnk").symlink_to(tmp / "does-not-exist")
    return str(tmp / "lnk"), p.root


def _data_folder_via_symlinked_parent(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "alias").symlink_to(p.root)   # alias/data is the data's folder once the link is resolved
    return str(tmp / "alias" / "data"), tmp


def _parent_is_file(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "plain").write_text("a file\n")
    return str(tmp / "plain" / "run"), p.root


def _missing_parent(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(tmp / "no" / "such" / "run"), p.root


def _name_300(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(tmp / ("r" * 300)), p.root


def _name_just_over_temp_limit(tmp: Path, p: Project) -> tuple[str, Path]:
    # 250 bytes pass NAME_MAX (255) but its hidden temp folder ".<name>.tmp-<pid>-<hex8>" would not
    return str(tmp / ("r" * 250)), p.root


def _proc_self(tmp: Path, p: Project) -> tuple[str, Path]:
    return "/proc/self", p.root


def _proc_new(tmp: Path, p: Project) -> tuple[str, Path]:
    return "/proc/xyz", p.root


def _sys_new(tmp: Path, p: Project) -> tuple[str, Path]:
    return "/sys/sysid-run", p.root


def _cwd_parent(tmp: Path, p: Project) -> tuple[str, Path]:
    return "..", p.root / "configs"


def _filesystem_root(tmp: Path, p: Project) -> tuple[str, Path]:
    return "/", p.root


def _empty_string(tmp: Path, p: Project) -> tuple[str, Path]:
    return "", p.root   # not silently the default, not the current folder


def _symlink_loop_parent(tmp: Path, p: Project) -> tuple[str, Path]:
    (tmp / "loop1").symlink_to(tmp / "loop2")
    (tmp / "loop2").symlink_to(tmp / "loop1")
    return str(tmp / "loop1" / "run"), p.root


def _over_long_parent_component(tmp: Path, p: Project) -> tuple[str, Path]:
    return str(tmp / ("d" * 300) / "run"), p.root


def _run_folder_with_user_file(tmp: Path, p: Project) -> tuple[str, Path]:
    # a complete earlier run (marker and files) to which the user added a note: not replaceable
    d = tmp / "run"
    d.mkdir()
    (d / "summary.json").write_text("{}\n")
    (d / ".sysid-run").write_text('{"tool": "sysid-pipeline", "format": 1, "run_id": "demo-x", '
                                  '"files": {"summary.json": 3}}\n')
    (d / "my-notes.md").write_text("the reviewer said...\n")
    return str(d), p.root


def _folder_with_forged_marker_missing_files(tmp: Path, p: Project) -> tuple[str, Path]:
    d = tmp / "run"
    d.mkdir()
    (d / ".sysid-run").write_text('{"tool": "sysid-pipeline", "format": 1, "run_id": "demo-x", '
                                  '"files": {"summary.json": 3}}\n')
    (d / "data.csv").write_text("1,2\n")
    return str(d), p.root


CASES = {
    "user_folder": (_user_folder, "holds files this tool did not write"),
    "dot_in_git_checkout": (_git_checkout_dot, "current folder"),
    "data_folder": (_data_folder, "contains the input"),
    "config_folder": (_config_folder, "contains the input"),
    "ancestor_of_data": (_data_ancestor, "contains the input"),
    "data_folder_via_symlinked_parent": (_data_folder_via_symlinked_parent, "contains the input"),
    "data_file_itself": (_data_file_itself, "a file"),
    "a_file": (_a_file, "a file"),
    "symlink_to_folder": (_symlink_to_folder, "symlink"),
    "symlink_to_empty_folder": (_symlink_to_empty_folder, "symlink"),
    "symlink_to_file": (_symlink_to_file, "symlink"),
    "dangling_symlink": (_dangling_symlink, "symlink"),
    "parent_is_a_file": (_parent_is_file, "not a folder"),
    "missing_parent": (_missing_parent, "does not exist"),
    "name_300_chars": (_name_300, "bytes"),
    "name_fits_but_temp_would_not": (_name_just_over_temp_limit, "bytes"),
    "proc_self": (_proc_self, "/proc"),
    "proc_new_name": (_proc_new, "/proc"),
    "sys_new_name": (_sys_new, "/sys"),
    "parent_of_cwd": (_cwd_parent, "ancestor of the current folder"),
    "filesystem_root": (_filesystem_root, "ancestor of the current folder"),
    "empty_string": (_empty_string, "not a usable path"),
    "symlink_loop_in_parent": (_symlink_loop_parent, "symbolic links"),
    "over_long_parent_component": (_over_long_parent_component, "bytes"),
    "run_folder_with_user_file": (_run_folder_with_user_file, "holds files this tool did not write"),
    "forged_marker_missing_files": (_folder_with_forged_marker_missing_files, "holds files"),
}


def _assert_refused_fast(res, elapsed: float, *mention: str) -> None:
    assert_bad_input(res, "--out", *mention)
    assert "[diagnose]" not in res.stderr, "the analysis ran before --out was checked"
    assert elapsed < FAST_S, f"{elapsed:.1f} s: the analysis ran before --out was checked"


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_out_is_refused_before_the_analysis_and_changes_nothing(tmp_path, case):
    setup, mention = CASES[case]
    p = make_project(tmp_path)
    out, cwd = setup(tmp_path, p)
    before = tree(tmp_path)
    t0 = time.perf_counter()
    res = run_cli("report", str(p.config), "--out", out, cwd=cwd)
    _assert_refused_fast(res, time.perf_counter() - t0, mention)
    assert tree(tmp_path) == before


@pytest.fixture
def read_only_folder(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    (d / "existing.txt").write_text("keep\n")
    with read_only(d):
        yield d


def test_read_only_parent_is_refused(tmp_path, read_only_folder):
    p = make_project(tmp_path)
    before = tree(tmp_path)
    t0 = time.perf_counter()
    res = run_cli("report", str(p.config), "--out", str(read_only_folder / "run"), cwd=p.root)
    _assert_refused_fast(res, time.perf_counter() - t0, str(read_only_folder))
    assert tree(tmp_path) == before


def test_unwritable_default_reports_is_refused(tmp_path):
    """The default ``reports/<run-id>`` where ``reports`` is a file: refused, the file intact."""
    p = make_project(tmp_path)
    (p.root / "reports").write_text("my reports list\n")
    before = tree(tmp_path)
    t0 = time.perf_counter()
    res = run_cli("diagnose", str(p.config), cwd=p.root)
    _assert_refused_fast(res, time.perf_counter() - t0, "reports")
    assert tree(tmp_path) == before
