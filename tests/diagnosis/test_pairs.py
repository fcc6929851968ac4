"""The joint test of two hypotheses that hide each other (``pipeline.diagnostics.pairs``): shares in
closed form, the Bonferroni count, detection of a suppressed pair, no pair when the members' shares
add up, and the size under AR(1) residuals by Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from pipeline.diagnostics import stats
from pipeline.diagnostics.pairs import SYNERGY, Member, n_pairs, share, suppressed_pair


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


def test_the_bonferroni_count_is_every_hypothesis_pair_of_distinct_families():
    z = np.zeros((10, 1))
    members = [Member("a", "A", z, 3), Member("b", "B", z, 2), Member("c", "C", z, 5)]
    assert n_pairs(members) == 3 * 2 + 3 * 5 + 2 * 5
    assert n_pairs(members + [Member("a2", "A", z, 4)]) == 31 + 4 * 2 + 4 * 5


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
    basis = stats.column_basis(J)
    pair = suppressed_pair(e, basis, members, 0.01, lambda S: stats.added_terms_test(e, J, S, basis=basis))
    assert pair is not None and {pair.a, pair.b} == {0, 1}
    assert pair.share >= SYNERGY * sum(pair.shares) and pair.share > 0.8
    assert pair.n_pairs == 1 * 2 + 3 * 1 * 4 + 3 * 2 * 4 + 3 * 4 * 4
    assert pair.p_value == pytest.approx(min(1.0, pair.wald.p_value * pair.n_pairs))
    assert pair.wald.dof == 2


def test_no_pair_when_the_members_shares_add_up():
    """Two independent causes: each explains its own part, the pair the sum, not twice it. (The loop
    names them one after the other; the joint test is for pairs that hide each other.)"""
    rng = np.random.default_rng(6)
    n = 2000
    v, z1, z2 = _smooth(rng, n, k=3).T
    e = z1 + z2 + 0.3 * np.std(z1) * rng.standard_normal(n)
    J = v[:, None]
    basis = stats.column_basis(J)
    members = [Member("a", "A", z1[:, None], 1), Member("b", "B", z2[:, None], 1)]
    assert suppressed_pair(e, basis, members, 0.01, lambda S: stats.added_terms_test(e, J, S, basis=basis)) is None


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.5, 0.9])
def test_size_under_ar1_residuals_with_one_pair(phi):
    """400 null records (N = 1000; the residual an AR(1) φ independent of the members; one pair, so no
    Bonferroni factor to hide behind): the synergy screen and the joint test together reject at most
    1.5 α (the added-term test's own Monte Carlo tolerance, tests/diagnosis/test_mc_calibration.py). The
    members are built to look suppressed (a = z + 3w, b = −3w): the screen passes on a good part of the
    records, so the test is exercised."""
    rng = np.random.default_rng([21, int(100 * phi)])
    rejected = screened = 0
    reps, alpha, n = 400, 0.05, 1000
    for _ in range(reps):
        v, z, w = _smooth(rng, n, k=3).T
        e = lfilter([1.0], [1.0, -phi], rng.standard_normal(n))
        e = e - v * (v @ e) / (v @ v)
        J = v[:, None]
        basis = stats.column_basis(J)
        members = [Member("a", "A", (z + 3 * w)[:, None], 1), Member("b", "B", (-3 * w)[:, None], 1)]
        seen = []

        def test(S):
            seen.append(1)
            return stats.added_terms_test(e, J, S, basis=basis)
        rejected += suppressed_pair(e, basis, members, alpha, test) is not None
        screened += bool(seen)
    assert screened >= 0.1 * reps
    assert rejected / reps <= 1.5 * alpha
