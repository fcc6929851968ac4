"""Error-reduction-ratio (ERR) forward selection: FROLS.

Orthogonal forward regression of Chen, Billings & Luo (1989, Int. J. Control 50(5), "Orthogonal
least squares methods and their application to non-linear system identification"), as in
Billings (2013, "Nonlinear System Identification", Wiley, §3.2, eqs. 3.18–3.33):

* candidates p_j (columns of Φ) are orthogonalised against the selected set by modified
  Gram–Schmidt, w_j = p_j − Σ_i (q_iᵀ p_j) q_i with q_i = w_i/‖w_i‖;
* ERR_j = (w_jᵀ y)² / (w_jᵀ w_j · yᵀ y) — the fraction of the output energy explained by w_j;
* each step selects the candidate with the largest ERR (Billings 2013, eq. 3.29);
* stopping: 1 − Σ ERR < ρ (the ERR threshold, eq. 3.32), or an information criterion of the model
  with the first k terms (AIC/AICc/BIC/FPE with MATLAB's definitions, :mod:`pipeline.criteria`);
* coefficients are back-solved from the triangular system A θ = g (eq. 3.25).

Speed (no Python loop over candidates): with Q the orthonormal selected basis and
C[i, j] = q_iᵀ p_j, every candidate's orthogonalised energy and correlation follow from matrix
products, w_jᵀw_j = p_jᵀp_j − Σ_i C[i, j]² (the orthogonal-least-squares norm recursion
‖w_j‖² ← ‖w_j‖² − (q_sᵀp_j)², Chen, Billings & Luo 1989) and w_jᵀy = p_jᵀr (r ⟂ Q).  Since the
residual update is r_s = r_{s−1} − g_s q_s (Billings 2013, eq. 3.25 with g_s = q_sᵀr_{s−1}), the
correlations follow by the same downdate, Φᵀr_s = Φᵀr_{s−1} − g_s Φᵀq_s, from the row c_s = q_sᵀΦ
that the norm recursion needs anyway; they are recomputed as Φᵀr_s every ``REANCHOR`` = 10 terms so
that rounding cannot accumulate (measured drift ~1e-15 of ‖p_j‖‖y‖ after 30 terms, no growth).
The reported ERR values use g_s = q_sᵀr_{s−1} computed directly, not the downdated vector.  So each
step costs exactly one read pass over the N × M candidate matrix (the matrix–vector product q_sᵀΦ),
plus one initial pass for the column energies p_jᵀp_j and yᵀΦ together (a small numba kernel), and
Φ is never copied or modified.  This is the same selection as MGS on the whole candidate matrix
(Billings 2013, §3.2.2) with a fraction of its memory traffic; the chosen column itself is
orthogonalised explicitly with a re-orthogonalisation pass so Q stays orthonormal to machine
precision, and near-dependent candidates (w_jᵀw_j < tol·p_jᵀp_j) are excluded, which avoids the
cancellation in the downdate.  The residual energy after k terms is ‖r_k‖², r_k = y − Σ_{i≤k} g_i q_i
— exactly the least-squares residual of the first k terms — so the criterion of every model size
comes from the same single pass, without refitting.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from numba import njit
from scipy.linalg import solve_triangular

from pipeline import criteria
from pipeline.errors import InputError
from pipeline.structures.library import Library

CRITERIA = ("aic", "aicc", "bic", "fpe", "bic_energy")
#: the downdated correlations g = Φᵀr are recomputed from r every REANCHOR selected terms
REANCHOR = 10


# Column energies p_jᵀp_j and correlations p_jᵀy of every candidate (ERR of step 1, Billings 2013,
# eq. 3.29) in ONE read pass over Φ instead of two (np.einsum + y @ Φ).  Only reassociation and FMA
# contraction are allowed (SIMD reduction); no finite-math assumption, so NaN/inf still propagate
# to the finiteness check.  Results agree with einsum / BLAS to rounding (~1e-15 relative).
_FM = {"reassoc", "contract"}


@njit(cache=True, nogil=True, fastmath=_FM)
def _energy_corr_f(P, y, nn, g):  # P column-major: four contiguous columns at a time
    n, m = P.shape
    m4 = m - m % 4  # 8 independent accumulators keep the FMA pipeline full (memory-bound like gemv)
    for j in range(0, m4, 4):
        e0 = e1 = e2 = e3 = 0.0
        c0 = c1 = c2 = c3 = 0.0
        for i in range(n):
            yi = y[i]
            v = P[i, j]
            e0 += v * v
            c0 += v * yi
            v = P[i, j + 1]
            e1 += v * v
            c1 += v * yi
            v = P[i, j + 2]
            e2 += v * v
            c2 += v * yi
            v = P[i, j + 3]
            e3 += v * v
            c3 += v * yi
        nn[j], nn[j + 1], nn[j + 2], nn[j + 3] = e0, e1, e2, e3
        g[j], g[j + 1], g[j + 2], g[j + 3] = c0, c1, c2, c3
    for j in range(m4, m):
        e0 = 0.0
        c0 = 0.0
        for i in range(n):
            v = P[i, j]
            e0 += v * v
            c0 += v * y[i]
        nn[j] = e0
        g[j] = c0


@njit(cache=True, nogil=True, fastmath=_FM)
def _energy_corr_c(P, y, nn, g):  # P row-major: one contiguous row at a time, accumulated over rows
    n, m = P.shape
    nn[:] = 0.0
    g[:] = 0.0
    for i in range(n):
        yi = y[i]
        for j in range(m):
            v = P[i, j]
            nn[j] += v * v
            g[j] += v * yi


def _energy_corr(P: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p_jᵀp_j, p_jᵀy) for all columns j of ``P`` in one pass over memory."""
    m = P.shape[1]
    nn, g = np.empty(m), np.empty(m)
    if P.flags.f_contiguous:
        _energy_corr_f(P, y, nn, g)
    elif P.flags.c_contiguous:
        _energy_corr_c(P, y, nn, g)
    else:
        nn, g = np.einsum("ij,ij->j", P, P), y @ P
    return nn, g


def _criterion(name: str, r: np.ndarray, k: int) -> float:
    if name == "bic_energy":
        return criteria.bic_energy(float(r @ r), r.shape[0], k)
    return getattr(criteria, name)(r, k)


@dataclass
class FrolsResult:
    """Selected terms in selection order; the model is the first ``n_terms`` of them.

    ``err[i]`` is the ERR (fraction, 0..1) of the i-th selected term, ``sse[k]`` the residual
    energy Σe² of the least-squares model with the first k terms (``sse[0] = yᵀy``),
    ``criterion_values[k-1]`` the chosen criterion of that model, ``coef`` the coefficients of the
    model terms in the original (non-orthogonal) basis.
    """

    names: list[str]
    indices: np.ndarray
    err: np.ndarray
    sse: np.ndarray
    n_terms: int
    coef: np.ndarray
    criterion: str | None
    criterion_values: np.ndarray
    stop_reason: str
    n_samples: int
    _R: np.ndarray = field(repr=False, default=None)
    _g: np.ndarray = field(repr=False, default=None)

    @property
    def terms(self) -> list[str]:
        return self.names[: self.n_terms]

    def coef_for(self, k: int) -> np.ndarray:
        """Least-squares coefficients of the model with the first ``k`` selected terms."""
        if not 1 <= k <= len(self.names):
            raise InputError(f"coef_for: k = {k}; expected 1 <= k <= {len(self.names)} selected terms")
        return solve_triangular(self._R[:k, :k], self._g[:k], lower=False)

    def predict(self, X: np.ndarray | Mapping[str, np.ndarray]) -> np.ndarray:
        """One-step prediction Φ_sel θ: ``X`` is the full candidate matrix, or data for the terms."""
        if isinstance(X, Mapping):
            return Library(self.terms).evaluate(X) @ self.coef
        return np.asarray(X)[:, self.indices[: self.n_terms]] @ self.coef

    def equation(self, lhs: str = "y", precision: int = 4) -> str:
        parts = [f"{c:+.{precision}g}*{n}" if n != "1" else f"{c:+.{precision}g}"
                 for c, n in zip(self.coef, self.terms)]
        return f"{lhs} = " + " ".join(parts)


def frols(
    P: np.ndarray,
    y: np.ndarray,
    names: Sequence[str] | None = None,
    *,
    max_terms: int | None = None,
    rho: float | None = None,
    criterion: str | None = None,
    patience: int | None = None,
    tol: float = 1e-10,
) -> FrolsResult:
    """FROLS on a candidate matrix ``P`` (N × M) and output ``y`` (N,).

    Stopping: with ``rho`` only, stop once 1 − Σ ERR < ρ; with ``criterion`` (one of
    ``aic, aicc, bic, fpe, bic_energy``) select up to ``max_terms`` (or until the criterion has not
    improved for ``patience`` steps) and keep the size k minimising it; with neither, AIC is used.
    Candidates whose orthogonalised squared norm falls below ``tol`` × their original one (linearly
    dependent on the selected set) are not selected.  ``P`` is only read (never copied when it is
    float64).
    Candidate count M may exceed N (only ``max_terms < N`` terms are ever selected).
    """
    y = np.asarray(y, dtype=float).ravel()
    P = np.asarray(P)
    if P.ndim != 2:
        raise InputError(f"frols: candidate matrix has shape {P.shape}; expected 2-D (N samples × M terms)")
    n, m = P.shape
    if m == 0:
        raise InputError("frols: the candidate library is empty; expected at least one term")
    if y.shape[0] != n:
        raise InputError(f"frols: y has {y.shape[0]} samples but the candidate matrix has {n} rows; expected equal")
    names = [f"p{j}" for j in range(m)] if names is None else list(names)
    if len(names) != m:
        raise InputError(f"frols: {len(names)} names for {m} candidate columns; expected one name per column")
    if not np.all(np.isfinite(y)):
        raise InputError("frols: y contains NaN/inf; expected finite values (drop the first max-lag rows)")
    if criterion is not None and criterion not in CRITERIA:
        raise InputError(f"frols: criterion = {criterion!r}; expected one of {list(CRITERIA)}")
    if rho is not None and not 0 < rho < 1:
        raise InputError(f"frols: rho = {rho!r}; expected 0 < rho < 1")
    if rho is None and criterion is None:
        criterion = "aic"
    limit = n - 2
    if max_terms is None:
        max_terms = min(m, limit) if criterion is None else min(m, limit, 40)
    if max_terms < 1 or max_terms > m:
        raise InputError(f"frols: max_terms = {max_terms}; expected 1 <= max_terms <= {m} candidates")
    if max_terms > limit:
        raise InputError(
            f"frols: max_terms = {max_terms} terms for {n} samples; expected fewer terms than samples − 1"
        )
    yy = float(y @ y)
    if yy == 0.0:
        raise InputError("frols: y is identically zero; expected an output with non-zero energy")

    P = np.asarray(P, dtype=np.float64)
    norms0, g_all = _energy_corr(P, y)  # p_jᵀp_j and p_jᵀy, one pass
    if not np.all(np.isfinite(norms0)):
        bad = [names[j] for j in np.flatnonzero(~np.isfinite(norms0))[:5]]
        raise InputError(f"frols: candidate column(s) {bad} contain NaN/inf; expected finite regressors "
                         "(evaluate the library with drop_initial=True)")
    wn = norms0.copy()  # ‖w_j‖² of every candidate orthogonalised against the selected set
    # g_all[j] = w_jᵀ r = p_jᵀ r, because r ⟂ span(selected); r = y before the first step
    active = norms0 > 0
    C = np.zeros((max_terms, m))  # C[i, j] = q_iᵀ p_j
    Q = np.empty((n, max_terms))
    R = np.zeros((max_terms, max_terms))
    r = y.copy()
    sel, errs, gs = [], [], []
    sse = [yy]
    crit_vals: list[float] = []
    stop = f"max_terms = {max_terms} reached"
    best_k, best_val, since_best = 0, np.inf, 0
    for s in range(max_terms):
        while True:
            valid = active & (wn > tol * norms0)
            if not valid.any():
                break
            err = np.where(valid, g_all * g_all / np.where(valid, wn, 1.0) / yy, -1.0)
            j = int(np.argmax(err))
            # orthogonalise the chosen column (Gram–Schmidt with one re-orthogonalisation pass,
            # "twice is enough": Giraud, Langou & Rozložník 2005) so the q_i stay orthonormal
            Qs = Q[:, :s]
            w = P[:, j] - Qs @ C[:s, j]
            d = Qs.T @ w
            w -= Qs @ d
            nrm2 = float(w @ w)
            if nrm2 > tol * norms0[j]:
                break
            active[j] = False  # the downdated norm was optimistic: dependent column
        if not valid.any():
            stop = "no linearly independent candidate left"
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
        k = s + 1
        if criterion is not None:
            v = _criterion(criterion, r, k)
            crit_vals.append(v)
            if v < best_val:
                best_k, best_val, since_best = k, v, 0
            else:
                since_best += 1
            if patience is not None and since_best >= patience:
                stop = f"{criterion} did not improve for {patience} steps"
                break
        if rho is not None and 1.0 - sum(errs) < rho:
            stop = f"1 - sum(ERR) = {1.0 - sum(errs):.3g} < rho = {rho}"
            if criterion is None:
                best_k = k
            break
        if k == max_terms:
            break
        # the only read pass over all candidates per step: c = qᵀP (new row of C); then
        # Φᵀr_new = Φᵀ(r − g_q q) = g_all − g_q c and ‖p_j⊥‖² ← ‖p_j⊥‖² − c_j² (downdates, no pass)
        c = q @ P
        C[s] = c
        if k % REANCHOR == 0:
            g_all = r @ P  # periodic re-anchoring of the downdated correlations (one extra pass)
        else:
            g_all -= gq * c
        wn -= c * c
    if rho is not None and criterion is None and best_k == 0:
        best_k = len(sel)
    kk = len(sel)
    R = R[:kk, :kk]
    g = np.asarray(gs)
    res = FrolsResult(
        names=[names[j] for j in sel], indices=np.asarray(sel, dtype=int), err=np.asarray(errs),
        sse=np.asarray(sse), n_terms=best_k, coef=np.empty(0), criterion=criterion,
        criterion_values=np.asarray(crit_vals), stop_reason=stop, n_samples=n, _R=R, _g=g,
    )
    res.coef = res.coef_for(best_k) if best_k else np.empty(0)
    return res


def frols_library(
    lib: Library,
    data: Mapping[str, np.ndarray],
    target: str,
    **kwargs,
) -> FrolsResult:
    """FROLS with candidates from a :class:`Library` evaluated on ``data``; output ``data[target]``.

    The first ``lib.max_lag`` rows (where delayed regressors are undefined) are dropped.
    """
    if not isinstance(lib, Library):
        lib = Library(lib)
    if target not in data:
        raise InputError(f"frols: target {target!r} is not in the data; expected one of {sorted(data)}")
    leak = [t.name for t in lib if target in t.current_variables()]
    if leak:
        raise InputError(f"frols: terms {leak[:5]} use the target {target!r} without delay; expected only "
                         f"delayed outputs such as {target}(t-1)")
    P = lib.evaluate(data, drop_initial=True)
    y = np.asarray(data[target], dtype=float)[lib.max_lag:]
    return frols(P, y, lib.names, **kwargs)
