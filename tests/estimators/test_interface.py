"""Every registered estimator follows fit(regressors, target, **options) -> Estimate."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.errors import EstimationError
from pipeline.estimators import ESTIMATORS, Estimate, bayes, fit

OPTIONS = {
    "ls": {},
    "wls": {"weights": np.full(40, 2.0)},
    "iv": {"instruments": None},
    "ml": {"density": "student_t"},
    "map": {"prior": bayes.GaussianPrior(0.0, 100.0), "sigma": 0.3},
    "mcmc": {"prior": bayes.GaussianPrior(0.0, 100.0), "sigma": 0.3, "nwalkers": 8, "nsteps": 2000, "seed": 0},
    "rls": {"lam": 1.0, "p0": 1e6},
    "nls": {"model": lambda x, th: x @ th, "theta0": [0.0, 0.0]},
}


@pytest.mark.parametrize("name", sorted(OPTIONS))
def test_registry_entries_share_the_interface(name):
    assert set(ESTIMATORS) >= {"ls", "wls", "iv", "ml", "map", "mcmc", "rls"}
    rng = np.random.default_rng(0)
    phi = np.column_stack([np.ones(40), rng.uniform(-1, 1, 40)])
    y = phi @ np.array([0.5, 2.0]) + rng.normal(0, 0.3, 40)
    opts = dict(OPTIONS[name])
    if name == "iv":
        opts["instruments"] = phi  # Z = Φ reduces IV to LS
    est = fit(name, phi, y, **opts)
    assert isinstance(est, Estimate) and est.name == name
    assert est.theta.shape == (2,) and est.residuals.shape == (40,)
    assert est.cov is None or est.cov.shape == (2, 2)
    assert est.loglik is None or isinstance(est.loglik, float)
    assert isinstance(est.extra, dict) and est.n_params >= 2
    np.testing.assert_allclose(est.theta, [0.5, 2.0], atol=0.3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.theta = np.zeros(2)


def test_unknown_estimator_name():
    with pytest.raises(EstimationError, match="unknown estimator 'lsq'; expected one of ls, wls"):
        fit("lsq", np.ones(3), np.ones(3))
