"""Access to ../shared/seed-cases/seed_cases.yaml by case id (tests reproduce seed cases by id)."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import pytest
import yaml

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SEED_FILE = SHARED / "seed-cases" / "seed_cases.yaml"
DATASETS = SHARED / "datasets"


@functools.lru_cache(maxsize=1)
def _cases() -> dict:
    if not SEED_FILE.exists():
        return {}
    with open(SEED_FILE, encoding="utf-8") as fh:
        doc = yaml.safe_load(fh)
    return {c["id"]: c for c in doc["cases"]}


def case(case_id: str) -> dict:
    """The seed case with this id; skips the test when ../shared is absent (a user's fresh clone)."""
    cases = _cases()
    if not cases:
        pytest.skip(f"seed cases not found at {SEED_FILE}")
    return cases[case_id]


def require_dataset(relpath: str) -> Path:
    """Path of a shared dataset file; skip when absent unless SYSID_REQUIRE_REALDATA=1 (CI)."""
    p = DATASETS / relpath
    if not p.exists():
        if os.environ.get("SYSID_REQUIRE_REALDATA") == "1":
            pytest.fail(f"SYSID_REQUIRE_REALDATA=1 but dataset {p} is missing")
        pytest.skip(f"dataset {p} not present")
    return p
