"""Takagi–Sugeno models (textbook §2.5, eq. 2.161 / corrected 2.165): seed cases wro_ex2_12, wro_ex2_13."""

import math

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.structures.takagi_sugeno import (
    TakagiSugeno, fit_takagi_sugeno, memberships, select_rules,
)
from tests.seedcases import case

K_GRID = [1, 2, 3, 5, 8, 11, 16, 24]


def ex2_13_data(n=120, noise=0.25, seed=0):
    """Synthetic stand-in for Fig. 2.23 (data not published; the seed case suggests y = sin u + noise
    on [0, 2π]).  Inputs are drawn in random order, as a measured record would be."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 2 * np.pi, n)
    return u, np.sin(u) + rng.normal(0.0, noise, n)


def test_wro_ex2_12_takagi_sugeno_inference():
    c = case("wro_ex2_12_takagi_sugeno_inference")
    # K = 2, m = (0, 2), sigma = (1, 1), y1 = u, y2 = -u + 4; evaluate at u = 1
    ts = TakagiSugeno(centres=np.array([[0.0], [2.0]]), sigmas=np.array([[1.0], [1.0]]),
                      theta=np.array([[1.0, 0.0], [-1.0, 4.0]]))
    assert ts.predict([1.0])[0] == pytest.approx(c["expected"]["instance_y_at_u1"], abs=float(c["tolerance"]))
    # a second point by hand: at u = 0, β1 = 1, β2 = e^-4 -> y = 4 e^-4 / (1 + e^-4)
    assert ts.predict([0.0])[0] == pytest.approx(4 * math.exp(-4) / (1 + math.exp(-4)), abs=1e-15)


def test_membership_has_no_factor_two():
    """(2.164): exp(-(u-m)²/σ²) — σ is not the Gaussian standard deviation (seed-case flag)."""
    b = memberships(np.array([[1.5, 0.0]]), np.array([[0.5, 1.0]]), np.array([[2.0, 0.5]]))
    assert b[0, 0] == pytest.approx(math.exp(-(1.0 / 2.0) ** 2 - (1.0 / 0.5) ** 2), rel=1e-15)


def test_wro_ex2_13_takagi_sugeno_fit():
    c = case("wro_ex2_13_takagi_sugeno_fit")
    assert c["expected_source"].startswith("document (figures only)")
    u, y = ex2_13_data()
    for method in ("global", "local"):
        res = select_rules(u, y, K_GRID, k=5, gap=0, seed=0, method=method)
        mse = dict(zip(K_GRID, res["train_mse"]))
        assert mse[2] > mse[5] > mse[11], method  # Figs 2.24–2.26: the fit improves with more rules
        # CV picks neither extreme: too few rules underfit, too many fit the noise
        assert res["chosen"] not in (K_GRID[0], K_GRID[-1]), method
        assert res["scores"].shape == (len(K_GRID), 5)
        cvm = dict(zip(K_GRID, res["mean"]))
        if method == "global":  # the joint fit of many narrow rules overfits clearly
            assert cvm[res["chosen"]] < 0.8 * min(cvm[K_GRID[0]], cvm[K_GRID[-1]])


def test_global_ls_fits_training_data_at_least_as_well_as_local():
    u, y = ex2_13_data(seed=3)
    for K in (2, 5, 11):
        g = fit_takagi_sugeno(u, y, K, method="global")
        loc = fit_takagi_sugeno(u, y, K, method="local")
        np.testing.assert_array_equal(g.centres, loc.centres)
        assert np.mean((g.predict(u) - y) ** 2) <= np.mean((loc.predict(u) - y) ** 2) + 1e-12


def test_global_ls_reproduces_a_known_ts_model():
    truth = TakagiSugeno(np.array([[0.0], [np.pi], [2 * np.pi]]), np.full((3, 1), np.pi),
                         np.array([[1.0, 0.0], [-1.0, 3.0], [0.5, -2.0]]))
    u = np.linspace(0, 2 * np.pi, 200)
    fit = fit_takagi_sugeno(u, truth.predict(u), 3, centres="grid", width=1.0)
    np.testing.assert_allclose(fit.centres, truth.centres, atol=1e-12)
    np.testing.assert_allclose(fit.theta, truth.theta, atol=1e-8)


def test_kmeans_centres_are_seeded_and_two_inputs_work():
    rng = np.random.default_rng(2)
    U = rng.uniform(-1, 1, (300, 2))
    y = U[:, 0] * U[:, 1] + np.sin(2 * U[:, 0])
    a = fit_takagi_sugeno(U, y, 6, centres="kmeans", seed=4)
    b = fit_takagi_sugeno(U, y, 6, centres="kmeans", seed=4)
    np.testing.assert_array_equal(a.centres, b.centres)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert np.mean((a.predict(U) - y) ** 2) < 0.2 * np.var(y)
    assert len(a.rules()) == 6 and a.rules()[0].startswith("R1: IF u0 ~ N(")


def test_bad_input():
    u, y = ex2_13_data(n=20)
    with pytest.raises(InputError, match="11 rules need 22 consequent parameters but there are only 20 samples"):
        fit_takagi_sugeno(u, y, 11)
    with pytest.raises(InputError, match="method"):
        fit_takagi_sugeno(u, y, 2, method="newton")
    with pytest.raises(InputError, match="n_rules"):
        fit_takagi_sugeno(u, y, 0)
    with pytest.raises(InputError, match="K = k\\*\\*2"):
        fit_takagi_sugeno(np.column_stack([u, u]), y, 3)
    with pytest.raises(InputError, match="NaN"):
        fit_takagi_sugeno(np.full(20, np.nan), y, 2)
