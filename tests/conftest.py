"""Fixtures shared by test modules."""

from pathlib import Path

import pytest

from pipeline.cli import main

DEMO = Path(__file__).resolve().parents[1] / "configs" / "demo.yaml"


@pytest.fixture(scope="session")
def demo_runs(tmp_path_factory):
    """The demo (a mass-spring-damper with a hidden cubic stiffness) through both commands, once per
    session: ``report`` (with HTML) into the first folder, ``diagnose`` into the second. Read only."""
    base = tmp_path_factory.mktemp("demo")
    assert main(["report", str(DEMO), "--out", str(base / "a")]) == 0
    assert main(["diagnose", str(DEMO), "--out", str(base / "b")]) == 0
    return base / "a", base / "b"
