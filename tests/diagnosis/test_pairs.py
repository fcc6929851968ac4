"""The test of one hypothesis given another, for two that hide each other
(``pipeline.diagnostics.pairs``): shares in closed form, the weighted Bonferroni factor, the
conditional test against statsmodels' F test, detection of a suppressed pair, no pair when the members'
shares add up, and the size under AR(1) residuals by Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from pipeline.diagnostics import stats
from pipeline.diagnostics.pairs import SYNERGY, Member, factor, given, hidden_pairs, n_family_pairs, share


def _smooth(rng, n, phi=0.95, k=1):
    return lfilter([1.0], [1.0, -phi], rng.standard_normal((n + 300, k)), axis=0)[300:]


def _orthonormal(rng, n, k):
    return np.linalg.qr(rng.standard_normal((n, k)))[0]


def test_shares_of_a_suppressed_pair_in_closed_form():
    """e, q, r orthonormal; S_a = e + M q + r, S_b = −M q + 2 r, J = r. Off J: S_a⊥ = e + M q, S_b⊥ = −M q,
    so alone S_a explains (e·S_a⊥)²/‖S_a⊥‖² = 1/(1 + M²) of ‖e‖², S_b nothing (q ⟂ e), and together all of
    it (S_a⊥ + S_b⊥ = e): the textbook suppressor (Conger 1974)."""
    e, q, r = _orthonormal(np.random.default_rng(1), 500, 3).T
    M = 3.0
    Sa, Sb = (e + M * q + r)[:, None], (-M * q + 2 * r)[:, None]
    off = lambda S: S - r[:, None] @ (r[None, :] @ S)
    assert share(e, off(Sa)) == pytest.approx(1 / (1 + M ** 2), abs=1e-12)
    assert share(e, off(Sb)) == pytest.approx(0.0, abs=1e-12)
    assert share(e, np.hstack([off(Sa), off(Sb)])) == pytest.approx(1.0, abs=1e-12)


def test_the_weighted_bonferroni_factor_is_ordered_family_pairs_times_the_multiplicities():
    """α split equally over the 2F ordered pairs of families, then over each one's m_a·m_b hypothesis
    pairs: the weights 1/(2F·m_a·m_b) over all ordered hypothesis pairs sum to one (the union bound's
    condition)."""
    z = np.zeros((10, 1))
    members = [Member("a", "A", z, 3), Member("b", "B", z, 2), Member("c", "C", z, 5), Member("d", "D", z, 1)]
    assert n_family_pairs(members) == 6
    assert factor(members, 0, 1) == 12 * 3 * 2 and factor(members, 3, 2) == 12 * 1 * 5
    weights = sum(m_a.multiplicity * m_b.multiplicity / factor(members, i, j)
                  for i, m_a in enumerate(members) for j, m_b in enumerate(members) if i != j)
    assert weights == pytest.approx(1.0)


def test_the_test_given_a_has_the_coefficient_of_the_regression_on_both():
    """Frisch–Waugh–Lovell: b's coefficient in the test given a is its OLS coefficient in the regression
    of e on [J, S_a, S_b] (statsmodels). With a white residual the decision at 1 % is the F test's (the
    HAC variance with its fixed-b reference is more cautious, so the p-values are not equal)."""
    import statsmodels.api as sm
    rng = np.random.default_rng(3)
    n = 1500
    J, Sa, Sb = _smooth(rng, n, k=3).T[:, :, None]
    e = 0.05 * Sb[:, 0] + 0.3 * Sa[:, 0] + rng.standard_normal(n)
    e = e - J[:, 0] * (J[:, 0] @ e) / (J[:, 0] @ J[:, 0])
    w = given(e, J, Sa, Sb)
    ols = sm.OLS(e, np.hstack([J, Sa, Sb])).fit()
    assert w.beta[0] == pytest.approx(ols.params[2], rel=1e-8)
    f = ols.f_test(np.array([[0.0, 0.0, 1.0]]))
    assert float(f.pvalue) < 0.01 and w.p_value < 0.01


def _suppressed(rng, n=2000, noise=0.3):
    """A residual made of z (smooth) plus AR(0.5) noise; member a = z + 3w + v, member b = −3w + v/2
    (w smooth, v the current parameter's sensitivity), and three unrelated smooth members."""
    v, z, w = _smooth(rng, n, k=3).T
    e = z + noise * np.std(z) * lfilter([1.0], [1.0, -0.5], rng.standard_normal(n))
    e = e - v * (v @ e) / (v @ v)              # the residual of the current fit is orthogonal to J
    J = v[:, None]
    members = [Member("a", "A", (z + 3 * w + v)[:, None], 1), Member("b", "B", (-3 * w + 0.5 * v)[:, None], 2)]
    members += [Member(k, k.upper(), _smooth(rng, n), 4) for k in "cde"]
    return e, J, members


def test_a_suppressed_pair_is_found_with_its_bonferroni_p_value():
    e, J, members = _suppressed(np.random.default_rng(5))
    pairs = hidden_pairs(e, J, stats.column_basis(J), members, 0.01)
    assert pairs and {pairs[0].a, pairs[0].b} == {0, 1}
    ra, rb, rab = pairs[0].shares
    assert rab - ra >= SYNERGY * rb and rab > 0.8
    assert pairs[0].factor == 2 * 10 * 1 * 2                # 5 families: 10 pairs of families; m = 1 and 2
    assert pairs[0].p_value == pytest.approx(min(1.0, pairs[0].wald.p_value * pairs[0].factor))
    assert all({p.a, p.b} == {0, 1} for p in pairs)        # the unrelated members reveal nothing


def test_no_pair_when_the_members_shares_add_up():
    """Two independent causes: each explains its own part, given the other the same again, not twice
    it. (The loop names them one after the other; this test is for pairs that hide each other.)"""
    rng = np.random.default_rng(6)
    n = 2000
    v, z1, z2 = _smooth(rng, n, k=3).T
    e = z1 + z2 + 0.3 * np.std(z1) * rng.standard_normal(n)
    e = e - v * (v @ e) / (v @ v)
    J = v[:, None]
    members = [Member("a", "A", z1[:, None], 1), Member("b", "B", z2[:, None], 1)]
    assert hidden_pairs(e, J, stats.column_basis(J), members, 0.01) == []


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.5, 0.9])
def test_size_under_ar1_residuals_with_one_pair(phi):
    """400 null records (N = 1000; the residual an AR(1) φ independent of the members; one pair of
    families, so the Bonferroni factor is 2): the screen and the test given the other together reject
    at most 1.5 α (the added-term test's own Monte Carlo tolerance, tests/diagnosis/test_mc_calibration.py).
    The members are built to look suppressed (a = z + 3w, b = −3w): the screen passes on a good part of
    the records, so the test is exercised."""
    import pipeline.diagnostics.pairs as pairs
    rng = np.random.default_rng([21, int(100 * phi)])
    rejected = screened = 0
    reps, alpha, n = 400, 0.05, 1000
    real = pairs.given
    seen = []

    def counted(*a):
        seen.append(1)
        return real(*a)
    pairs.given = counted
    try:
        for _ in range(reps):
            v, z, w = _smooth(rng, n, k=3).T
            e = lfilter([1.0], [1.0, -phi], rng.standard_normal(n))
            e = e - v * (v @ e) / (v @ v)
            J = v[:, None]
            members = [Member("a", "A", (z + 3 * w)[:, None], 1), Member("b", "B", (-3 * w)[:, None], 1)]
            seen.clear()
            rejected += bool(hidden_pairs(e, J, stats.column_basis(J), members, alpha))
            screened += bool(seen)
    finally:
        pairs.given = real
    assert screened >= 0.2 * reps
    assert rejected / reps <= 1.5 * alpha
