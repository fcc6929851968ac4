"""Estimators sharing one interface: ``fit(regressors, target, **options) -> Estimate``.

Registry keys: ls, wls, iv, ml, map, mcmc, rls (and nls). Helpers that are not regressions on data
(exact determination, continuous criteria, type I/II regression, Yule–Walker, Lyapunov real-time
estimators) live in their modules.
"""

from __future__ import annotations

from . import bayes, iv, ls, ml, nls, regression, rls, wls
from .base import Estimate, EstimationError
from .rls import rls as rls_estimator

ESTIMATORS = {
    "ls": ls.fit,
    "wls": wls.fit,
    "iv": iv.fit,
    "ml": ml.fit,
    "map": bayes.fit_map,
    "mcmc": bayes.fit_mcmc,
    "rls": rls.fit,
    "nls": nls.fit,
}


def fit(name: str, regressors, target, **options) -> Estimate:
    """Run the estimator registered under ``name``."""
    try:
        est = ESTIMATORS[name]
    except KeyError:
        raise EstimationError(f"unknown estimator '{name}'; expected one of {', '.join(ESTIMATORS)}") from None
    return est(regressors, target, **options)


__all__ = ["ESTIMATORS", "Estimate", "EstimationError", "fit", "rls_estimator", "bayes", "iv", "ls", "ml", "nls",
           "regression", "rls", "wls"]
