"""The backward step: every finding but the last revisited in the final model.

The loop is forward selection: each cause is chosen given the causes before it, never given the ones
found after it. An early choice can be a stand-in for a later cause. On an independent record with an
input dead time of 0.1 s *and* a cubic spring (:mod:`pipeline.bench.two_causes`, seed 2009), the
missing spring's slow misfit colours the residual; a first-order input lag and the delay are then 1.4
effective BIC units apart, the lag is named, and the spring after it. With the spring in the model the
delay fits the estimation part far better (weighted SSE 1.07 against 1.48, the delay 0.0998 s): the
lag was chosen for the spring's misfit. Stepwise regression re-examines the earlier choices after each
addition for this reason (Efroymson 1960, "Multiple regression analysis", in Ralston & Wilf,
*Mathematical Methods for Digital Computers*; Miller 2002, *Subset Selection in Regression*, §3.3, on
the exchange step).

Four moves, each judged in the final model, that is given every cause found after it:

1. **Swap** (:func:`swap`). A finding whose round refitted alternatives of another family within
   ``RUNNER_UP_DBIC`` of it (its runners-up): the final model is rebuilt with the alternative in its
   place (the later extensions applied on top, at their final values) and refitted. The alternative
   replaces the finding when the final model's criterion, the number :func:`engine.choose` ranks by
   (ΔBIC with the residual's effective sample size, :func:`engine.effective_bic`, plus the model
   prior's 2 ln(places)), falls by more than ``TIE_CRITERION`` (2: "positive" evidence on Kass &
   Raftery's 2 ln B scale, 1995, §3.2). The two alternatives of each finding with the lowest criterion
   are tried.
2. **Drop** (:func:`drop_switch`). An intersample switch chosen before a later finding must still pass
   the rule it was accepted by (:meth:`.intersample_stage.IntersampleStage.run`: ΔBIC below −2, a validation
   gain of at least 0.1 % and lower at the one-sided 5 % level), now against the final model refitted
   with the configured intersample. Otherwise it is dropped: a switch to zoh on a foh record is half a
   sample of input dead time (``Intersample.equivalent``), which a later delay finding takes over.

3. **To a switch** (:func:`to_switch`). A finding that a wrong intersample assumption may stand in for
   (a family's ``mimics_hold``: an input dead time or first-order input lag of at most one sample; a
   held input simulated as foh lags by half a sample, ``Intersample.equivalent``), when the chain has
   no switch: the final model is rebuilt without it, with the intersample whose equivalent that is (zoh
   from foh), and refitted. The switch takes its place when the criterion falls by more than
   ``TIE_CRITERION`` (the switch adds no parameter, so about as good a fit is enough) and the switch
   passes its own rule (move 2's) against that model with the configured intersample. In the forward
   round a later cause's misfit can hide the switch: on an independent held-input record with a force
   offset and a weak spring (configured foh; ``tests/diagnosis/test_revisit.py``, seeds 1 and 11), a
   lag of 0.6 samples and a dead time of half a sample were named before the spring, the switch more
   than the 10 BIC units it is allowed behind; with the spring in the model zoh fits as well (weighted
   SSE 1.397 against 1.396) with one parameter fewer.

4. **Drop** (:func:`drop`). A finding that no longer earns its place given all the others (the final
   model against the final model refitted without it, by the rule any extension is accepted by:
   :func:`place`) is removed: stepwise regression's backward elimination (Efroymson 1960's
   F-to-remove). Tried after the other moves, so a finding with a runner-up that fits better is
   swapped rather than dropped. On the dead time + spring record of :mod:`pipeline.bench.two_causes`
   with seeds 2044, 2051 and 2063, a first-order input lag was named in the first round (the delay's
   validation gain was not yet bounded away from 0 while the spring was missing), then the spring,
   then the delay: with both in the model the lag adds nothing (validation gain interval across 0), and
   the findings were three where the record has two causes.

After a move every later link is refitted in order on the new chain (its finding's gain is then
measured against the link before it), and every moved or refitted link must earn its place given all the
others, by the rule any extension is accepted by (:func:`earns_place`: the final model against the final
model refitted without it, the validation gain's 95 % lower bound above 0 and the likelihood-ratio p
below α). If one does not, the move is not made. A finding whose forward gain (given only the ones
before it) has an interval reaching 0 carries this gain given the others as ``gain_given``, as a
look-ahead finding does. Look-ahead findings are revisited like the others; a move that would have to
refit an intersample switch after the moved finding is not made.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..criteria import bic_effective_delta as bic_eff
from ..errors import InputError, SimulationError
from ..fit import FitResult, estimated_x0, fit_output_error
from ..model import Model
from . import stats
from .families import REGISTRY, Hypothesis
from .console import log
from .gain import gain_resid
from .intersample_stage import INTERSAMPLE_MAX_DBIC, INTERSAMPLE_MIN_GAIN, ONE_SIDED_LEVEL
from .naming import CONTEST_SENTENCES, TIE_CRITERION, finding
from .refit_criteria import bic_of

MAX_ALTERNATIVES = 2     # the runners-up of a finding tried in its place, lowest criterion first
_FAIL = (InputError, SimulationError, np.linalg.LinAlgError, ArithmeticError, ValueError, KeyError)


@dataclass
class Link:
    """One step of the forward pass: ``kind`` "intersample", "extension" or "look-ahead"; the fits
    before and after it; for an extension its candidate (an ``engine.Candidate``) and the refitted
    alternatives of its round that belong to other families."""

    kind: str
    before: FitResult
    after: FitResult
    cand: object | None = None
    alts: list = field(default_factory=list)


def gap(final: FitResult, alt: FitResult, searched_final: int, searched_alt: int, prior_gap: float) -> float:
    """The criterion of ``alt`` minus that of ``final`` (negative: ``alt`` is preferred): ΔBIC on the
    estimation part with the effective sample size of the better fit's residual (the one closer to the
    noise, as :func:`engine.effective_bic` takes it), plus the prior's difference."""
    n = final.resid_est.shape[0]
    better = alt if alt.sse_w < final.sse_w else final
    n_eff = max(stats.effective_n(n, stats.lag1(better.resid_est))[1], 2.0)
    d_raw = bic_of(alt, searched_alt) - bic_of(final, searched_final)
    dk = alt.n_params + searched_alt - final.n_params - searched_final
    return bic_eff(d_raw, dk, n, n_eff) + prior_gap


def searched(links: list[Link]) -> int:
    return sum(len(l.cand.hyp.searched) for l in links if l.cand is not None)


def new_names(hyp: Hypothesis) -> set[str]:
    return set(hyp.coefs) | set(hyp.extra_params) | set(hyp.extra_states)


def reapply(model: Model, link: Link, values: dict[str, float]) -> Model | None:
    """``link``'s change applied to ``model`` (an intersample switch's mode, or the extension's
    hypothesis at ``values``), or None when it cannot be (a name it adds is taken)."""
    if link.kind == "intersample":
        return replace(model, intersample=link.after.model.intersample, substeps=link.after.model.substeps)
    hyp = link.cand.hyp
    if new_names(hyp) & (set(model.params) | set(model.states)):
        return None
    vals = {k: float(values[k]) for k in new_names(hyp) if k in values}
    try:
        return REGISTRY[hyp.family].extend(model, hyp, vals)
    except _FAIL:          # an extension that does not fit this model (a name or state it needs is gone)
        return None


def at_values(model: Model, values: dict[str, float], keep: set[str]) -> Model:
    """``model`` with every parameter it shares with ``values`` set from there, except ``keep``."""
    return replace(model, params={k: (v if k in keep or k not in values else float(values[k]))
                                  for k, v in model.params.items()})


def rebuild(dg, start: Model, later: list[Link], final: FitResult, keep: set[str]) -> FitResult | None:
    """The final model rebuilt from ``start`` with the ``later`` links re-applied (at the final fit's
    values; ``keep``: parameters that keep ``start``'s values) and refitted jointly; None when a link
    cannot be re-applied or the refit fails."""
    m = start
    for link in later:
        m = reapply(m, link, final.model.params)
        if m is None:
            return None
    m = at_values(m, final.model.params, keep)
    try:
        return fit_output_error(dg._compiled_if_long(m), dg.prob, start=estimated_x0(final))
    except _FAIL:
        return None


def rechain(dg, head: FitResult, later: list[Link], last: FitResult, seed_key: int) -> list[Link] | None:
    """The ``later`` links refitted in order on ``head`` (the last one is ``last``, the joint refit of the
    same structure), each weighed against the link before it (:meth:`engine.Diagnoser._weigh`, the
    forward rule); None when one cannot be refitted. Intersample links are not moved (module
    docstring)."""
    from .engine import Candidate, effective_bic
    out, prev = [], head
    for j, link in enumerate(later):
        if link.cand is None:
            return None
        if j == len(later) - 1:
            f = last
        else:
            m = reapply(prev.model, link, last.model.params)
            if m is None:
                return None
            m = at_values(m, last.model.params, set())
            try:
                f = fit_output_error(dg._compiled_if_long(m), dg.prob, start=estimated_x0(prev))
            except _FAIL:
                return None
        c = link.cand
        c2 = Candidate(c.hyp, c.wald, c.p_family, list(c.evidence), fit=f, start=dict(c.start), places=c.places)
        dg._weigh(c2, prev, gain_resid(prev, dg.prob), bic_of(prev), np.random.default_rng([dg.seed, seed_key, j]))
        effective_bic([c2], prev)
        out.append(Link("extension", prev, dg._accepted(f), c2))
        prev = out[-1].after
    return out


def place(dg, links: list[Link], j: int, seed_key: int) -> tuple[bool, FitResult | None, dict | None, object]:
    """The backward rule for link ``j`` of a chain: the final model against the final model refitted
    without it, by the rule any extension is accepted by (:meth:`engine.Diagnoser._held_out`: the
    validation gain's 95 % lower bound above 0 and the likelihood-ratio p below α). Returns whether it
    holds, the final model refitted without the link (None when that refit fails: the link then
    counts as earning its place), the gain and the likelihood-ratio test."""
    final, link = links[-1].after, links[j]
    without = link.before if j == len(links) - 1 else rebuild(dg, link.before.model, links[j + 1:], final, set())
    if without is None:
        return False, None, None, None
    g, lr, ok = dg._held_out(without, gain_resid(without, dg.prob), final, len(link.cand.hyp.searched),
                             np.random.default_rng([dg.seed, seed_key, 100 + j]))
    return ok, without, g, lr


def earns_place(dg, links: list[Link], j: int, seed_key: int) -> bool:
    """:func:`place` for link ``j`` of a revised chain (False when the refit without it fails). A link
    whose forward weighing (given only the links before it) did not accept it gets this gain as its
    ``given`` (as a look-ahead finding does: its gain with the others in the model)."""
    link = links[j]
    ok, without, g, lr = place(dg, links, j, seed_key)
    if ok and not link.cand.accepted:
        final = links[-1].after
        others = ", ".join(l.cand.hyp.key if l.cand is not None else f"intersample {l.after.model.intersample}"
                           for k, l in enumerate(links) if k != j)
        link.cand = replace(link.cand, given={"with": others, "gain": g, "lr_p_value": lr.p_value,
                                              "lr_statistic": lr.statistic, "fit": final})
    return ok


def swap(dg, links: list[Link], i: int) -> tuple[list[Link], dict] | None:
    """Move 1 of the module docstring for link ``i``: the new chain and the revisit's row, or None."""
    final = links[-1].after
    link = links[i]
    c = link.cand
    s_final = searched(links)
    best = None
    for r in sorted(link.alts, key=lambda o: o.criterion)[:MAX_ALTERNATIVES]:
        if any(l.cand is not None and l.cand.hyp.family == r.hyp.family for l in links[i + 1:]):
            continue
        alt = rebuild(dg, r.fit.model, links[i + 1:], final, new_names(r.hyp))
        if alt is None:
            continue
        s_alt = s_final - len(c.hyp.searched) + len(r.hyp.searched)
        d = gap(final, alt, s_final, s_alt, r.prior_penalty - c.prior_penalty)
        if d < -TIE_CRITERION and (best is None or d < best[0]):
            best = (d, r, alt)
    if best is None:
        return None
    d, r, alt = best
    head = Link("extension", link.before, dg._accepted(r.fit), replace(r, given=None))
    tail = rechain(dg, head.after, links[i + 1:], alt, 7000 + i)
    if tail is None:
        return None
    new = links[:i] + [head] + tail
    if not all(earns_place(dg, new, j, 7000 + i) for j in range(i, len(new))):
        return None
    later = ", ".join(l.cand.hyp.key for l in links[i + 1:])
    text = (f"{r.hyp.key} in place of {c.hyp.key}: with {later} in the model the estimation part prefers it by "
            f"{-d:.1f} criterion units (effective ΔBIC and the model prior; weighted SSE {alt.sse_w:.4g} "
            f"against {final.sse_w:.4g}); at its own round the two were {abs(r.criterion - c.criterion):.1f} units apart")
    row = {"move": "swap", "short": f"{r.hyp.key} in place of {c.hyp.key}", "finding": c.hyp.key, "family": c.hyp.family, "replaced_by": r.hyp.key,
           "replaced_by_family": r.hyp.family, "criterion_change": d, "sse_w": [final.sse_w, alt.sse_w],
           "detail": text}
    return new, row


@dataclass
class SwitchRule:
    """An intersample switch judged in a final model ``final`` against the same model refitted with the
    configured intersample (``configured``): its gain, ΔBIC and whether it passes the stage's rule."""

    configured: FitResult
    gain: dict
    delta_bic: float
    holds: bool


def switch_rule(dg, final: FitResult, conf: Model, key: int) -> SwitchRule | None:
    """The rule a switch was accepted by (:meth:`.intersample_stage.IntersampleStage.run`: ΔBIC below −2, a
    validation gain of at least 0.1 % and lower at the one-sided 5 % level), applied to ``final``
    against ``final``'s model with ``conf``'s intersample and step, refitted; None when that refit
    fails. The gain's interval is analytic (:func:`gain.gain_ci`; ``key`` only seeds the generator its
    signature takes), so the switch that :func:`to_switch` puts in gets the same answer when
    :func:`drop_switch` re-examines it in the same final model."""
    m = replace(final.model, intersample=conf.intersample, substeps=conf.substeps)
    try:
        alt = fit_output_error(dg._compiled_if_long(m), dg.prob, start=estimated_x0(final))
    except _FAIL:
        return None
    g, dbic = dg.inter.switch_gain(alt, final, np.random.default_rng([dg.seed, key]))
    holds = g["p_not_lower"] < ONE_SIDED_LEVEL and g["relative"] >= INTERSAMPLE_MIN_GAIN and dbic < INTERSAMPLE_MAX_DBIC
    return SwitchRule(alt, g, dbic, holds)


def to_switch(dg, links: list[Link], i: int) -> tuple[list[Link], dict] | None:
    """Move 3 of the module docstring for the extension link ``i``: the new chain and the row, or None."""
    link, final = links[i], links[-1].after
    c = link.cand
    if ("intersample" not in dg.families or any(l.kind == "intersample" for l in links)
            or not REGISTRY[c.hyp.family].mimics_hold(c.hyp, link.after.model, dg.dt)):
        return None
    inter, base = REGISTRY["intersample"], link.before.model
    chosen = next((o for o, _ in inter.alternatives(base) if inter.equivalent(base, o, dg.dt) is not None), None)
    if chosen is None:
        return None
    switched = replace(base, intersample=chosen)
    alt = rebuild(dg, switched, links[i + 1:], final, set())
    if alt is None:
        return None
    s_final = searched(links)
    d = gap(final, alt, s_final, s_final - len(c.hyp.searched), -c.prior_penalty)
    if d >= -TIE_CRITERION:
        return None
    rule = switch_rule(dg, alt, base, 7100 + i)
    if rule is None or not rule.holds:
        return None
    try:
        head_fit = fit_output_error(dg._compiled_if_long(switched), dg.prob, start=estimated_x0(link.before))
    except _FAIL:
        return None
    head = Link("intersample", link.before, dg._accepted(head_fit))
    tail = rechain(dg, head.after, links[i + 1:], alt, 7300 + i)
    if tail is None:
        return None
    new = links[:i] + [head] + tail
    if not all(earns_place(dg, new, j, 7300 + i) for j in range(i + 1, len(new))):
        return None
    later = ", ".join(l.cand.hyp.key for l in links[i + 1:])
    g = rule.gain
    k = c.fit.n_params + len(c.hyp.searched) - link.before.n_params
    text = (f"the switch to {chosen} in place of {c.hyp.key}: with {later} in the model it fits the estimation "
            f"part {'better' if alt.sse_w < final.sse_w else 'about as well'} (weighted SSE {alt.sse_w:.4g} against "
            f"{final.sse_w:.4g}) with {k} parameter{'s' if k != 1 else ''} fewer, {-d:.1f} criterion units better "
            f"(effective ΔBIC and the model prior), and against the configured {base.intersample} in that model it passes the "
            f"switch's own rule (validation gain {100 * g['relative']:+.2f} %, one-sided p = {g['p_not_lower']:.2g} "
            f"that it is not lower; ΔBIC {rule.delta_bic:+.1f})")
    row = {"move": "swap", "short": f"the switch to {chosen} in place of {c.hyp.key}", "finding": c.hyp.key,
           "family": c.hyp.family, "replaced_by": f"intersample:{chosen}", "replaced_by_family": "intersample",
           "criterion_change": d, "sse_w": [final.sse_w, alt.sse_w], "detail": text,
           "gain_given": {"with": later, **g}}
    return new, row


def drop_switch(dg, links: list[Link], i: int) -> tuple[list[Link], dict] | None:
    """Move 2 of the module docstring for the intersample link ``i``: the new chain and the row, or None."""
    final = links[-1].after
    before = links[i].before.model
    rule = switch_rule(dg, final, before, 7100 + i)
    if rule is None or rule.holds:
        return None
    alt, g, dbic = rule.configured, rule.gain, rule.delta_bic
    tail = rechain(dg, links[i].before, links[i + 1:], alt, 7200 + i)
    if tail is None:
        return None
    new = links[:i] + tail
    if not all(earns_place(dg, new, j, 7200 + i) for j in range(i, len(new))):
        return None
    chosen = links[i].after.model
    was = f"substeps={chosen.substeps}" if chosen.substeps != before.substeps else chosen.intersample
    conf = before.intersample if was == chosen.intersample else f"substeps={before.substeps}"
    later = ", ".join(l.cand.hyp.key for l in links[i + 1:])
    text = (f"the switch to {was} no longer earns its place with {later} in the model: against the configured "
            f"{conf} its validation gain is {100 * g['relative']:+.2f} % (one-sided p = {g['p_not_lower']:.2g} "
            f"that it is not lower) and ΔBIC {dbic:+.1f}; the configured {conf} is kept")
    row = {"move": "drop", "short": f"the switch to {was} dropped", "finding": f"intersample:{was}", "family": "intersample", "replaced_by": None,
           "replaced_by_family": None, "criterion_change": dbic, "sse_w": [final.sse_w, alt.sse_w], "detail": text}
    return new, row


def drop(dg, links: list[Link], i: int) -> tuple[list[Link], dict] | None:
    """Move 4 of the module docstring for the extension link ``i``: the new chain and the row, or None."""
    link, final = links[i], links[-1].after
    c = link.cand
    ok, without, g, lr = place(dg, links, i, 7400 + i)
    if ok or without is None:
        return None
    tail = rechain(dg, link.before, links[i + 1:], without, 7400 + i)
    if tail is None:
        return None
    new = links[:i] + tail
    if not all(earns_place(dg, new, j, 7400 + i) for j in range(i, len(new))):
        return None
    s_final = searched(links)
    d = gap(final, without, s_final, s_final - len(c.hyp.searched), -c.prior_penalty)
    later = ", ".join(l.cand.hyp.key if l.cand is not None else f"intersample {l.after.model.intersample}"
                      for l in links[i + 1:])
    why = ("the interval's lower bound is not above 0" if g["ci95"][0] <= 0 else
           f"its likelihood-ratio p is {lr.p_value:.2g}, not below α = {dg.alpha:g}")
    text = (f"{c.hyp.key} no longer earns its place with {later} in the model: against that model refitted without "
            f"it, its validation gain is {100 * g['relative']:+.2f} % (95 % interval {100 * g['ci95'][0]:+.2f} to "
            f"{100 * g['ci95'][1]:+.2f} %) and {why}; weighted SSE {final.sse_w:.4g} with it, {without.sse_w:.4g} "
            f"without; it is dropped")
    row = {"move": "drop", "short": f"{c.hyp.key} dropped", "finding": c.hyp.key, "family": c.hyp.family,
           "replaced_by": None, "replaced_by_family": None, "criterion_change": d,
           "sse_w": [final.sse_w, without.sse_w], "detail": text}
    return new, row


def revisit(dg, links: list[Link]) -> tuple[list[Link], list[dict]]:
    """The moves over the chain until none applies: the chain and a row per move made
    (``Diagnosis.revisit``). A finding is tried for a swap once (the one swapped in has no alternatives);
    an intersample switch again after every move, since the final model it is judged in has changed."""
    if len(links) < 2:
        return links, []
    rows, tried = [], set()
    changed = True
    while changed:
        changed = False
        for i, link in enumerate(links[:-1]):
            key = (link.kind, link.cand.hyp.key if link.cand is not None else
                   f"{link.after.model.intersample}/{link.after.model.substeps}")
            if key in tried:
                continue
            tried.add(key)
            out = swap(dg, links, i) if link.cand is not None and link.alts else None
            if out is None and link.cand is not None:
                out = to_switch(dg, links, i)
            if out is None and link.kind == "intersample":
                out = drop_switch(dg, links, i)
            if out is None and link.cand is not None:
                out = drop(dg, links, i)
            if out is not None:
                links, row = out
                rows.append(row)
                log(f"  revisit: {row['detail']}")
                if row["move"] == "swap" and links[i].cand is not None:
                    tried.add(("extension", links[i].cand.hyp.key))
                # a switch is judged against the final model, which the move changed: judge it again
                tried = {k for k in tried if k[0] != "intersample"}
                changed = True
                break
    return links, rows


# a finding's keys that describe how its own forward round weighed it against the others
FORWARD_ROUND_KEYS = ("selection", "runners_up", "tied_with", "disputed_by")


def revisited_findings(dg, links: list[Link], old: list[Link], findings: list[dict],
                       moves: list[dict]) -> list[dict]:
    """The findings of a chain the backward step changed (:mod:`.revisit`): a link it kept keeps its
    finding (matched by its fit); a moved or refitted one gets a new finding from its candidate, with
    the move in ``revisit`` and its evidence. A refitted one (the same hypothesis, not swapped in)
    keeps what its forward round said about the alternatives (``FORWARD_ROUND_KEYS`` and the
    sentences on ties and disputes), marked as the forward round's: the refit does not weigh them
    again (on the delay + offset record of seed 2007 the offset's runner-up was lost when the zoh
    switch before it was dropped)."""
    out = []
    for link in links:
        k = next((j for j, l in enumerate(old) if l.after is link.after), None)
        if k is not None:
            out.append(findings[k])
        elif link.cand is None:         # a switch the backward step put in (revisit.to_switch)
            chosen = link.after.model.intersample
            g, dbic = dg.inter.switch_gain(link.before, link.after, np.random.default_rng([dg.seed, 7400]))
            f = dg.inter.switch_finding(link.before, chosen, link.after, dbic, g)
            move = next((m for m in moves if m["replaced_by"] == f"intersample:{chosen}"), None)
            if move is not None:
                f["revisit"] = move["detail"]
                f["gain_given"] = move["gain_given"]
                f["evidence"] = f["evidence"] + [{"test": "revisit_swap", "statistic": -move["criterion_change"],
                                                  "p_value": None, "detail": move["detail"]}]
            else:
                f["revisit"] = "refitted after the backward step (" + "; ".join(m["short"] for m in moves) + ")"
            f["description"] += f" Backward step: {f['revisit']}."
            out.append(f)
        else:
            f = finding(dg.prob, dg.dt, link.cand, [])
            move = next((m for m in moves if m["replaced_by"] == link.cand.hyp.key), None)
            if move is not None:
                f["revisit"] = move["detail"]
                f["evidence"] = f["evidence"] + [{"test": "revisit_swap", "statistic": -move["criterion_change"],
                                                  "p_value": None, "detail": move["detail"]}]
            else:
                f["revisit"] = ("refitted after the backward step (" + "; ".join(m["short"] for m in moves) + ")")
                f["description"] += forward_round(f, next(
                    (findings[j] for j, l in enumerate(old) if l.cand is not None and l.cand.hyp is link.cand.hyp),
                    None))
            f["description"] += f" Backward step: {f['revisit']}."
            out.append(f)
    return out


def forward_round(f: dict, before: dict | None) -> str:
    """Copies into the refitted finding ``f`` what its forward-round finding ``before`` said about the
    other causes (``FORWARD_ROUND_KEYS``, where ``f`` has none of its own), and returns the forward
    round's sentences on ties and disputes, introduced as such ("" when there are none)."""
    if before is None:
        return ""
    carried = [key for key in FORWARD_ROUND_KEYS if before.get(key) and not f.get(key)]
    for key in carried:
        f[key] = before[key]
    if carried:
        f["forward_round"] = carried
    desc = before.get("description", "")
    at = [desc.find(m) for m in CONTEST_SENTENCES if m in desc]
    return f" In its forward round:{desc[min(at):]}" if at else ""
