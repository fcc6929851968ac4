"""Continuous-time identification from sampled data.

* :mod:`pipeline.ct.orthogonal` - Tsang & Billings (1991) orthogonal polynomial approximation with the
  error reduction ratio, derivatives and repeated integrals of the fit (eqs. 6-10, 15-16, 35-36);
* :mod:`pipeline.ct.integral_eq` - integral-equation regression with initial conditions from the fit,
  (extended) least squares with MA noise terms and iterated prefiltering with the current model
  (eqs. 29-50, Table 6);
* :mod:`pipeline.ct.lambda_operator` - state-variable-filter / lambda-operator regression
  (Johansson, Exercises 12.1-12.2, with the corrected sign of (12.2)).

Linear estimates expose ``num`` / ``den`` (continuous transfer function, highest power first).
"""

from pipeline.ct.integral_eq import CTEstimate, NonlinearTerm, identify_ct, iterated_prefiltering
from pipeline.ct.lambda_operator import LambdaEstimate, identify_lambda, lambda_ls
from pipeline.ct.orthogonal import fit, orthogonal_basis

__all__ = [
    "CTEstimate",
    "NonlinearTerm",
    "identify_ct",
    "iterated_prefiltering",
    "LambdaEstimate",
    "identify_lambda",
    "lambda_ls",
    "fit",
    "orthogonal_basis",
]
