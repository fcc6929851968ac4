"""Takagi–Sugeno fuzzy model with Gaussian memberships and affine consequents.

Takagi & Sugeno (1985, IEEE Trans. SMC 15(1), 116–132); textbook: Brzostowski & Drapała, §2.5,
eqs. (2.159)–(2.165).  Rule k: IF u is A_k THEN y_k = θ_kᵀu + θ_k⁽⁰⁾ (2.159).  Membership (2.164):

    β_k(u) = exp(−Σ_s (u⁽ˢ⁾ − m_k⁽ˢ⁾)² / (σ_k⁽ˢ⁾)²)      (no factor 2: σ is not the Gaussian s.d.)

Output (2.161; eq. 2.165 as printed puts the consequent outside both sums — corrected here, seed
case ``wro_ex2_12_takagi_sugeno_inference``, misprint #16): the normalised weighted average

    y = Σ_k β_k(u) (θ_kᵀu + θ_k⁽⁰⁾) / Σ_k β_k(u).

Centres come from a grid (equally spaced over the data range) or k-means with a fixed seed;
consequents are fitted by global least squares (all rules jointly on the normalised-membership
regressors, Babuška & Verbruggen 2003) or local, membership-weighted least squares (one weighted LS
per rule).  The number of rules K is chosen by blocked cross-validation (:mod:`pipeline.selection`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from pipeline.errors import InputError
from pipeline.selection import cross_validate


def _as_2d(U) -> np.ndarray:
    U = np.asarray(U, dtype=float)
    if U.ndim == 1:
        U = U[:, None]
    if U.ndim != 2:
        raise InputError(f"takagi_sugeno: inputs have shape {U.shape}; expected (N,) or (N, S)")
    if not np.all(np.isfinite(U)):
        raise InputError("takagi_sugeno: inputs contain NaN/inf; expected finite values")
    return U


def memberships(U, centres, sigmas) -> np.ndarray:
    """β (N × K), eq. (2.164) multiplied over the inputs: exp(−Σ_s (u_s − m_ks)²/σ_ks²)."""
    U = _as_2d(U)
    m = np.atleast_2d(np.asarray(centres, dtype=float))
    if m.shape[1] != U.shape[1]:
        raise InputError(f"takagi_sugeno: centres have {m.shape[1]} coordinates but inputs have {U.shape[1]}")
    sg = np.asarray(sigmas, dtype=float)
    if sg.ndim == 1 and sg.size == m.shape[0]:
        sg = sg[:, None]  # one width per rule, shared by the inputs
    try:
        sg = np.broadcast_to(sg, m.shape)
    except ValueError:
        raise InputError(f"takagi_sugeno: sigmas have shape {np.shape(sigmas)}; expected a scalar, (K,) or "
                         f"(K, S) = {m.shape}") from None
    if np.any(sg <= 0):
        raise InputError("takagi_sugeno: membership widths sigma must be positive")
    d = (U[:, None, :] - m[None, :, :]) / sg[None, :, :]
    return np.exp(-np.sum(d * d, axis=2))


def _normalised(beta: np.ndarray) -> np.ndarray:
    s = beta.sum(axis=1, keepdims=True)
    if np.any(s <= 0):
        raise InputError("takagi_sugeno: an input lies outside the support of every rule "
                         "(all memberships underflow to 0); expected inputs within the data range")
    return beta / s


@dataclass
class TakagiSugeno:
    """K rules: ``centres`` (K × S), ``sigmas`` (K × S), ``theta`` (K × (S+1)) = [θ_k, θ_k⁽⁰⁾]."""

    centres: np.ndarray
    sigmas: np.ndarray
    theta: np.ndarray
    method: str = "given"
    info: dict = field(default_factory=dict, repr=False)

    @property
    def n_rules(self) -> int:
        return self.centres.shape[0]

    def predict(self, U) -> np.ndarray:
        """Normalised weighted average of the affine consequents (eq. 2.161 / corrected 2.165)."""
        U = _as_2d(U)
        w = _normalised(memberships(U, self.centres, self.sigmas))
        yk = U @ self.theta[:, :-1].T + self.theta[:, -1][None, :]  # N × K rule outputs
        return np.sum(w * yk, axis=1)

    def rules(self, precision: int = 3) -> list[str]:
        out = []
        for k in range(self.n_rules):
            cond = " and ".join(f"u{s} ~ N({self.centres[k, s]:.{precision}g}, {self.sigmas[k, s]:.{precision}g})"
                                for s in range(self.centres.shape[1]))
            cons = " + ".join(f"{self.theta[k, s]:.{precision}g}*u{s}" for s in range(self.centres.shape[1]))
            out.append(f"R{k + 1}: IF {cond} THEN y = {cons} + {self.theta[k, -1]:.{precision}g}")
        return out


def _centres(U: np.ndarray, K: int, how, seed: int, width: float):
    lo, hi = U.min(axis=0), U.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    S = U.shape[1]
    if isinstance(how, str) and how == "grid":
        per = round(K ** (1.0 / S))
        if per ** S != K:
            raise InputError(f"takagi_sugeno: a grid of K = {K} rules over {S} inputs; expected K = k**{S}")
        axes = [np.linspace(lo[s], hi[s], per) if per > 1 else np.array([(lo[s] + hi[s]) / 2]) for s in range(S)]
        m = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
        spacing = span / max(per - 1, 1)
    elif isinstance(how, str) and how == "kmeans":
        from sklearn.cluster import KMeans

        km = KMeans(n_clusters=K, random_state=seed, n_init=10).fit(U)
        m = km.cluster_centers_[np.lexsort(km.cluster_centers_.T[::-1])]
        spacing = span / max(K ** (1.0 / S) - 1, 1)
    elif isinstance(how, str):
        raise InputError(f"takagi_sugeno: centres = {how!r}; expected 'grid', 'kmeans' or a K × S array")
    else:
        m = np.atleast_2d(np.asarray(how, dtype=float))
        if m.shape != (K, S):
            raise InputError(f"takagi_sugeno: centres have shape {m.shape}; expected ({K}, {S})")
        spacing = span / max(K ** (1.0 / S) - 1, 1)
    sig = np.broadcast_to(width * spacing, m.shape).copy()
    return m, sig


def fit_takagi_sugeno(
    U,
    y,
    n_rules: int,
    centres: str | np.ndarray = "grid",
    width: float = 1.0,
    method: str = "global",
    seed: int = 0,
    ridge: float = 0.0,
) -> TakagiSugeno:
    """Fit the consequents of a K-rule T–S model; σ = ``width`` × centre spacing.

    ``method="global"``: one least-squares problem y ≈ Σ_k w_k(u)[uᵀ, 1]θ_k with w_k the normalised
    memberships (best overall fit).  ``method="local"``: for each rule, least squares weighted by w_k
    (each consequent is a local linearisation; more interpretable, slightly worse fit).
    """
    U = _as_2d(U)
    y = np.asarray(y, dtype=float).ravel()
    n, S = U.shape
    if y.shape[0] != n:
        raise InputError(f"takagi_sugeno: y has {y.shape[0]} samples, inputs {n}; expected equal")
    if not np.all(np.isfinite(y)):
        raise InputError("takagi_sugeno: y contains NaN/inf; expected finite values")
    if isinstance(n_rules, bool) or not isinstance(n_rules, (int, np.integer)) or n_rules < 1:
        raise InputError(f"takagi_sugeno: n_rules = {n_rules!r}; expected a positive integer")
    if method not in ("global", "local"):
        raise InputError(f"takagi_sugeno: method = {method!r}; expected 'global' or 'local'")
    p = n_rules * (S + 1)
    if method == "global" and p > n:
        raise InputError(f"takagi_sugeno: {n_rules} rules need {p} consequent parameters but there are only "
                         f"{n} samples; expected fewer parameters than samples")
    if not width > 0:
        raise InputError(f"takagi_sugeno: width = {width!r}; expected a positive number")
    m, sig = _centres(U, int(n_rules), centres, seed, width)
    w = _normalised(memberships(U, m, sig))
    X1 = np.hstack([U, np.ones((n, 1))])
    if method == "global":
        Phi = (w[:, :, None] * X1[:, None, :]).reshape(n, -1)
        if ridge:
            A = Phi.T @ Phi + ridge * np.eye(p)
            theta = np.linalg.solve(A, Phi.T @ y)
        else:
            theta = np.linalg.lstsq(Phi, y, rcond=None)[0]
        theta = theta.reshape(n_rules, S + 1)
    else:
        theta = np.empty((n_rules, S + 1))
        for k in range(n_rules):
            sw = np.sqrt(w[:, k])
            theta[k] = np.linalg.lstsq(sw[:, None] * X1, sw * y, rcond=None)[0]
    return TakagiSugeno(m, sig, theta, method, {"width": width, "centres": centres if isinstance(centres, str) else "given"})


def select_rules(
    U,
    y,
    candidates: Sequence[int],
    k: int = 5,
    gap: int = 0,
    seed: int = 0,
    **fit_kwargs,
) -> dict:
    """Choose K by blocked k-fold CV (contiguous blocks of the record, ``gap`` samples excluded).

    For a static map the model output depends only on the current input, so the validation score
    (mean squared error on the block) is both the one-step and the free-run simulation error.
    Returns ``{"chosen": K, "mean": [...], "sd": [...], "scores": K × folds, "train_mse": [...]}``.
    """
    U = _as_2d(U)
    y = np.asarray(y, dtype=float).ravel()
    n = U.shape[0]
    means, sds, table, train_mse = [], [], [], []
    for K in candidates:
        def fit(tr, K=K):
            return fit_takagi_sugeno(U[tr], y[tr], K, seed=seed, **fit_kwargs)

        def score(model, va):
            return float(np.mean((model.predict(U[va]) - y[va]) ** 2))

        res = cross_validate(fit, score, n, k, gap, seed, kind="simulation")
        means.append(res.mean)
        sds.append(res.sd)
        table.append(res.scores)
        full = fit_takagi_sugeno(U, y, K, seed=seed, **fit_kwargs)
        train_mse.append(float(np.mean((full.predict(U) - y) ** 2)))
    best = int(np.argmin(means))
    return {"candidates": list(candidates), "chosen": int(list(candidates)[best]), "mean": np.asarray(means),
            "sd": np.asarray(sds), "scores": np.asarray(table), "train_mse": np.asarray(train_mse),
            "label": "validation MSE (static map: simulation = one-step error)"}
