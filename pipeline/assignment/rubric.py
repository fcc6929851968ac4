"""The score of a submission, from the rubric of the template (weights and tolerances).

Each item is a share in [0, 1]; the score is ``100 * sum(w_i * share_i) / sum(w_i)``:

* ``cause``: 1 when the claimed cause is the key's family, else 0.
* ``parameter``: 0 unless the cause is right; with the relative error
  ``e = |c_student - c_key| / |c_key|`` of the cause's size (see :func:`pipeline.assignment.grade`),
  ``clip(2 - e / parameter_tolerance, 0, 1)``: full marks up to the tolerance, none at twice it.
  For an input delay the error is in samples, ``e = |d_student - d_key| / dt``, and the tolerance is
  ``delay_tolerance_samples`` (default 1.5 samples: the accuracy the diagnosis contract asks of a
  found delay), scored the same way.
* ``validation``: with the held-out free-run RMSE of the refitted starter model (``nominal``), of the
  student's refitted model (``student``) and of the noise-free truth (``truth``, the measurement noise
  alone), the share of the achievable improvement ``s = (nominal - student) / (nominal - truth)``,
  scored ``clip(s / validation_target, 0, 1)``. (If the starter model is already at the noise level,
  ``s`` is 1 when the student's model is no worse, else 0.)
* ``gain``: 1 when the claimed gain is within ``gain_tolerance`` (absolute) of the measured one.

When ``require_issued_data`` is set, a submission whose data file is not the issued one scores 0.
"""

from __future__ import annotations

import math

from .template import Rubric


def clip01(x: float) -> float:
    return min(1.0, max(0.0, x))


def validation_share(nominal: float, student: float, truth: float) -> float:
    """Share of the achievable held-out improvement the student's model achieves (NaN-safe: 0)."""
    if not all(math.isfinite(v) for v in (nominal, student, truth)):
        return 0.0
    achievable = nominal - truth
    if achievable <= 0:
        return 1.0 if student <= nominal else 0.0
    return (nominal - student) / achievable


def shares(r: Rubric, *, cause_correct: bool, parameter_error: float, validation: float,
           gain_reproduces: bool, tolerance: float | None = None) -> dict[str, float]:
    """The share of each rubric item (see the module docstring); ``tolerance`` replaces
    ``r.parameter_tolerance`` (the input delay's error is in samples)."""
    tol = r.parameter_tolerance if tolerance is None else tolerance
    p = 0.0
    if cause_correct and math.isfinite(parameter_error):
        p = clip01(2.0 - parameter_error / tol)
    v = clip01(validation / r.validation_target) if math.isfinite(validation) else 0.0
    return {"cause": 1.0 if cause_correct else 0.0, "parameter": p, "validation": v,
            "gain": 1.0 if gain_reproduces else 0.0}


def score(r: Rubric, item_shares: dict[str, float], data_issued: bool) -> float:
    """The score in [0, 100]."""
    if r.require_issued_data and not data_issued:
        return 0.0
    w = r.weights.model_dump()
    return 100.0 * sum(w[k] * item_shares[k] for k in w) / sum(w.values())
