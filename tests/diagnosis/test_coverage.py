"""pipeline.diagnostics.coverage: where the validation part leaves the estimation range, with numbers
worked out by hand."""

import numpy as np

from pipeline.diagnostics.coverage import coverage, coverage_text


def fmt(x):
    return f"{x:.3g}"


def test_ranges_shares_and_levels_by_hand():
    # input: estimation levels 4 and 9, validation 3, 6, 9, 9 (3 is below the range, 3 and 6 are new)
    u = np.array([4, 9, 4, 9, 3, 6, 9, 9], float)[:, None]
    # output: estimation 0..10, validation -1, 5, 12, 10: two of four outside, 2/10 of the width beyond
    y = np.array([0, 10, 5, 2, -1, 5, 12, 10], float)[:, None]
    rows = coverage(u, y, ["V"], ["T"], (0, 4), (4, 8))
    ru, ry = rows
    assert ru["signal"] == "V" and ru["kind"] == "input"
    assert ru["estimation_range"] == [4, 9] and ru["validation_range"] == [3, 9]
    assert ru["validation_outside_share"] == 0.25 and ru["validation_outside_by"] == 0.2
    assert ru["estimation_levels"] == [4, 9] and ru["new_levels"] == [3, 6]
    assert ry["validation_outside_share"] == 0.5 and ry["validation_outside_by"] == 0.2
    text = coverage_text(rows, fmt)
    assert "input V spans 3 to 9 on validation, 4 to 9 on estimation (25 % of validation samples outside" in text
    assert "takes 2 levels on validation (3, 6) that the estimation part never had (it has 4, 9)" in text
    assert "output T spans -1 to 12" in text


def test_a_stationary_signal_slightly_past_its_extremes_is_not_reported():
    # 2 % of the validation samples 5 % of the width beyond the estimation range: chance, not a finding
    e = np.linspace(-1, 1, 1000)
    v = np.r_[np.linspace(-1, 1, 980), np.full(20, 1.1)]
    rows = coverage(np.r_[e, v][:, None], np.r_[e, v][:, None], ["u"], ["y"], (0, 1000), (1000, 2000))
    assert rows[0]["validation_outside_share"] == 0.02
    assert coverage_text(rows, fmt) is None


def test_a_few_samples_far_beyond_are_reported():
    # Silverbox's arrow: 0.1 % of the samples, but 25 % of the width beyond the estimation range
    e = np.linspace(-1, 1, 1000)
    v = np.r_[np.linspace(-1, 1, 999), 1.5]
    rows = coverage(np.r_[e, v][:, None], np.r_[e, v][:, None], ["u"], ["y"], (0, 1000), (1000, 2000))
    assert rows[0]["validation_outside_by"] == 0.25
    assert "reaching 25 % of the estimation range beyond it" in coverage_text(rows, fmt)


def test_levels_of_a_continuous_signal_are_not_listed():
    x = np.random.default_rng(0).normal(size=(200, 1))
    rows = coverage(x, x, ["u"], ["y"], (0, 100), (100, 200))
    assert "estimation_levels" not in rows[0] and "new_levels" not in rows[0]
