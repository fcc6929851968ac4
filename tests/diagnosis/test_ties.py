"""Which alternatives a finding states as tied (``naming.unresolved_ties``), on residuals built by
hand: a tie needs an accepted extension of another family within ``TIE_CRITERION`` of the finding's
criterion whose validation error neither part separates (the rule of ``naming.separate``: the 95 %
interval of the relative gain above 0 and at least 1 %, on either side). The independent-record side
is in ``test_choice_on_coloured_noise.py``."""

from types import SimpleNamespace as NS

import numpy as np

from pipeline.diagnostics import naming

N = 2000


def _setup():
    rng = np.random.default_rng(0)
    y = np.zeros((N, 1))
    e = rng.standard_normal((N, 1))
    prob = NS(Y=y, split=NS(val_slice=lambda: slice(0, N)))

    def cand(family, key, resid, criterion, accepted=True):
        fit = NS(Yhat=y - resid)
        return NS(fit=fit, gain={"after": float(np.sqrt(np.mean(resid ** 2)))}, accepted=accepted,
                  hyp=NS(family=family, key=key), criterion=criterion)
    return prob, rng, e, cand


def test_only_an_unseparated_near_equal_of_another_family_is_a_tie():
    prob, rng, e, cand = _setup()
    c = cand("unmodeled_dynamics", "lag", e, -50.0)
    others = [
        cand("input_delay", "same", e + 0.01 * rng.standard_normal((N, 1)), -49.5),      # a tie
        cand("offset", "worse", 1.2 * e + 0.3 * rng.standard_normal((N, 1)), -49.0),    # clearly worse on validation
        cand("cubic_stiffness", "better", 0.8 * e, -49.0),                              # clearly better: separate's case
        cand("parameter_drift", "far", e, -47.0),                                      # criterion 3 behind
        cand("unmodeled_dynamics", "same-family", e, -50.0),                           # the same cause elsewhere
        cand("periodic_disturbance", "rejected", e, -50.0, accepted=False),            # not accepted
    ]
    ties = naming.unresolved_ties(prob, c, others)
    assert [t["hypothesis"] for t in ties] == ["same"]
    t = ties[0]
    assert t["family"] == "input_delay" and t["criterion_gap"] == 0.5
    assert t["ci95"][0] < 0 < t["ci95"][1] or abs(t["relative"]) < naming.SEPARATION_MIN_GAIN


def test_a_significant_but_immaterial_difference_is_still_a_tie():
    """A validation error lower by 0.3 % with an interval above 0 (the difference is deterministic, the
    noise small) is below the 1 % that separates: still a tie."""
    prob, rng, e, cand = _setup()
    c = cand("unmodeled_dynamics", "lag", e, -50.0)
    o = cand("input_delay", "delay", 0.997 * e, -49.0)
    ties = naming.unresolved_ties(prob, c, [o])
    assert len(ties) == 1 and ties[0]["ci95"][0] > 0 and ties[0]["relative"] < naming.SEPARATION_MIN_GAIN


def test_a_runner_up_the_validation_part_clearly_prefers_beyond_a_tie_is_stated():
    """``naming.disputed``: an accepted extension of another family that the estimation part ranks
    behind the finding by ``SEPARATE_CRITERION`` or more but within ``RUNNER_UP_DBIC``, and whose
    validation error is clearly lower (the rule of ``separate``), is stated; one closer (``separate``'s
    own case), one too far behind, one not clearly better, a rejected one and the same family are not."""
    prob, rng, e, cand = _setup()
    c = cand("unmodeled_dynamics", "lag", e, -50.0)
    others = [
        cand("input_delay", "delay", 0.85 * e, -43.0),                                  # 7 behind, 15 % lower
        cand("cubic_stiffness", "positive", 0.8 * e, -46.0),                            # separate's case
        cand("offset", "far", 0.8 * e, -50.0 + naming.RUNNER_UP_DBIC + 1.0),         # beyond the runners-up
        cand("parameter_drift", "not-better", 0.998 * e, -43.0),                        # 0.2 % lower: not clear
        cand("periodic_disturbance", "rejected", 0.8 * e, -43.0, accepted=False),
        cand("unmodeled_dynamics", "same-family", 0.8 * e, -43.0),
    ]
    out = naming.disputed(prob, c, others)
    assert [t["hypothesis"] for t in out] == ["delay"]
    assert out[0]["criterion_gap"] == 7.0 and out[0]["ci95"][0] > 0 and abs(out[0]["relative"] - 0.15) < 1e-9
