"""Criteria of a refit against the model it extends, on the estimation part: BIC and the
likelihood-ratio test with the residual's effective sample size. Used by the diagnosis loop
(:mod:`.engine`), its intersample stage (:mod:`.intersample_stage`) and the backward step (:mod:`.revisit`).
"""

from __future__ import annotations

from .. import criteria
from ..fit import FitResult
from . import stats


def lr_against(current: FitResult, refit: FitResult, alpha: float, searched: int = 0,
               break_trim: float | None = None) -> stats.TestResult:
    """The likelihood-ratio test of ``refit`` against the ``current`` model it extends, on the estimation
    part, with the effective sample size from the **refit's** residual (:func:`stats.lr_test`: the
    current residual carries the missing effect itself and would leave N_eff < 1 on a large smooth one).
    ``searched``: parameters the family estimated by a search and held fixed in the refit (a jump's
    time), counted in the degrees of freedom: a conservative stand-in for the supremum-LR law of an
    estimated change point (Andrews 1993, Econometrica 61(4)), which is more spread than χ²₁;
    ``break_trim``: that law itself (:func:`stats.sup_lr_break_p`) for one coefficient's jump."""
    return stats.lr_test(current.sse_w, refit.sse_w, current.resid_est.size,
                         refit.n_params - current.n_params + searched, stats.lag1(refit.resid_est), alpha,
                         break_trim=break_trim)


def bic_of(fit: FitResult, searched: int = 0) -> float:
    """BIC of the fit on the estimation part; ``searched`` parameters estimated by a search and held
    fixed in the refit (a jump's time) count like the fitted ones (Schwarz 1978: k is every estimated
    parameter; uncounted, a jump at a searched time beat a drift with as many fitted parameters)."""
    return criteria.bic(fit.resid_est, fit.n_params + searched)
