"""Shared harness of the hostile-input corpus: run the real CLI in a subprocess under a time and memory
bound and check the contract for bad input (exit 2, one ``error:`` line naming the file and the key or
column, no traceback, nothing left behind)."""

from __future__ import annotations

import hashlib
import os
import resource
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MEMORY_LIMIT = 3 << 30    # bytes of address space per CLI run
TIME_LIMIT = 120          # seconds per CLI run


@dataclass
class CliResult:
    rc: int
    stdout: str
    stderr: str


def _limits():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_cli(*args: str, cwd: Path | None = None, timeout: float = TIME_LIMIT, env: dict | None = None) -> CliResult:
    """``python -m pipeline ARGS`` with this checkout's package first on the path."""
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    e.setdefault("MPLBACKEND", "Agg")
    e.update(env or {})
    p = subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=cwd or ROOT, capture_output=True,
                       text=True, timeout=timeout, env=e, preexec_fn=_limits)
    return CliResult(p.returncode, p.stdout, p.stderr)


def snapshot(folder: Path) -> dict[str, str]:
    """sha256 of every file below ``folder`` (relative path -> digest), links not followed."""
    out = {}
    for p in sorted(Path(folder).rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def assert_bad_input(res: CliResult, *must_mention: str) -> None:
    """Exit 2, no traceback, exactly one ``error:`` line that mentions every given string."""
    assert res.rc == 2, f"exit {res.rc}, stderr:\n{res.stderr[-2000:]}"
    assert "Traceback" not in res.stderr, res.stderr[-2000:]
    errs = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errs) == 1, res.stderr[-2000:]
    for s in must_mention:
        assert s in errs[0], f"{s!r} not in {errs[0]!r}"
