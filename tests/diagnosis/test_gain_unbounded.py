"""``gain.unbounded_note``: a rejected extension whose 95 % interval hit the clip says that the record
cannot bound the gain (few degrees of freedom), instead of reading like a gain near 0."""

import numpy as np

from pipeline.diagnostics.gain import gain_ci, unbounded_note


def test_a_smooth_misfit_gives_an_unbounded_interval_and_says_so():
    """A misfit that is an AR(1) with φ = 0.995, half removed by the after-model, white noise at 1 % of it,
    1024 samples (the cascaded tanks' validation length): the loss differential is a few slow waves, the
    prewhitening factor is at its cap and ν < 1 (seed 0 of scipy's lfilter on numpy's generator)."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(0)
    d = lfilter([1.0], [1.0, -0.995], rng.standard_normal(1024))
    e = 0.01 * rng.standard_normal(1024)
    g = gain_ci(d + e, 0.5 * d + e)
    assert abs(g["relative"] - 0.5) < 0.01
    assert g["ci95"][0] <= -99 and g["bootstrap"]["dof"] < 1
    note = unbounded_note(g)
    assert "unbounded below" in note and f"{100 * g['relative']:+.1f} %" in note


def test_a_bounded_interval_adds_nothing():
    rng = np.random.default_rng(0)
    e = rng.standard_normal(2000)
    g = gain_ci(e + 0.5, e)
    assert g["ci95"][0] > 0
    assert unbounded_note(g) == ""


def test_an_after_model_more_than_100_times_better_keeps_an_interval_above_its_point():
    """An auditor's record (a hidden bilinear term −2·x·u) had an RMSE ratio of 186: the upper end was
    clipped at ln 100 and then to the point itself (0.99421 to 0.99461). Here the before-residual is a
    misfit 186 times the white noise left after: the interval must bracket the point strictly on both
    sides and stay below 1."""
    rng = np.random.default_rng(1)
    e = rng.standard_normal(2000)
    b = 186.0 * np.sin(np.linspace(0, 40, 2000)) * np.sqrt(2) + e
    g = gain_ci(b, e)
    assert g["relative"] > 0.99
    assert g["ci95"][0] < g["relative"] < g["ci95"][1] < 1.0


def test_an_after_model_more_than_100_times_worse_keeps_an_interval_below_its_point():
    """The same on the other side: the lower end is clipped 100 times below the point, not at it."""
    rng = np.random.default_rng(1)
    e = rng.standard_normal(2000)
    a = 186.0 * np.sin(np.linspace(0, 40, 2000)) * np.sqrt(2) + e
    g = gain_ci(e, a)
    assert g["relative"] < -99
    assert g["ci95"][0] < g["relative"] < g["ci95"][1]
