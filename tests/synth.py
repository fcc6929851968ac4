"""Write a synthetic record with a hidden effect plus its nominal config, and run the pipeline."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import yaml

from pipeline import synthetic
from pipeline.config import load_config
from pipeline.runs import analyse


def write_case(tmp: Path, system: str, effect: str, seed: int, **overrides) -> tuple[Path, synthetic.Synthetic]:
    syn = synthetic.generate(system, effect, seed)
    tmp.mkdir(parents=True, exist_ok=True)
    syn.to_frame().to_csv(tmp / "record.csv", index=False)
    cfg = synthetic.config_for(syn, "record.csv", seed=seed)
    for k, v in overrides.items():
        cfg[k] = v
    path = tmp / "config.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path, syn


def run_case(tmp: Path, system: str, effect: str, seed: int):
    path, syn = write_case(tmp, system, effect, seed)
    with contextlib.redirect_stderr(io.StringIO()):
        ctx = analyse(load_config(path))
    return ctx.summary, syn
