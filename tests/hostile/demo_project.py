"""A throw-away copy of the demo (config in ``configs/``, record in ``data/``) and a tree fingerprint,
shared by the run-folder tests of the hostile corpus."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from .harness import ROOT


@dataclass
class Project:
    root: Path       # the project folder (an ancestor of both inputs)
    config: Path     # root/configs/demo.yaml
    data: Path       # root/data/demo.csv


def make_project(base: Path) -> Project:
    """``base/proj`` holding ``configs/demo.yaml`` (reading ``../data/demo.csv``) and ``data/demo.csv``."""
    root = base / "proj"
    (root / "configs").mkdir(parents=True)
    (root / "data").mkdir()
    shutil.copy(ROOT / "data" / "demo.csv", root / "data" / "demo.csv")
    cfg = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    cfg["data"]["path"] = "../data/demo.csv"
    (root / "configs" / "demo.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return Project(root, root / "configs" / "demo.yaml", root / "data" / "demo.csv")


def tree(folder: Path) -> dict[str, str]:
    """Every entry below ``folder`` (links not followed): a file's sha256, a folder as ``dir`` with
    its mode, a symlink as ``link -> target``. Equal trees mean nothing was added, removed or changed."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        for n in sorted(dirnames + filenames):
            p = Path(dirpath) / n
            rel = str(p.relative_to(folder))
            if p.is_symlink():
                out[rel] = f"link -> {os.readlink(p)}"
            elif p.is_dir():
                out[rel] = f"dir {oct(p.stat().st_mode & 0o7777)}"
            else:
                out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def run_files(folder: Path) -> dict[str, bytes]:
    """The files of a run folder by name (the marker and the volatile manifest aside)."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())
            if p.is_file() and p.name not in (".sysid-run", "manifest.json")}


def marker(folder: Path) -> dict:
    return json.loads((folder / ".sysid-run").read_text())


@contextlib.contextmanager
def read_only(d: Path):
    """Make the folder ``d`` one nothing can be created in: chmod 0555 for a normal user; as root (who
    ignores modes) a read-only bind mount of it onto itself; ``pytest.skip`` where neither works."""
    if os.geteuid() != 0:
        d.chmod(0o555)
        try:
            yield d
        finally:
            d.chmod(0o755)
        return
    if shutil.which("mount") is None:
        pytest.skip("root without mount(8): cannot make a read-only folder")
    ok = subprocess.run(["mount", "--bind", str(d), str(d)], capture_output=True).returncode == 0
    ok = ok and subprocess.run(["mount", "-o", "remount,bind,ro", str(d)], capture_output=True).returncode == 0
    if not ok:
        subprocess.run(["umount", str(d)], capture_output=True)
        pytest.skip("root without permission to bind-mount read-only")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=True)
