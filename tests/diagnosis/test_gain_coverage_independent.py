"""Issue 9, "an interval that means what it says": the first finding's 95 % gain interval, measured on
the diagnosis of records made by the independent generator (``pipeline.bench.independent``: solve_ivp
on continuous-time inputs, no code shared with the detector).

The interval says (``gain.ci95_meaning``) that it is the sampling uncertainty of the noise on the
validation record's input. So the reference is the gain of the same two fitted models on 16 records
with the *same input* and fresh noise, pooled over the same validation window (the bench's
``_fresh_gain(..., fresh_input=False)``), whose own sampling error is 1/4 of one record's. Test seeds
(1000–1002 are the issue's; 1010–1029 here), three families, 60 records. An exactly calibrated 95 %
interval covers the pooled reference with probability 94.3 %, so a bare "≥ 93 % of the records" would
fail a calibrated interval about once in four record sets (it was set for the earlier, conservative
interval, which covered 30/30 of the first 30). Asserted instead: a one-sided exact binomial test does
not reject "coverage ≥ 93 %" at 5 % (it rejects at 51 of 60 or fewer), and every finding's interval
brackets its own ``relative``. Measured when written: 55 of 60 (91.7 %; binomial p = 0.41), the five
misses by at most 0.0011 in the gain.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest
from scipy.stats import binomtest

from pipeline.bench.diagnosis import Spec, _fresh_gain
from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse

CASES = [("offset", "msd"), ("cubic_stiffness", "pendulum"), ("input_saturation", "msd")]
SEEDS = range(1010, 1030)


def coverage(tmp_path: Path) -> tuple[int, int, list]:
    """(covered, records with a first finding whose gain is the validation RMSE, one row per record)."""
    covered, total, rows = 0, 0, []
    for family, base in CASES:
        for seed in SEEDS:
            spec = Spec(family, base, seed, "medium", 0.02, "white", "band")
            case = make_case(family, base, seed, out_dir=tmp_path)
            with contextlib.redirect_stderr(io.StringIO()):
                ctx = analyse(load_config(Path(case.dir) / "config.yaml"))
            findings = ctx.summary["diagnosis"]["findings"]
            if not findings or findings[0]["gain"]["metric"] != "validation_rmse_sim":
                continue
            g = findings[0]["gain"]
            assert "validation input" in g["ci95_meaning"]
            ref = _fresh_gain(spec, ctx, fresh_input=False)
            assert ref is not None
            lo, hi = g["ci95"]
            assert lo <= g["relative"] <= hi
            total += 1
            covered += lo <= ref <= hi
            rows.append((family, seed, round(lo, 4), round(g["relative"], 4), round(hi, 4), round(ref, 4)))
    return covered, total, rows


@pytest.mark.slow
def test_gain_interval_covers_the_gain_on_fresh_noise_with_the_same_input(tmp_path: Path):
    covered, total, rows = coverage(tmp_path)
    assert total >= 54, rows                       # nearly every record has a first finding
    assert binomtest(covered, total, 0.93, alternative="less").pvalue >= 0.05, (covered, total, rows)
