"""MLflow backend (optional extra ``[mlflow]``: ``mlflow-skinny``, ``sqlalchemy``, ``alembic``).

One run folder becomes one MLflow run: params = the resolved config flattened to dotted keys
(``model.params.k``), metrics = the DVC metrics tree of :mod:`pipeline.tracking.dvc` flattened the same
way, tags = verdict, main cause, run id, data sha256, git commit, and the run folder logged as
artifacts. The default store is ``sqlite:///reports/mlruns.db`` (artifacts beside it in
``reports/mlartifacts``); any tracking URI works. Logging the same folder twice (same run id and same
``manifest.created``) is a no-op that returns the existing MLflow run id.

Open the UI with ``mlflow ui --backend-store-uri sqlite:///reports/mlruns.db``.
"""

from __future__ import annotations

import json
import logging
import os
import re
import time
from pathlib import Path
from typing import Any

import yaml

from ..errors import InputError
from . import DEFAULT_TRACKING_URI
from .dvc import dvc_metrics, flatten

EXPERIMENT = "sysid"
_BAD_KEY = re.compile(r"[^\w\-. /:]")
_PARAM_MAX = 6000            # MLflow's limit on a param value (characters)


def _key(k: str) -> str:
    """MLflow keys allow alphanumerics, ``_ - . / :`` and spaces; anything else (``+`` in
    ``nominal+cubic_stiffness``) becomes ``_``."""
    return _BAD_KEY.sub("_", k)[:250]


def _import_mlflow():
    try:
        import mlflow  # noqa: F401
        from mlflow.tracking import MlflowClient
    except ImportError:
        raise InputError("MLflow tracking needs the optional extra: pip install -e '.[mlflow]'",
                         key="--track") from None
    for name in ("alembic", "mlflow.store.db.utils", "mlflow.store.db"):
        logging.getLogger(name).setLevel(logging.WARNING)
    return MlflowClient


URI_SCHEMES = ("sqlite", "file", "http", "https", "databricks")


def check_uri(uri: str | None, key: str = "--uri") -> str:
    """The tracking URI, checked before any work (a bad one failed inside MLflow after the analysis):
    ``None``/``"default"`` is the default sqlite store; otherwise ``sqlite:///FILE`` (FILE's folder
    is checked like an output path), ``file:///FOLDER`` or a plain folder path, ``http(s)://HOST``,
    ``databricks``. InputError naming ``key`` otherwise."""
    from ..runfolder import check_new_path
    uri = DEFAULT_TRACKING_URI if uri in (None, "", "default") else uri
    scheme = uri.split("://", 1)[0] if "://" in uri else ("databricks" if uri == "databricks" else "")
    if scheme == "sqlite":
        if not uri.startswith("sqlite:///") or len(uri) == len("sqlite:///"):
            raise InputError(f"{uri!r}: expected sqlite:///PATH/TO/FILE.db", key=key)
        check_new_path(uri[len("sqlite:///"):], key=key, folder=False)
    elif scheme == "file":
        check_new_path(uri[len("file://"):], key=key, folder=True)
    elif scheme in ("http", "https"):
        if not uri.split("://", 1)[1].strip("/"):
            raise InputError(f"{uri!r}: expected {scheme}://HOST[:PORT]", key=key)
    elif scheme == "":
        check_new_path(uri, key=key, folder=True)       # a plain path: MLflow's file store
    elif scheme != "databricks":
        raise InputError(f"{uri!r}: unknown tracking URI scheme {scheme!r}; expected one of "
                         f"{', '.join(URI_SCHEMES)} (e.g. sqlite:///reports/mlruns.db)", key=key)
    return uri


def check_tracking(uri: str | None, key: str) -> str:
    """Before a run that will be tracked: the URI is usable (:func:`check_uri`) and MLflow installed."""
    uri = check_uri(uri, key)
    _import_mlflow()
    check_reachable(uri, key)       # before the analysis, not after it
    return uri


def resolve_uri(uri: str | None) -> str:
    """``None``/``"default"`` → the default sqlite store; a sqlite file's folder is created."""
    uri = check_uri(uri)
    if uri.startswith("sqlite:///"):
        try:
            Path(uri[len("sqlite:///"):]).parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{uri}: cannot create the folder of the database: {exc.strerror}", key="--uri") from None
    return uri


REACH_TIMEOUT_S = 5.0    # seconds to open a TCP connection to an http(s) tracking server


def check_reachable(uri: str, key: str = "--uri") -> None:
    """An http(s) tracking server must accept a TCP connection within ``REACH_TIMEOUT_S``: MLflow's client
    retries a refused connection with exponential backoff (7 retries, about 4 minutes, meant for a
    rate-limiting server), so an unreachable address took 247 s to fail (an independent probe). A server
    that answers keeps MLflow's retries."""
    import socket
    from urllib.parse import urlsplit
    parts = urlsplit(uri)
    if parts.scheme not in ("http", "https"):
        return
    try:
        host, port = parts.hostname, parts.port or (443 if parts.scheme == "https" else 80)
    except ValueError as exc:
        raise InputError(f"{uri}: {exc}", key=key) from None
    if not host:
        raise InputError(f"{uri}: expected a host, as in http://HOST:PORT", key=key)
    try:
        socket.create_connection((host, port), timeout=REACH_TIMEOUT_S).close()
    except OSError as exc:
        raise InputError(f"cannot reach the tracking server {host}:{port} ({exc.strerror or type(exc).__name__}); "
                         "is it running? (mlflow server --port PORT)", key=key) from None


def _artifact_location(uri: str) -> str | None:
    if uri.startswith("sqlite:///"):
        return (Path(uri[len("sqlite:///"):]).resolve().parent / "mlartifacts").as_uri()
    return None


def params_of(config: dict) -> dict[str, str]:
    out = {}
    for k, v in flatten(config).items():
        s = v if isinstance(v, str) else json.dumps(v)
        out[_key(k)] = s if len(s) <= _PARAM_MAX else s[:_PARAM_MAX - 1] + "…"
    return out


def metrics_of(summary: dict) -> dict[str, float]:
    return {_key(k): float(v) for k, v in flatten(dvc_metrics(summary)).items()}


def tags_of(summary: dict, manifest: dict) -> dict[str, str]:
    diag = summary.get("diagnosis") or {}
    f = diag.get("findings") or []
    git = manifest.get("git") or {}
    tags = {"verdict": diag.get("verdict"), "main_cause": f[0].get("family") if f else "none",
            "sysid.run_id": summary.get("run_id"), "sysid.data_sha256": summary.get("data_sha256"),
            "sysid.config_sha256": summary.get("config_sha256"), "sysid.created": manifest.get("created"),
            "sysid.selected_model": summary.get("selected_model"),
            "mlflow.source.git.commit": git.get("commit")}
    return {k: str(v) for k, v in tags.items() if v is not None}


def _chunks(items: list, n: int):
    for i in range(0, len(items), n):
        yield items[i:i + n]


def read_run(folder: Path) -> tuple[dict, dict, dict]:
    """(summary, manifest, resolved config) of a run folder; InputError naming the folder when one is
    missing or unreadable (``track`` reads every folder before it logs any)."""
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
        config = yaml.safe_load((folder / "config.resolved.yaml").read_text(encoding="utf-8")) or {}
    except (OSError, ValueError, yaml.YAMLError) as exc:
        raise InputError(f"not a complete run folder ({exc})", file=str(folder)) from None
    if not all(isinstance(x, dict) for x in (summary, manifest, config)):
        raise InputError("not a complete run folder (summary.json, manifest.json and config.resolved.yaml "
                         "must each hold a mapping)", file=str(folder))
    return summary, manifest, config


def log_run(folder: str | Path, tracking_uri: str | None = None, experiment: str = EXPERIMENT) -> str:
    """Log one run folder; returns the MLflow run id."""
    MlflowClient = _import_mlflow()
    folder = Path(folder)
    summary, manifest, config = read_run(folder)
    uri = resolve_uri(tracking_uri)
    if not experiment or not experiment.strip():
        raise InputError("expected a non-empty experiment name", key="--experiment")
    check_reachable(uri)
    try:
        return _log(MlflowClient(tracking_uri=uri), folder, summary, manifest, config, uri, experiment)
    except InputError:
        raise
    except Exception as exc:   # the tracking store failed (unreachable, locked, refused): not the analysis
        if not _from_tracking_store(exc):
            raise
        raise InputError(f"MLflow could not log the run to {uri}: {type(exc).__name__}: "
                         f"{str(exc).splitlines()[0][:300] if str(exc) else ''}", key="--uri") from None


def _from_tracking_store(exc: BaseException) -> bool:
    """Is ``exc`` the tracking store's own failure (MLflow, SQLAlchemy, the network, the disk)?"""
    mod = type(exc).__module__ or ""
    return isinstance(exc, OSError) or mod.split(".")[0] in ("mlflow", "sqlalchemy", "requests", "urllib3")


def _log(client, folder: Path, summary: dict, manifest: dict, config: dict, uri: str, experiment: str) -> str:
    from mlflow.entities import Metric, Param, RunTag
    exp = client.get_experiment_by_name(experiment)
    exp_id = exp.experiment_id if exp else client.create_experiment(experiment, artifact_location=_artifact_location(uri))
    tags = tags_of(summary, manifest)
    flt = " and ".join(f"tags.`{k}` = '{tags[k]}'" for k in ("sysid.run_id", "sysid.created") if k in tags)
    if flt:
        prev = client.search_runs([exp_id], filter_string=flt, max_results=1)
        if prev:
            return prev[0].info.run_id
    run = client.create_run(exp_id, run_name=str(summary.get("run_id") or folder.name))
    rid = run.info.run_id
    ts = int(time.time() * 1000)
    metrics = [Metric(k, v, ts, 0) for k, v in metrics_of(summary).items()]
    params = [Param(k, v) for k, v in params_of(config).items()]
    tag_list = [RunTag(k, v) for k, v in tags.items()]
    for part in _chunks(params, 100):
        client.log_batch(rid, params=part)
    for part in _chunks(metrics, 1000):
        client.log_batch(rid, metrics=part)
    for part in _chunks(tag_list, 100):
        client.log_batch(rid, tags=part)
    client.log_artifacts(rid, str(folder))
    client.set_terminated(rid)
    return rid


def search(tracking_uri: str | None = None, experiment: str = EXPERIMENT) -> Any:
    """``mlflow.search_runs`` on the store (a pandas DataFrame)."""
    _import_mlflow()
    import mlflow
    uri = resolve_uri(tracking_uri)
    check_reachable(uri)
    old = os.environ.get("MLFLOW_TRACKING_URI")
    mlflow.set_tracking_uri(uri)
    try:
        return mlflow.search_runs(experiment_names=[experiment])
    finally:
        if old is not None:
            mlflow.set_tracking_uri(old)
