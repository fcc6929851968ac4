"""Blocked k-fold CV: contiguous folds, gap around each validation block, seeded, full coverage."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.selection import blocked_folds, cross_validate, segments

CASES = [(100, 5, 0, None), (101, 4, 3, 7), (1000, 10, 12, 0), (37, 3, 5, 123)]


@pytest.mark.parametrize("n,k,gap,seed", CASES)
def test_every_sample_validated_exactly_once(n, k, gap, seed):
    folds = blocked_folds(n, k, gap, seed)
    assert len(folds) == k
    counts = np.zeros(n, dtype=int)
    for _, val in folds:
        counts[val] += 1
    np.testing.assert_array_equal(counts, np.ones(n, dtype=int))


@pytest.mark.parametrize("n,k,gap,seed", CASES)
def test_no_training_sample_within_lag_window_of_a_validation_sample(n, k, gap, seed):
    for train, val in blocked_folds(n, k, gap, seed):
        assert np.intersect1d(train, val).size == 0
        dist = np.abs(train[:, None] - val[None, :]).min()
        assert dist > gap  # a training regressor window [i-gap, i] never touches the block, and vice versa
        # everything outside the block and its gap is used for estimation
        expected = np.setdiff1d(np.arange(n), np.arange(max(0, val[0] - gap), min(n, val[-1] + gap + 1)))
        np.testing.assert_array_equal(train, expected)


@pytest.mark.parametrize("n,k,gap,seed", CASES)
def test_validation_blocks_are_contiguous_and_balanced(n, k, gap, seed):
    sizes = []
    for _, val in blocked_folds(n, k, gap, seed):
        assert np.all(np.diff(val) == 1)
        sizes.append(val.size)
    assert max(sizes) - min(sizes) <= 1


def test_same_seed_same_folds_and_seed_only_reorders():
    a = blocked_folds(200, 6, 4, seed=11)
    b = blocked_folds(200, 6, 4, seed=11)
    for (ta, va), (tb, vb) in zip(a, b):
        np.testing.assert_array_equal(ta, tb)
        np.testing.assert_array_equal(va, vb)
    plain = blocked_folds(200, 6, 4, seed=None)
    firsts = [v[0] for _, v in plain]
    assert firsts == sorted(firsts)
    assert sorted(v[0] for _, v in a) == firsts  # same blocks, in a seeded order
    orders = {tuple(v[0] for _, v in blocked_folds(200, 6, 4, seed=s)) for s in range(10)}
    assert len(orders) > 1


def test_segments_split_training_set_at_the_hole():
    train, val = blocked_folds(30, 3, 2, None)[1]
    segs = segments(train)
    assert len(segs) == 2
    assert segs[0][-1] == val[0] - 3 and segs[1][0] == val[-1] + 3


def test_cross_validate_scores_mean_sd_and_label():
    y = np.arange(50.0)

    def fit(train):
        return float(np.mean(y[train]))

    def score(model, val):
        return float(np.mean((y[val] - model) ** 2))

    res = cross_validate(fit, score, 50, k=5, gap=2, seed=3, kind="one-step")
    manual = [score(fit(tr), va) for tr, va in blocked_folds(50, 5, 2, 3)]
    np.testing.assert_allclose(res.scores, manual)
    assert res.mean == pytest.approx(np.mean(manual))
    assert res.sd == pytest.approx(np.std(manual, ddof=1))
    assert res.label == "one-step-ahead prediction error"
    sim = cross_validate(fit, score, 50, k=5, gap=2, seed=3, kind="simulation")
    assert sim.label == "free-run simulation error"


@pytest.mark.parametrize("args,match", [((10, 11, 0, None), "k = 11"), ((10, 1, 0, None), "k = 1"),
                                        ((10, 2, -1, None), "gap"), ((10, 2, 10, None), "no estimation samples"),
                                        ((1, 2, 0, None), "n = 1")])
def test_bad_fold_arguments(args, match):
    with pytest.raises(InputError, match=match):
        blocked_folds(*args)


def test_bad_score_kind():
    with pytest.raises(InputError, match="kind"):
        cross_validate(lambda tr: 0, lambda m, va: 0.0, 10, 2, 0, None, kind="r2")
