"""``state_nonlinearity``: an adequacy row for a static nonlinearity of a state that no library holds.

The families test named terms (x², x³, sqrt, tanh, …). A law of another shape (x·exp(−x²), a spring
that softens and stiffens again) is only partly explained by them: an added x³ or tanh term is not
significant after the corrections for the many hypotheses tested, no structural test fails, and the
residual it leaves is smooth and was named ``colored_noise``. This probe asks the question without a
library: for each dynamic equation and each state of the nominal model that equation uses (its own
physics, no coupling), K Gaussian bumps of the state,

    Σ_k c_k exp(−((z − q_k)/s)²),  q_k the 10 … 90 % quantiles of z on the estimation part, s their spacing,

are added to the equation and tested jointly (q = K) by the engine's added-term test (output
sensitivities, feasible-GLS, prewhitened EWC, fixed-b F law: :func:`stats.added_terms_test`, sized by
Monte Carlo in ``tests/diagnosis/test_mc_calibration.py``). Gaussian radial basis functions on the
range of z approximate any continuous function of z there (Park & Sandberg 1991, *Neural Computation*
3(2)); the current parameters' sensitivities are projected out, so only what the model cannot already
do is tested.

The measurement gets the same question: for each measured output that is a state z of the model,
a gain and K bumps of z are added to the output, y = z + a·z + Σ_k c_k exp(−((z − q_k)/s)²) (a sensor's
static law, y = x + c·x³ say, which no family holds: on the independent bench's generator with such a
law and 2 % white noise, 9 of 54 records had ended ``colored_noise``). The gain term is needed: such a
law is mostly a gain over the output's range, which the bumps on the 10–90 % quantiles do not hold
(on one record they explained 2 % of the residual, with the gain 75 %). Directions the current
parameters already produce (an output gain beside a free input gain) are dropped before the test
(:func:`stats.determined`).

The row's p is Bonferroni over the places tested (equation–state pairs and measured states); like
every adequacy row it fails adequacy only when it also explains ``MATERIAL_R2`` of the residual
(:func:`adequacy.material`).

Measured on the independent bench's tuning seeds (final models): 1 of 126 null and coloured-noise
records significant at 0.01 (share 0.9 %, not material), none of 84 heavy-tailed or heteroscedastic
noise records; the x·exp(−x²) records that ended ``colored_noise`` explain 2.4 % and 22 % of the
residual here (p = 0.002 and 1e-5).

On a very smooth residual (lag-1 autocorrelation ~0.99) the linearised test has few effective degrees
of freedom: x·exp(−x²) springs on fresh seeds left it at p = 0.04–0.6 and ended ``colored_noise`` on
white noise. So before the noise families may explain a coloured residual, the most significant
probe is refitted by output error and judged on the validation part (``state_nonlinearity_refit``,
``engine.Diagnoser.probe_refit``): it fails when the 95 % interval of its validation gain lies above 0
and the validation mean square falls by at least ``MATERIAL_R2``.
"""

from __future__ import annotations

import numpy as np

from .families.base import Context, Hypothesis, Structure, additive

K = 5                     # bumps per state
NAME = "state_nonlinearity"


def probe_hypotheses(ctx: Context, k: int = K) -> list[Hypothesis]:
    """One hypothesis of ``k`` Gaussian bumps per (dynamic equation, nominal state it uses). The
    hypotheses borrow ``static_nonlinearity``'s extension (an additive term); they are refitted only by
    ``engine.Diagnoser.probe_refit``, never named as a cause."""
    m = ctx.model
    out = []
    for eq in Structure.of(m).dynamic_eqs:
        used = m.equations[eq].names
        for z in (s for s in m.nominal_states if s in used):
            qs, s = _centres(ctx.state(z)[slice(*ctx.est)], k)
            if not s > 0:
                continue
            hs = [additive("static_nonlinearity", m, eq, f"exp(-(({z} - {q:.6g})/{s:.6g})**2)",
                           name="probe", suffix=f"{z}{i}") for i, q in enumerate(qs)]
            out.append(Hypothesis("static_nonlinearity", f"{NAME}:{eq}:{z}", [t for h in hs for t in h.terms],
                                  [c for h in hs for c in h.coefs], equation=eq, state=z,
                                  info={"range": (float(qs[0]), float(qs[-1]))}))
    # the measurement: y = z + g(z) for a measured state z (a sensor's static nonlinearity)
    for y in (y for y in ctx.out_names if y in m.nominal_states):
        qs, s = _centres(ctx.state(y)[slice(*ctx.est)], k)
        if not s > 0:
            continue
        # with a gain term: a sensor law y = z + c·z³ is mostly a gain on an output's range, which no
        # sum of bumps on the 10–90 % quantiles holds (on one record the bumps alone explained 2 % of such
        # a residual, with the gain 75 %)
        hs = [additive("static_nonlinearity", m, y, y, output=True, name="probe_out", suffix="gain")]
        hs += [additive("static_nonlinearity", m, y, f"exp(-(({y} - {q:.6g})/{s:.6g})**2)", output=True,
                        name="probe_out", suffix=f"{i}") for i, q in enumerate(qs)]
        out.append(Hypothesis("static_nonlinearity", f"{NAME}:output:{y}", [t for h in hs for t in h.terms],
                              [c for h in hs for c in h.coefs], output=y, state=y,
                              info={"range": (float(qs[0]), float(qs[-1]))}))
    return out


def _centres(x: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    """The bumps' centres (the 10 … 90 % quantiles of x) and their width (the centres' spacing)."""
    qs = np.quantile(x, np.linspace(0.1, 0.9, k))
    return qs, float(qs[-1] - qs[0]) / max(k - 1, 1)


def what(h: Hypothesis) -> str:
    """A probe's terms, for its sentences: "5 Gaussian bumps of x" or "a gain and 5 Gaussian bumps of x"."""
    n = len(h.coefs) - (1 if h.output else 0)
    return ("a gain and " if h.output else "") + f"{n} Gaussian bumps of {h.state}"


def where(h: Hypothesis) -> str:
    """Where a probe acts, for its sentences: "the equation of v" or "the measured output x"."""
    return f"the measured output {h.output}" if h.output else f"the equation of {h.equation}"
