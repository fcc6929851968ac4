"""Does the validation part stay where the model was fitted?

A validation error measured where the inputs or outputs leave the range they had on the estimation part
measures extrapolation: a model right on the estimation data can be wrong there (a lamp's V² looks linear
between two voltages), and a cause that the estimation data cannot show cannot be named from them. These
are plain facts about the record, per signal: the estimation and validation ranges, the share of
validation samples outside the estimation range, and the levels of a piecewise-constant signal (at most
``MAX_LEVELS`` distinct values). The ranges are those of the signals the model was fitted to (after the
prefilter and mean removal)."""

from __future__ import annotations

import numpy as np

MAX_LEVELS = 8        # a signal with at most this many distinct values has its levels listed
# the report names a signal whose validation part is outside the estimation range on this share of its
# samples (a stationary signal's validation part exceeds the estimation extremes on a few % by chance),
# or reaches this far beyond it (a share of the estimation range's width: Silverbox's arrow, 25 %)
OUTSIDE_REPORTED = 0.05
BEYOND_REPORTED = 0.2


def _levels(x: np.ndarray) -> list[float] | None:
    lv = np.unique(x)
    return [float(v) for v in lv] if lv.size <= MAX_LEVELS else None


def coverage(U: np.ndarray, Y: np.ndarray, inputs: list[str], outputs: list[str],
             est: tuple[int, int], val: tuple[int, int]) -> list[dict]:
    """One row per input and output: ``estimation_range``, ``validation_range``,
    ``validation_outside_share`` (the share of validation samples below the estimation minimum or above
    its maximum), ``validation_outside_by`` (how far the validation range reaches beyond the estimation
    range, over the estimation range's width) and, for signals with few values, ``estimation_levels``,
    ``validation_levels`` and ``new_levels`` (validation levels never seen on the estimation part)."""
    rows = []
    for kind, names, M in (("input", inputs, U), ("output", outputs, Y)):
        for j, name in enumerate(names):
            e = M[est[0]:est[1], j]
            v = M[val[0]:val[1], j]
            e, v = e[np.isfinite(e)], v[np.isfinite(v)]
            if not e.size or not v.size:
                continue
            lo, hi, vlo, vhi = float(e.min()), float(e.max()), float(v.min()), float(v.max())
            width = hi - lo
            row = {"signal": name, "kind": kind, "estimation_range": [lo, hi], "validation_range": [vlo, vhi],
                   "validation_outside_share": float(np.mean((v < lo) | (v > hi))),
                   "validation_outside_by": (max(lo - vlo, vhi - hi, 0.0) / width) if width > 0 else None}
            le, lv = _levels(e), _levels(v)
            if le is not None and lv is not None:
                row.update(estimation_levels=le, validation_levels=lv,
                           new_levels=[x for x in lv if x not in set(le)])
            rows.append(row)
    return rows


def coverage_text(rows: list[dict], fmt) -> str | None:
    """One sentence naming the signals whose validation part leaves the estimation range (on at least
    ``OUTSIDE_REPORTED`` of its samples, or by ``BEYOND_REPORTED`` of its width) or holds input levels the estimation part never had; None when
    the validation part stays inside. ``fmt`` formats a number (the report's significant digits)."""
    parts = []
    for r in rows:
        lo, hi = r["estimation_range"]
        vlo, vhi = r["validation_range"]
        by = r["validation_outside_by"] or 0.0
        outside = r["validation_outside_share"] >= OUTSIDE_REPORTED or (by >= BEYOND_REPORTED
                                                                         and r["validation_outside_share"] > 0)
        new = r.get("new_levels") if r["kind"] == "input" else None
        if not outside and not new:
            continue
        s = f"{r['kind']} {r['signal']}"
        if outside:
            s += (f" spans {fmt(vlo)} to {fmt(vhi)} on validation, {fmt(lo)} to {fmt(hi)} on estimation "
                  f"({fmt(100 * r['validation_outside_share'])} % of validation samples outside, reaching "
                  f"{fmt(100 * by)} % of the estimation range beyond it)")
        if new:
            s += ((", and takes" if outside else " takes") + f" {len(new)} level{'s' if len(new) > 1 else ''} "
                  f"on validation ({', '.join(fmt(x) for x in new)}) that the estimation part never had "
                  f"(it has {', '.join(fmt(x) for x in r['estimation_levels'])})")
        parts.append(s)
    if not parts:
        return None
    return ("The validation part goes where the model was not fitted: " + "; ".join(parts)
            + ". There the validation error tests the model beyond the data it was fitted to, and an effect "
              "that shows only there cannot be found from the estimation data.")
