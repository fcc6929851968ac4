"""JSON output shared by the run record and the stages: numpy to Python, floats rounded to 10
significant digits (so byte-identical reruns do not depend on the last bits), NaN/inf to null."""

from __future__ import annotations

import json
import math

import numpy as np


def clean(x):
    """JSON-ready copy: numpy → Python, floats rounded to 10 significant digits, NaN/inf → None."""
    if isinstance(x, dict):
        return {str(k): clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return [clean(v) for v in x.tolist()]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        if not math.isfinite(v):
            return None
        return float(f"{v:.10g}")
    return x


def dumps(obj) -> str:
    return json.dumps(clean(obj), indent=2, sort_keys=False) + "\n"


