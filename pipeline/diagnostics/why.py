"""Why no cause is named: one plain paragraph for an ``unexplained_discrepancy`` verdict, from the
diagnosis history's last round (the extensions refitted against the final model).

The failing adequacy rows say *where* the final model misses (``where_it_fails``); the families' reasons
say why each was not taken. A reader of an unexplained verdict also needs the synthesis: which refitted
extensions did lower the validation error, by how much, and what kept them out. Three situations recur on
real records and each means something different:

* **the record cannot bound the gain**: the 95 % interval reaches the clip at −99 (:func:`.gain.unbounded_note`):
  the validation residual is so smooth that it carries well under one degree of freedom (the cascaded
  tanks: ν = 0.15–0.26, point gains 42–47 %). A point gain is then no evidence;
* **causes of different kinds gain alike**: extensions of two or more families lower the validation error
  by nearly the same share (within ``ALIKE`` of the best, relatively) and none of them has a gain bounded
  above 0: the validation part does not say which cause is at work (the cascaded tanks: an offset
  47.2 %, a square-root outflow 46.5 %);
* **a validation gain the estimation part does not support**: the interval is above 0 but the
  likelihood-ratio test with the residual's effective sample size is not significant (a sensor offset on
  the cascaded tanks, 23 % with interval 12 to 32 %, LR p = 0.017 at N_eff = 3.6), or the interval is
  bounded and contains 0 (not significant).

Nothing here is a new test: it restates the engine's own decisions (``reason``, ``gain`` of each
candidate record) so that the verdict reads as a conclusion, not as a list."""

from __future__ import annotations

from .adequacy import material
from .gain import is_unbounded

ALIKE = 0.8          # another family's point gain at least this share of the best one's is "alike"
MAX_LISTED = 4       # refitted extensions named in the sentence


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %"


def _but(reason: str) -> str:
    """A rejection reason after "but": the engine's "estimation fit not better by …" made a clause."""
    pre = "estimation fit not better"
    return ("its estimation fit is not better" + reason[len(pre):]) if reason.startswith(pre) else reason


LOOKED_AHEAD = "looked ahead: "   # the engine's mark on a reason (Diagnoser._lookahead)


def refitted_not_accepted(history: list[dict]) -> list[dict]:
    """The last round's candidates that were refitted, lowered the validation error (point gain > 0) and
    were not accepted, largest gain first (intersample rows included: they are refits too)."""
    if not history:
        return []
    rows = [c for c in history[-1].get("candidates", [])
            if c.get("gain") and not c.get("accepted") and (c["gain"].get("relative") or 0.0) > 0]
    rows.sort(key=lambda c: -c["gain"]["relative"])
    return rows


def varying_parameters(adequacy) -> str:
    """The sentence for a failed, material ``parameter_stability`` row (:mod:`.stability`), or "": the
    final model's parameters are not constant over the record, which no family describes unless the
    change is one step or a straight line (those families were tested and not taken)."""
    for t in adequacy:
        if t.name.startswith("parameter_stability") and material(t):
            where = t.detail.split("); ", 1)[-1]
            return (f"The fitted parameters do not stay constant over the estimation record ({where}). "
                    "No family holds a parameter that varies like this: a jump is one step and a drift a "
                    "straight line.")
    return ""


def why_unexplained(history: list[dict], adequacy=()) -> dict:
    """``{"refitted": [...], "sentence": str}``: the refitted, not accepted extensions of the last round
    (hypothesis, family, gain, interval, degrees of freedom, kind of rejection) and one paragraph that says
    what kept them out. ``kind``: ``unbounded`` (the record cannot bound the gain), ``not_lower`` (a bounded
    interval that reaches 0), ``estimation`` (the interval is above 0; the likelihood-ratio test or another
    estimation-part check is not passed). ``adequacy``: the final model's adequacy rows; a failed
    parameter-stability row puts its sentence first (:func:`varying_parameters`)."""
    w = _why(history)
    first = varying_parameters(adequacy)
    return {**w, "sentence": f"{first} {w['sentence']}"} if first else w


def _why(history: list[dict]) -> dict:
    if history and any(c.get("accepted") for c in history[-1].get("candidates", [])):
        # the loop stopped at max_findings: its last round's refits were weighed against the model before
        # the final one, and the final model's own test round refits nothing
        return {"refitted": [], "sentence": (
            "The diagnosis stopped at max_findings with its last accepted extension, so nothing was refitted "
            "on the final model; raise diagnose.max_findings to let the loop go on.")}
    rows = refitted_not_accepted(history)
    out = []
    for c in rows:
        g = c["gain"]
        kind = "unbounded" if is_unbounded(g) else ("not_lower" if g["ci95"][0] <= 0 else "estimation")
        label = c["hypothesis"] if c["family"] != "intersample" else f"intersample {c['hypothesis']}"
        out.append({"family": c["family"], "hypothesis": label, "relative": g["relative"],
                    "ci95": list(g["ci95"]), "dof": (g.get("bootstrap") or {}).get("dof"), "kind": kind,
                    "reason": c.get("reason") or ""})
    if not out:
        tried = [c for c in (history[-1].get("candidates", []) if history else []) if c.get("gain")]
        sentence = ("No refitted extension lowered the validation error." if tried else
                    "No family's extension was refitted on the final model: none of their added-term tests "
                    "was significant after Holm correction, so the misfit lies in no family's direction.")
        return {"refitted": [], "sentence": sentence}
    listed = out[:MAX_LISTED]
    parts = [f"{r['hypothesis']} {_pct(r['relative'])}" for r in listed]
    more = f" and {len(out) - len(listed)} more" if len(out) > len(listed) else ""
    s = [f"Refitted on the final model, these extensions lower the validation error but were not accepted: "
         f"{', '.join(parts)}{more}."]
    unb = [r for r in out if r["kind"] == "unbounded"]
    if unb:
        dofs = [r["dof"] for r in unb if r["dof"] is not None]
        nu = f" (ν ≤ {max(dofs):.2g} degrees of freedom)" if dofs else ""
        who = "any of them" if len(unb) == len(out) else f"{len(unb)} of them"
        s.append(f"The validation record cannot bound the gain of {who}{nu}: its residual is too smooth for "
                 "a point gain to be evidence.")
    best = out[0]["relative"]
    alike = [r for r in out if r["relative"] >= ALIKE * best]
    fams = list(dict.fromkeys(r["family"] for r in alike))
    if len(fams) > 1:
        lo, hi = min(r["relative"] for r in alike), max(r["relative"] for r in alike)
        # "which cause" is open only when none of them has a gain bounded above 0: a bounded gain is
        # evidence for its cause that the others' point values do not match
        open_ = all(r["kind"] != "estimation" for r in alike)
        s.append(f"Extensions of {len(fams)} different causes ({', '.join(fams)}) lower the validation error by "
                 f"similar amounts ({100 * lo:.1f} to {100 * hi:.1f} %)"
                 + (": these data do not say which cause is at work." if open_ else "."))
    if out[0]["kind"] == "not_lower":
        r = out[0]
        s.append(f"The largest, {r['hypothesis']}, has a 95 % interval of {_pct(r['ci95'][0])} to "
                 f"{_pct(r['ci95'][1])}: not significantly better.")
    # a bounded validation gain above 0 is the strongest evidence in the list: said even when not the largest
    est = next((r for r in out if r["kind"] == "estimation"), None)
    if est is not None:
        s.append(f"{est['hypothesis']} has a validation gain of {_pct(est['relative'])} (95 % interval "
                 f"{_pct(est['ci95'][0])} to {_pct(est['ci95'][1])}), but {_but(est['reason'])}.")
    ahead = next((r for r in out if LOOKED_AHEAD in r["reason"]), None)
    if ahead is not None:
        s.append(f"Taken as the model for one more round, to look for a second cause beside it, "
                 f"{ahead['hypothesis']}: {ahead['reason'].split(LOOKED_AHEAD, 1)[1]}.")
    return {"refitted": out, "sentence": " ".join(s)}
