"""The diagnosis does not depend on the units of the data.

An independent probe scaled the demo's input and output by 10⁶ (the same physics in micro-units: the
linear parameters unchanged, a cubic coefficient 10⁻¹² times smaller): the nominal fit was identical,
but the cubic spring's refit kept a quarter of its gain and the run ended `unexplained_discrepancy`
with two static terms. scipy's finite-difference step is √ε·max(1, |θ|), absolute below 1, so a
coefficient of 3·10⁻¹² got a step 5 000 times its size (``fit.TINY_PARAM``). The record here is made by
the independent generator (``solve_ivp``), then rescaled."""

from __future__ import annotations

import contextlib
import io

import pandas as pd
import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse


def _diagnose(case, scale: float, tmp_path):
    d = tmp_path / f"x{scale:g}"
    d.mkdir()
    df = pd.read_csv(case.dir / "data.csv")
    for col in ("u", "x"):
        df[col] = df[col] * scale
    df.to_csv(d / "data.csv", index=False)
    (d / "config.yaml").write_text((case.dir / "config.yaml").read_text())
    with contextlib.redirect_stderr(io.StringIO()):
        return analyse(load_config(d / "config.yaml")).summary["diagnosis"]


@pytest.mark.parametrize("scale", [1e6, 1e-6])
def test_a_cubic_spring_is_named_alike_in_other_units(tmp_path, scale):
    case = make_case("cubic_stiffness", "msd", 1000, magnitude="medium", noise=0.02, colour="white",
                     input_kind="band", out_dir=tmp_path / "case")
    base = _diagnose(case, 1.0, tmp_path)["findings"][0]
    other = _diagnose(case, scale, tmp_path)["findings"][0]
    assert (base["family"], base["equation"], base["term"]) == ("cubic_stiffness", "v", "x**3")
    assert (other["family"], other["equation"], other["term"]) == ("cubic_stiffness", "v", "x**3")
    # x → s·x, u → s·u: v' = u − c v − k x + a x³ holds with a/s² (here s = 10⁶: 10⁻¹² times smaller)
    assert other["coefficient"] * scale ** 2 == pytest.approx(base["coefficient"], rel=1e-3)
    assert other["gain"]["relative"] == pytest.approx(base["gain"]["relative"], abs=1e-3)
