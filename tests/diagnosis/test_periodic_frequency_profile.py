"""The periodic disturbance's frequency, refitted from a profile around the periodogram peak
(:meth:`pipeline.diagnostics.families.periodic_disturbance.PeriodicDisturbance.estimate`).

A sinusoid between the Fourier bins of the estimation window (0.3375 Hz; bins 0.0357 Hz apart on 28 s)
was refitted from the peak and ended on a neighbouring lobe: the cause was rejected and the run ended
"unexplained" at 2 % noise. On 20 fresh seeds of this setting (independent generator, solve_ivp; seeds
2200-2219, outside the bench's sets) 14 -> 16 are named; the other four are not detected at all (the
periodic family does not fire), which this change does not touch."""

import contextlib
import io
import math
from pathlib import Path

import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.runs import analyse


@pytest.mark.parametrize("seed", [2201, 2212])
def test_a_sinusoid_between_fourier_bins_is_named_with_its_frequency(tmp_path, seed):
    case = make_case("periodic_disturbance", "msd", seed, magnitude="large", noise=0.02, colour="white",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    truth = case.truth["params"]
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    f = d["findings"][0]
    assert (f["family"], f["equation"]) == ("periodic_disturbance", truth["equation"])
    # the tolerances: frequency within 5 %, key parameter within 20 %
    assert f["frequency_hz"] == pytest.approx(truth["frequency_hz"], rel=0.05)
    assert f["amplitude"] == pytest.approx(truth["amplitude"], rel=0.2)
    dphi = (f["phase_rad"] - truth["phase_rad"] + math.pi) % (2 * math.pi) - math.pi
    assert abs(dphi) < 0.2
    assert f["gain"]["ci95"][0] > 0.5
