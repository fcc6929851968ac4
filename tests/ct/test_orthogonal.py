"""Tsang & Billings (1991) section 2: orthogonal approximation, ERR, derivatives and integrals."""

from __future__ import annotations

import random

import numpy as np
import pytest

from pipeline.ct.orthogonal import (
    beta_from_f,
    fit,
    orthogonal_basis,
    orthogonal_integrals,
    poly_derivative_at,
    poly_repeated_integral,
)
from pipeline.errors import InputError
from tests.seedcases import case

T = np.arange(21) * 0.5  # t = 0, 0.5, ..., 10
F_CLEAN = np.sin(0.3 * T) + np.sin(0.8 * T)  # eq. (17)


def _true_values():
    """Exact f(5), f'(5), f''(5), int_0^10 f, int_0^10 int_0^t f of eq. (17)."""
    return np.array([
        np.sin(1.5) + np.sin(4.0),
        0.3 * np.cos(1.5) + 0.8 * np.cos(4.0),
        -0.09 * np.sin(1.5) - 0.64 * np.sin(4.0),
        (1 - np.cos(3.0)) / 0.3 + (1 - np.cos(8.0)) / 0.8,
        (10 - np.sin(3.0) / 0.3) / 0.3 + (10 - np.sin(8.0) / 0.8) / 0.8,
    ])


def _fit_values(r, t0=-5.0, t1=5.0, mid=0.0):
    return np.array([r.value(mid), r.value(mid, 1), r.value(mid, 2), r.integral(t0, t1, 1), r.integral(t0, t1, 2)])


def _round_like(x: float, printed: float) -> float:
    """Round ``x`` to the number of significant digits of the printed value (from its repr)."""
    mant = repr(float(printed)).lower().split("e")[0].lstrip("-").replace(".", "").lstrip("0")
    return float(f"{x:.{max(len(mant), 1) - 1}e}")


@pytest.mark.parametrize("base", ["A", "B"])
def test_tb_table1_orthogonal_approx_clean(base):
    c = case("tb_table1_orthogonal_approx_clean")
    exp = c["expected"]
    # misprint #17: f7, f8 exponents are E-5 and E-6 (the printed ERR column confirms it)
    f_expected = np.array(exp["f_i"], dtype=float)
    f_expected[7], f_expected[8] = 1.6428e-5, -2.0228e-6
    tb = T - 5.0 if base == "A" else T
    r = fit(orthogonal_basis(tb, 8), F_CLEAN, order=8)
    # rel 1e-4 against the 7-digit recomputation; against the printed values (some have only 4
    # significant digits, e.g. 0.01593) agreement to the printed digits
    np.testing.assert_allclose(r.f, c["recomputed"]["f_i"], rtol=1e-4)
    for got, printed in zip(r.f, f_expected):
        assert _round_like(got, printed) == pytest.approx(printed, rel=1e-12), (got, printed)
    np.testing.assert_allclose(r.err, exp["ERR"], atol=1e-4)
    assert round(r.err_total, 4) == pytest.approx(exp["ERR_total"], abs=1e-4)
    np.testing.assert_allclose(r.basis.sum_w2, c["recomputed"]["sum_w_i^2"], rtol=1e-6)


def test_eq8_beta_recovery_matches_direct_expansion():
    """Eq. (8) with the alpha_ri of eq. (6) gives the monomial coefficients of sum_i f_i w_i
    (tb_eq18_20 beta_A_ts, corrected exponents)."""
    c = case("tb_eq18_20_monomial_coefficients")
    b = orthogonal_basis(T - 5.0, 8)
    r = fit(b, F_CLEAN, order=8)
    np.testing.assert_allclose(r.beta, c["recomputed"]["beta_A_ts"], rtol=1e-4)
    np.testing.assert_allclose(beta_from_f(r.f, b.alpha), r.f @ b.coef, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.polyval(r.beta[::-1], T - 5.0), r.fitted(), atol=1e-12)


def test_orthogonal_integrals_recurrence_matches_quadrature():
    """Eqs. (15)-(16) (tb_orthogonal_integrals): recurrence integrals of w_i equal quadrature."""
    b = orthogonal_basis(T - 5.0, 8)
    im1 = orthogonal_integrals(b, 1, -5.0, 5.0)
    im2 = orthogonal_integrals(b, 2, -5.0, 5.0)
    x, wq = np.polynomial.legendre.leggauss(20)  # exact for polynomials of degree <= 39
    s = 5.0 * x
    for i in range(9):
        wi = np.polynomial.Polynomial(b.coef[i])
        q1 = 5.0 * np.sum(wq * wi(s))
        q2 = 5.0 * np.sum(wq * (5 - s) * wi(s))  # Cauchy's formula for the double integral
        assert im1[i] == pytest.approx(q1, rel=1e-10, abs=1e-9)
        assert im2[i] == pytest.approx(q2, rel=1e-10, abs=1e-9)


def test_tb_table2_derivative_integral_clean():
    c = case("tb_table2_derivative_integral_clean")
    rec = c["recomputed"]
    true = _true_values()
    # misprint #18: the true integral is 8.0652 (8.065183), not 8.6052
    assert true[3] == pytest.approx(8.0652, abs=1e-4)
    np.testing.assert_allclose(true, list(rec["true_exact"].values()), atol=1e-6)
    for base, mid, t0, t1 in (("A", 0.0, -5.0, 5.0), ("B", 5.0, 0.0, 10.0)):
        tb = T - 5.0 if base == "A" else T
        r = fit(orthogonal_basis(tb, 8), F_CLEAN, order=8)
        vals = _fit_values(r, t0, t1, mid)
        np.testing.assert_allclose(vals, list(rec["exact_LS_fit (A == B)"].values()), rtol=1e-4)
        pct = 100 * np.abs(vals - true) / np.abs(true)
        np.testing.assert_allclose(pct, rec["pct_err"], atol=0.01)


def _noisy(seed: int) -> np.ndarray:
    rng = random.Random(seed)
    return F_CLEAN + np.array([rng.gauss(0.0, 0.1) for _ in T])  # eq. (21), variance 0.01


SEED_TABLE3 = 1  # fixed noise seed (the case's tolerance is for one fixed seed; 114 of seeds 0..199 meet it)


def test_tb_table3_noisy_orthogonal_approx():
    """Fifth-order fit of noisy samples: ERR_total in [98.5, 99.8] and f_0, f_3 within 0.02 of the
    noise-free values (seed 1); ERR stopping at 99 % selects the fifth order, as in the paper."""
    c = case("tb_table3_noisy_orthogonal_approx")
    assert "ERR_total in [98.5, 99.8]" in c["tolerance"]
    b = orthogonal_basis(T - 5.0, 8)
    clean = fit(b, F_CLEAN, order=8)
    f = _noisy(SEED_TABLE3)
    r = fit(b, f, order=5)
    assert 98.5 <= r.err_total <= 99.8
    assert abs(r.f[0] - clean.f[0]) < 0.02
    assert abs(r.f[3] - clean.f[3]) < 0.02
    assert fit(b, f, threshold=99.0).order == 5
    # statistically: f_0 error ~ N(0, 0.1/sqrt(21)); over 200 seeds the share within 0.02 is ~0.63
    share = np.mean([abs(fit(b, _noisy(s), order=5).f[0] - clean.f[0]) < 0.02 for s in range(200)])
    assert 0.5 < share < 0.76


def test_tb_table4_noisy_derivative_integral():
    c = case("tb_table4_noisy_derivative_integral")
    true = _true_values()
    # (a) the printed eq. (22) polynomial reproduces the document's percent errors within 2 points
    beta22 = case("tb_table3_noisy_orthogonal_approx")["expected"]["eq22_beta_ts"]
    vals22 = np.array([poly_derivative_at(beta22, 0.0, 0), poly_derivative_at(beta22, 0.0, 1),
                       poly_derivative_at(beta22, 0.0, 2), poly_repeated_integral(beta22, 1, -5, 5),
                       poly_repeated_integral(beta22, 2, -5, 5)])
    pct22 = 100 * np.abs(vals22 - true) / np.abs(true)
    np.testing.assert_allclose(pct22, c["expected"]["pct_err"], atol=2.0)
    # (b) property over 200 noise seeds: integrals are far more robust than f(5) and f''(5)
    b = orthogonal_basis(T - 5.0, 8)
    pcts = np.array([100 * np.abs(_fit_values(fit(b, _noisy(s), order=5)) - true) / np.abs(true) for s in range(200)])
    mean = pcts.mean(axis=0)
    assert max(mean[3], mean[4]) < min(mean[0], mean[2])


def test_bad_inputs():
    with pytest.raises(InputError, match="m_max"):
        orthogonal_basis(T, 21)
    b = orthogonal_basis(T, 5)
    with pytest.raises(InputError, match="threshold"):
        fit(b, F_CLEAN, threshold=120.0)
    with pytest.raises(InputError, match="f: expected 21"):
        fit(b, F_CLEAN[:10])
