"""ERR / FROLS (Chen, Billings & Luo 1989; Billings 2013 §3.2): recovery, one-pass criteria, bad input."""

import math
import os
import time

import numpy as np
import pytest

from pipeline import criteria
from pipeline.errors import InputError
from pipeline.structures.frols import frols, frols_library
from pipeline.structures.library import Library, narx


def siso_data(n=1000, sigma=0.001, seed=0):
    """SysIdentPy's get_siso_data, seeded: y[k] = 0.2y[k-1] + 0.1y[k-1]x[k-1] + 0.9x[k-2] + e[k]."""
    from pipeline.synthetic import siso_narx
    x, y = siso_narx(n, sigma, seed)
    return {"x": x, "y": y}


def sparse_narx(seed, n=2000, sigma=0.02):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    e = rng.normal(0, sigma, n)
    y = np.zeros(n)
    for k in range(3, n):
        y[k] = 0.4 * y[k - 1] + 0.8 * u[k - 1] - 0.5 * u[k - 2] ** 2 + 0.2 * y[k - 2] * u[k - 1] + 0.1 + e[k]
    return {"u": u, "y": y}


SPARSE_TRUE = {"y(t-1)": 0.4, "u(t-1)": 0.8, "u(t-2)**2": -0.5, "y(t-2)*u(t-1)": 0.2, "1": 0.1}


@pytest.mark.parametrize("stop", [{"criterion": "bic", "max_terms": 10}, {"rho": 1e-4}])
def test_sysidentpy_documented_example(stop):
    """SysIdentPy docs: xlag = ylag = 2, degree 2 -> x1(k-2), y(k-1), x1(k-1)y(k-1); θ = 0.9, 0.2, 0.1."""
    res = frols_library(narx("y", "x", 2, 2, 2), siso_data(), "y", **stop)
    assert set(res.terms) == {"x(t-2)", "y(t-1)", "y(t-1)*x(t-1)"}
    assert res.terms[0] == "x(t-2)"  # largest ERR first, as in the documented results table
    coef = dict(zip(res.terms, res.coef))
    assert coef["x(t-2)"] == pytest.approx(0.9, abs=0.01)
    assert coef["y(t-1)"] == pytest.approx(0.2, abs=0.01)
    assert coef["y(t-1)*x(t-1)"] == pytest.approx(0.1, abs=0.01)
    assert 1 - res.err[:3].sum() < 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_true_terms_of_sparse_narx(seed):
    lib = narx("y", "u", 3, 3, 3)  # 84 candidates
    res = frols_library(lib, sparse_narx(seed), "y", criterion="bic", max_terms=15)
    assert set(res.terms) == set(SPARSE_TRUE)
    for name, c in zip(res.terms, res.coef):
        assert c == pytest.approx(SPARSE_TRUE[name], abs=0.02)


def test_one_pass_criterion_equals_refit_for_every_model_size():
    data = sparse_narx(5, n=800, sigma=0.05)
    lib = narx("y", "u", 3, 3, 2)
    P = lib.evaluate(data, drop_initial=True)
    y = data["y"][lib.max_lag:]
    n = y.size
    res = frols(P, y, lib.names, criterion="aic", max_terms=12)
    assert len(res.names) == 12
    assert res.sse[0] == pytest.approx(y @ y)
    for k in range(1, 13):
        Pk = P[:, res.indices[:k]]
        theta, *_ = np.linalg.lstsq(Pk, y, rcond=None)
        e = y - Pk @ theta
        sse = float(e @ e)
        assert res.sse[k] == pytest.approx(sse, rel=1e-8)
        assert res.criterion_values[k - 1] == pytest.approx(criteria.aic(e, k), abs=n * 1e-8)
        np.testing.assert_allclose(res.coef_for(k), theta, rtol=1e-7, atol=1e-10)
        # ERR decomposition of the output energy: Σ ERR + SSE/yᵀy = 1
        assert res.err[:k].sum() + sse / (y @ y) == pytest.approx(1.0, abs=1e-10)
    assert res.n_terms == int(np.argmin(res.criterion_values)) + 1


@pytest.mark.parametrize("name", ["aicc", "bic", "fpe", "bic_energy"])
def test_other_criteria_match_pipeline_criteria(name):
    data = sparse_narx(6, n=500)
    lib = narx("y", "u", 2, 2, 2)
    P = lib.evaluate(data, drop_initial=True)
    y = data["y"][2:]
    res = frols(P, y, lib.names, criterion=name, max_terms=6)
    k = 4
    e = y - P[:, res.indices[:k]] @ res.coef_for(k)
    ref = criteria.bic_energy(float(e @ e), y.size, k) if name == "bic_energy" else getattr(criteria, name)(e, k)
    assert res.criterion_values[k - 1] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_err_threshold_stops_at_first_size_meeting_rho():
    data = sparse_narx(3)
    lib = narx("y", "u", 3, 3, 3)
    full = frols_library(lib, data, "y", criterion="bic", max_terms=8)
    rho = 0.5 * (1 - full.err[:3].sum()) + 0.5 * (1 - full.err[:4].sum())  # met at 4 terms, not at 3
    res = frols_library(lib, data, "y", rho=rho)
    assert res.n_terms == 4 and res.terms == full.names[:4]
    assert 1 - res.err.sum() < rho <= 1 - res.err[:3].sum()


def test_linearly_dependent_candidates_are_not_selected_twice():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 300))
    P = np.column_stack([a, 2 * a, b, a + b])
    y = 3 * a - b + 0.01 * rng.normal(size=300)
    res = frols(P, y, ["a", "2a", "b", "a+b"], rho=1e-12, max_terms=4)
    assert len(res.names) == 2  # the remaining columns lie in span(selected)
    assert "no linearly independent candidate" in res.stop_reason
    np.testing.assert_allclose(res.predict(P), np.linalg.lstsq(P[:, :3:2], y, rcond=None)[0] @ P[:, :3:2].T,
                               rtol=1e-9)


def test_candidate_matrix_is_not_modified():
    data = sparse_narx(1, n=300)
    lib = narx("y", "u", 2, 2, 2)
    P = lib.evaluate(data, drop_initial=True)
    P0 = P.copy()
    frols(P, data["y"][2:], lib.names, max_terms=5)
    np.testing.assert_array_equal(P, P0)


def test_bad_input():
    y = np.ones(10)
    with pytest.raises(InputError, match="empty"):
        frols(np.empty((10, 0)), y)
    with pytest.raises(InputError, match="max_terms = 12 terms for 10 samples"):
        frols(np.random.default_rng(0).normal(size=(10, 30)), y, max_terms=12)
    with pytest.raises(InputError, match="criterion"):
        frols(np.ones((10, 2)), y, criterion="mdl")
    with pytest.raises(InputError, match="NaN"):
        frols(np.full((10, 2), np.nan), y)
    with pytest.raises(InputError, match="identically zero"):
        frols(np.ones((10, 2)), np.zeros(10))
    with pytest.raises(InputError, match="without delay"):
        frols_library(Library(["y", "u(t-1)"]), {"y": np.ones(10), "u": np.ones(10)}, "y")
    with pytest.raises(InputError, match="does not parse"):
        frols_library(["x.real"], {"y": np.ones(10), "x": np.ones(10)}, "y")


@pytest.mark.skipif(os.environ.get("SYSID_BENCH") != "1", reason="benchmark: set SYSID_BENCH=1")
def test_benchmark_lags10_degree4():
    n = int(os.environ.get("SYSID_BENCH_N", "10000"))
    data = sparse_narx(0, n=n)
    lib = narx("y", "u", 10, 10, 4)
    assert len(lib) == math.comb(24, 4)
    t0 = time.perf_counter()
    P = lib.evaluate(data, drop_initial=True)
    t1 = time.perf_counter()
    res = frols(P, data["y"][10:], lib.names, max_terms=10, criterion="bic")
    t2 = time.perf_counter()
    print(f"\nN={n} M={len(lib)}: evaluate {t1 - t0:.2f} s, FROLS 10 terms {t2 - t1:.2f} s; {res.terms}")
    assert set(SPARSE_TRUE) <= set(res.names)
