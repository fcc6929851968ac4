"""The R-only QR paths of LS / WLS and the cross-moment path of IV give the same results as a
reference: numpy.linalg.lstsq / pinv, and the previous algorithms (SVD of Φ + explicit Q; explicit
p×N matrix P for IV), written inline here.  Relative agreement 1e-10, also for ill-conditioned and
rank-deficient regressors."""

from fractions import Fraction

import numpy as np
import pytest
from scipy.linalg import solve_triangular

from pipeline.estimators import iv, ls, wls
from pipeline.estimators.base import augmented_r, numerical_rank
from pipeline.errors import EstimationError

RTOL = 1e-10


def _rel(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _designed(n, s, seed):
    """N×p matrix U diag(s) Vᵀ with prescribed singular values s."""
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.standard_normal((n, len(s))))
    v, _ = np.linalg.qr(rng.standard_normal((len(s), len(s))))
    return (u * s) @ v.T


def _old_ls(phi, y):
    """Previous LS algorithm: numerical rank from the SVD of Φ, then reduced QR with explicit Q."""
    n, p = phi.shape
    rank, s, v, tol = numerical_rank(phi)
    q, r = np.linalg.qr(phi, mode="reduced")
    theta = solve_triangular(r, q.T @ y)
    rinv = solve_triangular(r, np.eye(p))
    return rank, s, tol, theta, rinv @ rinv.T


def _problems():
    rng = np.random.default_rng(0)
    phi = rng.standard_normal((3000, 8))
    yield "well", phi, phi @ rng.standard_normal(8) + 0.1 * rng.standard_normal(3000)
    # ill-conditioned: singular values 1 .. 1e-6 (cond 1e6), small residual
    phi = _designed(2000, np.logspace(0, -6, 7), 1)
    yield "ill", phi, phi @ rng.standard_normal(7) + 1e-9 * rng.standard_normal(2000)
    # badly scaled columns (cond ~1e5 from scaling only)
    phi = rng.standard_normal((1500, 5)) * np.array([1e-3, 1.0, 1e2, 10.0, 1e-1])
    yield "scaled", phi, phi @ rng.standard_normal(5) + 0.01 * rng.standard_normal(1500)
    # polynomial (Vandermonde) regressors
    t = np.linspace(-1, 1, 500)
    phi = np.vander(t, 9, increasing=True)
    yield "vander", phi, np.cos(3 * t) + 1e-3 * rng.standard_normal(500)


@pytest.mark.parametrize("case", list(_problems()), ids=lambda c: c[0])
def test_ls_fast_path_matches_lstsq_and_previous_algorithm(case):
    _, phi, y = case
    est = ls.fit(phi, y)
    ref = np.linalg.lstsq(phi, y, rcond=None)[0]
    assert _rel(est.theta, ref) < RTOL
    rank, s, tol, theta_old, gram_old = _old_ls(phi, y)
    assert est.extra["rank"] == rank == phi.shape[1]
    assert _rel(est.theta, theta_old) < RTOL
    assert _rel(est.extra["singular_values"], s) < RTOL  # relative to s_max
    assert est.extra["rank_tol"] == pytest.approx(tol, rel=RTOL)
    assert _rel(est.extra["pinv_gram"], gram_old) < 1e-8 * np.linalg.cond(phi) ** 2 * 1e-4 + RTOL
    resid = y - phi @ ref
    assert est.extra["sse"] == pytest.approx(float(resid @ resid), rel=1e-8)
    assert est.extra["null_space"].shape == (phi.shape[1], 0) and est.extra["min_norm"] is False
    # SSE = r22² of the augmented factor
    r = augmented_r(phi, y)
    assert r[-1, -1] ** 2 == pytest.approx(est.extra["sse"], rel=1e-8)


def test_ls_cov_matches_previous_algorithm_well_conditioned():
    rng = np.random.default_rng(5)
    phi = rng.standard_normal((4000, 6))
    y = phi @ rng.standard_normal(6) + rng.standard_normal(4000)
    est = ls.fit(phi, y)
    _, _, _, theta_old, gram_old = _old_ls(phi, y)
    resid = y - phi @ theta_old
    cov_old = float(resid @ resid) / (4000 - 6) * gram_old
    assert _rel(est.cov, cov_old) < 1e-12
    assert _rel(est.theta, theta_old) < 1e-12


def test_ls_rank_deficient_same_message_null_space_and_min_norm():
    rng = np.random.default_rng(2)
    a = rng.standard_normal((400, 3))
    phi = np.column_stack([a, a[:, 0] - 2.0 * a[:, 2]])  # 4th column dependent
    y = a @ [1.0, -1.0, 0.5] + 0.01 * rng.standard_normal(400)
    rank, s, v, tol = numerical_rank(phi)
    with pytest.raises(EstimationError) as exc:
        ls.fit(phi, y)
    msg = str(exc.value)
    assert f"numerical rank {rank} < 4 parameters (N = 400, SVD tolerance {tol:.3g})" in msg
    assert "direction(s) [-0.5, 0, 1, 0.5]" in msg and "min_norm=True" in msg
    est = ls.fit(phi, y, min_norm=True)
    assert est.extra["min_norm"] is True and est.extra["rank"] == 3
    assert _rel(est.theta, np.linalg.pinv(phi, rcond=400 * np.finfo(float).eps) @ y) < RTOL
    assert _rel(est.theta, np.linalg.lstsq(phi, y, rcond=None)[0]) < RTOL
    null = est.extra["null_space"]
    assert null.shape == (4, 1)
    assert _rel(np.abs(null[:, 0]), np.abs(v[:, 3])) < RTOL
    assert np.linalg.norm(phi @ null) < 1e-10 * np.linalg.norm(phi)


def test_ls_near_rank_deficient_and_rtol_decided_like_the_svd_of_phi():
    s = np.array([1.0, 1e-3, 1e-9, 1e-14])
    phi = _designed(800, s, 3)
    y = phi @ np.ones(4)
    for rtol in (None, 1e-10, 1e-6, 1e-2):
        rank_ref, s_ref, v_ref, tol_ref = numerical_rank(phi, rtol)
        if rank_ref < 4:
            with pytest.raises(EstimationError, match=f"numerical rank {rank_ref} < 4"):
                ls.fit(phi, y, rtol=rtol)
            est = ls.fit(phi, y, rtol=rtol, min_norm=True)
            assert est.extra["rank"] == rank_ref
            pinv = np.linalg.pinv(phi, rcond=rtol if rtol is not None else 800 * np.finfo(float).eps)
            assert _rel(est.theta, pinv @ y) < RTOL
            assert _rel(np.abs(est.extra["null_space"]), np.abs(v_ref[:, rank_ref:])) < 1e-8
        else:
            est = ls.fit(phi, y, rtol=rtol)
            assert est.extra["rank"] == 4
    # the R-based rank equals the Φ-based rank
    r = augmented_r(phi, y)
    for rtol in (None, 1e-10, 1e-6, 1e-2):
        assert numerical_rank(r[:4, :4], rtol, n_rows=800)[0] == numerical_rank(phi, rtol)[0]
        assert numerical_rank(r[:4, :4], rtol, n_rows=800)[3] == pytest.approx(numerical_rank(phi, rtol)[3],
                                                                               rel=RTOL)


@pytest.mark.parametrize("n", [3, 5])
def test_ls_square_and_wide(n):
    rng = np.random.default_rng(n)
    phi = rng.standard_normal((n, 5))
    y = rng.standard_normal(n)
    if n == 5:
        est = ls.fit(phi, y)
        assert _rel(est.theta, np.linalg.solve(phi, y)) < RTOL
        assert est.cov is None and est.extra["dof"] == 0
    else:
        with pytest.raises(EstimationError, match="numerical rank 3 < 5"):
            ls.fit(phi, y)
        est = ls.fit(phi, y, min_norm=True)
        assert _rel(est.theta, np.linalg.lstsq(phi, y, rcond=None)[0]) < RTOL
        assert est.extra["null_space"].shape == (5, 2)


def test_augmented_r_matches_qr():
    rng = np.random.default_rng(7)
    phi = rng.standard_normal((300, 4))
    y = rng.standard_normal(300)
    w = rng.uniform(0.5, 2.0, 300)
    r = augmented_r(phi, y, np.sqrt(w))
    r_ref = np.linalg.qr(np.column_stack([phi, y]) * np.sqrt(w)[:, None], mode="r")
    assert r.shape == (5, 5)
    assert _rel(np.abs(r), np.abs(r_ref)) < 1e-12
    assert np.all(np.tril(r, -1) == 0)


@pytest.mark.parametrize("case", list(_problems()), ids=lambda c: c[0])
def test_wls_weights_fast_path_matches_lstsq_on_whitened_data(case):
    _, phi, y = case
    rng = np.random.default_rng(11)
    w = rng.uniform(0.2, 5.0, y.size)
    sw = np.sqrt(w)
    est = wls.fit(phi, y, weights=w)
    ref = np.linalg.lstsq(phi * sw[:, None], y * sw, rcond=None)[0]
    assert _rel(est.theta, ref) < RTOL
    # previous algorithm: explicit whitened Φ, reduced QR with Q, e_w from Φ_w
    phi_w, y_w = phi * sw[:, None], y * sw
    q, r = np.linalg.qr(phi_w, mode="reduced")
    theta_old = solve_triangular(r, q.T @ y_w)
    rinv = solve_triangular(r, np.eye(phi.shape[1]))
    e_w = y_w - phi_w @ theta_old
    assert _rel(est.theta, theta_old) < RTOL
    assert est.extra["weighted_sse"] == pytest.approx(float(e_w @ e_w), rel=1e-8)
    dof = y.size - phi.shape[1]
    if case[0] == "well":
        assert _rel(est.cov, float(e_w @ e_w) / dof * (rinv @ rinv.T)) < 1e-12


def test_wls_noise_cov_and_fgls_match_reference():
    rng = np.random.default_rng(12)
    n = 200
    phi = rng.standard_normal((n, 3))
    y = phi @ [1.0, -2.0, 0.5] + rng.standard_normal(n)
    a = rng.standard_normal((n, n))
    rcov = a @ a.T / n + np.eye(n)
    est = wls.fit(phi, y, noise_cov=rcov)
    ri = np.linalg.inv(rcov)
    gls = np.linalg.solve(phi.T @ ri @ phi, phi.T @ ri @ y)  # Johansson (5.76)
    assert _rel(est.theta, gls) < 1e-10
    assert _rel(est.cov, np.linalg.inv(phi.T @ ri @ phi)) < 1e-10  # (5.77)
    # feasible GLS: the final θ is WLS with the final weights
    y2 = phi @ [1.0, -2.0, 0.5] + np.abs(phi[:, 0]) * rng.standard_normal(n)
    f = wls.fit(phi, y2, fgls=True, n_iter=3)
    sw = np.sqrt(f.extra["weights"])
    assert _rel(f.theta, np.linalg.lstsq(phi * sw[:, None], y2 * sw, rcond=None)[0]) < RTOL


def test_wls_rank_deficient_same_message():
    rng = np.random.default_rng(13)
    a = rng.standard_normal((100, 2))
    phi = np.column_stack([a, a.sum(axis=1)])
    with pytest.raises(EstimationError, match=r"singular weighted regressors: numerical rank 2 < 3 parameters; "
                                              "expected full column rank"):
        wls.fit(phi, rng.standard_normal(100), weights=rng.uniform(0.5, 2, 100))


def _old_iv(phi, y, z, ma_lags=0):
    """Previous IV algorithm with the explicit p×N matrix P (Johansson (6.54)–(6.58), (6.66))."""
    keep = np.all(np.isfinite(z), axis=1)
    phi, y, z = phi[keep], y[keep], z[keep]
    n, p = phi.shape
    if z.shape[1] == p:
        pz = np.linalg.solve(z.T @ phi, z.T)
    else:
        w = np.linalg.inv(z.T @ z)
        m = phi.T @ z @ w
        pz = np.linalg.solve(m @ z.T @ phi, m @ z.T)
    theta = pz @ y
    resid = y - phi @ theta
    dof = n - p
    gam = np.array([resid[: n - l] @ resid[l:] / dof for l in range(ma_lags + 1)])
    cov = gam[0] * (pz @ pz.T)
    for l in range(1, ma_lags + 1):
        c = pz[:, : n - l] @ pz[:, l:].T
        cov += gam[l] * (c + c.T)
    return theta, cov, resid, gam, keep


@pytest.mark.parametrize("q_extra", [0, 3])
@pytest.mark.parametrize("ma_lags", [0, 1, 3])
def test_iv_cross_moments_match_explicit_p(q_extra, ma_lags):
    rng = np.random.default_rng(20 + q_extra + ma_lags)
    n, p = 3000, 4
    z0 = rng.standard_normal((n, p + q_extra))
    phi = z0[:, :p] + 0.3 * z0[:, p:].sum(axis=1, keepdims=True) + 0.5 * rng.standard_normal((n, p))
    e = rng.standard_normal(n + 2)
    y = phi @ [1.0, -0.5, 2.0, 0.3] + e[2:] + 0.6 * e[1:-1] + 0.3 * e[:-2]
    est = iv.fit(phi, y, instruments=z0, ma_lags=ma_lags)
    theta, cov, resid, gam, _ = _old_iv(phi, y, z0, ma_lags)
    assert _rel(est.theta, theta) < RTOL
    assert _rel(est.cov, cov) < RTOL
    assert _rel(est.residuals, resid) < RTOL
    assert _rel(est.extra["noise_autocov"], gam) < RTOL
    assert est.extra["rows_kept"].all() and est.extra["n_used"] == n
    if ma_lags == 0:  # the stated special case of (6.66)
        if q_extra:
            a = phi.T @ z0 @ np.linalg.inv(z0.T @ z0) @ z0.T @ phi
            assert _rel(est.cov, gam[0] * np.linalg.inv(a)) < RTOL
        else:
            b = np.linalg.inv(z0.T @ phi)
            assert _rel(est.cov, gam[0] * b @ (z0.T @ z0) @ b.T) < RTOL


def test_iv_delayed_instruments_drop_rows_like_before():
    rng = np.random.default_rng(30)
    n = 2000
    u = rng.standard_normal(n + 1)
    phi = np.column_stack([u[1:], u[:-1] + 0.2 * rng.standard_normal(n)])
    y = phi @ [0.7, -1.2] + 0.1 * rng.standard_normal(n)
    z = iv.delayed(u[:-1], [0, 1, 2], n)
    for lags in (0, 2):
        est = iv.fit(phi, y, inputs=u[:-1], delays=[0, 1, 2], ma_lags=lags)
        theta, cov, resid, gam, keep = _old_iv(phi, y, z, lags)
        assert np.array_equal(est.extra["rows_kept"], keep) and est.extra["n_used"] == keep.sum() == n - 2
        assert _rel(est.theta, theta) < RTOL and _rel(est.cov, cov) < RTOL


def test_iv_ill_conditioned_instruments_match_explicit_p():
    rng = np.random.default_rng(31)
    n = 2000
    phi = _designed(n, np.array([1.0, 1e-1, 1e-2]), 32)
    z = phi + 1e-3 * rng.standard_normal((n, 3))  # cond(ZᵀΦ) ~ 1e4
    y = phi @ [1.0, 2.0, 3.0] + 1e-2 * rng.standard_normal(n)
    for zz in (z, np.column_stack([z, phi + 1e-3 * rng.standard_normal((n, 3))])):
        est = iv.fit(phi, y, instruments=zz, ma_lags=1)
        theta, cov, _, _, _ = _old_iv(phi, y, zz, 1)
        assert _rel(est.theta, theta) < RTOL
        assert _rel(est.cov, cov) < RTOL


# --- very ill-conditioned problems: two backward-stable algorithms can only agree to ~cond·eps, so the
# reference is the exact (rational-arithmetic) solution of the normal equations of the float data, and
# the new paths must be as accurate as the previous ones.

def _exact_solve(a, b):
    """Exact solution of the square rational system a x = b (Gaussian elimination on Fractions)."""
    n = len(b)
    m = [list(row) + [b[i]] for i, row in enumerate(a)]
    for k in range(n):
        piv = next(i for i in range(k, n) if m[i][k] != 0)
        m[k], m[piv] = m[piv], m[k]
        for i in range(k + 1, n):
            f = m[i][k] / m[k][k]
            if f:
                m[i] = [u - f * v for u, v in zip(m[i], m[k])]
    x = [Fraction(0)] * n
    for k in range(n - 1, -1, -1):
        x[k] = (m[k][n] - sum(m[k][j] * x[j] for j in range(k + 1, n))) / m[k][k]
    return np.array([float(v) for v in x])


def _exact_cross(a, b):
    """Exact AᵀB of float matrices in rational arithmetic."""
    ca = [[Fraction(v) for v in col] for col in np.asarray(a).T]
    cb = [[Fraction(v) for v in col] for col in np.asarray(b).T]
    return [[sum(u * v for u, v in zip(x, w)) for w in cb] for x in ca]


def test_ls_very_ill_conditioned_as_accurate_as_before():
    rng = np.random.default_rng(40)
    phi = rng.standard_normal((300, 4)) * np.array([1e-4, 1.0, 1e3, 1e-2])  # cond ~1e7
    y = phi @ rng.standard_normal(4) + 1e-3 * rng.standard_normal(300)
    exact = _exact_solve(_exact_cross(phi, phi), [r[0] for r in _exact_cross(phi, y[:, None])])
    err_new = _rel(ls.fit(phi, y).theta, exact)
    err_old = _rel(_old_ls(phi, y)[3], exact)
    cond = np.linalg.cond(phi)
    assert cond > 1e6
    assert err_new < 10 * cond * np.finfo(float).eps and err_new < 10 * max(err_old, np.finfo(float).eps)
    sw = np.sqrt(rng.uniform(0.5, 2.0, 300))
    exact_w = _exact_solve(_exact_cross(phi * sw[:, None], phi * sw[:, None]),
                           [r[0] for r in _exact_cross(phi * sw[:, None], (y * sw)[:, None])])
    assert _rel(wls.fit(phi, y, weights=sw ** 2).theta, exact_w) < 10 * cond * np.finfo(float).eps


def test_iv_very_ill_conditioned_as_accurate_as_before():
    rng = np.random.default_rng(31)
    n = 400
    phi = _designed(n, np.array([1.0, 1e-2, 1e-4]), 32)
    z = phi + 1e-5 * rng.standard_normal((n, 3))  # cond(ZᵀΦ) ~ 1e8
    y = phi @ [1.0, 2.0, 3.0] + 1e-6 * rng.standard_normal(n)
    exact = _exact_solve(_exact_cross(z, phi), [r[0] for r in _exact_cross(z, y[:, None])])
    cond = np.linalg.cond(z.T @ phi)
    err_new = _rel(iv.fit(phi, y, instruments=z).theta, exact)
    err_old = _rel(_old_iv(phi, y, z)[0], exact)
    assert cond > 1e7
    assert err_new < 10 * cond * np.finfo(float).eps and err_new < 10 * err_old


def test_iv_dependent_instruments_raise():
    rng = np.random.default_rng(33)
    phi = rng.standard_normal((100, 2))
    z = np.column_stack([phi, phi[:, 0]])  # q = 3 > p, ZᵀZ singular
    with pytest.raises(EstimationError, match="instrument"):
        iv.fit(phi, rng.standard_normal(100), instruments=z)
