"""Experiment tracking: DVC-conventional ``metrics.json``/``params.yaml`` (:mod:`.dvc`) and an optional
MLflow backend (:mod:`.mlflow_backend`, extra ``[mlflow]``)."""

from __future__ import annotations

from .dvc import dvc_metrics, dvc_params, flatten

DEFAULT_TRACKING_URI = "sqlite:///reports/mlruns.db"

__all__ = ["DEFAULT_TRACKING_URI", "dvc_metrics", "dvc_params", "flatten"]
