"""Regression of type I and type II for a known joint density f(u, y) (closed-form integrals by quad).

* Type I: ȳ(u) = E[y | u] = ∫ y f(u, y) dy / f_u(u), f_u(u) = ∫ f(u, y) dy (Wrocław Example 2.10,
  (2.137)–(2.140)). Only the ratio matters, so an unnormalised density gives the same regression
  (Wrocław Exercise 2.9, misprint 14: the density integrates to 2 there).
* Type II: best model θᵀg(u) in mean square, min_θ ∫ (Φ*(u) − θᵀg(u))² f_u(u) du with Φ* the type-I
  regression (Wrocław Example 2.11, (2.141)–(2.158)); normal equations by quad
  (:func:`pipeline.estimators.wls.continuous_fit`).
"""

from __future__ import annotations

from scipy import integrate

from .base import Estimate, EstimationError
from .wls import continuous_fit

_OPTS = {"epsabs": 1e-13, "epsrel": 1e-12, "limit": 200}


def total_mass(joint_pdf, u_domain, y_bounds) -> float:
    """∫∫ f(u, y) dy du over the support (should be 1 for a density)."""
    a, b = u_domain
    return integrate.quad(lambda u: marginal_u(joint_pdf, y_bounds, u), a, b, **_OPTS)[0]


def marginal_u(joint_pdf, y_bounds, u: float) -> float:
    """f_u(u) = ∫_{y_lo(u)}^{y_hi(u)} f(u, y) dy."""
    lo, hi = y_bounds(u)
    if hi <= lo:
        return 0.0
    return integrate.quad(lambda y: joint_pdf(u, y), lo, hi, **_OPTS)[0]


def type1(joint_pdf, y_bounds, u: float) -> float:
    """Type-I regression ȳ(u) = E[y | u] (Wrocław (2.137)–(2.140))."""
    lo, hi = y_bounds(u)
    fu = marginal_u(joint_pdf, y_bounds, u)
    if fu <= 0:
        raise EstimationError(f"f_u({u}) = 0: the conditional mean is undefined outside the support of u")
    return integrate.quad(lambda y: y * joint_pdf(u, y), lo, hi, **_OPTS)[0] / fu


def type2(joint_pdf, u_domain, y_bounds, basis) -> Estimate:
    """Type-II regression: θ* = argmin ∫ (Φ*(u) − θᵀg(u))² f_u(u) du (Wrocław (2.141)–(2.158)).
    ``basis`` callables g_i(u), e.g. [lambda u: u, lambda u: 1.0] for θ1 u + θ0.
    ``extra['gram']``/``extra['rhs']`` hold the normal equations (moments of u and Φ*)."""
    mass = total_mass(joint_pdf, u_domain, y_bounds)
    if mass <= 0:
        raise EstimationError("joint density has zero mass on the given support")

    def phi_star(u):
        return type1(joint_pdf, y_bounds, u)

    def fu(u):
        return marginal_u(joint_pdf, y_bounds, u) / mass

    est = continuous_fit(phi_star, basis, fu, u_domain)
    est.extra["mass"] = mass
    return est
