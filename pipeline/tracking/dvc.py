"""``metrics.json`` and ``params.yaml`` in DVC's conventions, so ``dvc metrics diff`` / ``dvc params
diff`` work on run folders.

DVC reads metrics as a tree of mappings whose leaves are numbers, addressed by the dotted tree path
(``final.validation.fit_percent``); values inside lists and nulls are not metrics and are dropped by
``dvc metrics show`` (DVC docs, "metrics": "Metrics can be organized as tree hierarchies in JSON or
YAML files. DVC addresses specific metrics by the tree path"). So lists become mappings keyed by name,
and nulls are left out. ``params.yaml`` holds what a stage *consumes* (DVC docs, "params": values "used
inside your code to tune the analysis"): here the resolved config. Fitted parameter values are outputs
and are in ``metrics.json`` (``nominal.params.k``).
"""

from __future__ import annotations

import math
from typing import Any

_MODEL_KEYS = ("bic", "n_params", "validation_rmse_sim", "cv_mean", "cv_sd", "aic", "aicc", "fpe")


def _numeric_tree(x: Any) -> Any:
    """Keep mappings and finite numbers (bools as 0/1); drop everything else (None → dropped)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            c = _numeric_tree(v)
            if c is not None and c != {}:
                out[str(k)] = c
        return out
    if isinstance(x, bool):
        return int(x)
    if isinstance(x, (int, float)) and math.isfinite(float(x)):
        return x
    return None


def dvc_metrics(summary: dict) -> dict:
    """The metrics tree of a run from its ``summary.json`` content (numbers only)."""
    out: dict[str, Any] = {}
    for which in ("nominal", "final"):
        b = summary.get(which) or {}
        out[which] = _numeric_tree({k: b.get(k) for k in ("estimation", "validation", "bic", "n_params",
                                                          "converged", "params", "param_std")})
    diag = summary.get("diagnosis") or {}
    findings = diag.get("findings") or []
    out["diagnosis"] = {"n_findings": len(findings),
                        "n_tests_failed": sum(1 for t in diag.get("tests") or [] if not t.get("passed", True))}
    if findings:
        g = findings[0].get("gain") or {}
        ci = g.get("ci95") or [None, None]
        out["diagnosis"]["main_gain"] = _numeric_tree({"relative": g.get("relative"), "ci95_low": ci[0],
                                                       "ci95_high": ci[1], "delta_bic": findings[0].get("delta_bic")})
    nv, fv = (summary.get("nominal") or {}).get("validation", {}), (summary.get("final") or {}).get("validation", {})
    if nv.get("rmse_sim") and fv.get("rmse_sim") is not None:
        out["diagnosis"]["total_gain_relative"] = 1.0 - fv["rmse_sim"] / nv["rmse_sim"]
    models: dict[str, Any] = {}
    for m in summary.get("models") or []:
        key = m.get("name", "?") if "estimator" not in m or m.get("name", "").startswith("nominal") \
            else f"{m.get('name')}/{m.get('estimator')}"
        models[key] = _numeric_tree({k: m.get(k) for k in _MODEL_KEYS})
    out["models"] = models
    return _numeric_tree(out)


def dvc_params(canonical_config: dict) -> dict:
    """``params.yaml``: the resolved config the run consumed (DVC params are a stage's inputs)."""
    return canonical_config


def flatten(tree: Any, prefix: str = "", sep: str = ".") -> dict[str, Any]:
    """Dotted-path view of a nested mapping (DVC's addressing); lists are indexed ``key.0``."""
    out: dict[str, Any] = {}
    if isinstance(tree, dict):
        for k, v in tree.items():
            out.update(flatten(v, f"{prefix}{sep}{k}" if prefix else str(k), sep))
    elif isinstance(tree, (list, tuple)):
        for i, v in enumerate(tree):
            out.update(flatten(v, f"{prefix}{sep}{i}" if prefix else str(i), sep))
    else:
        out[prefix] = tree
    return out
