"""Three demo runs made once (by the batch runner, with a broken fourth config) for the store,
tracking and batch tests."""

from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs" / "demo.yaml"


def write_configs(d: Path) -> dict[str, Path]:
    """a: the demo; b: the demo at alpha 0.05 under another name; c: no extension allowed
    (max_findings 0, so the nominal model is final); broken: a free parameter that is not a param."""
    base = yaml.safe_load(DEMO.read_text())
    base["data"]["path"] = str(ROOT / "data" / "demo.csv")
    out = {}
    b = yaml.safe_load(yaml.safe_dump(base))
    b["name"], b["diagnose"]["alpha"] = "demo_b", 0.05
    c = yaml.safe_load(yaml.safe_dump(base))
    c["name"], c["diagnose"]["max_findings"] = "demo_c", 0
    broken = yaml.safe_load(yaml.safe_dump(base))
    broken["name"], broken["model"]["free"] = "broken", ["c", "k", "nosuch"]
    for key, cfg in (("a", base), ("b", b), ("c", c), ("broken", broken)):
        p = d / f"{key}.yaml"
        p.write_text(yaml.safe_dump(cfg, sort_keys=False))
        out[key] = p
    return out


@pytest.fixture(scope="session")
def batch_runs(tmp_path_factory):
    from pipeline.batch import run_batch
    d = tmp_path_factory.mktemp("batch")
    cfgs = write_configs(d)
    results = run_batch([str(cfgs[k]) for k in ("a", "broken", "b", "c")], jobs=2, root=d / "runs")
    return {"dir": d, "root": d / "runs", "configs": cfgs, "results": results}
