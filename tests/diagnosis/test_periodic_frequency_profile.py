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

import numpy as np
import pytest

from pipeline.bench.independent.case import make_case
from pipeline.config import load_config
from pipeline.diagnostics.families.periodic_disturbance import n_lines, strongest_bins
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


@pytest.mark.parametrize("seed", [2205, 2209])
def test_a_sinusoid_whose_residual_peak_is_bins_away_is_found_by_the_half_bin_scan(tmp_path, seed):
    """The nominal fit bends its stiffness and damping towards the sinusoid, and the residual's
    periodogram then peaks near the resonance (0.29 Hz for a 0.4125 Hz disturbance, seed 2205), while
    the whitened peak sits on the shoulder of the AR notch (0.447 Hz). Tested only there, the family
    was not significant (p = 0.0018 against Holm's 0.0007) and the run ended unexplained; the raw
    periodogram's strongest bins and the half bins beside them are now tested too (Bonferroni over the
    n_est − 1 half-bin frequencies), and the refit starts from them as well."""
    case = make_case("periodic_disturbance", "msd", seed, magnitude="large", noise=0.02, colour="white",
                     input_kind="prbs", n=2000, out_dir=tmp_path)
    truth = case.truth["params"]
    with contextlib.redirect_stderr(io.StringIO()):
        d = analyse(load_config(Path(case.dir) / "config.yaml")).summary["diagnosis"]
    assert d["findings"], d["verdict"]
    f = d["findings"][0]
    assert (f["family"], f["equation"]) == ("periodic_disturbance", truth["equation"])
    assert f["frequency_hz"] == pytest.approx(truth["frequency_hz"], rel=0.05)
    assert f["amplitude"] == pytest.approx(truth["amplitude"], rel=0.2)
    line = {e["test"].split("[")[0]: e for e in f["evidence"]}["periodic_line_test"]
    assert "x 1399 frequencies searched" in line["detail"]
    assert f["gain"]["ci95"][0] > 0.5


def test_strongest_bins_and_the_number_of_frequencies_searched():
    """The scan's bins from the raw periodogram, summed over outputs (closed form: a sinusoid on bin k of
    an n-sample window puts all its power on bin k; one on bin 7.5 splits it equally between 7 and 8),
    and the line test's Bonferroni count: n/2 Fourier frequencies, or n − 1 half-bin frequencies."""
    n = 400
    t = np.arange(n)
    R = np.column_stack([3.0 * np.sin(2 * np.pi * 5 * t / n) + 1.0 * np.cos(2 * np.pi * 21 * t / n),
                         2.0 * np.sin(2 * np.pi * 7.5 * t / n) + 0.5])
    # powers ∝ 3² on bin 5, (2·2/π)² ≈ 1.6 on each of bins 7 and 8, 1² on bin 21; the mean is no bin
    assert strongest_bins(R, 1) == [5]
    assert set(strongest_bins(R, 3)) == {5, 7, 8}
    assert strongest_bins(R, 4)[3] == 21
    assert n_lines(1400, False) == 700 and n_lines(1400, True) == 1399
