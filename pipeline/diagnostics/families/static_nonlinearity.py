"""``static_nonlinearity``: a missing static term ``c*g`` in a dynamic equation, g from a small library
over the names the nominal equation already uses (its own physics, no coupling by default):

* states z: ``z**2``, ``sqrt(z)`` (z > 0 on the simulated record: a square-root outflow), ``z*abs(z)``
  (for states that are not velocities: velocity drag is ``quadratic_damping``), ``tanh(z/s)``
  (sign-changing states only, on a one-signed state it is the ``offset``; not of a velocity either: an
  odd saturating law of the velocity is friction, ``coulomb_friction``; at most one per state and
  equation). Its scale s is a parameter: tested at the state's spread (the added-term test needs one s:
  at c = 0 the scale is not identified), then estimated by :meth:`StaticNonlinearity.estimate`;
* inputs u: ``u**2`` (a lamp's power ∝ V²), ``abs(u)`` (sign-changing inputs), ``sqrt(u)`` (u > 0);
  none of them when it is affine in u on the estimation data (any g(u) of a two-level PRBS);
* products ``z*u`` of a state and an input of the equation.

Terms other families own (``x**3``, ``sign(v)``, ``v*abs(v)``, the constant) are left to them."""

from dataclasses import replace

import numpy as np

from .base import Context, Family, Hypothesis, additive, pname, present


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
            out.append(f"tanh({z}/{s:.6g})")    # the spread: the scale's start (StaticNonlinearity._hyp)
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
        that empties), and a NaN there would end the refit; the finding is still named ``sqrt(z)``.
        ``tanh(z/s)`` gets its scale as a parameter, held at the spread ``s`` in the test and estimated
        by a search (:meth:`estimate`)."""
        if g.startswith("sqrt(") and g[5:-1] in ctx.model.states:
            return additive(self.id, ctx.model, eq, f"sqrt(maximum({g[5:-1]}, 0))", name="static", suffix=g, term=g)
        if g.startswith("tanh("):
            z, spread = g[5:-1].split("/")
            sc = pname(ctx.model, "static_scale", eq, z)
            h = additive(self.id, ctx.model, eq, f"tanh({z}/{sc})", name="static", suffix=f"tanh{z}", term=g)
            return replace(h, extra_params={sc: float(spread)}, fixed=(sc,), searched=(sc,),
                           info={"tanh_scale": sc, "state": z})
        return additive(self.id, ctx.model, eq, g, name="static")

    # the scale search: refits at these multiples of the state's spread (tanh(z/s) of a spread-1 state
    # is nearly sign(z) at 0.15 and nearly linear, i.e. the nominal stiffness, beyond 2), then a
    # golden-section search in log s between the best one's neighbours
    SCALE_GRID = (0.15, 0.25, 0.4, 0.63, 1.0, 1.6)
    SCALE_STEPS = 5

    def estimate(self, dg, fit, cand):
        """The generic refit, and for ``tanh(z/s)`` the least-squares scale: a refit of the coefficient
        and the free parameters at each scale of ``SCALE_GRID`` × the spread, then a golden-section
        search in log s between the best one's neighbours, s fixed in each refit and counted as an
        estimated parameter (``Hypothesis.searched``) in ΔBIC and the likelihood-ratio test. With the
        scale fixed at the spread, a tanh(x/0.2) spring on a state of spread 0.54 was fitted as
        −2.87·tanh(x/0.54) and then a second tanh term of coefficient 62 (the independent probe's
        ``ti_tanh_lo``, truth −1.5)."""
        from ..engine import Candidate
        hyp = cand.hyp
        sc = hyp.info.get("tanh_scale")
        if sc is None:
            return dg.refit(fit, cand)
        s0 = hyp.extra_params[sc]

        def refit(log_s):
            h = replace(hyp, extra_params={sc: float(s0 * np.exp(log_s))})
            return dg.refit(fit, Candidate(h, cand.wald, cand.p_family, []))

        sse = lambda f: np.inf if f is None else f.sse_w
        grid = np.log(self.SCALE_GRID)
        fits = [refit(g) for g in grid]
        k = int(np.argmin([sse(f) for f in fits]))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        best = fits[k]
        gr = (np.sqrt(5) - 1) / 2
        c, d = b - gr * (b - a), a + gr * (b - a)
        fc, fd = refit(c), refit(d)
        for _ in range(self.SCALE_STEPS):
            if sse(fc) < sse(fd):
                b, d, fd = d, c, fc
                c = b - gr * (b - a)
                fc = refit(c)
            else:
                a, c, fc = c, d, fd
                d = a + gr * (b - a)
                fd = refit(d)
        for f in (fc, fd):
            if sse(f) < sse(best):
                best = f
        return best

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        term = hyp.term
        sc = hyp.info.get("tanh_scale")
        extra = {}
        if sc is not None:
            s = float(fit.model.params[sc])
            term = f"tanh({hyp.info['state']}/{s:.4g})"
            extra = {"scale": s}
        return ({"equation": hyp.equation, "term": term, "coefficient": c, "coefficient_std": sd.get(hyp.coefs[0]),
                 **extra},
                f"A static term {term} is missing from the equation of {hyp.equation}: adding {c:.4g}*{term}")


def _has_tanh(model, g: str, eq: str) -> bool:
    """Is a ``tanh`` of g's state already in equation ``eq`` (an accepted ``tanh(z/s)`` has a fitted scale:
    a second one at another scale is one shape fitted twice)?"""
    if not g.startswith("tanh("):
        return False
    z = g[5:-1].split("/")[0]
    return any(t.target == eq and (t.label or "").startswith(f"tanh({z}/") for t in model.terms)
