"""Blocked k-fold cross-validation for dynamic models.

Ordinary shuffled k-fold leaks information between estimation and validation when the model has
lags: a NARX regressor row at sample ``i`` contains samples ``i-1, ..., i-lag``.  Here the record is
split into ``k`` contiguous blocks (Bergmeir & Benítez 2012, "blocked" CV; Racine 2000,
"hv-block" CV with a gap): fold ``f`` validates on block ``f`` and estimates on everything else
except ``gap`` samples either side of the block, so no estimation sample lies within ``gap``
samples of a validation sample (and no estimation regressor window reaches into the block).
Use ``gap >= max lag`` of the model.  Every sample is validated exactly once.

A score is labelled by what it measures: ``"simulation"`` (free-run simulation error: the model
is run on the measured input only, its own past outputs fed back) or ``"one-step"`` (one-step-ahead
prediction error from measured past outputs).  The two are not comparable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from pipeline import progress
from pipeline.errors import InputError

SCORE_KINDS = {
    "simulation": "free-run simulation error",
    "one-step": "one-step-ahead prediction error",
}


def blocked_folds(n: int, k: int, gap: int = 0, seed: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Contiguous folds ``[(train_idx, val_idx), ...]`` over samples ``0..n-1``.

    Block boundaries are ``floor(f n / k)``, f = 0..k, so the validation blocks partition the record.
    ``seed`` (an int) only permutes the order in which the folds are returned (same seed, same
    list); ``None`` keeps the natural order.  Training indices exclude ``gap`` samples on both
    sides of the validation block.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise InputError(f"blocked_folds: n = {n!r}; expected an integer number of samples >= 2")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2 or k > n:
        raise InputError(f"blocked_folds: k = {k!r}; expected an integer number of folds with 2 <= k <= n = {n}")
    if isinstance(gap, bool) or not isinstance(gap, (int, np.integer)) or gap < 0:
        raise InputError(f"blocked_folds: gap = {gap!r}; expected a non-negative integer (the model's max lag)")
    edges = (np.arange(k + 1) * n) // k
    order = np.arange(k)
    if seed is not None:
        order = np.random.default_rng(seed).permutation(k)
    folds = []
    all_idx = np.arange(n)
    for f in order:
        v0, v1 = int(edges[f]), int(edges[f + 1])
        val = all_idx[v0:v1]
        train = np.concatenate([all_idx[: max(0, v0 - gap)], all_idx[min(n, v1 + gap):]])
        if train.size == 0:
            raise InputError(
                f"blocked_folds: fold {f} has no estimation samples (n = {n}, k = {k}, gap = {gap}); "
                "expected n large enough that each fold leaves samples outside the block and its gap"
            )
        folds.append((train, val))
    return folds


def segments(idx: np.ndarray) -> list[np.ndarray]:
    """Split sorted indices into contiguous runs (a training set of a middle fold has two)."""
    idx = np.asarray(idx)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) != 1) + 1
    return np.split(idx, cuts)


@dataclass
class CVResult:
    """Per-fold scores of a blocked cross-validation with their mean and sample sd."""

    scores: np.ndarray
    mean: float
    sd: float
    kind: str
    label: str
    folds: list = field(repr=False, default_factory=list)


def cross_validate(
    fit_fn: Callable[[np.ndarray], Any],
    score_fn: Callable[[Any, np.ndarray], float],
    n: int,
    k: int = 5,
    gap: int = 0,
    seed: int | None = None,
    kind: str = "simulation",
) -> CVResult:
    """Blocked k-fold CV: ``model = fit_fn(train_idx)``, ``score = score_fn(model, val_idx)`` per fold.

    ``kind`` labels the score: ``"simulation"`` (free-run simulation error) or ``"one-step"``.
    Returns per-fold scores (in fold order), their mean and sample standard deviation (ddof = 1).
    """
    if kind not in SCORE_KINDS:
        raise InputError(f"cross_validate: kind = {kind!r}; expected one of {sorted(SCORE_KINDS)}")
    folds = blocked_folds(n, k, gap, seed)
    scores = []
    for train, val in progress.bar(folds, len(folds), "CV folds", always_final=False):
        model = fit_fn(train)
        s = float(score_fn(model, val))
        scores.append(s)
    arr = np.asarray(scores, dtype=float)
    sd = float(arr.std(ddof=1)) if arr.size > 1 else 0.0
    return CVResult(arr, float(arr.mean()), sd, kind, SCORE_KINDS[kind], folds)
