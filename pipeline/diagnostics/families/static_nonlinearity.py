"""``static_nonlinearity``: a missing static term ``c*g`` in a dynamic equation, g from a small library
over the names the nominal equation already uses (its own physics, no coupling by default):

* states z: ``z**2``, ``sqrt(z)`` (z > 0 on the simulated record: a square-root outflow), ``z*abs(z)``
  (for states that are not velocities: velocity drag is ``quadratic_damping``), ``tanh(z/s)``
  (sign-changing states only, on a one-signed state it is the ``offset``; not of a velocity either: an
  odd saturating law of the velocity is friction, ``coulomb_friction``). Its scale s is tested at the
  state's spread and **estimated in the refit** (a saturating law's knee is part of its form: held at
  the spread, −0.6·tanh(2·T1) of a thermal record with spread 0.27 was explained better by T1·|T1|,
  then by an added sign(T1)), and named with its fitted value, ``tanh(T1/0.5)``;
* inputs u: ``u**2`` (a lamp's power ∝ V²), ``abs(u)`` (sign-changing inputs), ``sqrt(u)`` (u > 0);
  none of them when it is affine in u on the estimation data (any g(u) of a two-level PRBS);
* products ``z*u`` of a state and an input of the equation.

Terms other families own (``x**3``, ``sign(v)``, ``v*abs(v)``, the constant) are left to them."""

from dataclasses import replace

import numpy as np

from ...fit import bound_side
from .base import Context, Family, Hypothesis, additive, pname, present


# the knee of tanh(z/s) is at least this share of the state's spread: below it tanh(z/s) is sign(z) but for
# the few samples near 0, a smoothed sign, which is Coulomb friction's form (contract §2 allows it). Free,
# the refit took the friction of the independent bench's DC motor (−F·tanh(w/ε), ε 1 % of the spread) as
# tanh(w/0.0124) and named it a static nonlinearity (4 of 1 764 grid records)
SCALE_MIN = 0.1
# and at most the 99th percentile of |z| on the estimation part: the record must reach the knee (tanh(1) =
# 0.76). Above it tanh(z/s) = z/s − (z/s)³/3 + … on the data, a linear plus a cubic term: free, the refit
# took a hardening spring (k3·x³, two-causes bench, delay + cubic, seed 2008) as 5.97·tanh(x/0.83),
# knee 4 times the spread, and named it over the cubic stiffness (0.5 criterion units apart)
SCALE_MAX_QUANTILE = 0.99
AFFINE_RTOL = 1e-3   # a term within this relative RMS of an affine function of its input is affine


def _not_affine(g: np.ndarray, u: np.ndarray) -> bool:
    """Is g(u) more than an affine function a + b·u on the data? On an input with two levels (a PRBS)
    every g(u) is affine in u: it is an offset plus a change of the input gain, not a nonlinearity."""
    X = np.column_stack([np.ones_like(u), u])
    r = g - X @ np.linalg.lstsq(X, g, rcond=None)[0]
    return float(np.sqrt(np.mean(r ** 2))) > AFFINE_RTOL * float(np.sqrt(np.mean(g ** 2)))


def library(ctx: Context, eq: str) -> list[str]:
    m = ctx.model
    used = m.equations[eq].names
    states = [s for s in m.nominal_states if s in used]
    inputs = [u for u in m.inputs if u in used]
    sl = slice(*ctx.est)
    out = []
    for z in states:
        x = ctx.state(z)[sl]
        out.append(f"{z}**2")
        if np.all(x > 0):
            out.append(f"sqrt({z})")
        velocity = z in ctx.structure.velocities and ctx.structure.kin
        if not velocity:
            out.append(f"{z}*abs({z})")
        s = float(np.std(x))
        # tanh of a one-signed state is an offset; tanh of a velocity is a friction law (a smoothed
        # sign(v)), which coulomb_friction and quadratic_damping own
        if s > 0 and min(np.mean(x > 0), np.mean(x < 0)) >= 0.05 and not velocity:
            out.append(f"tanh({z}/{s:.6g})")
    for u in inputs:
        x = ctx.U[sl, m.inputs.index(u)]
        # a term affine in u on the data (any g(u) of a two-level PRBS) is an offset plus an input
        # gain, which ``offset`` and the nominal b·u cover: as a "nonlinearity" it ties and wins by chance
        if _not_affine(x ** 2, x):
            out.append(f"{u}**2")
        if min(np.mean(x > 0), np.mean(x < 0)) >= 0.05 and _not_affine(np.abs(x), x):
            out.append(f"abs({u})")
        if np.all(x > 0) and _not_affine(np.sqrt(x), x):
            out.append(f"sqrt({u})")
    out += [f"{z}*{u}" for z in states for u in inputs]
    return out


class StaticNonlinearity(Family):
    id = "static_nonlinearity"
    # on a Torricelli tank fitted as linear, h**2 and h*u explain more of the residual than sqrt(h) at
    # the linear fit, yet sqrt(h)'s refit is the better model: the forms are compared by their refits
    refit_alternates = True

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return [self._hyp(ctx, eq, g) for eq in ctx.structure.dynamic_eqs
                for g in library(ctx, eq) if not present(ctx.model, g, eq) and not _has_tanh(ctx.model, g, eq)]

    def _hyp(self, ctx: Context, eq: str, g: str) -> Hypothesis:
        """``sqrt(z)`` of a state is simulated as ``sqrt(maximum(z, 0))``: the state is positive on the
        current simulation, but a refit passes through parameter values where it dips below 0 (a tank
        that empties), and a NaN there would end the refit; the finding is still named ``sqrt(z)``."""
        if g.startswith("sqrt(") and g[5:-1] in ctx.model.states:
            return additive(self.id, ctx.model, eq, f"sqrt(maximum({g[5:-1]}, 0))", name="static", suffix=g, term=g)
        if g.startswith("tanh(") and "/" in g:
            z, s0 = g[5:-1].split("/")
            s = pname(ctx.model, "static_scale", eq, z)
            # named as before the knee was freed (key and coefficient carry the scale it is tested at)
            h = additive(self.id, ctx.model, eq, f"tanh({z}/{s})", name="static", suffix=g, term=g)
            h.extra_params, h.fixed = {s: float(s0)}, (s,)
            top = float(np.quantile(np.abs(ctx.state(z)[slice(*ctx.est)]), SCALE_MAX_QUANTILE))
            h.info = {"scale_name": s, "state": z, "scale_min": SCALE_MIN * float(s0),
                      "scale_max": max(top, float(s0))}
            return h
        return additive(self.id, ctx.model, eq, g, name="static")

    def refit_model(self, model, hyp, start):
        """tanh(z/s): the scale, held at the state's spread in the test, is free in the refit, between
        ``SCALE_MIN`` of the spread and the ``SCALE_MAX_QUANTILE`` quantile of |z|."""
        m = self.extend(model, hyp, start)
        s = hyp.info.get("scale_name")
        if not s:
            return m
        return replace(m, free=m.free + (s,), bounds={**m.bounds, s: (hyp.info["scale_min"], hyp.info["scale_max"])})

    def describe(self, hyp, fit, val, sd):
        c, term, extra, note = val[hyp.coefs[0]], hyp.term, {}, ""
        s = hyp.info.get("scale_name")
        if s:
            sv = float(val.get(s, fit.model.params[s]))
            term = f"tanh({hyp.info['state']}/{sv:.4g})"
            bound = bound_side(fit.model, s, sv)
            # at a bound the standard deviation is an interior optimum's and describes nothing
            extra = {"scale": sv, "scale_std": None if bound else sd.get(s), "scale_at_bound": bound}
            if bound:
                note = (f" (its knee is at the {bound} end of the range searched, "
                        + ("a tenth of the state's spread: a sharper law is a smoothed sign)" if bound == "lower"
                           else "the 99th percentile of the state: the record does not reach a flatter knee)"))
        return ({"equation": hyp.equation, "term": term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0]),
                 **extra},
                f"A static term {term} is missing from the equation of {hyp.equation}{note}: adding {c:.4g}*{term}")


def _has_tanh(model, g: str, eq: str) -> bool:
    """A tanh(z/·) term of this family is already in the equation (its scale is a fitted parameter, so
    the text differs from the library's)."""
    return g.startswith("tanh(") and any(t.family == "static_nonlinearity" and t.target == eq and t.text
                                         and t.text.startswith(g.split("/")[0] + "/") for t in model.terms)
