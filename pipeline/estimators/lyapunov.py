"""Lyapunov-based real-time (continuous-time) estimators of the course project (seed 000).

Parallel (output-error) configuration for x' = Ax + Bu + w (Problem 1, system (Σ)):
    x̂' = Âx̂ + B̂u,  e = x − x̂,  Â' = γ1 e x̂ᵀ − γ1 σ_δ(Â)Â,  B̂' = γ2 e uᵀ − γ2 σ_δ(B̂)B̂
with V = ½eᵀe + tr(ẽ_Aᵀẽ_A)/(2γ1) + tr(ẽ_Bᵀẽ_B)/(2γ2), V' = eᵀAe <= 0 without disturbance and
σ-modification (Problem 1(a), corrected eq (1): e' = Ae − ẽ_A x̂ − ẽ_B u with ẽ_A = Â − A). σ-modification
(Problem 1(b)): σ_δ(θ) = 0 for |θ| < M, σ(|θ|/M − 1) for M <= |θ| <= 2M, σ beyond 2M, per parameter.
Projection: estimates clipped to [low, high] after each step.

Series-parallel configuration for a scalar x' = f(x) + g(x, u) with g known (Problem 2(a)):
    x̂' = θ̂ᵀφ(x) + g(x, u) + θ_m (x − x̂),  θ̂_i' = γ_i e φ_i(x),  e = x − x̂,
error energy E = Σ_k e_k² Δt over the N = T/Δt + 1 samples (seed_cases.md section 6).

Integration: classical fixed-step RK4 (numba-compiled loops). The plant does not depend on the
estimator, so for the series-parallel case the plant's RK4 stage values are computed once and shared.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .base import EstimationError

# ---------------------------------------------------------------- parallel LTI (Problem 1)


@njit(cache=True)
def _sigma_delta(th, m, sig):
    a = abs(th)
    if sig <= 0.0 or a < m:
        return 0.0
    if a <= 2.0 * m:
        return sig * (a / m - 1.0)
    return sig


@njit(cache=True)
def _par_rhs(x, xh, ah, bh, a, b, u, w, g1, g2, ma, sa, mb, sb, dx, dxh, dah, dbh, sda, sdb):
    n = x.shape[0]
    m = bh.shape[1]
    for i in range(n):
        s = w[i]
        sh = 0.0
        for j in range(n):
            s += a[i, j] * x[j]
            sh += ah[i, j] * xh[j]
        for j in range(m):
            s += b[i, j] * u[j]
            sh += bh[i, j] * u[j]
        dx[i] = s
        dxh[i] = sh
    for i in range(n):
        e = x[i] - xh[i]
        for j in range(n):
            sd = _sigma_delta(ah[i, j], ma[i, j], sa[i, j])
            sda[i, j] = sd
            dah[i, j] = g1 * e * xh[j] - g1 * sd * ah[i, j]
        for j in range(m):
            sd = _sigma_delta(bh[i, j], mb[i, j], sb[i, j])
            sdb[i, j] = sd
            dbh[i, j] = g2 * e * u[j] - g2 * sd * bh[i, j]


@njit(cache=True)
def _parallel_kernel(a, b, uh, wh, dt, x0, xh0, ah0, bh0, g1, g2, loa, hia, lob, hib, ma, sa, mb, sb):
    n = a.shape[0]
    m = b.shape[1]
    k_steps = (uh.shape[0] - 1) // 2
    xs = np.empty((k_steps + 1, n))
    xhs = np.empty((k_steps + 1, n))
    ahs = np.empty((k_steps + 1, n, n))
    bhs = np.empty((k_steps + 1, n, m))
    v = np.empty(k_steps + 1)
    proj = np.zeros(k_steps + 1, dtype=np.bool_)
    sdas = np.zeros((k_steps + 1, n, n))
    sdbs = np.zeros((k_steps + 1, n, m))
    x = x0.copy()
    xh = xh0.copy()
    ah = ah0.copy()
    bh = bh0.copy()
    # stage buffers
    kx = np.empty((4, n))
    kxh = np.empty((4, n))
    ka = np.empty((4, n, n))
    kb = np.empty((4, n, m))
    sda = np.empty((n, n))
    sdb = np.empty((n, m))
    tx = np.empty(n)
    txh = np.empty(n)
    ta = np.empty((n, n))
    tb = np.empty((n, m))
    for k in range(k_steps + 1):
        xs[k] = x
        xhs[k] = xh
        ahs[k] = ah
        bhs[k] = bh
        vv = 0.0
        for i in range(n):
            vv += 0.5 * (x[i] - xh[i]) ** 2
            for j in range(n):
                vv += (ah[i, j] - a[i, j]) ** 2 / (2.0 * g1)
            for j in range(m):
                vv += (bh[i, j] - b[i, j]) ** 2 / (2.0 * g2)
        v[k] = vv
        if k == k_steps:
            # record σ_δ at the final point
            _par_rhs(x, xh, ah, bh, a, b, uh[2 * k], wh[2 * k], g1, g2, ma, sa, mb, sb,
                     kx[0], kxh[0], ka[0], kb[0], sda, sdb)
            sdas[k] = sda
            sdbs[k] = sdb
            break
        cs = (0.0, 0.5, 0.5, 1.0)
        for s in range(4):
            c = cs[s]
            if s == 0:
                tx[:] = x
                txh[:] = xh
                ta[:, :] = ah
                tb[:, :] = bh
            else:
                for i in range(n):
                    tx[i] = x[i] + c * dt * kx[s - 1, i]
                    txh[i] = xh[i] + c * dt * kxh[s - 1, i]
                    for j in range(n):
                        ta[i, j] = ah[i, j] + c * dt * ka[s - 1, i, j]
                    for j in range(m):
                        tb[i, j] = bh[i, j] + c * dt * kb[s - 1, i, j]
            idx = 2 * k + (0 if s == 0 else (1 if s < 3 else 2))
            _par_rhs(tx, txh, ta, tb, a, b, uh[idx], wh[idx], g1, g2, ma, sa, mb, sb,
                     kx[s], kxh[s], ka[s], kb[s], sda, sdb)
            if s == 0:
                sdas[k] = sda
                sdbs[k] = sdb
        for i in range(n):
            x[i] += dt / 6.0 * (kx[0, i] + 2 * kx[1, i] + 2 * kx[2, i] + kx[3, i])
            xh[i] += dt / 6.0 * (kxh[0, i] + 2 * kxh[1, i] + 2 * kxh[2, i] + kxh[3, i])
            for j in range(n):
                val = ah[i, j] + dt / 6.0 * (ka[0, i, j] + 2 * ka[1, i, j] + 2 * ka[2, i, j] + ka[3, i, j])
                if val < loa[i, j]:
                    val = loa[i, j]
                    proj[k + 1] = True
                elif val > hia[i, j]:
                    val = hia[i, j]
                    proj[k + 1] = True
                ah[i, j] = val
            for j in range(m):
                val = bh[i, j] + dt / 6.0 * (kb[0, i, j] + 2 * kb[1, i, j] + 2 * kb[2, i, j] + kb[3, i, j])
                if val < lob[i, j]:
                    val = lob[i, j]
                    proj[k + 1] = True
                elif val > hib[i, j]:
                    val = hib[i, j]
                    proj[k + 1] = True
                bh[i, j] = val
    return xs, xhs, ahs, bhs, v, proj, sdas, sdbs


def _half_grid(fn, t, dt, width):
    th = np.empty(2 * t.size - 1)
    th[0::2] = t
    th[1::2] = t[:-1] + 0.5 * dt
    if fn is None:
        return np.zeros((th.size, width))
    out = np.asarray(fn(th), dtype=float)
    if out.ndim == 1:
        out = out[:, None]
    if out.shape[0] != th.size:
        out = out.T
    if out.shape != (th.size, width):
        raise EstimationError(f"signal function returned shape {out.shape}, expected ({th.size}, {width})")
    return np.ascontiguousarray(out)


def _full(value, shape, fill):
    if value is None:
        return np.full(shape, fill, dtype=float)
    # a writable C-contiguous copy (a read-only broadcast view would be a different numba type)
    return np.array(np.broadcast_to(np.asarray(value, dtype=float), shape), dtype=float, order="C")


def parallel_lti(A, B, u_fn, *, T: float, dt: float, gamma1: float, gamma2: float, x0=None, xh0=None,
                 A0=None, B0=None, w_fn=None, A_bounds=(None, None), B_bounds=(None, None),
                 M_A=None, sigma_A=None, M_B=None, sigma_B=None) -> dict:
    """Parallel Lyapunov estimator of (Â, B̂) for x' = Ax + Bu + w (course project Problem 1(a), 1(b)).

    ``u_fn(t)``/``w_fn(t)`` are vectorised signals; ``A_bounds``/``B_bounds`` = (low, high) arrays for
    the projection (None = unbounded); ``M_*``/``sigma_*`` per-parameter σ-modification thresholds and
    strengths (σ = 0 disables it). Returns a dict with t, x, xh, A_hat, B_hat, V, projection_active,
    sigma_delta_A, sigma_delta_B (all sampled at t_k = k·dt).
    """
    a = np.ascontiguousarray(np.atleast_2d(np.asarray(A, dtype=float)))
    b = np.asarray(B, dtype=float)
    b = np.ascontiguousarray(b.reshape(a.shape[0], -1))
    n, m = b.shape
    if gamma1 <= 0 or gamma2 <= 0 or dt <= 0 or T <= 0:
        raise EstimationError("gamma1, gamma2, dt and T must be positive")
    k_steps = int(round(T / dt))
    t = np.arange(k_steps + 1) * dt
    uh = _half_grid(u_fn, t, dt, m)
    wh = _half_grid(w_fn, t, dt, n)
    res = _parallel_kernel(
        a, b, uh, wh, float(dt), _full(x0, (n,), 0.0), _full(xh0, (n,), 0.0), _full(A0, (n, n), 0.0),
        _full(B0, (n, m), 0.0), float(gamma1), float(gamma2),
        _full(A_bounds[0], (n, n), -np.inf), _full(A_bounds[1], (n, n), np.inf),
        _full(B_bounds[0], (n, m), -np.inf), _full(B_bounds[1], (n, m), np.inf),
        _full(M_A, (n, n), np.inf), _full(sigma_A, (n, n), 0.0), _full(M_B, (n, m), np.inf), _full(sigma_B, (n, m), 0.0))
    xs, xhs, ahs, bhs, v, proj, sda, sdb = res
    return {"t": t, "x": xs, "xh": xhs, "A_hat": ahs, "B_hat": bhs, "V": v, "projection_active": proj,
            "sigma_delta_A": sda, "sigma_delta_B": sdb, "e": xs - xhs}


# ---------------------------------------------------------------- series-parallel (Problem 2)


def rk4_plant_stages(f, x0: float, u_fn, T: float, dt: float):
    """RK4 for a scalar plant x' = f(x, u(t)); returns t (K+1,), x (K+1,), stage states (K, 4) and stage
    inputs (K, 4) (stages at t, t + dt/2, t + dt/2, t + dt)."""
    k_steps = int(round(T / dt))
    t = np.arange(k_steps + 1) * dt
    uh = np.asarray(u_fn(np.concatenate([t, t[:-1] + 0.5 * dt])), dtype=float)
    u_full, u_half = uh[: k_steps + 1], uh[k_steps + 1:]
    xs = np.empty(k_steps + 1)
    st = np.empty((k_steps, 4))
    su = np.column_stack([u_full[:-1], u_half, u_half, u_full[1:]])
    x = float(x0)
    for k in range(k_steps):
        xs[k] = x
        k1 = f(x, su[k, 0])
        x2 = x + 0.5 * dt * k1
        k2 = f(x2, su[k, 1])
        x3 = x + 0.5 * dt * k2
        k3 = f(x3, su[k, 2])
        x4 = x + dt * k3
        k4 = f(x4, su[k, 3])
        st[k] = (x, x2, x3, x4)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.isfinite(x):
            raise EstimationError(f"plant simulation diverged at t = {t[k]:g}")
    xs[k_steps] = x
    return t, xs, st, su


@njit(cache=True)
def _sp_kernel(xst, phist, knownst, gamma, theta_m, dt, xh0, theta0, adapt):
    k_steps = xst.shape[0]
    p = gamma.shape[0]
    xh = xh0
    th = theta0.copy()
    xhs = np.empty(k_steps + 1)
    ths = np.empty((k_steps + 1, p))
    kth = np.empty((4, p))
    kxh = np.empty(4)
    tth = np.empty(p)
    for k in range(k_steps):
        xhs[k] = xh
        ths[k] = th
        g = 1.0 if adapt[k] else 0.0
        for s in range(4):
            c = 0.0 if s == 0 else (0.5 if s < 3 else 1.0)
            txh = xh if s == 0 else xh + c * dt * kxh[s - 1]
            for i in range(p):
                tth[i] = th[i] if s == 0 else th[i] + c * dt * kth[s - 1, i]
            e = xst[k, s] - txh
            acc = knownst[k, s] + theta_m * e
            for i in range(p):
                acc += tth[i] * phist[k, s, i]
                kth[s, i] = g * gamma[i] * e * phist[k, s, i]
            kxh[s] = acc
        xh += dt / 6.0 * (kxh[0] + 2 * kxh[1] + 2 * kxh[2] + kxh[3])
        for i in range(p):
            th[i] += dt / 6.0 * (kth[0, i] + 2 * kth[1, i] + 2 * kth[2, i] + kth[3, i])
    xhs[k_steps] = xh
    ths[k_steps] = th
    return xhs, ths


def series_parallel(plant, basis, *, gamma, theta_m: float, dt: float, xh0: float = 0.0, theta0=None,
                    known=None, adapt=None) -> dict:
    """Series-parallel Lyapunov estimator (course project Problem 2(a)).

    ``plant`` = (t, x, stage_x, stage_u) from :func:`rk4_plant_stages`; ``basis(x)`` maps an array of
    states to (..., p) basis values; ``known(x, u)`` the part of f known to the estimator (default u);
    ``adapt`` (K,) booleans switch adaptation per step (used for cross-validation folds).
    Returns t, x, xh, e, theta (K+1, p) and the error energy E = Σ e_k² dt.
    """
    t, xs, st, su = plant
    phist = np.asarray(basis(st), dtype=float)
    if phist.ndim == 2:
        phist = phist[..., None]
    p = phist.shape[-1]
    gam = np.broadcast_to(np.asarray(gamma, dtype=float), (p,)).copy()
    if np.any(gam <= 0):
        raise EstimationError(f"adaptation gains must be positive, got {gamma}")
    knownst = su.copy() if known is None else np.asarray(known(st, su), dtype=float)
    th0 = np.zeros(p) if theta0 is None else np.asarray(theta0, dtype=float)
    ad = np.ones(st.shape[0], dtype=np.bool_) if adapt is None else np.asarray(adapt, dtype=np.bool_)
    xhs, ths = _sp_kernel(np.ascontiguousarray(st), np.ascontiguousarray(phist), np.ascontiguousarray(knownst),
                          gam, float(theta_m), float(dt), float(xh0), th0, ad)
    e = xs - xhs
    return {"t": t, "x": xs, "xh": xhs, "e": e, "theta": ths, "E": float(np.sum(e * e) * dt)}


def blocked_cv(plant, basis, *, gamma, theta_m: float, dt: float, folds: int = 10, known=None) -> dict:
    """Blocked k-fold cross-validation of the series-parallel estimator (protocol for kar_p2a_cv10,
    which the document leaves unspecified).

    The record is cut into ``folds`` contiguous blocks. For fold j the estimator runs over the whole
    record with adaptation switched off inside block j (so only the other 90 % of the data drive
    learning), and θ̂_j is its final value. Test: in block j the series-parallel observer with θ̂_j frozen
    is restarted from x̂ = x at the block start; the fold error is the mean of e² over the block.
    Returns per-fold errors and their average.
    """
    t, xs, st, su = plant
    k_steps = st.shape[0]
    edges = np.linspace(0, k_steps, folds + 1).round().astype(int)
    errs = []
    for j in range(folds):
        adapt = np.ones(k_steps, dtype=bool)
        adapt[edges[j]: edges[j + 1]] = False
        train = series_parallel(plant, basis, gamma=gamma, theta_m=theta_m, dt=dt, known=known, adapt=adapt)
        th_j = train["theta"][-1]
        sub = (t[edges[j]: edges[j + 1] + 1], xs[edges[j]: edges[j + 1] + 1], st[edges[j]: edges[j + 1]],
               su[edges[j]: edges[j + 1]])
        test = series_parallel(sub, basis, gamma=gamma, theta_m=theta_m, dt=dt, known=known,
                               xh0=float(xs[edges[j]]), theta0=th_j,
                               adapt=np.zeros(edges[j + 1] - edges[j], dtype=bool))
        errs.append(float(np.mean(test["e"] ** 2)))
    return {"fold_errors": np.array(errs), "cv": float(np.mean(errs)), "edges": edges}
