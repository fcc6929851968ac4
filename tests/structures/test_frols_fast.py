"""FROLS one-pass-per-term selection (downdated correlations Φᵀr, fused first pass) gives the same
selection, ERR values, residual energies and coefficients as the previous algorithm (Φᵀr recomputed
by a full pass at every step, column energies by einsum), written inline here."""

import importlib

import numpy as np
import pytest
from scipy.linalg import solve_triangular

from pipeline.errors import InputError
from pipeline.structures.frols import _energy_corr, frols
from pipeline.structures.library import narx

RTOL = 1e-10
frols_mod = importlib.import_module("pipeline.structures.frols")  # the package re-exports the function


def _reference(P, y, max_terms, tol=1e-10):
    """Previous FROLS selection loop (Billings 2013 §3.2): g = rᵀP and c = qᵀP by two passes per step."""
    P = np.asarray(P, dtype=float)
    n, m = P.shape
    yy = float(y @ y)
    norms0 = np.einsum("ij,ij->j", P, P)
    wn = norms0.copy()
    g_all = y @ P
    active = norms0 > 0
    C = np.zeros((max_terms, m))
    Q = np.empty((n, max_terms))
    R = np.zeros((max_terms, max_terms))
    r = y.copy()
    sel, errs, gs, sse = [], [], [], [yy]
    for s in range(max_terms):
        while True:
            valid = active & (wn > tol * norms0)
            if not valid.any():
                break
            err = np.where(valid, g_all * g_all / np.where(valid, wn, 1.0) / yy, -1.0)
            j = int(np.argmax(err))
            Qs = Q[:, :s]
            w = P[:, j] - Qs @ C[:s, j]
            d = Qs.T @ w
            w -= Qs @ d
            nrm2 = float(w @ w)
            if nrm2 > tol * norms0[j]:
                break
            active[j] = False
        if not valid.any():
            break
        nrm = np.sqrt(nrm2)
        q = w / nrm
        Q[:, s] = q
        R[:s, s] = C[:s, j] + d
        R[s, s] = nrm
        gq = float(q @ r)
        r -= gq * q
        sel.append(j)
        errs.append(gq * gq / yy)
        gs.append(gq)
        active[j] = False
        sse.append(float(r @ r))
        if s + 1 == max_terms:
            break
        c = q @ P
        C[s] = c
        g_all = r @ P
        wn -= c * c
    k = len(sel)
    coef = solve_triangular(R[:k, :k], np.asarray(gs))
    return np.asarray(sel), np.asarray(errs), np.asarray(sse), coef


def _narx_problem(n=1500, seed=0, lag=4, degree=3):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, n)
    e = rng.normal(0, 0.05, n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.2 * y[k - 1] + 0.1 * y[k - 1] * x[k - 1] + 0.9 * x[k - 2] + e[k]
    lib = narx("y", "u", lag, lag, degree)
    P = lib.evaluate({"y": y, "u": x}, drop_initial=True)
    return P, y[lib.max_lag:], lib.names


def _dependent_problem(seed=1):
    """Candidates with exact duplicates, scaled copies, exact and nearly exact linear combinations."""
    rng = np.random.default_rng(seed)
    n = 600
    a = rng.standard_normal((n, 12))
    cols = [a, a[:, :2], 3.0 * a[:, 2:3], a[:, [3]] + a[:, [4]], a[:, [5]] - 2 * a[:, [6]] + 1e-9 * rng.standard_normal(
        (n, 1)), np.zeros((n, 1)), 1e-3 * rng.standard_normal((n, 4))]
    P = np.asfortranarray(np.column_stack(cols))
    y = a[:, :8] @ rng.standard_normal(8) + 0.01 * rng.standard_normal(n)
    return P, y


def _check_same(res, ref):
    sel, errs, sse, coef = ref
    assert list(res.indices) == list(sel)
    np.testing.assert_allclose(res.err, errs, rtol=RTOL, atol=0)
    np.testing.assert_allclose(res.sse, sse, rtol=RTOL, atol=1e-14 * sse[0])
    k = len(sel)
    np.testing.assert_allclose(res.coef_for(k), coef, rtol=RTOL, atol=1e-12 * np.max(np.abs(coef)))


@pytest.mark.parametrize("max_terms", [10, 25])
def test_frols_matches_previous_algorithm_on_narx_library(max_terms):
    P, y, names = _narx_problem()
    res = frols(P, y, names, max_terms=max_terms, rho=1e-300)
    _check_same(res, _reference(P, y, max_terms))


@pytest.mark.parametrize("order", ["F", "C", "strided"])
def test_frols_matches_previous_algorithm_for_every_memory_layout(order):
    P, y, names = _narx_problem(n=800, seed=3, lag=3, degree=3)
    if order == "C":
        P = np.ascontiguousarray(P)
    elif order == "strided":
        big = np.zeros((P.shape[0], 2 * P.shape[1]), order="F")
        big[:, ::2] = P
        P = big[:, ::2]
        assert not (P.flags.f_contiguous or P.flags.c_contiguous)
    res = frols(P, y, names, max_terms=15, rho=1e-300)
    _check_same(res, _reference(P, y, 15))


def _proportional_class(P: np.ndarray) -> np.ndarray:
    """Index of the first column each column is proportional to (exact duplicates and scaled copies)."""
    u = P / np.where(np.linalg.norm(P, axis=0) > 0, np.linalg.norm(P, axis=0), 1.0)
    u = u * np.sign(u[np.argmax(np.abs(u), axis=0), np.arange(P.shape[1])])
    cls = np.arange(P.shape[1])
    for j in range(P.shape[1]):
        for i in range(j):
            if np.allclose(u[:, i], u[:, j], rtol=0, atol=1e-12):
                cls[j] = cls[i]
                break
    return cls


def test_frols_matches_previous_algorithm_with_dependent_candidates():
    """Proportional columns (a and 3a) have exactly the same ERR, so which of the two is taken is
    decided by rounding, which differs between BLAS kernels (it flipped on a newer CPU). The selection
    is compared up to that tie, by proportionality class, and the coefficients by the fitted values;
    ERR and residual energies must agree as on the other problems."""
    P, y = _dependent_problem()
    res = frols(P, y, max_terms=14, rho=1e-300)
    sel, errs, sse, coef = _reference(P, y, 14)
    cls = _proportional_class(P)
    assert list(cls[res.indices]) == list(cls[sel])
    np.testing.assert_allclose(res.err, errs, rtol=RTOL, atol=0)
    np.testing.assert_allclose(res.sse, sse, rtol=RTOL, atol=1e-14 * sse[0])
    fitted = P[:, sel] @ coef
    np.testing.assert_allclose(P[:, res.indices] @ res.coef_for(14), fitted, rtol=0,
                               atol=1e-9 * np.max(np.abs(fitted)))
    assert len(res.indices) == 14


@pytest.mark.parametrize("reanchor", [1, 3, 10, 10**9])
def test_downdated_correlations_do_not_drift(monkeypatch, reanchor):
    """Re-anchoring Φᵀr every step, every 3, every 10 (default) or never: same selection and ERR."""
    monkeypatch.setattr(frols_mod, "REANCHOR", reanchor)
    P, y, names = _narx_problem(n=2000, seed=5)
    res = frols(P, y, names, max_terms=35, rho=1e-300)
    _check_same(res, _reference(P, y, 35))


def test_downdated_correlations_track_the_direct_product():
    """The downdate Φᵀr_s = Φᵀr_{s−1} − g_s Φᵀq_s stays within rounding of the direct product over 30
    steps (relative to ‖p_j‖·‖y‖, the scale of the rounding error of either computation)."""
    P, y, _ = _narx_problem(n=2000, seed=6)
    sel = frols(P, y, max_terms=30, rho=1e-300).indices
    g = y @ P
    r = y.copy()
    Q = np.empty((y.size, 0))
    scale = np.sqrt(np.einsum("ij,ij->j", P, P)) * np.linalg.norm(y)
    worst = 0.0
    for j in sel:
        w = P[:, j] - Q @ (Q.T @ P[:, j])
        w -= Q @ (Q.T @ w)
        q = w / np.linalg.norm(w)
        Q = np.column_stack([Q, q])
        gq = float(q @ r)
        r = r - gq * q
        g = g - gq * (q @ P)
        worst = max(worst, float(np.max(np.abs(g - r @ P) / scale)))
    assert worst < 1e-13


@pytest.mark.parametrize("order", ["F", "C", "strided"])
def test_energy_corr_matches_einsum(order):
    rng = np.random.default_rng(9)
    P = rng.standard_normal((257, 23)) * rng.uniform(1e-3, 1e3, 23)
    P = np.asfortranarray(P) if order == "F" else np.ascontiguousarray(P) if order == "C" else P[::2, ::2]
    y = rng.standard_normal(P.shape[0])
    nn, g = _energy_corr(P, y)
    np.testing.assert_allclose(nn, np.einsum("ij,ij->j", P, P), rtol=1e-13)
    np.testing.assert_allclose(g, y @ P, rtol=0, atol=1e-13 * np.max(np.abs(y @ P)))


@pytest.mark.parametrize("order", ["F", "C"])
def test_non_finite_candidates_still_rejected(order):
    P, y, names = _narx_problem(n=300, seed=2, lag=2, degree=2)
    P = np.array(P, order=order)
    P[5, 3] = np.nan
    P[7, 6] = np.inf
    with pytest.raises(InputError, match=r"candidate column\(s\) \[.*\] contain NaN/inf"):
        frols(P, y, names, max_terms=3)
