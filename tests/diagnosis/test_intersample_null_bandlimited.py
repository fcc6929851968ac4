"""A switch from foh to the band-limited signal needs positive estimation evidence (ΔBIC below −2,
``intersample_stage.INTERSAMPLE_MAX_DBIC``). Null records of the independent bench's test seeds (multisine inputs,
configured foh, no effect) whose slow plants make the two interpolations differ by 0.1–0.2 % of the
validation RMSE got an intersample finding at ΔBIC −0.27 to −1.2 when ΔBIC < 0 was enough."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse


@pytest.mark.parametrize("base,seed,colour", [("dcmotor", 1001, "ar0.5"), ("dcmotor2", 1000, "white")])
def test_an_immaterial_band_limited_switch_on_a_null_record_is_not_a_finding(tmp_path, base, seed, colour):
    case = make_case("none", base, seed, magnitude="medium", noise=0.02, colour=colour, input_kind="band",
                     n=2000, out_dir=tmp_path)
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    assert "intersample" not in [f["family"] for f in d["findings"]]
    row = next(c for h in d["history"] for c in h["candidates"] if c.get("hypothesis") == "bandlimited")
    assert -2.0 <= row["delta_bic"] < 0 and row["gain"]["relative"] > 0 and not row["accepted"]
    assert "BIC not lower by more than 2" in row["reason"]
